//! Stage 3: the hash-consed expression DAG, simplification, differentiation, the reference
//! evaluator and infix display. Knows no spans, no IO and no Cranelift.

pub mod functions;
pub mod node;
pub mod store;

pub use functions::*;
pub use node::*;
pub use store::*;
