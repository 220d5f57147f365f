//! One evaluation of a fit: run the compiled model at one parameter vector and read every
//! target's value and its exact gradient row from the run's sensitivities (`dstate`/`doutputs`
//! at `t_end`, their totals `dstate_total`/`doutputs_total` at a `stop` event, `dtime` for event
//! times). Knows runs and targets, not the solver.

use std::fmt;

use nalgebra::DMatrix;

use super::target::{Observable, Target};
use crate::sim::{HybridSystem, Runner, SimResult, StopReason, SystemInfo};

/// The residuals of one run and their Jacobian with respect to the free parameters.
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// The model's value of each target.
    pub values: Vec<f64>,
    /// `weight * (value - target)`, one per target.
    pub residuals: Vec<f64>,
    /// `d residual_i / d free_j` (targets x free parameters).
    pub jacobian: DMatrix<f64>,
    /// Ids of the fired events in order: which smooth piece of the objective this point is on.
    pub events: Vec<usize>,
}

impl Evaluation {
    /// `0.5 * sum(residual^2)`.
    pub fn objective(&self) -> f64 {
        0.5 * self.residuals.iter().map(|r| r * r).sum::<f64>()
    }
}

/// Why a parameter vector gives no usable residuals. At a trial point the solver rejects the
/// trial and shortens the step; at the starting point the fit cannot begin.
#[derive(Clone, Debug, PartialEq)]
pub enum Rejection {
    /// The run stopped early (Zeno behaviour or a runtime fault), or refused its input.
    RunStopped {
        /// Why it stopped.
        message: String,
    },
    /// A target's event fired fewer times than its firing number.
    MissingEvent {
        /// The target.
        target: String,
        /// How many times its event fired.
        fired: usize,
    },
    /// A target's gradient does not exist: a grazing event came at or before it.
    NoGradient {
        /// The target.
        target: String,
    },
    /// A `NAME@TIME` target's time is after the run's stop (a `stop` event).
    NotReached {
        /// The target.
        target: String,
    },
    /// A target's value or gradient is not a finite number.
    NonFinite {
        /// The target.
        target: String,
    },
    /// Every residual is finite but `0.5 * sum(residual^2)` overflows: the objective, its
    /// gradient and every convergence test would be infinities and NaNs.
    ObjectiveOverflow {
        /// The target with the largest residual.
        target: String,
        /// That residual.
        residual: f64,
    },
}

impl fmt::Display for Rejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Rejection::RunStopped { message } => write!(f, "the run stopped early: {message}"),
            Rejection::MissingEvent { target, fired } => {
                let fired = match fired {
                    0 => "never fired".to_string(),
                    1 => "fired only once".to_string(),
                    n => format!("fired only {n} times"),
                };
                write!(f, "target `{target}` does not exist: its event {fired}")
            }
            Rejection::NoGradient { target } => write!(
                f,
                "target `{target}` has no gradient: a grazing event (a guard touched at a crossing speed near \
                 zero) came at or before it"
            ),
            Rejection::NonFinite { target } => write!(f, "target `{target}` is not a finite number"),
            Rejection::NotReached { target } => {
                write!(f, "target `{target}` does not exist: the run stopped before its time")
            }
            Rejection::ObjectiveOverflow { target, residual } => write!(
                f,
                "the objective 0.5 sum(residual^2) overflows a double (residual {} for target `{target}`): \
                 scale the target or its weight (`@W`)",
                crate::sim::short(*residual)
            ),
        }
    }
}

