//! Stage 3: the hash-consed expression DAG, simplification, differentiation, the reference
//! evaluator and infix display. Knows no spans, no IO and no Cranelift.

pub mod diff;
pub mod display;
pub mod enclose;
pub mod eval;
pub mod finite;
pub mod functions;
pub mod node;
pub mod simplify;
pub mod store;
pub mod vjp_dir;

pub use diff::{diff, Differentiator, Var};
pub use display::{to_infix, to_infix_capped, to_infix_group, Group};
pub use enclose::Enclosure;
pub use eval::{
    apply_binary, apply_lookup, apply_select, apply_unary, eval, eval_one, lookup_weights, scatter_lookup,
    Tape,
};
pub use finite::finite_at_finite_inputs;
pub use functions::*;
pub use node::*;
pub use store::*;
pub use vjp_dir::{flow_vjp_dir_terms, VjpDirTerms};
