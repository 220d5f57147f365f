//! One run's status in one word: the single vocabulary of the sweep rows (`hybc sweep`, Python
//! `Model.sweep`, `hybc.dask.sweep`), Python's `Run.status` and `hybc.jax`'s `status` output, so
//! a grazing run is "grazing" whichever interface ran it. Reads a finished `SimResult`; no IO.

use crate::sim::{non_finite_finals, SimResult, SimWarning, StopReason, SystemInfo};

/// Why a run's numbers are what they are. Complete runs (ended at `t_end` or by a `stop` event)
/// are `Ok`, `Grazing`, `NotDifferentiable` or `NonFinite`; the others ended early and have no
/// final values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunStatus {
    /// Complete, final values finite, every derivative exists (a near-grazing crossing keeps its
    /// exact gradients and stays `Ok`; its warning states the margin).
    Ok,
    /// Complete, but an event grazed its guard: the derivatives that depend on its time are NaN.
    Grazing,
    /// Complete, but some derivative stopped existing (a flow switch at an event instant, a flow
    /// whose derivative is not finite): those derivatives are NaN.
    NotDifferentiable,
    /// Complete, but a final state or output is NaN or infinite.
    NonFinite,
    /// Events accumulate before `t_end`.
    Zeno,
    /// The state cannot leave a guard, or events keep firing at one instant.
    Stuck,
    /// `max_events` events fired before `t_end`.
    MaxEvents,
    /// The integration failed (step size underflow, too many steps, a non-finite state).
    Fault,
}

impl RunStatus {
    /// The status of a finished run. For a complete run the most severe finding wins: values
    /// that are not finite, then a grazing event (values exact, some derivatives gone), then
    /// derivatives that stopped existing otherwise.
    pub fn of(info: &SystemInfo, result: &SimResult) -> RunStatus {
        match &result.stopped_by {
            StopReason::TEnd | StopReason::Event { .. } => {}
            StopReason::Zeno { .. } => return RunStatus::Zeno,
            StopReason::Stuck { .. } => return RunStatus::Stuck,
            StopReason::MaxEvents { .. } => return RunStatus::MaxEvents,
            StopReason::Fault { .. } => return RunStatus::Fault,
        }
        if non_finite_finals(info, &result.final_state).is_some() {
            return RunStatus::NonFinite;
        }
        let mut status = RunStatus::Ok;
        for warning in &result.warnings {
            match warning {
                SimWarning::Grazing { .. } => return RunStatus::Grazing,
                SimWarning::SwitchAtEvent { .. }
                | SimWarning::EventAtKnot { .. }
                | SimWarning::KnotsApart { .. }
                | SimWarning::NotDifferentiable { .. }
                | SimWarning::ResetOntoGuard { .. } => status = RunStatus::NotDifferentiable,
                SimWarning::NearGrazing { .. }
                | SimWarning::StartsAcross { .. }
                | SimWarning::NearBreakpoint { .. }
                | SimWarning::CostUnresolved { .. }
                | SimWarning::AdjointNotCarried { .. } => {}
            }
        }
        status
    }

    /// The word every interface prints.
    pub fn name(self) -> &'static str {
        match self {
            RunStatus::Ok => "ok",
            RunStatus::Grazing => "grazing",
            RunStatus::NotDifferentiable => "not_differentiable",
            RunStatus::NonFinite => "non_finite",
            RunStatus::Zeno => "zeno",
            RunStatus::Stuck => "stuck",
            RunStatus::MaxEvents => "max_events",
            RunStatus::Fault => "fault",
        }
    }

    /// Whether the run ended as asked (at `t_end` or by a `stop` event) with finite final values:
    /// its values can be used, whatever became of some derivatives.
    pub fn has_values(self) -> bool {
        matches!(self, RunStatus::Ok | RunStatus::Grazing | RunStatus::NotDifferentiable)
    }
}