/// Runs the simulator's model at parameters `p` (all of them) and reads the targets. A fit keeps
/// one `Runner` for all its evaluations, so its scratch buffers are allocated once.
pub fn evaluate<S: HybridSystem + ?Sized>(
    simulator: &mut Runner<&S>,
    p: &[f64],
    targets: &[Target],
) -> Result<Evaluation, Rejection> {
    let sys: &S = simulator.handle();
    let info = sys.info();
    let result = simulator.run(p).map_err(|e| Rejection::RunStopped { message: e.to_string() })?;
    let f = &result.final_state;
    // At a stop event the final time moves with the parameters: only the total derivatives
    // describe how the final values change.
    let finals = match &result.stopped_by {
        StopReason::TEnd => Finals { dstate: &f.dstate, doutputs: &f.doutputs },
        StopReason::Event { .. } => Finals { dstate: &f.dstate_total, doutputs: &f.doutputs_total },
        _ => {
            return Err(Rejection::RunStopped { message: failure(&result, info) });
        }
    };
    let mut values = Vec::with_capacity(targets.len());
    let mut residuals = Vec::with_capacity(targets.len());
    let mut jacobian = DMatrix::zeros(targets.len(), info.n_grad());
    for (i, target) in targets.iter().enumerate() {
        let label = || target.label(info);
        let (value, gradient) =
            read(&result, info, &finals, target.observable).map_err(|missing| match missing {
                Missing::Event { fired } => Rejection::MissingEvent { target: label(), fired },
                Missing::Gradient => Rejection::NoGradient { target: label() },
                Missing::Time => Rejection::NotReached { target: label() },
            })?;
        let residual = target.weight * (value - target.value);
        if !residual.is_finite() || gradient.iter().any(|d| !d.is_finite()) {
            return Err(Rejection::NonFinite { target: label() });
        }
        values.push(value);
        residuals.push(residual);
        for (j, d) in gradient.into_iter().enumerate() {
            jacobian[(i, j)] = target.weight * d;
        }
    }
    let evaluation =
        Evaluation { values, residuals, jacobian, events: result.events.iter().map(|e| e.event).collect() };
    if !evaluation.objective().is_finite() {
        let (i, residual) = evaluation
            .residuals
            .iter()
            .copied()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .unwrap_or((0, f64::INFINITY));
        return Err(Rejection::ObjectiveOverflow { target: targets[i].label(info), residual });
    }
    Ok(evaluation)
}

/// The derivatives of the final values that apply to how the run ended.
struct Finals<'r> {
    dstate: &'r Option<Vec<f64>>,
    doutputs: &'r Option<Vec<f64>>,
}

enum Missing {
    Event {
        fired: usize,
    },
    Gradient,
    /// The run stopped before a `NAME@TIME` target's time.
    Time,
}

/// One target's value and its gradient over the free parameters.
fn read(
    result: &SimResult,
    info: &SystemInfo,
    finals: &Finals<'_>,
    observable: Observable,
) -> Result<(f64, Vec<f64>), Missing> {
    let f = &result.final_state;
    let row =
        |d: &[f64], rows: usize, i: usize| (0..info.n_grad()).map(|j| d[j * rows + i]).collect::<Vec<f64>>();
    // A derivative that does not exist is NaN: the target then has no gradient.
    let existing = |d: Vec<f64>| if d.iter().any(|v| v.is_nan()) { Err(Missing::Gradient) } else { Ok(d) };
    match observable {
        Observable::Output(i) => {
            let d = finals.doutputs.as_ref().ok_or(Missing::Gradient)?;
            Ok((f.outputs[i], existing(row(d, info.n_outputs(), i))?))
        }
        Observable::State(i) => {
            let d = finals.dstate.as_ref().ok_or(Missing::Gradient)?;
            Ok((f.state[i], existing(row(d, info.n_states(), i))?))
        }
        Observable::EventTime { name_event, occurrence } => {
            let name = &info.events[name_event].name;
            let firings: Vec<_> =
                result.events.iter().filter(|e| info.events[e.event].name == *name).collect();
            let record = firings.get(occurrence - 1).ok_or(Missing::Event { fired: firings.len() })?;
            let d = record.dtime.as_ref().ok_or(Missing::Gradient)?;
            Ok((record.time, existing(d.clone())?))
        }
        Observable::LastFiring { name_event } => {
            let name = &info.events[name_event].name;
            let record = result.events.iter().rfind(|e| info.events[e.event].name == *name);
            let record = record.ok_or(Missing::Event { fired: 0 })?;
            let d = record.dtime.as_ref().ok_or(Missing::Gradient)?;
            Ok((record.time, existing(d.clone())?))
        }
        Observable::At { output, index, time } => {
            // `fit` samples every target's time; one the run did not reach has no value.
            let sample = result.samples.at_time(time).filter(|s| s.reached);
            let sample = sample.ok_or(Missing::Time)?;
            let (values, d, rows) = if output {
                (&sample.outputs, &sample.doutputs, info.n_outputs())
            } else {
                (&sample.state, &sample.dstate, info.n_states())
            };
            let d = d.as_ref().ok_or(Missing::Gradient)?;
            Ok((values[index], existing(row(d, rows, index))?))
        }
    }
}

/// The run report's own wording for a run that stopped early (names, time, mode and state).
fn failure(result: &SimResult, info: &SystemInfo) -> String {
    let described = result.stopped_by.describe(info, &result.events, &result.final_state);
    described.unwrap_or_else(|| "the run stopped early".to_string())
}
