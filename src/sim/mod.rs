//! Stage 5: the event-locating integrator with forward sensitivities. Depends only on the
//! [`HybridSystem`] trait, never on Cranelift.
//!
//! Code map: `options` (what to ask), `tableau` + `rk` (adaptive Runge-Kutta stepping),
//! `dense` (interpolation inside a step), `events` (detection and root finding), `jump` (event
//! time gradients and saltation), `run` (the driver), `result` (what a run reports).

mod dense;
mod events;
mod jump;
mod options;
mod result;
mod rk;
mod run;
mod sums;
pub mod system;
mod tableau;

pub use options::*;
pub use result::*;
pub use run::{run, Simulator, SystemRef};
pub use system::*;
