//! Stage 5: the event-locating integrator with forward sensitivities. Depends only on the
//! [`HybridSystem`] trait, never on Cranelift.

pub mod system;

pub use system::*;
