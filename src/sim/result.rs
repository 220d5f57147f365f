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

use super::options::GradientsOf;
use super::system::SystemInfo;

/// Errors of a simulation: bad input (returned by `run`) and runtime faults (carried by
/// [`StopReason::Fault`] next to everything computed before them).
#[derive(Clone, Debug, PartialEq, thiserror::Error, Serialize)]
pub enum SimError {
    /// The parameter vector is not as long as the model's parameters.
    #[error("parameter vector has {got} values, the model needs {expected}")]
    ParamLength {
        /// The model's parameters.
        expected: usize,
        /// The values given.
        got: usize,
    },
    /// An option's value is refused (`sim::run` checks its own options).
    #[error("option `{name}` has invalid value {value}")]
    InvalidOption {
        /// The option.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    #[error(
        "sample time {t} is not in order within the run: sample times are ascending, from t_start = {t_start} \
         to t_end = {t_end} (the one before is {previous})"
    )]
    /// A sample time (`SimOptions::at`) out of order or outside the run.
    SampleTime {
        /// The time.
        t: f64,
        /// The run's start.
        t_start: f64,
        /// The run's end.
        t_end: f64,
        /// The sample time before it.
        previous: f64,
    },
    /// The system describes itself inconsistently (an index past its count).
    #[error("model shape is inconsistent: {what} index {index} out of range (count {count})")]
    BadIndex {
        /// What the index is of.
        what: &'static str,
        /// The index.
        index: usize,
        /// How many there are.
        count: usize,
    },
    // The runtime faults: one wording, `fault_text`, with names (`describe`) or indices (here).
    /// A fault: the step size fell below the resolution of time.
    #[error("{}", self.fault_text(None))]
    StepTooSmall {
        /// The time it happened.
        t: f64,
        /// The step size.
        h: f64,
        /// The mode it happened in (index).
        mode: usize,
        /// The state there.
        state: Vec<f64>,
        /// The relative tolerance.
        rtol: f64,
        /// The absolute tolerance.
        atol: f64,
    },
    /// A fault: `max_steps` attempts were made.
    #[error("{}", self.fault_text(None))]
    TooManySteps {
        /// The time it happened.
        t: f64,
        /// The cap.
        max_steps: usize,
        /// The mode it happened in (index).
        mode: usize,
        /// The state there.
        state: Vec<f64>,
    },
    /// A fault: the state stopped being finite.
    #[error("{}", self.fault_text(None))]
    NonFinite {
        /// The time it happened.
        t: f64,
        /// The mode it happened in (index).
        mode: usize,
        /// The state there.
        state: Vec<f64>,
    },
    /// A fault: a guard stopped being finite before any crossing.
    #[error("{}", self.fault_text(None))]
    GuardNotFinite {
        /// The guard's event's name.
        event: Arc<str>,
        /// The time it happened.
        t: f64,
        /// The mode it happened in (index).
        mode: usize,
        /// The state there.
        state: Vec<f64>,
    },
    /// A fault: the knots of an input of the current mode cannot be timed (its window has no
    /// length, or an end that is not finite).
    #[error("{}", self.fault_text(None))]
    KnotsNotFinite {
        /// The input: `pwl(t, .., u)`.
        input: Arc<str>,
        /// The time it happened.
        t: f64,
        /// The mode it happened in (index).
        mode: usize,
        /// The state there.
        state: Vec<f64>,
    },
    #[error(
        "rtol {rtol:e} cannot be met: below {floor:e} the error estimates are round-off in double precision"
    )]
    /// `rtol` below what double precision can resolve.
    ToleranceTooSmall {
        /// The tolerance asked for.
        rtol: f64,
        /// The smallest that can be met.
        floor: f64,
    },
    /// A Rosenbrock method asked for, and the flow's Jacobian could not be compiled.
    #[error("the method {method} needs the flow's Jacobian, which this model could not provide: {reason}")]
    NoJacobians {
        /// The method's name.
        method: &'static str,
        /// Why the Jacobian is missing.
        reason: String,
    },
    /// Forward sensitivities asked for, and the kernel of their right-hand side could not be
    /// compiled.
    #[error(
        "the forward sensitivities need their right-hand side, which this model could not provide: {reason}"
    )]
    NoSensitivities {
        /// Why it is missing.
        reason: String,
    },
    #[error(
        "a trajectory sampled every {dt:e} from t = {t_start} to {t_end} has {rows:.0} rows, more than the \
         {cap:.0} a run keeps in memory (sample more coarsely)"
    )]
    /// A trajectory sampled so finely that its rows exceed what a run keeps.
    TooManyRows {
        /// The sampling interval.
        dt: f64,
        /// The run's start.
        t_start: f64,
        /// The run's end.
        t_end: f64,
        /// The rows it would hold.
        rows: f64,
        /// The most a run keeps.
        cap: f64,
    },
}

impl SimError {
    /// The message with the mode and the states named, as every message of hybc gives them
    /// (`at t = 0 in mode main, state y = 1, v = 0`); the `Display` form, without the model's
    /// names, says `in mode 0, state x[0] = 1, x[1] = 0` in the same words.
    pub fn describe(&self, info: &SystemInfo) -> String {
        self.fault_text(Some(info))
    }

