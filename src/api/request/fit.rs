//! A whole fit as a user asks for it (`hybc fit` and Python's `Model.fit`): targets as text, an
//! optional data file's text, the start and the options, run on a model compiled with the free
//! parameters as its gradient parameters. Parses, runs the solver (`fit::fit`, the core) and
//! builds the report, so that both front ends say the same things about the same fit.

use std::time::Instant;

use crate::api::{Compiled, Error};
use crate::fit::data::{self, DataError};
use crate::fit::{fit, Bounds, FitError, FitOptions, FitProblem, FitReport, Rejection, Target, TargetError};
use crate::sim::SimOptions;

/// What to fit, as text where the user wrote text.
#[derive(Clone, Debug)]
pub struct FitRequest<'a> {
    /// `NAME=VALUE[@W]` targets.
    pub targets: &'a [String],
    /// A data file's text and its name for messages.
    pub data: Option<(&'a str, &'a str)>,
    /// Every parameter's value: the free ones start there, the others stay there.
    pub start: Vec<f64>,
    /// The options of every run.
    pub sim: SimOptions,
    /// When the solver stops.
    pub options: FitOptions,
}

/// Why a fit gave no report.
#[derive(Debug, thiserror::Error)]
pub enum FitFailure {
    /// A target does not parse against the model (`--target`, Python's `targets=`).
    #[error(transparent)]
    Target(TargetError),
    /// The data does not fit the model (`--data`, Python's `data=`).
    #[error(transparent)]
    Data(DataError),
    /// The solver refused the problem before running it (a start outside the bounds, no
    /// targets): a usage error.
    #[error(transparent)]
    Refused(FitError),
    /// The run at the start fails (`Rejection::Run`, a missing event, a derivative that does not
    /// exist): a simulation failure.
    #[error(transparent)]
    StartRun(FitError),
    /// The run at the start works, but the objective is not finite: the goal cannot be met.
    #[error(transparent)]
    StartObjective(FitError),
}

impl FitRequest<'_> {
    /// Runs the fit on `compiled` (compiled with the free parameters as gradient parameters),
    /// with `warn` told when there are fewer targets than free parameters.
    pub fn run(self, compiled: &Compiled, warn: &mut dyn FnMut(&str)) -> Result<FitReport, Error> {
        let info = compiled.info().clone();
        let mut targets = self
            .targets
            .iter()
            .map(|t| Target::parse(t, &info).map_err(FitFailure::Target))
            .collect::<Result<Vec<_>, _>>()?;
        // A value at a time the run does not reach is refused here, with its cause, not by the run.
        for (target, text) in targets.iter().zip(self.targets) {
            if let Some(t) = target.observable.sample_time() {
                crate::api::options::sample_times_within(&[t], self.sim.t_start, self.sim.t_end, "")
                    .map_err(|reason| {
                        let reason = reason.trim_start_matches(": ").to_string();
                        FitFailure::Target(TargetError::TimeOutside { text: text.clone(), reason })
                    })?;
            }
        }
        let mut sigma_known = false;
        if let Some((text, file)) = self.data {
            let span = (self.sim.t_start, self.sim.t_end);
            let data = data::parse_data(text, file, &info, span).map_err(FitFailure::Data)?;
            sigma_known = data.sigma_known;
            targets.extend(data.targets);
        }
        let free = &info.grad_params;
        if targets.len() < free.len() {
            warn(&format!(
                "{} free parameters but {} target(s): the fit is underdetermined; the damped steps stay \
                 near the start and the condition number is infinite",
                free.len(),
                targets.len()
            ));
        }
        let params = &compiled.model().checked().params;
        let bounds = free.iter().map(|&p| Bounds::from_range(params[p].range)).collect();
        let problem =
            FitProblem { system: compiled.system(), start: self.start, bounds, targets, sim: self.sim };
        let started = Instant::now();
        let result = fit(&problem, &self.options).map_err(|e| match e {
            FitError::Start(Rejection::ObjectiveOverflow { .. } | Rejection::NonFinite { .. }) => {
                FitFailure::StartObjective(e)
            }
            FitError::Start(_) => FitFailure::StartRun(e),
            e => FitFailure::Refused(e),
        })?;
        Ok(FitReport {
            model: compiled.model().name().to_string(),
            info,
            targets: problem.targets,
            options: self.options,
            result,
            compile_seconds: compiled.compile_seconds(),
            fit_seconds: started.elapsed().as_secs_f64(),
            sigma_known,
        })
    }
}
