//! The `status` output of a JAX call: why a point's numbers are what they are, as a small integer
//! (traced code cannot raise). The mapping is a contract shared with `hybc/jax.py` (`STATUS`) and
//! docs/python.md; `python/tests/test_jax.py` reaches every code but `stuck` and `non_finite`
//! (both decided by `hybc::status::RunStatus::of`; `non_finite` sweep rows: tests/it/limits.rs).

use hybc::sim::{SimResult, SystemInfo};
use hybc::status::RunStatus;

/// The run reached `t_end` (or a `stop` event) and every derivative asked for exists.
pub const OK: i32 = 0;
/// The run is complete but an event grazed its guard: the derivatives that depend on its time
/// are NaN (values are exact).
pub const GRAZING: i32 = 1;
/// The run is complete but some derivative stopped existing (a flow switch at an event instant,
/// or a flow whose derivative is not finite): those derivatives are NaN.
pub const NOT_DIFFERENTIABLE: i32 = 2;
/// Events accumulate (Zeno) before `t_end`: the final values do not exist (NaN); the events that
/// fired before are reported.
pub const ZENO: i32 = 3;
/// The state cannot leave an event's guard, or events keep firing at one instant: final values NaN.
pub const STUCK: i32 = 4;
/// `max_events` events fired before `t_end`: final values NaN.
pub const MAX_EVENTS: i32 = 5;
/// The integration failed (step size underflow, too many steps, a non-finite state): final
/// values NaN.
pub const FAULT: i32 = 6;
/// An input parameter is not finite or outside its declared range: nothing was run, all NaN.
pub const BAD_PARAM: i32 = 7;
/// The run is complete but a final state or output is NaN or infinite.
pub const NON_FINITE: i32 = 8;

/// The status of a finished run: the code of its `hybc::status::RunStatus`, the word Python's
/// `Run.status` and the sweep rows print for the same run.
pub fn of_run(info: &SystemInfo, result: &SimResult) -> i32 {
    match RunStatus::of(info, result) {
        RunStatus::Ok => OK,
        RunStatus::Grazing => GRAZING,
        RunStatus::NotDifferentiable => NOT_DIFFERENTIABLE,
        RunStatus::NonFinite => NON_FINITE,
        RunStatus::Zeno => ZENO,
        RunStatus::Stuck => STUCK,
        RunStatus::MaxEvents => MAX_EVENTS,
        RunStatus::Fault => FAULT,
    }
}