    /// The one formatting of every error, runtime faults with where they happened.
    fn fault_text(&self, info: Option<&SystemInfo>) -> String {
        let at = |t: f64, mode: usize, state: &[f64]| match info {
            Some(info) => {
                format!("at t = {t} in mode {}, state {}", mode_name(info, mode), named_state(info, state))
            }
            None => {
                let pairs: Vec<String> =
                    state.iter().enumerate().map(|(i, v)| format!("x[{i}] = {}", short(*v))).collect();
                format!("at t = {t} in mode {mode}, state {}", pairs.join(", "))
            }
        };
        match self {
            SimError::StepTooSmall { t, h, mode, state, rtol, atol } => format!(
                "step size underflow (h = {h:e}) {}: the tolerances rtol {rtol:e}, atol {atol:e} cannot be met \
                 there (a state at or near 0 takes atol as its scale; loosen them)",
                at(*t, *mode, state)
            ),
            SimError::TooManySteps { t, max_steps, mode, state } => {
                format!("more than {max_steps} steps {}", at(*t, *mode, state))
            }
            SimError::NonFinite { t, mode, state } if state.iter().all(|v| v.is_finite()) => format!(
                "every step attempted from a finite state gave values that are not finite {}: the flow (or, \
                 under a Rosenbrock method, its Jacobian: `der(y) = sqrt(x)` at x = 0) is not finite just \
                 there or beyond",
                at(*t, *mode, state)
            ),
            SimError::NonFinite { t, mode, state } => format!("non-finite state {}", at(*t, *mode, state)),
            SimError::GuardNotFinite { event, t, mode, state } => format!(
                "the guard of event `{event}` stops being finite {}: whether it crosses zero beyond that cannot be told",
                at(*t, *mode, state)
            ),
            SimError::KnotsNotFinite { input, t, mode, state } => format!(
                "the knots of `{input}` are not finite {}: its window must have two different, finite ends",
                at(*t, *mode, state)
            ),
            other => other.to_string(),
        }
    }
}

/// `name = value` for every state.
pub(crate) fn named_state(info: &SystemInfo, state: &[f64]) -> String {
    let pairs: Vec<String> =
        info.state_names.iter().zip(state).map(|(n, v)| format!("{n} = {}", short(*v))).collect();
    pairs.join(", ")
}

/// `final values not finite: energy = inf, y = NaN` for the final states and outputs that are not
/// finite numbers (a run can end as asked with an output such as `1 / y` at `y = 0`); `None` when
/// all are finite.
pub fn non_finite_finals(info: &SystemInfo, f: &FinalState) -> Option<String> {
    let bad: Vec<String> = info
        .state_names
        .iter()
        .zip(&f.state)
        .chain(info.output_names.iter().zip(&f.outputs))
        .filter(|(_, v)| !v.is_finite())
        .map(|(n, v)| format!("{n} = {}", short(*v)))
        .collect();
    (!bad.is_empty()).then(|| {
        format!(
            "final values not finite at t = {} in mode {}: {}",
            short(f.time),
            mode_name(info, f.mode),
            bad.join(", ")
        )
    })
}

fn mode_name(info: &SystemInfo, mode: usize) -> &str {
    info.modes.get(mode).map_or("?", |m| m.name.as_str())
}

