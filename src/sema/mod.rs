//! Stage 2: AST -> checked [`Model`]: name resolution and every semantic check.

mod check;
mod error;
pub mod lint;
pub mod model;
mod names;
mod quadrature;
mod switches;
mod walk;

pub use check::check;
pub use error::CheckError;
pub use model::*;
pub use names::closest as closest_name;
pub use quadrature::quadrature_states;
