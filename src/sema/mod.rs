//! Stage 2: AST -> checked [`Model`]: name resolution and every semantic check.

pub mod model;

pub use model::*;