/// A number with ten significant digits, without trailing zeros: the form every message and
/// table of hybc prints numbers in.
pub fn short(v: f64) -> String {
    if v == 0.0 {
        return "0".to_string(); // also for -0.0, which says nothing a reader needs
    }
    if !v.is_finite() {
        return format!("{v}");
    }
    let a = v.abs();
    if (1e-4..1e7).contains(&a) {
        let decimals = (9 - a.log10().floor() as i32).max(0) as usize;
        let s = format!("{v:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        format!("{v:.9e}")
    }
}

/// Non-fatal findings.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum SimWarning {
    /// The guard was crossed (or touched) too slowly for its time to be told apart from a touch
    /// at the run's tolerances (`conditioning = |g''| delta / d^2 >= graze_tol`): its time gradient
    /// does not exist, nor does any later derivative that depends on it.
    Grazing {
        /// The event (index into `SystemInfo::events`).
        event: usize,
        /// The event's name.
        name: Arc<str>,
        /// When.
        time: f64,
        /// The crossing speed `d`.
        denominator: f64,
        /// `|g''| delta / d^2`.
        conditioning: f64,
    },
    /// A crossing resolved by the tolerances but close to a touch: its gradients are exact but
    /// hold only while parameter changes move the guard's extremum by less than `margin`.
    NearGrazing {
        /// The event (index into `SystemInfo::events`).
        event: usize,
        /// The event's name.
        name: Arc<str>,
        /// When.
        time: f64,
        /// How far the guard's extremum is from zero.
        margin: f64,
    },
    /// A flow switch was crossed at the instant of a declared event that had already changed the
    /// state or the mode, so the flow before the switch is not known; no later derivative exists.
    SwitchAtEvent {
        /// The switch's name.
        name: Arc<str>,
        /// When.
        time: f64,
    },
    /// A declared event fired on an input knot where the flow jumps (a `pwc` knot, at the
    /// instant the step lands on it): where a parameter moves the event off the knot, the two meet
    /// in either order on the two sides of it, and the derivatives that differ between the two
    /// (the event time's, where the flow it crosses at jumps) do not exist from here on.
    EventAtKnot {
        /// The event (index into `SystemInfo::events`).
        event: usize,
        /// The event's name.
        name: Arc<str>,
        /// When.
        time: f64,
        /// The input: `pwc(t, .., u)`.
        input: Arc<str>,
    },
    /// Knots of inputs that move apart with a parameter meet at `time`, where the flow jumps:
    /// the derivatives with respect to such a parameter do not exist from here on (the flow
    /// between the two knots is neither input's jump).
    KnotsApart {
        /// The inputs, `pwc(t, .., u), pwc(t, .., w)`.
        inputs: Arc<str>,
        /// When.
        time: f64,
    },
    /// The derivative `d state / d param` (and `count - 1` others) stopped existing at `time`:
    /// the flow's derivative, or the initial state's, is not finite at a finite state there.
    NotDifferentiable {
        /// When.
        time: f64,
        /// The state whose derivative stopped existing.
        state: Arc<str>,
        /// The parameter it is with respect to.
        param: Arc<str>,
        /// How many derivatives stopped existing there.
        count: usize,
        /// What the flow's derivative is there, where it is known.
        cause: VoidCause,
    },
    /// The run starts strictly on the crossed side of a directional guard (the ball below its
    /// floor): the event fires only after the guard has gone back to its pre-crossing side, which
    /// is rarely what the model means. The run goes on.
    StartsAcross {
        /// The event (index into `SystemInfo::events`).
        event: usize,
        /// The event's name.
        name: Arc<str>,
        /// When.
        time: f64,
        /// The guard's value at the start.
        guard: f64,
    },
    /// A cascade: the event fired at an instant because a reset there put the state on its guard
    /// to round-off, with the flow carrying it across. Parameter changes that land the state
    /// before the guard make it fire later, by the flow; across it, at the instant: the one-sided
    /// derivatives differ, so its time derivative does not exist, nor does any later derivative
    /// that depends on it.
    ResetOntoGuard {
        /// The event (index into `SystemInfo::events`).
        event: usize,
        /// The event's name.
        name: Arc<str>,
        /// When.
        time: f64,
    },
    /// The event fired within `margin` (round-off, below `1e-9 max(|t|, 1)`) before a breakpoint
    /// where the run's values jump or end: `t_end`, or a time event. A parameter change that
    /// moves it past the breakpoint changes the final values by a jump (it leaves the run, or
    /// fires in the other order), so its derivatives hold only while the event moves by less
    /// than `margin`; `margin` 0 is on the breakpoint itself (a cusp; at `t_end` the other side's
    /// values are in `SimResult::end_cusp`).
    NearBreakpoint {
        /// The event (index into `SystemInfo::events`).
        event: usize,
        /// The event's name.
        name: Arc<str>,
        /// When.
        time: f64,
        /// The breakpoint: `t_end` or the time event's name.
        breakpoint: Arc<str>,
        /// How far before the breakpoint it fired.
        margin: f64,
    },
    /// A running cost (a quadrature state), left out of the step-size error test, had a local
    /// error estimate above its tolerance on `steps` accepted steps (the worst `worst` times the
    /// tolerance, on the step from `time`): its value and derivatives may be less accurate than
    /// `rtol` asks. `SimOptions::quadrature_error_control` puts it back in the test.
    CostUnresolved {
        /// The running cost's name.
        state: Arc<str>,
        /// On how many accepted steps.
        steps: usize,
        /// The largest error, in tolerances.
        worst: f64,
        /// The start of the worst step.
        time: f64,
    },
    /// `--sens adjoint` was asked for, but the run holds a piece the adjoint does not carry yet:
    /// the gradients are the forward sensitivities' (error-controlled as `sens_error_control`
    /// says).
    AdjointNotCarried {
        /// What the adjoint does not carry (`a step of a Rosenbrock method`, ...).
        what: &'static str,
    },
}

