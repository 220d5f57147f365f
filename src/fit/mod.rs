//! Least-squares fitting through events: find the free parameters that make the final outputs,
//! final states and event times of a run match targets. A library user of `sim`: every residual
//! and its exact Jacobian row come from one run of an already compiled model (the free
//! parameters are its gradient parameters), so a fit never recompiles.
//!
//! The objective `0.5 * sum(weight * (value - target))^2` is only piecewise smooth in the
//! parameters: where the sequence of events changes (a bounce moves past the final time) it has a
//! cusp or a jump. The solver (`lm`) is a Levenberg-Marquardt trust region that treats a trial
//! point on another piece with suspicion: it is kept only if the objective really decreased, and a
//! rejected one shortens the step. A trial whose run fails, whose target event does not fire, or
//! whose gradient does not exist (grazing) is rejected the same way.
//!
//! Code map: `target` (what to match, parsed from `NAME=VALUE@WEIGHT`), `evaluate` (one run ->
//! residuals and Jacobian), `lm` (the solver), `report` (names, table, JSON), `data` (a CSV of
//! measurements as targets, standard errors). A whole fit from text, for the CLI and Python, is
//! the door's `FitRequest` (`api/request/fit.rs`).

pub mod data;
mod evaluate;
mod lm;
mod report;
mod target;

pub use evaluate::{evaluate, Evaluation, Rejection};
pub use report::FitReport;
pub use target::{sample_times, Observable, Target, TargetError};

use crate::sim::{HybridSystem, Runner, SimOptions};

/// The box a free parameter must stay in; infinite ends for none. Trial points are projected
/// onto the box, and a parameter at a bound that the gradient pushes outwards is held there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// The lower end (`-inf` for none).
    pub lower: f64,
    /// The upper end (`inf` for none).
    pub upper: f64,
}

impl Bounds {
    /// No bounds.
    pub const NONE: Bounds = Bounds { lower: f64::NEG_INFINITY, upper: f64::INFINITY };

    /// The declared range of a parameter (`param e = 0.8 in [0, 1]`), or no bounds.
    pub fn from_range(range: Option<(f64, f64)>) -> Bounds {
        range.map_or(Bounds::NONE, |(lower, upper)| Bounds { lower, upper })
    }

    /// Whether `x` is inside (the ends included).
    pub fn contains(&self, x: f64) -> bool {
        (self.lower..=self.upper).contains(&x)
    }
}

/// When the solver stops. Tolerances are relative and dimensionless.
#[derive(Clone, Debug, PartialEq)]
pub struct FitOptions {
    /// Largest number of trial points (each one simulation run), the start not counted.
    pub max_iter: usize,
    /// Converged when the Gauss-Newton step is below `xtol` relative to the parameters (both
    /// scaled by the Jacobian's column norms).
    pub xtol: f64,
    /// Converged when the residual vector is this close to orthogonal to every Jacobian column
    /// (the cosine of the angle; the gradient condition of a nonzero-residual minimum).
    pub gtol: f64,
    /// Converged when an accepted step lowers the objective by less than this fraction.
    pub ftol: f64,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions { max_iter: 100, xtol: 1e-10, gtol: 1e-10, ftol: 1e-14 }
    }
}

/// What the solver did with one trial point.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// The starting point (iteration 0).
    Start,
    /// The objective decreased enough: the trial is the new point.
    Accepted,
    /// The objective did not decrease enough: the step is shortened.
    Rejected,
    /// The trial gave no residuals: the step is shortened.
    Failed(Rejection),
}

/// One trial point: one simulation run.
#[derive(Clone, Debug, PartialEq)]
pub struct Iteration {
    /// 0 for the start, then one per trial.
    pub iteration: usize,
    /// The free parameters of the trial.
    pub free: Vec<f64>,
    /// The trial's objective; `None` when it gave no residuals.
    pub objective: Option<f64>,
    /// Euclidean norm of the step to the trial, in parameter units.
    pub step_norm: f64,
    /// Number of events of the trial's run; `None` when the run failed.
    pub events: Option<usize>,
    /// The Levenberg-Marquardt damping the step was computed with (relative to the squared
    /// column norms of the Jacobian); `None` at the start.
    pub damping: Option<f64>,
    /// Whether the trial lies on another smooth piece (its event sequence differs).
    pub cusp: bool,
    /// How the trial went.
    pub outcome: Outcome,
}

