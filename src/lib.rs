//! hybc: a compiler for hybrid dynamical models with exact gradients through events.
//!
//! Pipeline: `syntax` (text -> AST) -> `sema` (AST -> checked model) -> `expr` (model functions
//! and their symbolic derivatives as a DAG) -> `codegen` (DAG -> native kernels) -> `sim`
//! (event-locating integrator with sensitivities).

pub mod codegen;
pub mod expr;
pub mod lower;
pub mod sema;
pub mod sim;
pub mod syntax;