impl fmt::Display for SimWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SimWarning::Grazing { name, time, denominator, conditioning, .. } => write!(
                f,
                "event `{name}` grazes its guard at t = {time} (crossing speed {denominator:e}, \
                 conditioning {conditioning:e}): derivatives that depend on its time do not exist"
            ),
            SimWarning::NearGrazing { name, time, margin, .. } => write!(
                f,
                "event `{name}` nearly grazes its guard at t = {time}: its gradients hold only while \
                 parameter changes move the guard's extremum by less than {margin:e}"
            ),
            SimWarning::SwitchAtEvent { name, time } => write!(
                f,
                "`{name}` was crossed at t = {time} together with an event that changed the state \
                 or the mode: no derivative exists from here on"
            ),
            SimWarning::NearBreakpoint { name, time, breakpoint, margin, .. } if *margin == 0.0 => write!(
                f,
                "event `{name}` fired at t = {time}, on {breakpoint}: the final values are a cusp in the \
                 parameters (derivatives on the side where it fires{})",
                if breakpoint.as_ref() == "t_end" {
                    "; the other side's: final.without_end_events"
                } else {
                    ""
                }
            ),
            SimWarning::NearBreakpoint { name, time, breakpoint, margin, .. } => write!(
                f,
                "event `{name}` fired at t = {time}, {margin:e} before {breakpoint}: its derivatives hold \
                 only while parameter changes move it by less than that"
            ),
            SimWarning::ResetOntoGuard { name, time, .. } => write!(
                f,
                "event `{name}` fired at t = {time} because a reset put the state on its guard (to \
                 round-off): derivatives that depend on its time do not exist (they differ on the two \
                 sides of the guard)"
            ),
            SimWarning::StartsAcross { name, time, guard, .. } => write!(
                f,
                "the run starts on the crossed side of the guard of event `{name}` (t = {time}, guard \
                 {guard:e}): it fires only after the guard has gone back across zero; check the initial \
                 values"
            ),
            SimWarning::CostUnresolved { state, steps, worst, time } => write!(
                f,
                "running cost `{state}` is outside the step-size error test (the default) and its \
                 local error exceeded the tolerance on {steps} step{} (worst {worst:.3e} times, from \
                 t = {time}): it may be less accurate than --rtol; --quadrature-error-control puts \
                 it under the error test",
                if *steps == 1 { "" } else { "s" }
            ),
            SimWarning::EventAtKnot { name, time, input, .. } => write!(
                f,
                "event `{name}` fired at t = {time} on a knot of `{input}`, where the flow jumps: \
                 derivatives that move the event off the knot and differ on its two sides do not \
                 exist from here on"
            ),
            SimWarning::AdjointNotCarried { what } => {
                write!(f, "the adjoint does not carry {what} yet: the gradients are forward sensitivities")
            }
            SimWarning::KnotsApart { inputs, time } => write!(
                f,
                "knots of {inputs} meet at t = {time}, where the flow jumps: derivatives with respect \
                 to parameters that move them apart do not exist from here on"
            ),
            SimWarning::NotDifferentiable { time, state, param, count, cause } => {
                let others = if *count > 1 {
                    format!(" (and {} other derivatives)", count - 1)
                } else {
                    String::new()
                };
                match cause {
                    VoidCause::Indeterminate => write!(
                        f,
                        "d{state}/d{param}{others} is withheld from t = {time} on: the flow's derivative is \
                         indeterminate at the state there (0/0 or inf - inf, NaN); it may have a finite \
                         limit, which hybc does not take"
                    ),
                    VoidCause::Infinite => write!(
                        f,
                        "d{state}/d{param}{others} does not exist from t = {time} on: the flow's derivative is \
                         infinite at the state there"
                    ),
                    VoidCause::NotFinite => write!(
                        f,
                        "d{state}/d{param}{others} does not exist from t = {time} on: the flow's derivative is \
                         not finite at the state there"
                    ),
                }
            }
        }
    }
}

/// Why a sensitivity stopped being finite at a finite state ([`SimWarning::NotDifferentiable`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum VoidCause {
    /// The flow's derivative is infinite at the state (`ln x` at `x = 0`): the derivative does
    /// not exist.
    Infinite,
    /// The flow's derivative is NaN at the state (`x / sqrt(p x)` at `x = 0`): an indeterminate
    /// form whose limit may be finite; hybc withholds the derivative without saying it does not
    /// exist.
    Indeterminate,
    /// Found inside a step or at the start, where which of the two is not told.
    NotFinite,
}

/// One fired event.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EventRecord {
    /// Position in the run's event sequence (0-based).
    pub index: usize,
    /// Event id (index into `SystemInfo::events`).
    pub event: usize,
    /// The event's name.
    pub name: Arc<str>,
    /// When it fired.
    pub time: f64,
    /// The mode before it (index).
    pub mode_before: usize,
    /// The mode after it (index).
    pub mode_after: usize,
    /// `dt_e/dp_j` per grad parameter, NaN where it does not exist (a grazing event, or one whose
    /// guard reads a derivative that does not exist); `None` when none exists.
    pub dtime: Option<Vec<f64>>,
    /// Whether the crossing grazed its guard (no time gradient).
    pub grazing: bool,
    /// Crossing speed `g_x f- + g_t` (the denominator of `dtime`).
    pub denominator: f64,
    /// For a near-grazing crossing: the distance of the guard's extremum from zero.
    pub margin: Option<f64>,
    /// How well the time is known: the guard's accuracy at the tolerances over the crossing
    /// speed (0 for an event that takes another's instant, in a cascade or a group).
    #[serde(skip)]
    pub resolution: f64,
}

