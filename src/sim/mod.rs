//! Stage 5: the event-locating integrator with forward sensitivities. Depends only on the
//! [`HybridSystem`] trait, never on Cranelift.

mod dense;
mod options;
mod rk;
mod tableau;
pub mod system;

pub use options::*;
pub use system::*;
