//! A whole optimisation as a user asks for it (`hybc optimize` and Python's `Model.optimize`):
//! the objective and constraints as text, bounds by name, the start and the options, against a
//! model compiled with the free parameters as its gradient parameters. Parses, solves and builds
//! the report, so that both front ends say the same things about the same problem.

use std::time::Instant;

use super::report::OptimizeReport;
use super::{
    optimize, parse_constraint, OptimizeError, OptimizeOptions, OptimizeProblem, Progress, Quantity, Slsqp,
};
use crate::fit::Bounds;
use crate::sema::ParamIdx;
use crate::sim::SimOptions;

/// What to solve, as text where the user wrote text.
pub struct Request<'a> {
    /// The objective (`--minimize`).
    pub minimize: &'a str,
    /// The constraints (`--subject-to`), each `Q OP V` or a path grid.
    pub subject_to: &'a [String],
    /// One box per free parameter (from [`bounds`]).
    pub bounds: Vec<Bounds>,
    /// Every parameter's value: the free ones start there, the others stay there.
    pub start: Vec<f64>,
    pub sim: SimOptions,
    pub options: OptimizeOptions,
}

/// Why an optimisation gave no report.
#[derive(Debug)]
pub enum Failure {
    /// The objective does not parse against the model.
    Objective(String),
    /// A constraint does not parse, or there are more than the cap.
    Constraint(String),
    /// The solver refused the problem (a start outside its bounds, ...).
    Refused(OptimizeError),
}

/// The box of every free parameter: its declared range, narrowed by `narrow` (a parameter or a
/// vector's name, with `lo < hi` within the declared range). Errors name the offending entry.
pub fn bounds(
    model: &crate::Model,
    free: &[ParamIdx],
    narrow: &[(String, f64, f64)],
) -> Result<Vec<Bounds>, String> {
    let params = &model.checked().params;
    let mut out: Vec<Bounds> = free.iter().map(|p| Bounds::from_range(params[p.0 as usize].range)).collect();
    for (name, lo, hi) in narrow {
        let (lo, hi) = (*lo, *hi);
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(format!("`{name}`: expected finite LO < HI, found [{lo}, {hi}]"));
        }
        let indices: Vec<ParamIdx> = match model.vector(name) {
            Some(v) => v.elements().collect(),
            None => vec![model.param_index(name).map_err(|e| e.to_string())?],
        };
        for p in indices {
            let k = free.iter().position(|f| *f == p).ok_or_else(|| {
                format!(
                    "`{}` is not a free parameter (name it in the free parameters)",
                    params[p.0 as usize].name
                )
            })?;
            let declared = out[k];
            if lo < declared.lower || hi > declared.upper {
                return Err(format!(
                    "[{lo}, {hi}] for `{}` leaves its declared range [{}, {}]",
                    params[p.0 as usize].name, declared.lower, declared.upper
                ));
            }
            out[k] = Bounds { lower: lo, upper: hi };
        }
    }
    Ok(out)
}

/// Solves `request` on `compiled` (compiled with the free parameters as gradient parameters),
/// telling `progress` about every trial.
pub fn run(
    model: &crate::Model,
    compiled: &crate::Compiled,
    request: Request<'_>,
    progress: Option<&Progress<'_>>,
) -> Result<OptimizeReport, Failure> {
    let info = compiled.info().clone();
    let objective =
        Quantity::parse(request.minimize, &info).map_err(|e| Failure::Objective(e.to_string()))?;
    let mut constraints = Vec::new();
    for text in request.subject_to {
        constraints.extend(parse_constraint(text, &info).map_err(|e| Failure::Constraint(e.to_string()))?);
        crate::limits::count("constraints in all", constraints.len(), 0, crate::limits::MAX_CONSTRAINTS)
            .map_err(|e| Failure::Constraint(e.to_string()))?;
    }
    let problem = OptimizeProblem {
        system: compiled.native(),
        start: request.start,
        bounds: request.bounds,
        objective,
        constraints,
        sim: request.sim,
    };
    let started = Instant::now();
    let result = optimize(&problem, &request.options, &Slsqp, progress).map_err(Failure::Refused)?;
    Ok(OptimizeReport {
        model: model.name().to_string(),
        info,
        objective: problem.objective,
        options: request.options,
        result,
        compile_seconds: compiled.compile_seconds(),
        optimize_seconds: started.elapsed().as_secs_f64(),
    })
}
