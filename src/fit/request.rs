//! A whole fit as a user asks for it (`hybc fit` and Python's `Model.fit`): targets as text, an
//! optional data file's text, the start and the options, against a model compiled with the free
//! parameters as its gradient parameters. Parses, runs the solver and builds the report, so that
//! both front ends say the same things about the same fit.

use std::time::Instant;

use super::{data, fit, Bounds, FitError, FitOptions, FitProblem, FitReport, Rejection, Target};
use crate::sim::SimOptions;

/// What to fit, as text where the user wrote text.
pub struct Request<'a> {
    /// `NAME=VALUE[@W]` targets.
    pub targets: &'a [String],
    /// A data file's text and its name for messages.
    pub data: Option<(&'a str, &'a str)>,
    /// Every parameter's value: the free ones start there, the others stay there.
    pub start: Vec<f64>,
    pub sim: SimOptions,
    pub options: FitOptions,
}

/// Why a fit gave no report.
#[derive(Debug)]
pub enum Failure {
    /// A target does not parse against the model (`--target`, Python's `targets=`).
    Target(super::TargetError),
    /// The data does not fit the model (`--data`, Python's `data=`).
    Data(data::DataError),
    /// The start is outside the bounds, or no targets: a usage error, with its message.
    Usage(String),
    /// The run at the start fails (`Rejection::Run`, a missing event, a derivative that does not
    /// exist): a simulation failure.
    StartRun(FitError),
    /// The run at the start works, but the objective is not finite: the goal cannot be met.
    StartObjective(FitError),
}

/// Runs the fit `request` asks for on `compiled` (compiled with the free parameters as gradient
/// parameters), with `warn` told when there are fewer targets than free parameters.
pub fn run(
    model: &crate::Model,
    compiled: &crate::Compiled,
    request: Request<'_>,
    warn: &mut dyn FnMut(&str),
) -> Result<FitReport, Failure> {
    let info = compiled.info().clone();
    let mut targets = request
        .targets
        .iter()
        .map(|t| Target::parse(t, &info).map_err(Failure::Target))
        .collect::<Result<Vec<_>, _>>()?;
    let mut sigma_known = false;
    if let Some((text, file)) = request.data {
        let data = data::parse_data(text, file, &info).map_err(Failure::Data)?;
        sigma_known = data.sigma_known;
        targets.extend(data.targets);
    }
    let free = &info.grad_params;
    if targets.len() < free.len() {
        warn(&format!(
            "{} free parameters but {} target(s): the fit is underdetermined; the damped steps stay near \
             the start and the condition number is infinite",
            free.len(),
            targets.len()
        ));
    }
    let bounds = free.iter().map(|&p| Bounds::from_range(model.checked().params[p].range)).collect();
    let problem =
        FitProblem { system: compiled.system(), start: request.start, bounds, targets, sim: request.sim };
    let started = Instant::now();
    let result = match fit(&problem, &request.options) {
        Ok(result) => result,
        Err(e @ FitError::Start(Rejection::ObjectiveOverflow { .. } | Rejection::NonFinite { .. })) => {
            return Err(Failure::StartObjective(e))
        }
        Err(e @ FitError::Start(_)) => return Err(Failure::StartRun(e)),
        Err(e) => return Err(Failure::Usage(e.to_string())),
    };
    Ok(FitReport {
        model: model.name().to_string(),
        info,
        targets: problem.targets,
        options: request.options,
        result,
        compile_seconds: compiled.compile_seconds(),
        fit_seconds: started.elapsed().as_secs_f64(),
        sigma_known,
    })
}