/// A trial whose event sequence differed from the current point's.
#[derive(Clone, Debug, PartialEq)]
pub struct Cusp {
    /// The trial (numbered from 1).
    pub iteration: usize,
    /// Number of events at the current point and at the trial.
    pub events_before: usize,
    /// Number of events at the trial.
    pub events_after: usize,
    /// Whether the trial was accepted.
    pub accepted: bool,
}

/// Why a fit stopped short of convergence on a stall.
#[derive(Clone, Debug, PartialEq)]
pub enum StallCause {
    /// The last trial rejected on another piece of the objective.
    Cusp(Cusp),
    /// The last trial that gave no residuals.
    Failed {
        /// The trial.
        iteration: usize,
        /// Why it gave no residuals.
        rejection: Rejection,
    },
    /// Trials on the same piece did not lower the objective although the Gauss-Newton step is not
    /// small: the simulation's error is larger than the step (tighten the tolerances).
    NoDecrease,
    /// The singular value decomposition of the Jacobian did not converge.
    Singular,
}

/// Why the solver stopped.
#[derive(Clone, Debug, PartialEq)]
pub enum FitStop {
    /// Converged: the residuals are orthogonal to the Jacobian's columns (within `gtol`), or
    /// every free parameter is held at a bound.
    Gradient,
    /// Converged: the Gauss-Newton step is below `xtol`.
    Step,
    /// Converged: the residuals are zero, or an accepted step lowered the objective by less than
    /// `ftol`.
    Objective,
    /// Not converged: `max_iter` trials.
    MaxIterations,
    /// Not converged: every trial was rejected until the step fell below `xtol`.
    Stalled(StallCause),
}

impl FitStop {
    /// Whether the fit converged (a least-squares minimum).
    pub fn is_converged(&self) -> bool {
        matches!(self, FitStop::Gradient | FitStop::Step | FitStop::Objective)
    }
}

/// What to fit: a compiled model whose gradient parameters are the free parameters.
#[derive(Clone, Debug)]
pub struct FitProblem<'s, S: HybridSystem> {
    /// The compiled model, its gradient parameters the free parameters.
    pub system: &'s S,
    /// All parameter values; those of the free parameters are the starting point.
    pub start: Vec<f64>,
    /// One per free parameter, in the system's gradient order.
    pub bounds: Vec<Bounds>,
    /// What to match.
    pub targets: Vec<Target>,
    /// The options of every run.
    pub sim: SimOptions,
}

/// A finished fit.
#[derive(Clone, Debug)]
pub struct FitResult {
    /// All parameter values at the end; the free ones fitted.
    pub params: Vec<f64>,
    /// Residuals, values and Jacobian at the end.
    pub evaluation: Evaluation,
    /// Ratio of the largest to the smallest singular value of the final Jacobian (infinite when
    /// it is rank deficient, as with fewer targets than free parameters).
    pub condition: f64,
    /// The start and every trial.
    pub iterations: Vec<Iteration>,
    /// Trials whose event sequence differed from the current point's.
    pub cusps: Vec<Cusp>,
    /// Why the solver stopped: a least-squares minimum (converged) or not.
    pub stop: FitStop,
    /// Per target: the largest `|value - goal|` that counts as met ([`target_tolerance`]).
    pub tolerances: Vec<f64>,
    /// The box of each free parameter (the problem's), to tell which ended at a bound.
    pub bounds: Vec<Bounds>,
    /// Per target: whether `|value - goal|` at the end is within its tolerance.
    pub met: Vec<bool>,
}

impl FitResult {
    /// Converged: the solver reached a minimum and every target is met there. Targets are
    /// equations, so a least-squares minimum that leaves one unmet (at a bound, between two event
    /// sequences, or because the targets contradict each other) is not a converged fit.
    pub fn is_converged(&self) -> bool {
        self.stop.is_converged() && self.targets_met()
    }

    /// Whether every target is within its tolerance at the end.
    pub fn targets_met(&self) -> bool {
        self.met.iter().all(|&m| m)
    }
}

