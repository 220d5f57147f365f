//! The seam between hybc and a constrained optimiser: a smooth nonlinear program handed over as
//! one evaluation function (objective, constraints and their exact gradients at a point, or
//! nothing when the run fails), and what the optimiser says when it stops. An optimiser is a
//! [`LocalSolver`]: `slsqp` (general constraints, up to a thousand variables) and `lbfgsb` (bounds
//! only, up to a hundred thousand); `choice` picks one. The verdict (converged or not) is not the
//! optimiser's: `kkt` checks the point it returns.

/// Objective, constraints and gradients at one point. Constraints are `c_i(x) = 0` for the first
/// `n_eq`, then `c_i(x) <= 0`.
#[derive(Clone, Debug, PartialEq)]
pub struct SmoothPoint {
    /// The objective's value.
    pub objective: f64,
    /// Its gradient.
    pub gradient: Vec<f64>,
    /// Each constraint's value.
    pub constraints: Vec<f64>,
    /// One gradient row per constraint.
    pub jacobian: Vec<Vec<f64>>,
}

/// The shape of the program and when the optimiser may stop on its own.
#[derive(Clone, Debug, PartialEq)]
pub struct Program {
    /// Box of each variable (infinite ends for none).
    pub bounds: Vec<(f64, f64)>,
    /// Equality constraints (the first ones).
    pub n_eq: usize,
    /// Inequality constraints (the rest).
    pub n_ineq: usize,
    /// How much each constraint may be off and still count as met; an optimiser may aim at
    /// a narrow band within this width around an equality (see `slsqp`).
    pub tolerances: Vec<f64>,
    /// Most evaluations (each one simulation run, unless it repeats the last point).
    pub max_evals: usize,
    /// Stop when a step changes every variable by less than this, relatively.
    pub xtol_rel: f64,
    /// Stop when a step changes the objective by less than this, relatively.
    pub ftol_rel: f64,
    /// The verdict's stationarity tolerance (`--kkt-tol`): an optimiser that measures the
    /// projected gradient may stop once it is below this times the gradient scale (the largest
    /// `|grad f|` at the start or at the point), as the verdict measures it for bounds alone.
    pub gtol: f64,
}

/// Why an optimiser stopped, in its own terms.
#[derive(Clone, Debug, PartialEq)]
pub struct SolverEnd {
    /// The point it returns.
    pub x: Vec<f64>,
    /// Its status word (`XtolReached`, `RoundoffLimited`, ...).
    pub status: String,
    /// It used up `max_evals`.
    pub out_of_evals: bool,
}

/// The evaluation function: `None` where the run fails (an optimiser must step back).
pub type Evaluate<'e> = dyn FnMut(&[f64]) -> Option<SmoothPoint> + 'e;

/// A local optimiser for smooth constrained problems with exact gradients.
pub trait LocalSolver: Sync {
    /// Its name in reports.
    fn name(&self) -> &'static str;
    /// The most free variables its workspace takes (`limits`).
    fn max_free(&self) -> usize;
    /// Whether it takes general constraints (else bounds only).
    fn takes_constraints(&self) -> bool;
    /// Minimises from `x0` (inside the bounds).
    fn solve(&self, program: &Program, x0: &[f64], evaluate: &mut Evaluate<'_>) -> SolverEnd;
}
