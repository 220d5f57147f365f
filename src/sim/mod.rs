//! Stage 5: the event-locating integrator with forward sensitivities. Depends only on the
//! [`HybridSystem`] trait, never on Cranelift.
//!
//! Code map (three wings and the run's core):
//! - `method/` (how one step is taken: the `Stepper` seam, the explicit pairs and Rosenbrock
//!   methods, their interpolants, `Auto`, the error norm, the polynomials of a dense output);
//!   code map in `method/mod.rs`.
//! - `event/` (detection along a step, root finding, jumps and saltation, Zeno); code map in
//!   `event/mod.rs`.
//! - `linalg/` (the Rosenbrock step's linear solves: dense, banded, sparse LU); code map in
//!   `linalg/mod.rs`.
//! - `system.rs`: the `HybridSystem` contract and `SystemInfo`.
//! - `options.rs`: what to ask (`SimOptions`).
//! - `integrator.rs`: the state of a run and its `step`, a state machine over a stepper.
//! - `mode_rhs.rs`: a mode's flow with its sensitivities as the stepper's right-hand side.
//! - `switch_landing.rs`: `SwitchLanding`, a step retried to land just before a flow switch it
//!   crossed (branch locking by cutting), owned by the integrator.
//! - `breakpoints.rs`: times landed on exactly, and events on or near them.
//! - `recorder.rs`: trajectories through an observer; the adjoint tape's entries.
//! - `adjoint/`: gradients by the discrete adjoint: a run recorded on a tape without
//!   sensitivities, walked backward once per quantity.
//! - `samples.rs`: the values at `SimOptions::at`, taken as the run passes them and completed
//!   once it is over.
//! - `run.rs`: a run from start to end, the reusable `Runner`.
//! - `fp_mode.rs`: IEEE arithmetic (subnormals kept) for the length of each entry into a run,
//!   whatever the calling thread set (XLA's threads flush them).
//! - `result.rs`: what a run reports.
//!
//! Imports between the wings go one way: `event/` uses `method/`'s `Interpolant` and `Stepper`
//! traits and its polynomials, `method/` uses `linalg/`, and `linalg/` uses neither.

pub mod adjoint;
mod breakpoints;
mod event;
mod fp_mode;
mod integrator;
mod knots;
mod linalg;
mod method;
mod mode_rhs;
mod options;
mod recorder;
mod result;
mod run;
mod samples;
mod switch_landing;
pub mod system;

pub use integrator::{Integrator, StepOutcome};
pub use linalg::linsolve::{FactorCosts, LinearSolver, SPARSE_COST, SPARSE_MIN_STATES};
pub use method::auto::{Auto, AutoDense};
pub use method::dense::Dense;
pub use method::rk::Rk;
pub use method::rosenbrock::{Rosenbrock, RowDense};
pub use method::stepper::{Interpolant, Rhs, Stepper, TapePair};
pub use options::*;
pub use recorder::{
    NoRecorder, Point, PointKind, Recorder, RowSchedule, TapeEntry, TapeSample, TapeStep, TrajectoryRecorder,
};
pub use result::*;
pub use run::{run, Driver, Runner, SystemRef, MAX_SAMPLED_ROWS, MIN_RTOL};
pub use system::*;

/// The distance from `|t|` to the next float: the resolution of time (or of any value) there.
/// Every search that steps or tolerates "a few spacings of `t`" measures them with this.
pub(crate) fn spacing(t: f64) -> f64 {
    let a = t.abs().max(f64::MIN_POSITIVE);
    a.next_up() - a
}
