//! Stage 5 (sim): what a run reports: events with their time gradients, the final state with its
//! sensitivities, why the run stopped, warnings, statistics and an optional trajectory. Plain
//! serialisable data; knows nothing of how it was computed.
//!
//! Sensitivity layouts follow `system.rs`: `dstate[j * n + i] = dx_i/dp_j`,
//! `doutputs[j * k + i] = dy_i/dp_j`, `dtime[j] = dt_e/dp_j`, `j` over the grad parameters.
//! Gradients that do not exist (after a grazing event) are `None`, never NaN.

use serde::Serialize;
use std::fmt;
use std::sync::Arc;

/// Errors of a simulation: bad input (returned by `run`) and runtime faults (carried by
/// [`StopReason::Fault`] next to everything computed before them).
#[derive(Clone, Debug, PartialEq, thiserror::Error, Serialize)]
pub enum SimError {
    #[error("parameter vector has {got} values, the model needs {expected}")]
    ParamLength { expected: usize, got: usize },
    #[error("option `{name}` has invalid value {value}")]
    InvalidOption { name: &'static str, value: f64 },
    #[error("model shape is inconsistent: {what} index {index} out of range (count {count})")]
    BadIndex { what: &'static str, index: usize, count: usize },
    #[error("step size underflow at t = {t} (h = {h}) in mode {mode}, state {state:?}")]
    StepTooSmall { t: f64, h: f64, mode: usize, state: Vec<f64> },
    #[error("more than {max_steps} steps at t = {t} in mode {mode}, state {state:?}")]
    TooManySteps { t: f64, max_steps: usize, mode: usize, state: Vec<f64> },
    #[error("non-finite state at t = {t} in mode {mode}: {state:?}")]
    NonFinite { t: f64, mode: usize, state: Vec<f64> },
}

/// Non-fatal findings.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum SimWarning {
    /// The guard was crossed (or touched) at a speed too small for its time gradient to exist;
    /// this event's and all later gradients are `None`.
    Grazing { event: usize, name: Arc<str>, time: f64, denominator: f64, scale: f64 },
    /// A flow switch was crossed at the instant of a declared event that had already changed the
    /// state or the mode, so the flow before the switch is not known; all later gradients are
    /// `None`.
    SwitchAtEvent { name: Arc<str>, time: f64 },
}

impl fmt::Display for SimWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SimWarning::Grazing { name, time, denominator, scale, .. } => write!(
                f,
                "event `{name}` grazes its guard at t = {time} (crossing speed {denominator:e}, \
                 scale {scale:e}): gradients from here on are not meaningful"
            ),
            SimWarning::SwitchAtEvent { name, time } => write!(
                f,
                "`{name}` was crossed at t = {time} together with an event that changed the state \
                 or the mode: gradients from here on are not meaningful"
            ),
        }
    }
}

/// One fired event.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EventRecord {
    /// Position in the run's event sequence (0-based).
    pub index: usize,
    /// Event id (index into `SystemInfo::events`).
    pub event: usize,
    pub name: Arc<str>,
    pub time: f64,
    pub mode_before: usize,
    pub mode_after: usize,
    /// `dt_e/dp_j` per grad parameter; `None` when grazing or after a grazing event.
    pub dtime: Option<Vec<f64>>,
    pub grazing: bool,
    /// Crossing speed `g_x f- + g_t` (the denominator of `dtime`).
    pub denominator: f64,
}

/// The state where the run stopped.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FinalState {
    pub time: f64,
    pub mode: usize,
    pub state: Vec<f64>,
    /// Sensitivities at fixed time (n * m); `None` after a grazing event.
    pub dstate: Option<Vec<f64>>,
    pub outputs: Vec<f64>,
    /// `y_x dstate + y_p` (k * m).
    pub doutputs: Option<Vec<f64>>,
    /// For a stop event: the total derivative of the final state including the motion of the
    /// stopping time, `R_x (S- + f- dt/dp) + R_p + R_t dt/dp` (= `S- + f- dt/dp` for an
    /// identity reset).
    pub dstate_total: Option<Vec<f64>>,
    /// For a stop event: `y_x dstate_total + y_p + y_t dt/dp`.
    pub doutputs_total: Option<Vec<f64>>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum StopReason {
    /// Reached `t_end`.
    TEnd,
    /// A stop event fired.
    Event {
        event: usize,
        name: Arc<str>,
    },
    /// Too many events in a short window, or `max_events`.
    Zeno {
        time: f64,
        event: usize,
        count: usize,
        /// Geometric extrapolation of the last inter-event intervals, when they shrink.
        accumulation: Option<f64>,
    },
    Fault {
        error: SimError,
    },
}

#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SimStats {
    /// Accepted steps.
    pub steps: usize,
    pub rejected: usize,
    /// Right-hand side (`flow_sens`) evaluations by the stepper.
    pub rhs_calls: usize,
    pub events: usize,
    /// Flow switches crossed (implicit events, not in `events`).
    pub switches: usize,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TrajectoryRow {
    pub t: f64,
    pub mode: usize,
    pub x: Vec<f64>,
    /// Sensitivities (n * m).
    pub s: Vec<f64>,
    pub outputs: Vec<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SimResult {
    pub events: Vec<EventRecord>,
    #[serde(rename = "final")]
    pub final_state: FinalState,
    pub stopped_by: StopReason,
    pub warnings: Vec<SimWarning>,
    pub stats: SimStats,
    pub trajectory: Option<Vec<TrajectoryRow>>,
}