/// The state where the run stopped.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FinalState {
    /// When the run stopped.
    pub time: f64,
    /// The mode it stopped in (index).
    pub mode: usize,
    /// The states there.
    pub state: Vec<f64>,
    /// Sensitivities at fixed time (n * m), NaN where a derivative does not exist; `None` when
    /// none exists.
    pub dstate: Option<Vec<f64>>,
    /// The outputs there.
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

/// Why a run ended.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[non_exhaustive]
pub enum StopReason {
    /// Reached `t_end`.
    TEnd,
    /// A stop event fired.
    Event {
        /// The stop event (index).
        event: usize,
        /// Its name.
        name: Arc<str>,
    },
    /// Events accumulate towards a point (docs/language.md rule 10): a bounce too small to
    /// resolve, intervals shrinking until what is left of them is below the accuracy of the event
    /// times, or a record at `max_events` whose intervals shrink summably.
    Zeno {
        /// The time of the last event.
        time: f64,
        /// The event that accumulates (index).
        event: usize,
        /// How many times it fired.
        count: usize,
        /// Where the events accumulate, from the decay of the intervals between them (when
        /// enough of them shrink).
        accumulation: Option<Accumulation>,
    },
    /// `max_events` events have fired.
    MaxEvents {
        /// When the cap was reached.
        time: f64,
        /// The events fired.
        count: usize,
    },
    /// The state cannot leave an event's guard: a contact whose reset leaves the state on its
    /// guard with the flow carrying it through again, or events that keep firing at one instant.
    Stuck {
        /// When.
        time: f64,
        /// The event (index).
        event: usize,
        /// Its name.
        name: Arc<str>,
        /// Cascade rounds at this instant (0 when the contact is stuck on its guard).
        rounds: usize,
    },
    /// A runtime fault ended the run; everything computed before it is kept.
    Fault {
        /// The fault.
        error: SimError,
    },
}

/// Where a Zeno run's events accumulate, fitted to the intervals between them
/// (docs/language.md rule 10).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Accumulation {
    /// The estimated accumulation point.
    pub estimate: f64,
    /// The same fit over the latest half of the shrinking intervals, when later than the
    /// estimate: an upper end for the accumulation point as long as the decay does not slow down.
    pub upper: Option<f64>,
    /// How the intervals shrink.
    pub decay: Decay,
}

/// How the intervals between accumulating events shrink.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub enum Decay {
    /// By a constant ratio per interval.
    Geometric {
        /// The ratio of successive intervals.
        ratio: f64,
    },
    /// Like `(k + k0)^-exponent`.
    Power {
        /// The exponent (summable above 1).
        exponent: f64,
    },
    /// Too little to be told (the intervals did not halve over the fit's span).
    Unclear,
}

impl Accumulation {
    /// ` near t = T (at most U; intervals shrinking like k^-p)`, for a message.
    pub fn describe(&self) -> String {
        let upper = self.upper.map(|u| format!("at most {u:.10}; ")).unwrap_or_default();
        let decay = match self.decay {
            Decay::Geometric { ratio } => format!("intervals shrinking geometrically, ratio {ratio:.4}"),
            Decay::Power { exponent } => format!("intervals shrinking like k^-{exponent:.2}"),
            Decay::Unclear => "intervals shrinking".to_string(),
        };
        format!(" near t = {:.10} ({upper}{decay})", self.estimate)
    }
}

impl StopReason {
    /// Whether the run ended as asked: at `t_end` or a `stop` event.
    pub fn is_complete(&self) -> bool {
        matches!(self, StopReason::TEnd | StopReason::Event { .. })
    }

    /// The name the JSON contract and the sweep's `status` use: `t_end`, the stop event's name,
    /// `zeno`, `max_events`, `stuck` or `fault`.
    pub fn name(&self) -> &str {
        match self {
            StopReason::TEnd => "t_end",
            StopReason::Event { name, .. } => name,
            StopReason::Zeno { .. } => "zeno",
            StopReason::MaxEvents { .. } => "max_events",
            StopReason::Stuck { .. } => "stuck",
            StopReason::Fault { .. } => "fault",
        }
    }

    /// Why a run that ended early ended, with time, mode and state named; `None` for a complete
    /// run.
    pub fn describe(
        &self,
        info: &SystemInfo,
        events: &[EventRecord],
        final_state: &FinalState,
    ) -> Option<String> {
        let where_ = || {
            format!(
                "mode {}, state {}",
                mode_name(info, final_state.mode),
                named_state(info, &final_state.state)
            )
        };
        let event_name = |e: usize| info.events.get(e).map_or("?", |e| &*e.name).to_string();
        Some(match self {
            StopReason::TEnd | StopReason::Event { .. } => return None,
            StopReason::Zeno { time, event, count, accumulation } => format!(
                "Zeno behaviour: event `{}` fired {count} times, the last at t = {time}; events \
                 accumulate{} ({})",
                event_name(*event),
                accumulation.as_ref().map(Accumulation::describe).unwrap_or_default(),
                where_(),
            ),
            StopReason::MaxEvents { time, count } => format!(
                "reached --max-events {count} at t = {time} (the last event `{}`; {}); raise --max-events to go on",
                events.last().map_or("?", |e| &*e.name),
                where_(),
            ),
            StopReason::Stuck { time, name, rounds: 0, .. } => format!(
                "stuck on the guard of event `{name}` at t = {time} ({}): its reset leaves the state on the \
                 guard and the flow carries it through again; if the contact should hold, switch to a mode \
                 where it does (`-> resting`, with a flow that keeps the guard at zero)",
                where_(),
            ),
            StopReason::Stuck { time, name, rounds, .. } => format!(
                "events keep firing at t = {time}: {rounds} rounds of cascading events, the last `{name}` ({}); \
                 their resets keep moving the state across each other's guards",
                where_(),
            ),
            StopReason::Fault { error } => format!("simulation failed: {}", error.describe(info)),
        })
    }
}