/// How far a target's model value may lie from its goal and still count as met:
/// `100 (rtol max(|goal|, |value|) + atol)` with the run's tolerances. A run's values move with the
/// parameters only as smoothly as the integrator's error control lets them (a different step
/// sequence shifts them by about the local tolerance), so a fit can solve its equations to that
/// level and no further; the factor 100 leaves room for the error accumulated over the steps and
/// events, while a target missed by a bound or a jump misses by far more. The weight does not
/// enter: it ranks residuals in the objective, the equation is the same.
pub fn target_tolerance(goal: f64, value: f64, sim: &SimOptions) -> f64 {
    100.0 * (sim.rtol * goal.abs().max(value.abs()) + sim.atol)
}

/// A fit that cannot start.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FitError {
    /// The system has no gradient parameters to fit.
    #[error("no free parameters: compile the model with the free parameters as gradient parameters")]
    NoFreeParameters,
    /// Nothing to fit to.
    #[error("no targets")]
    NoTargets,
    /// Not one box per free parameter.
    #[error("{got} bounds for {expected} free parameters")]
    BoundsLength {
        /// The free parameters.
        expected: usize,
        /// The boxes given.
        got: usize,
    },
    /// A start outside its box.
    #[error("start value {value} of `{name}` is outside its bounds [{lower}, {upper}]")]
    StartOutsideBounds {
        /// The parameter.
        name: String,
        /// Its start.
        value: f64,
        /// The box's lower end.
        lower: f64,
        /// The box's upper end.
        upper: f64,
    },
    /// The targets cannot be evaluated at the start.
    #[error("cannot evaluate the targets at the starting point: {0}")]
    Start(Rejection),
}

/// Fits the free parameters of `problem` to its targets.
pub fn fit<S: HybridSystem>(problem: &FitProblem<'_, S>, opts: &FitOptions) -> Result<FitResult, FitError> {
    let info = problem.system.info();
    let free = &info.grad_params;
    if free.is_empty() {
        return Err(FitError::NoFreeParameters);
    }
    if problem.targets.is_empty() {
        return Err(FitError::NoTargets);
    }
    if problem.bounds.len() != free.len() {
        return Err(FitError::BoundsLength { expected: free.len(), got: problem.bounds.len() });
    }
    let x0: Vec<f64> = free.iter().map(|&j| problem.start[j]).collect();
    for ((&j, b), &value) in free.iter().zip(&problem.bounds).zip(&x0) {
        if !b.contains(value) {
            let name = info.param_names[j].clone();
            return Err(FitError::StartOutsideBounds { name, value, lower: b.lower, upper: b.upper });
        }
    }
    let with_free = |x: &[f64]| {
        let mut p = problem.start.clone();
        for (&j, &v) in free.iter().zip(x) {
            p[j] = v;
        }
        p
    };
    // `NAME@TIME` targets are read off the run's samples at their times.
    let sampled =
        SimOptions { at: sample_times(problem.targets.iter().map(|t| &t.observable)), ..problem.sim.clone() };
    let mut simulator = Runner::new(problem.system, &sampled)
        .map_err(|e| FitError::Start(Rejection::RunStopped { message: e.to_string() }))?;
    let solved = lm::minimize(x0, &problem.bounds, opts, |x| {
        evaluate(&mut simulator, &with_free(x), &problem.targets)
    })
    .map_err(FitError::Start)?;
    let tolerances: Vec<f64> = problem
        .targets
        .iter()
        .zip(&solved.evaluation.values)
        .map(|(t, &v)| target_tolerance(t.value, v, &problem.sim))
        .collect();
    let met = problem
        .targets
        .iter()
        .zip(&solved.evaluation.values)
        .zip(&tolerances)
        .map(|((t, &v), &tol)| t.observed || (v - t.value).abs() <= tol)
        .collect();
    Ok(FitResult {
        params: with_free(&solved.x),
        condition: lm::condition_number(&solved.evaluation.jacobian),
        evaluation: solved.evaluation,
        iterations: solved.iterations,
        cusps: solved.cusps,
        stop: solved.stop,
        tolerances,
        bounds: problem.bounds.clone(),
        met,
    })
}
