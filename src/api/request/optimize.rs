//! A whole optimisation as a user asks for it (`hybc optimize` and Python's `Model.optimize`):
//! the objective and constraints as text, bounds by name, the start and the options, run on a
//! model compiled with the free parameters as its gradient parameters. Parses, solves
//! (`optimize::optimize`, the core) and builds the report, so that both front ends say the same
//! things about the same problem.

use std::time::Instant;

use crate::api::{Compiled, Error, Model};
use crate::fit::Bounds;
use crate::optimize::report::OptimizeReport;
use crate::optimize::{
    optimize, parse_constraint, OptimizeError, OptimizeOptions, OptimizeProblem, Progress, Quantity,
    SolverChoice,
};
use crate::sema::ParamIdx;
use crate::sim::SimOptions;

/// What to solve, as text where the user wrote text.
#[derive(Clone, Debug)]
pub struct OptimizeRequest<'a> {
    /// The objective (`--minimize`).
    pub minimize: &'a str,
    /// The constraints (`--subject-to`), each `Q OP V` or a path grid.
    pub subject_to: &'a [String],
    /// One box per free parameter (from [`OptimizeRequest::bounds`]).
    pub bounds: Vec<Bounds>,
    /// Every parameter's value: the free ones start there, the others stay there.
    pub start: Vec<f64>,
    /// The options of every run.
    pub sim: SimOptions,
    /// The solver's tolerances, the starts and the threads.
    pub options: OptimizeOptions,
    /// Which local solver runs (`--solver`, Python `solver=`).
    pub solver: SolverChoice,
}

/// Why an optimisation gave no report.
#[derive(Debug, thiserror::Error)]
pub enum OptimizeFailure {
    /// The objective does not parse against the model.
    #[error("{0}")]
    Objective(String),
    /// A constraint does not parse, or there are more than the cap.
    #[error("{0}")]
    Constraint(String),
    /// The solver asked for does not take the problem (L-BFGS-B with general constraints).
    #[error("{0}")]
    Solver(String),
    /// The solver refused the problem (a start outside its bounds, ...).
    #[error(transparent)]
    Refused(OptimizeError),
}

impl OptimizeRequest<'_> {
    /// The box of every free parameter: its declared range, narrowed by `narrow` (a parameter or
    /// a vector's name, with `lo < hi` within the declared range). Errors name the offending
    /// entry.
    pub fn bounds(
        model: &Model,
        free: &[ParamIdx],
        narrow: &[(String, f64, f64)],
    ) -> Result<Vec<Bounds>, String> {
        let params = &model.checked().params;
        let mut out: Vec<Bounds> =
            free.iter().map(|p| Bounds::from_range(params[p.0 as usize].range)).collect();
        for (name, lo, hi) in narrow {
            let (lo, hi) = (*lo, *hi);
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(format!("`{name}`: expected finite LO < HI, found [{lo}, {hi}]"));
            }
            for p in model.param_list(&[name]).map_err(|e| e.to_string())? {
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

    /// Solves the problem on `compiled` (compiled with the free parameters as gradient
    /// parameters), telling `progress` about every trial.
    pub fn run(self, compiled: &Compiled, progress: Option<&Progress<'_>>) -> Result<OptimizeReport, Error> {
        let info = compiled.info().clone();
        let objective =
            Quantity::parse(self.minimize, &info).map_err(|e| OptimizeFailure::Objective(e.to_string()))?;
        // A value at a time the run does not reach is refused here, with its cause, not by the run.
        let (t_start, t_end) = (self.sim.t_start, self.sim.t_end);
        let within = |q: &Quantity, text: &str| match q {
            Quantity::Observable(o) => o.sample_time().map_or(Ok(()), |t| {
                crate::api::options::sample_times_within(&[t], t_start, t_end, &format!("`{}`", text.trim()))
            }),
            Quantity::Param(_) => Ok(()),
        };
        within(&objective, self.minimize).map_err(OptimizeFailure::Objective)?;
        let mut constraints = Vec::new();
        for text in self.subject_to {
            let parsed =
                parse_constraint(text, &info).map_err(|e| OptimizeFailure::Constraint(e.to_string()))?;
            for c in &parsed {
                within(&c.quantity, text).map_err(OptimizeFailure::Constraint)?;
            }
            constraints.extend(parsed);
            crate::limits::count("constraints in all", constraints.len(), 0, crate::limits::MAX_CONSTRAINTS)
                .map_err(|e| OptimizeFailure::Constraint(e.to_string()))?;
        }
        let solver = self
            .solver
            .pick(compiled.info().grad_params.len(), constraints.len())
            .map_err(OptimizeFailure::Solver)?;
        let problem = OptimizeProblem {
            system: compiled.system(),
            start: self.start,
            bounds: self.bounds,
            objective,
            constraints,
            sim: self.sim,
        };
        let started = Instant::now();
        let result = optimize(&problem, &self.options, solver, progress).map_err(OptimizeFailure::Refused)?;
        Ok(OptimizeReport {
            model: compiled.model().name().to_string(),
            info,
            objective: problem.objective,
            options: self.options,
            result,
            compile_seconds: compiled.compile_seconds(),
            optimize_seconds: started.elapsed().as_secs_f64(),
        })
    }
}
