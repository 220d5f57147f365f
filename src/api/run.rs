//! One finished run with names attached: values and gradients by name, `None` where a number does
//! not exist.

use super::Compiled;
use crate::report::RunReport;
use crate::sim::{EventRecord, Samples, SimResult, SimWarning, StopReason};

/// The result of one simulation, read by name.
///
/// Gradient getters return `None` when the name is unknown, when the parameter was not among the
/// compiled gradient parameters, or when the derivative does not exist (after a grazing event).
#[derive(Clone, Debug)]
pub struct Run {
    compiled: Compiled,
    params: Vec<f64>,
    t_end: f64,
    result: SimResult,
    run_seconds: f64,
}

impl Run {
    pub(crate) fn new(
        compiled: Compiled,
        params: Vec<f64>,
        t_end: f64,
        result: SimResult,
        run_seconds: f64,
    ) -> Run {
        Run { compiled, params, t_end, result, run_seconds }
    }

    /// The events that fired, in order.
    pub fn events(&self) -> &[EventRecord] {
        &self.result.events
    }

    /// The values at `SimOptions::at`, one per time asked for, in order.
    pub fn samples(&self) -> &Samples {
        &self.result.samples
    }

    /// Why the run ended.
    pub fn stopped_by(&self) -> &StopReason {
        &self.result.stopped_by
    }

    /// Whether the run ended as asked (at `t_end` or a `stop` event) rather than early.
    pub fn is_complete(&self) -> bool {
        matches!(self.result.stopped_by, StopReason::TEnd | StopReason::Event { .. })
    }

    /// Every warning of the run (grazing, near-grazing, derivatives that stopped existing).
    pub fn warnings(&self) -> &[SimWarning] {
        &self.result.warnings
    }

    /// The time the run ended.
    pub fn final_time(&self) -> f64 {
        self.result.final_state.time
    }

    /// The parameter values of the run, in declaration order.
    pub fn param_values(&self) -> &[f64] {
        &self.params
    }

    /// The final value of state `name`.
    pub fn state(&self, name: &str) -> Option<f64> {
        let i = self.info().state_names.iter().position(|s| s == name)?;
        Some(self.result.final_state.state[i])
    }

    /// The final value of output `name`.
    pub fn output(&self, name: &str) -> Option<f64> {
        let i = self.info().output_names.iter().position(|s| s == name)?;
        Some(self.result.final_state.outputs[i])
    }

    /// `d state / d param` at the final time (at a `stop` event: at fixed time, see
    /// [`Self::dstate_total`]).
    pub fn dstate(&self, name: &str, param: &str) -> Option<f64> {
        let names = &self.info().state_names;
        self.column(names, name, param, self.result.final_state.dstate.as_deref())
    }

    /// `d output / d param` at the final time.
    pub fn doutput(&self, name: &str, param: &str) -> Option<f64> {
        let names = &self.info().output_names;
        self.column(names, name, param, self.result.final_state.doutputs.as_deref())
    }

    /// After a `stop` event: the total derivative of the final state, including the motion of
    /// the stopping time.
    pub fn dstate_total(&self, name: &str, param: &str) -> Option<f64> {
        let names = &self.info().state_names;
        self.column(names, name, param, self.result.final_state.dstate_total.as_deref())
    }

    /// After a `stop` event: the total derivative of output `name`.
    pub fn doutput_total(&self, name: &str, param: &str) -> Option<f64> {
        let names = &self.info().output_names;
        self.column(names, name, param, self.result.final_state.doutputs_total.as_deref())
    }

    /// `d t_k / d param` of the `k`-th event (0-based).
    pub fn devent_time(&self, k: usize, param: &str) -> Option<f64> {
        let j = self.grad_column(param)?;
        self.result.events.get(k)?.dtime.as_ref().map(|d| d[j]).filter(|d| !d.is_nan())
    }

    /// The raw result (layouts in `sim::result`).
    pub fn result(&self) -> &SimResult {
        &self.result
    }

    /// The raw result, taken.
    pub fn into_result(self) -> SimResult {
        self.result
    }

    /// The compiled model that produced this run.
    pub fn compiled(&self) -> &Compiled {
        &self.compiled
    }

    /// Seconds the run took.
    pub fn run_seconds(&self) -> f64 {
        self.run_seconds
    }

    /// The run as the report `hybc run` prints (table or JSON).
    pub fn report(&self) -> RunReport {
        self.clone().into_report()
    }

    /// The report, taking this run's result rather than copying it (a run at the
    /// `--max-events` cap holds 10^6 event records). The one place a `RunReport` is made: every
    /// report of a run, the CLI's and Python's, comes from a `Run`.
    pub fn into_report(self) -> RunReport {
        RunReport::new(
            self.compiled.model().name().to_string(),
            self.t_end,
            self.info().clone(),
            self.params,
            self.result,
            (self.compiled.compile_seconds(), self.run_seconds),
        )
    }

    fn info(&self) -> &crate::sim::SystemInfo {
        self.compiled.info()
    }

    fn grad_column(&self, param: &str) -> Option<usize> {
        let info = self.info();
        info.grad_params.iter().position(|&j| info.param_names[j] == param)
    }

    /// Entry `(name, param)` of a column-per-parameter array over `names`.
    fn column(&self, names: &[String], name: &str, param: &str, values: Option<&[f64]>) -> Option<f64> {
        let i = names.iter().position(|s| s == name)?;
        let j = self.grad_column(param)?;
        // A derivative that does not exist is NaN in the result.
        values.map(|v| v[j * names.len() + i]).filter(|d| !d.is_nan())
    }
}