/// What a run cost.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SimStats {
    /// Accepted steps.
    pub steps: usize,
    /// Rejected step attempts.
    pub rejected: usize,
    /// Right-hand side (`flow_sens`) evaluations by the stepper.
    pub rhs_calls: usize,
    /// Events fired (declared events; flow switches are `switches`).
    pub events: usize,
    /// Flow switches crossed (implicit events, not in `events`).
    pub switches: usize,
    /// How the gradients were computed (`None`: no parameter differentiated).
    pub sens: Option<super::Sens>,
}

/// One row of a recorded trajectory.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TrajectoryRow {
    /// The time.
    pub t: f64,
    /// The mode (index).
    pub mode: usize,
    /// The states.
    pub x: Vec<f64>,
    /// Sensitivities (n * m).
    pub s: Vec<f64>,
    /// The outputs.
    pub outputs: Vec<f64>,
}

/// Sets row `i` of a column-per-parameter array over `rows` quantities to NaN where `keep(i)` is
/// false.
fn mask_rows(a: &mut [f64], rows: usize, keep: impl Fn(usize) -> bool) {
    if rows == 0 {
        return;
    }
    for column in a.chunks_mut(rows) {
        for (i, v) in column.iter_mut().enumerate() {
            if !keep(i) {
                *v = f64::NAN;
            }
        }
    }
}

impl SimResult {
    /// Keeps only the gradients `of` asks for (`SimOptions::of`): the others' entries become
    /// NaN and the event times' `None`, and `gradients_of` records the choice, so that a report
    /// leaves them out rather than calling them missing.
    pub(crate) fn keep_gradients_of(&mut self, of: &GradientsOf, info: &SystemInfo) {
        let wanted = {
            let names: Vec<&str> = self.events.iter().map(|e| &*e.name).collect();
            of.events(info, &names)
        };
        for (e, wanted) in self.events.iter_mut().zip(wanted) {
            if !wanted {
                e.dtime = None;
            }
        }
        let (n, k) = (info.n_states(), info.n_outputs());
        let f = &mut self.final_state;
        let (cusp_x, cusp_y) = match self.end_cusp.as_mut() {
            Some(c) => (c.dstate.as_mut(), c.doutputs.as_mut()),
            None => (None, None),
        };
        for d in [f.dstate.as_mut(), f.dstate_total.as_mut(), cusp_x].into_iter().flatten() {
            mask_rows(d, n, |i| of.state(i));
        }
        for d in [f.doutputs.as_mut(), f.doutputs_total.as_mut(), cusp_y].into_iter().flatten() {
            mask_rows(d, k, |i| of.output(i));
        }
        self.samples.keep_gradients(|output, i, time| of.sample(output, i, time));
        self.gradients_of = Some(of.clone());
    }

    /// Per event record, whether the run reports its time's gradient: every one unless
    /// `SimOptions::of` named others.
    pub fn reports_event_gradients(&self, info: &SystemInfo) -> Vec<bool> {
        match &self.gradients_of {
            None => vec![true; self.events.len()],
            Some(of) => {
                let names: Vec<&str> = self.events.iter().map(|e| &*e.name).collect();
                of.events(info, &names)
            }
        }
    }

    /// Whether the report holds the gradient of state (`output` false) or output `i`: every one
    /// unless `SimOptions::of` named others.
    pub fn reports_gradient(&self, output: bool, i: usize) -> bool {
        match &self.gradients_of {
            None => true,
            Some(of) if output => of.output(i),
            Some(of) => of.state(i),
        }
    }
}

