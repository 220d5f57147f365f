//! Stage 5: the event-locating integrator with forward sensitivities. Depends only on the
//! [`HybridSystem`] trait, never on Cranelift.
//!
//! Code map: `options` (what to ask); `stepper` (the seam any method implements), `tableau`,
//! `sums`, `rk` and `dense` (the explicit Runge-Kutta pairs and their interpolants); `row_tableau`
//! and `rosenbrock` (the Rosenbrock methods for stiff flows, with their interpolant);
//! `integrator` (the state of a run and its `step`), `breakpoints` (times landed on exactly),
//! `events` (detection), `poly` (a guard along a dense output), `roots` (root finding), `jump`
//! (event-time gradients and saltation), `zeno` (accumulating events), `recorder` (trajectories
//! through an observer); `run` (a run from start to end, the reusable `Simulator`), `result`
//! (what a run reports).

mod auto;
mod breakpoints;
mod dense;
mod errnorm;
mod events;
mod integrator;
mod jump;
mod linsolve;
mod options;
mod poly;
mod recorder;
mod result;
mod rk;
mod roots;
mod rosenbrock;
mod row_tableau;
mod run;
mod samples;
mod sparse_lu;
mod stepper;
mod sums;
pub mod system;
mod tableau;
mod zeno;

pub use auto::{Auto, AutoDense};
pub use dense::Dense;
pub use integrator::{Integrator, StepOutcome};
pub use linsolve::{FactorCosts, LinearSolver, SPARSE_COST, SPARSE_MIN_STATES};
pub use options::*;
pub use recorder::{NoRecorder, Point, PointKind, Recorder, RowSchedule, TrajectoryRecorder};
pub use result::*;
pub use rk::Rk;
pub use rosenbrock::{Rosenbrock, RowDense};
pub use run::{run, Driver, Simulator, SystemRef, MAX_SAMPLED_ROWS, MIN_RTOL};
pub use stepper::{Interpolant, Rhs, Stepper};
pub use system::*;