/// Everything a run computed: events, final values and derivatives, why it stopped, warnings,
/// what it cost, the trajectory and samples asked for.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SimResult {
    /// The events that fired, in order.
    pub events: Vec<EventRecord>,
    /// Where the run stopped, with the derivatives there.
    #[serde(rename = "final")]
    pub final_state: FinalState,
    /// Why it stopped.
    pub stopped_by: StopReason,
    /// Everything the run warns of (grazing, near-grazing, derivatives that stopped existing).
    pub warnings: Vec<SimWarning>,
    /// What it cost.
    pub stats: SimStats,
    /// The trajectory, when `SimOptions::trajectory` asked for one.
    pub trajectory: Option<Vec<TrajectoryRow>>,
    /// Events fired at `t_end` itself make the final values a cusp in the parameters: a change
    /// that moves them later takes them out of the run. `final` is the side with them; this is
    /// the other side, the final values and derivatives had they not fired.
    pub end_cusp: Option<EndCusp>,
    /// The values at `SimOptions::at`, one per time asked for, in order.
    pub samples: Samples,
    /// Which method integrated which part of the run, in time order: one segment for a method
    /// asked for by name, one per switch under `Method::Auto`.
    pub methods: Vec<MethodSegment>,
    /// The quantities whose gradients the run kept (`SimOptions::of`); `None`: all.
    pub gradients_of: Option<GradientsOf>,
}

/// A stretch of a run integrated by one method (`SimResult::methods`): from `from` to `to`, with
/// its accepted and rejected steps.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MethodSegment {
    /// Where the stretch starts.
    pub from: f64,
    /// Where it ends.
    pub to: f64,
    /// The method.
    pub method: super::options::Method,
    /// Its accepted steps.
    pub steps: usize,
    /// Its rejected steps.
    pub rejected: usize,
}

/// The values at `SimOptions::at`, one row per time asked for, in order, kept in flat arrays
/// (one allocation per array and run, not per sample: a fit to a time series samples every run).
/// Read a row with [`Samples::get`] or [`Samples::iter`], which give [`Sample`] views.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Samples {
    /// (states, differentiated parameters, outputs).
    shape: (usize, usize, usize),
    time: Vec<f64>,
    reached: Vec<bool>,
    mode: Vec<usize>,
    /// Per row the states (n) then their derivatives (n * m): the layout the dense output fills.
    z: Vec<f64>,
    outputs: Vec<f64>,
    /// Per row k * m.
    doutputs: Vec<f64>,
    after_events: Vec<bool>,
    near_event: Vec<Option<usize>>,
}

/// The states and outputs at one time of `SimOptions::at`, from the dense output of the step
/// that holds it, with their derivatives at that fixed time (column per parameter, as
/// `FinalState`): the interpolated sensitivities, which are the derivative of the interpolated
/// states. A view into [`Samples`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Sample<'a> {
    /// The time asked for.
    pub time: f64,
    /// False when the run stopped before this time (an event `stop`, Zeno, a fault): then the
    /// values are NaN and the derivatives `None`.
    pub reached: bool,
    /// The mode at that time (index).
    pub mode: usize,
    /// The states.
    pub state: &'a [f64],
    /// `dx/dp` (n * m), NaN where a derivative does not exist; `None` without parameters.
    pub dstate: Option<&'a [f64]>,
    /// The outputs.
    pub outputs: &'a [f64],
    /// `y_x dx/dp + y_p` (k * m).
    pub doutputs: Option<&'a [f64]>,
    /// The sample is at an event instant: the values are those after the instant's events.
    pub after_events: bool,
    /// An event (its index in `SimResult::events`) within the time resolution of which the sample
    /// lies (`|t - t_e|` at most the guard's accuracy over its crossing speed): a parameter
    /// change moves the event across the sample, so the derivatives there hold on one side only
    /// (a cusp). The nearest such event.
    pub near_event: Option<usize>,
}

impl Samples {
    /// No rows yet, room for `rows` of `shape` (states, differentiated parameters, outputs).
    pub(crate) fn with_capacity(shape: (usize, usize, usize), rows: usize) -> Samples {
        let (n, m, k) = shape;
        Samples {
            shape,
            time: Vec::with_capacity(rows),
            reached: Vec::with_capacity(rows),
            mode: Vec::with_capacity(rows),
            z: Vec::with_capacity(rows * (n + n * m)),
            outputs: Vec::with_capacity(rows * k),
            doutputs: Vec::with_capacity(rows * k * m),
            after_events: Vec::with_capacity(rows),
            near_event: Vec::with_capacity(rows),
        }
    }

    /// The number of times asked for.
    pub fn len(&self) -> usize {
        self.time.len()
    }

    /// Whether no times were asked for.
    pub fn is_empty(&self) -> bool {
        self.time.is_empty()
    }

    /// Row `i`.
    pub fn get(&self, i: usize) -> Option<Sample<'_>> {
        if i >= self.len() {
            return None;
        }
        let (n, m, k) = self.shape;
        let (zw, dyw) = (n + n * m, k * m);
        let z = &self.z[i * zw..(i + 1) * zw];
        let reached = self.reached[i];
        let with_derivatives = reached && m > 0;
        Some(Sample {
            time: self.time[i],
            reached,
            mode: self.mode[i],
            state: &z[..n],
            dstate: with_derivatives.then(|| &z[n..]),
            outputs: &self.outputs[i * k..(i + 1) * k],
            doutputs: with_derivatives.then(|| &self.doutputs[i * dyw..(i + 1) * dyw]),
            after_events: self.after_events[i],
            near_event: self.near_event[i],
        })
    }

    /// The rows in time order.
    pub fn iter(&self) -> impl DoubleEndedIterator<Item = Sample<'_>> + ExactSizeIterator + '_ {
        (0..self.len()).map(|i| self.get(i).expect("in range"))
    }

    /// Sets the derivatives of the values `keep(output, index, time)` refuses to NaN
    /// (`SimOptions::of`).
    pub(crate) fn keep_gradients(&mut self, keep: impl Fn(bool, usize, f64) -> bool) {
        let (n, m, k) = self.shape;
        let (zw, dyw) = (n + n * m, k * m);
        for (r, &time) in self.time.iter().enumerate() {
            let ds = &mut self.z[r * zw + n..(r + 1) * zw];
            mask_rows(ds, n, |i| keep(false, i, time));
            mask_rows(&mut self.doutputs[r * dyw..(r + 1) * dyw], k, |i| keep(true, i, time));
        }
    }

    /// The same rows with room for the derivatives by `m` parameters, NaN until
    /// [`Self::set_derivatives`] fills them (the adjoint's recorded run carries none).
    pub(crate) fn widen(&mut self, m: usize) {
        let (n, m0, k) = self.shape;
        if m == m0 {
            return;
        }
        let rows = self.len();
        let (zw0, zw) = (n + n * m0, n + n * m);
        let mut z = vec![f64::NAN; rows * zw];
        for r in 0..rows {
            z[r * zw..r * zw + n].copy_from_slice(&self.z[r * zw0..r * zw0 + n]);
        }
        self.z = z;
        self.doutputs = vec![f64::NAN; rows * k * m];
        self.shape = (n, m, k);
    }

    /// Row `row`'s derivatives of state (or, `output`, output) `index` by each parameter.
    pub(crate) fn set_derivatives(&mut self, row: usize, output: bool, index: usize, d: &[f64]) {
        let (n, m, k) = self.shape;
        let (zw, dyw) = (n + n * m, k * m);
        for (j, &v) in d.iter().enumerate().take(m) {
            if output {
                self.doutputs[row * dyw + j * k + index] = v;
            } else {
                self.z[row * zw + n + j * n + index] = v;
            }
        }
    }

    /// The first row at time `t` (the times are ascending), if one was asked for.
    pub fn at_time(&self, t: f64) -> Option<Sample<'_>> {
        let i = self.time.partition_point(|&s| s < t);
        self.time.get(i).filter(|&&s| s == t).and_then(|_| self.get(i))
    }

    /// Appends a row at `time` in `mode` and gives its state-and-sensitivities, outputs and
    /// output-derivative slots (zeroed) to fill.
    pub(crate) fn push(&mut self, time: f64, mode: usize) -> (&mut [f64], &mut [f64], &mut [f64]) {
        let (n, m, k) = self.shape;
        self.time.push(time);
        self.reached.push(true);
        self.mode.push(mode);
        self.after_events.push(false);
        self.near_event.push(None);
        let (z0, y0, dy0) = (self.z.len(), self.outputs.len(), self.doutputs.len());
        self.z.resize(z0 + n + n * m, 0.0);
        self.outputs.resize(y0 + k, 0.0);
        self.doutputs.resize(dy0 + k * m, 0.0);
        (&mut self.z[z0..], &mut self.outputs[y0..], &mut self.doutputs[dy0..])
    }

    /// The state-and-sensitivities, outputs and output-derivative slots of row `i`.
    pub(crate) fn row_mut(&mut self, i: usize) -> (&mut [f64], &mut [f64], &mut [f64]) {
        let (n, m, k) = self.shape;
        let (zw, dyw) = (n + n * m, k * m);
        (
            &mut self.z[i * zw..(i + 1) * zw],
            &mut self.outputs[i * k..(i + 1) * k],
            &mut self.doutputs[i * dyw..(i + 1) * dyw],
        )
    }

    /// Appends a row for a time the run did not reach: NaN values, no derivatives.
    pub(crate) fn push_unreached(&mut self, time: f64) {
        let (z, y, dy) = self.push(time, 0);
        z.fill(f64::NAN);
        y.fill(f64::NAN);
        dy.fill(f64::NAN);
        *self.reached.last_mut().expect("just pushed") = false;
    }

    /// The times of the rows.
    pub fn times(&self) -> &[f64] {
        &self.time
    }

    /// Marks row `i` as taken after the events of its instant, and the event it is near.
    pub(crate) fn mark(&mut self, i: usize, after_events: bool, near_event: Option<usize>) {
        self.after_events[i] = after_events;
        self.near_event[i] = near_event;
    }
}

impl Serialize for Samples {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_seq(self.iter())
    }
}

/// The final values of a run without the events it fired at `t_end` (see `SimResult::end_cusp`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EndCusp {
    /// The events fired at `t_end` (ids).
    pub events: Vec<usize>,
    /// The states.
    pub state: Vec<f64>,
    /// As `FinalState::dstate`.
    pub dstate: Option<Vec<f64>>,
    /// The outputs.
    pub outputs: Vec<f64>,
    /// As `FinalState::doutputs`.
    pub doutputs: Option<Vec<f64>>,
}
