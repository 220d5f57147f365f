//! Constrained optimisation over model parameters with exact gradients through events
//! (`hybc optimize`): minimise a quantity a run reports (an output, a state, an event time, a
//! value at a time, or a parameter) subject to equalities and inequalities on such quantities and
//! to the parameters' boxes. Single shooting: every point is one run of the model compiled once
//! with the free parameters as gradient parameters, so objective and constraint gradients are the
//! run's sensitivities.
//!
//! The problem is only piecewise smooth: where the sequence of events changes, values jump or
//! kink. The optimiser (behind the `solver` seam: `slsqp` for general constraints, `lbfgsb` for
//! bounds only and many variables, `choice` picks) sees a smooth program and a failed run as a
//! point to step back from; the verdict is ours (`kkt`): converged only
//! where the KKT conditions hold to a stated tolerance at the point returned. Every run whose
//! event sequence differs from the previous run's is logged, and the optimum's own run is
//! searched for the flags that make a gradient hold only locally (an event at a breakpoint or at
//! `t_end`, a near-grazing event). Several starts (seeded, within the bounds) run in parallel and
//! the distinct optima are reported with their event sequences: hybrid problems have a local
//! optimum per event branch.
//!
//! One entry point for every front end: [`optimize`] takes the problem and options and returns an
//! [`OptimizeResult`]. Code map: `spec` (objective and constraints from text), `evaluate` (one
//! run -> program values and gradients), `solver` (the seam), `slsqp` and `lbfgsb` (the
//! optimisers), `choice` (which one runs), `kkt` (the verdict), `curvature` (the minimum check),
//! `report` (table and JSON), `shards` (the report of a multi-start run in shards, merged). A whole problem from text, for the CLI and Python, is the door's
//! `OptimizeRequest` (`api/request/optimize.rs`).

mod choice;
mod curvature;
mod evaluate;
mod kkt;
mod lbfgsb;
pub mod report;
mod shards;
mod slsqp;
pub mod solver;
mod spec;

pub use choice::{SolverChoice, LBFGSB_ABOVE};
pub use curvature::Descent;
pub use kkt::Kkt;
pub use lbfgsb::Lbfgsb;
pub use shards::merge_shards;
pub use slsqp::Slsqp;
pub use spec::{parse_constraint, Constraint, Quantity, Sense, SpecError};

use rayon::prelude::*;

use crate::fit::{sample_times, target_tolerance, Bounds, Rejection};
use crate::sim::{HybridSystem, Runner, SimOptions, SimResult, SimWarning, StopReason};
use evaluate::{Evaluated, Layout};
use solver::{LocalSolver, Program, SmoothPoint};

/// What to optimise: a compiled model whose gradient parameters are the free parameters.
#[derive(Clone, Debug)]
pub struct OptimizeProblem<'s, S: HybridSystem> {
    /// The compiled model, its gradient parameters the free parameters.
    pub system: &'s S,
    /// All parameter values; those of the free parameters are the first start.
    pub start: Vec<f64>,
    /// One per free parameter, in the system's gradient order.
    pub bounds: Vec<Bounds>,
    /// What to minimise.
    pub objective: Quantity,
    /// What must hold.
    pub constraints: Vec<Constraint>,
    /// The options of every run.
    pub sim: SimOptions,
}

/// How long to search and when a point counts as optimal.
#[derive(Clone, Debug, PartialEq)]
pub struct OptimizeOptions {
    /// Most evaluations the optimiser may ask for in one local solve: each is a run, except a
    /// request for the point it asked for last (served from a cache), so a solve makes at most
    /// this many runs.
    pub max_iter: usize,
    /// Converged when the projected Lagrangian gradient is at most this times the gradient scale
    /// (`Kkt::scale`: the objective's gradient at the start and the Lagrangian's terms at the end)
    /// and every constraint is met to its tolerance.
    pub kkt_tol: f64,
    /// The optimiser may stop when a step changes every parameter by less than this, relatively.
    pub xtol: f64,
    /// The optimiser may stop when a step changes the objective by less than this, relatively.
    pub ftol: f64,
    /// Starting points: the problem's start, then `starts - 1` drawn uniformly in the bounds.
    pub starts: usize,
    /// Seed of the drawn starts (ChaCha8, as `hybc sweep --samples`).
    pub seed: u64,
    /// Worker threads for the starts (0: one per core).
    pub threads: usize,
    /// Only the starts `first..last` of the `starts` (the same seeded draw): one shard of a
    /// multi-start spread over processes (`hybc.dask.optimize`). `merge_shards` puts
    /// the shards' reports together into the report of the whole. `None`: every start.
    pub shard: Option<(usize, usize)>,
}

impl Default for OptimizeOptions {
    fn default() -> Self {
        OptimizeOptions {
            max_iter: 200,
            kkt_tol: 1e-6,
            xtol: 1e-10,
            ftol: 1e-12,
            starts: 1,
            seed: 0,
            threads: 0,
            shard: None,
        }
    }
}

/// One run of a local solve.
#[derive(Clone, Debug, PartialEq)]
pub struct Trial {
    /// 0-based count of runs in this local solve.
    pub run: usize,
    /// The free parameters.
    pub free: Vec<f64>,
    /// The objective; `None` when the run failed.
    pub objective: Option<f64>,
    /// The largest constraint violation (0 when every constraint holds).
    pub violation: Option<f64>,
    /// Number of events; `None` when the run failed.
    pub events: Option<usize>,
    /// The event sequence differs from the previous successful run's.
    pub new_sequence: bool,
    /// Why the run gave no values.
    pub failure: Option<String>,
}

/// A run whose event sequence differed from the previous successful run's.
#[derive(Clone, Debug, PartialEq)]
pub struct SequenceChange {
    /// The run (numbered from 1).
    pub run: usize,
    /// Event ids before and after.
    pub before: Vec<usize>,
    /// Event ids after.
    pub after: Vec<usize>,
}

/// Why a local solve ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Verdict {
    /// The KKT conditions hold to the tolerances at the point returned.
    Converged,
    /// The optimiser used up its `max_iter` evaluations first.
    MaxIterations,
    /// The optimiser stopped where runs nearby have another event sequence (the last such run is
    /// named): the point sits at a cusp or jump of the problem, not at a smooth optimum.
    StalledAtCusp {
        /// The last run with another event sequence.
        run: usize,
    },
    /// The optimiser stopped after runs that failed (the last one's reason).
    RunsFailing {
        /// Why the last run failed.
        message: String,
    },
    /// A constraint is not met to its tolerance (the optimiser found no feasible point).
    Infeasible,
    /// Feasible, but the Lagrangian's gradient does not vanish to `kkt_tol`.
    Stalled,
    /// The KKT conditions hold, but the point is no minimum: the Lagrangian's curvature is
    /// negative along a direction the bounds and active constraints leave free, and values along
    /// it confirm the descent (a maximum or a saddle; `curvature.rs`).
    NotAMinimum {
        /// The negative curvature, in the variables scaled by their scales.
        curvature: f64,
        /// How much lower the Lagrangian is a thousandth of the scales away along it.
        drop: f64,
    },
    /// The starting point cannot be evaluated.
    StartFailed {
        /// Why it cannot be evaluated.
        message: String,
    },
}

impl Verdict {
    /// The JSON word.
    pub fn word(&self) -> &'static str {
        match self {
            Verdict::Converged => "converged",
            Verdict::MaxIterations => "max_iterations",
            Verdict::StalledAtCusp { .. } => "stalled_at_cusp",
            Verdict::RunsFailing { .. } => "runs_failing",
            Verdict::Infeasible => "infeasible",
            Verdict::Stalled => "stalled",
            Verdict::NotAMinimum { .. } => "not_a_minimum",
            Verdict::StartFailed { .. } => "start_failed",
        }
    }
}

/// One local solve from one start.
#[derive(Clone, Debug)]
pub struct LocalResult {
    /// Which start this is (0 the problem's own, then the drawn ones in order).
    pub index: usize,
    /// Free parameters at the start.
    pub start: Vec<f64>,
    /// Free parameters at the end.
    pub x: Vec<f64>,
    /// All parameter values at the end.
    pub params: Vec<f64>,
    /// Objective then constraint values at the end (layout order: see `OptimizeResult::constraints`);
    /// empty when the end cannot be evaluated.
    pub values: Vec<f64>,
    /// The KKT measures at the end, when it could be evaluated.
    pub kkt: Option<Kkt>,
    /// Why the solve ended.
    pub verdict: Verdict,
    /// The optimiser's own status word.
    pub status: String,
    /// The optimiser's evaluations, one run each.
    pub trials: Vec<Trial>,
    /// Simulation runs in all: the evaluations, one or two at the end for the report, and the
    /// second-order check's (`probe_runs`).
    pub runs: usize,
    /// The runs of the second-order check at a stationary end (`curvature.rs`).
    pub probe_runs: usize,
    /// How many times the optimiser asked for a point with a non-finite coordinate: no run is
    /// made there, the optimiser is told the point failed, and its search has broken down.
    pub non_finite: usize,
    /// The runs whose event sequence differed from the previous one's.
    pub changes: Vec<SequenceChange>,
    /// The end's run (events, final state, warnings), when it could be run.
    pub run: Option<SimResult>,
    /// What makes the end's gradients hold only locally: events at a breakpoint or at `t_end`,
    /// (near-)grazing events, samples within an event's resolution. Empty for a smooth optimum.
    pub cusp_notes: Vec<String>,
}

impl LocalResult {
    /// Whether it ended at a point where the KKT conditions hold.
    pub fn converged(&self) -> bool {
        self.verdict == Verdict::Converged
    }

    /// Event ids of the end's run.
    pub fn events(&self) -> Vec<usize> {
        self.run.as_ref().map(|r| r.events.iter().map(|e| e.event).collect()).unwrap_or_default()
    }
}

/// The outcome of every start.
#[derive(Clone, Debug)]
pub struct OptimizeResult {
    /// The constraints in the order of `LocalResult::values` (equalities first).
    pub constraints: Vec<Constraint>,
    /// Per constraint, how far it may be off (at the best end; at the first end if none converged).
    pub tolerances: Vec<f64>,
    /// Every start's solve, in start order.
    pub locals: Vec<LocalResult>,
    /// Distinct converged optima, best first: the indices of the starts that reached each (the
    /// first is its representative). Two ends are the same optimum when they have the same event
    /// sequence and every free parameter agrees to 1e-6 of its scale.
    pub optima: Vec<Vec<usize>>,
    /// The optimiser's name.
    pub solver: &'static str,
}

impl OptimizeResult {
    /// The best converged end, if any.
    pub fn best(&self) -> Option<&LocalResult> {
        self.optima.first().map(|group| &self.locals[group[0]])
    }

    /// The end to report when none converged: the first start's.
    pub fn reported(&self) -> &LocalResult {
        self.best().unwrap_or(&self.locals[0])
    }

    /// Simulation runs in all, over every start.
    pub fn runs(&self) -> usize {
        self.locals.iter().map(|l| l.runs).sum()
    }
}

/// An optimisation that cannot start.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum OptimizeError {
    /// The system has no gradient parameters to optimise.
    #[error("no free parameters: compile the model with the free parameters as gradient parameters")]
    NoFreeParameters,
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
    /// Several starts asked for, and a free parameter without a finite box to draw them in.
    #[error("several starts are drawn within the bounds, but `{name}` has no finite range: declare `in [lo, hi]` or give --bounds")]
    StartsNeedBounds {
        /// The parameter.
        name: String,
    },
    /// No start asked for.
    #[error("at least one start")]
    NoStarts,
    #[error(
        "{free} free parameters and {constraints} constraints: {solver} takes at most {max_free} and {} (its workspace)",
        crate::limits::MAX_CONSTRAINTS
    )]
    /// More free parameters or constraints than the optimiser's workspace takes.
    TooLarge {
        /// The free parameters.
        free: usize,
        /// The constraints.
        constraints: usize,
        /// The optimiser.
        solver: &'static str,
        /// The most free parameters it takes.
        max_free: usize,
    },
    /// General constraints handed to an optimiser for bounds only.
    #[error("{solver} takes bounds only, and the problem has {constraints} constraint(s): use SLSQP")]
    BoundsOnly {
        /// The optimiser.
        solver: &'static str,
        /// The constraints.
        constraints: usize,
    },
    /// The worker threads could not be started.
    #[error("cannot start a worker thread: {0}")]
    Threads(String),
    /// A shard outside the starts.
    #[error("shard {first}..{last} of {starts} starts: expected first < last <= starts")]
    Shard {
        /// Its first start.
        first: usize,
        /// One past its last.
        last: usize,
        /// The starts in all.
        starts: usize,
    },
}

/// Progress: called after every run with the start's index and the run.
pub type Progress<'p> = dyn Fn(usize, &Trial) + Sync + 'p;

/// Minimises `problem`'s objective from every start with `solver`, in parallel.
pub fn optimize<S: HybridSystem + Sync>(
    problem: &OptimizeProblem<'_, S>,
    opts: &OptimizeOptions,
    solver: &dyn LocalSolver,
    progress: Option<&Progress<'_>>,
) -> Result<OptimizeResult, OptimizeError> {
    let info = problem.system.info();
    let free = &info.grad_params;
    if free.is_empty() {
        return Err(OptimizeError::NoFreeParameters);
    }
    if problem.bounds.len() != free.len() {
        return Err(OptimizeError::BoundsLength { expected: free.len(), got: problem.bounds.len() });
    }
    if opts.starts == 0 {
        return Err(OptimizeError::NoStarts);
    }
    // SLSQP's dense workspace grows as (parameters + constraints)^2, L-BFGS-B's as parameters.
    if free.len() > solver.max_free() || problem.constraints.len() > crate::limits::MAX_CONSTRAINTS {
        return Err(OptimizeError::TooLarge {
            free: free.len(),
            constraints: problem.constraints.len(),
            solver: solver.name(),
            max_free: solver.max_free(),
        });
    }
    if !solver.takes_constraints() && !problem.constraints.is_empty() {
        return Err(OptimizeError::BoundsOnly {
            solver: solver.name(),
            constraints: problem.constraints.len(),
        });
    }
    for (&j, b) in free.iter().zip(&problem.bounds) {
        let value = problem.start[j];
        if !b.contains(value) {
            let name = info.param_names[j].clone();
            return Err(OptimizeError::StartOutsideBounds { name, value, lower: b.lower, upper: b.upper });
        }
        if opts.starts > 1 && !(b.lower.is_finite() && b.upper.is_finite()) {
            return Err(OptimizeError::StartsNeedBounds { name: info.param_names[j].clone() });
        }
    }
    let ranges = free.iter().zip(&problem.bounds).map(|(&j, b)| (j, b.lower, b.upper)).collect();
    let samples =
        crate::sweep::Draws::new(problem.start.clone(), ranges, opts.starts.saturating_sub(1), opts.seed);
    let start_of = |i: usize| {
        let mut p = problem.start.clone();
        if i > 0 {
            samples.fill(i - 1, &mut p);
        }
        p
    };
    let (first, last) = opts.shard.unwrap_or((0, opts.starts));
    if !(first < last && last <= opts.starts) {
        return Err(OptimizeError::Shard { first, last, starts: opts.starts });
    }
    let layout = Layout::new(problem.objective, &problem.constraints);
    let mut locals: Vec<LocalResult> = if last - first == 1 {
        vec![local(problem, &layout, opts, solver, start_of(first), &|t| report(progress, first, t))]
    } else {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(opts.threads)
            .build()
            .map_err(|e| OptimizeError::Threads(e.to_string()))?;
        pool.install(|| {
            (first..last)
                .into_par_iter()
                .map(|i| local(problem, &layout, opts, solver, start_of(i), &|t| report(progress, i, t)))
                .collect()
        })
    };
    for (l, index) in locals.iter_mut().zip(first..) {
        l.index = index;
    }
    let optima = distinct_optima(&locals, &problem.bounds);
    let shown = optima.first().map_or(0, |g| g[0]);
    let tolerances = constraint_tolerances(&layout, &locals[shown].values, &problem.sim);
    Ok(OptimizeResult { constraints: layout.constraints, tolerances, locals, optima, solver: solver.name() })
}

fn report(progress: Option<&Progress<'_>>, start: usize, trial: &Trial) {
    if let Some(p) = progress {
        p(start, trial);
    }
}

/// How far each constraint may be off: the tolerance `hybc fit` allows a target,
/// `100 (rtol max(|bound|, |value|) + atol)`, at the constraint's value (its bound when unknown).
fn constraint_tolerances(layout: &Layout, values: &[f64], sim: &SimOptions) -> Vec<f64> {
    layout
        .constraints
        .iter()
        .enumerate()
        .map(|(k, c)| target_tolerance(c.value, values.get(k + 1).copied().unwrap_or(c.value), sim))
        .collect()
}

/// One local solve from `start` (all parameters).
fn local<S: HybridSystem>(
    problem: &OptimizeProblem<'_, S>,
    layout: &Layout,
    opts: &OptimizeOptions,
    solver: &dyn LocalSolver,
    start: Vec<f64>,
    progress: &dyn Fn(&Trial),
) -> LocalResult {
    let info = problem.system.info();
    let free = &info.grad_params;
    let x0: Vec<f64> = free.iter().map(|&j| start[j]).collect();
    let with_free = |x: &[f64]| {
        let mut p = start.clone();
        for (&j, &v) in free.iter().zip(x) {
            p[j] = v;
        }
        p
    };
    let sampled = SimOptions { at: sample_times(layout.observables()), ..problem.sim.clone() };
    let failed = |message: String, status: &str, runs: usize| LocalResult {
        index: 0,
        start: x0.clone(),
        x: x0.clone(),
        params: start.clone(),
        values: Vec::new(),
        kkt: None,
        verdict: Verdict::StartFailed { message },
        status: status.to_string(),
        runs,
        probe_runs: 0,
        non_finite: 0,
        trials: Vec::new(),
        changes: Vec::new(),
        run: None,
        cusp_notes: Vec::new(),
    };
    let mut simulator = match Runner::new(problem.system, &sampled) {
        Ok(s) => s,
        Err(e) => return failed(e.to_string(), "not started", 0),
    };
    let first = match evaluate::evaluate(&mut simulator, info, layout, &with_free(&x0)) {
        Ok(e) => e,
        Err(r) => return failed(r.to_string(), "not started", 1),
    };
    let tolerances = constraint_tolerances(layout, &first.values, &problem.sim);
    let start_gradient = first.point.gradient.clone();
    let program = Program {
        bounds: problem.bounds.iter().map(|b| (b.lower, b.upper)).collect(),
        n_eq: layout.n_eq,
        n_ineq: layout.constraints.len() - layout.n_eq,
        tolerances: tolerances.clone(),
        max_evals: opts.max_iter,
        xtol_rel: opts.xtol,
        ftol_rel: opts.ftol,
        gtol: opts.kkt_tol,
    };
    let mut trials: Vec<Trial> = Vec::new();
    let mut changes: Vec<SequenceChange> = Vec::new();
    let mut previous: Option<Vec<usize>> = None;
    let mut last: Option<(Vec<f64>, Result<Evaluated, Rejection>)> = None;
    let mut non_finite = 0;
    let mut end = {
        let mut evaluate_at = |x: &[f64]| -> Option<SmoothPoint> {
            // No run at a point that is not one: the optimiser is told it failed.
            if x.iter().any(|v| !v.is_finite()) {
                non_finite += 1;
                return None;
            }
            let run = trials.len();
            let outcome = if run == 0 {
                Ok(first.clone())
            } else {
                evaluate::evaluate(&mut simulator, info, layout, &with_free(x))
            };
            let trial = match &outcome {
                Ok(e) => {
                    let new_sequence = previous.as_ref().is_some_and(|p| *p != e.events);
                    if new_sequence {
                        let before = previous.clone().unwrap_or_default();
                        changes.push(SequenceChange { run, before, after: e.events.clone() });
                    }
                    previous = Some(e.events.clone());
                    Trial {
                        run,
                        free: x.to_vec(),
                        objective: Some(e.point.objective),
                        violation: Some(violation(&e.point, layout.n_eq)),
                        events: Some(e.events.len()),
                        new_sequence,
                        failure: None,
                    }
                }
                Err(r) => Trial {
                    run,
                    free: x.to_vec(),
                    objective: None,
                    violation: None,
                    events: None,
                    new_sequence: false,
                    failure: Some(r.to_string()),
                },
            };
            progress(&trial);
            trials.push(trial);
            let point = outcome.as_ref().ok().map(|e| e.point.clone());
            last = Some((x.to_vec(), outcome));
            point
        };
        solver.solve(&program, &x0, &mut evaluate_at)
    };
    // A variable the verdict counts as held (`kkt::held`: on its bound to round-off) is put on
    // it, so that the report and the `set:` list say 0 where the box holds a thrust at 0.
    let sides = kkt::held(&end.x, &x0, &program.bounds);
    for ((v, &(lo, hi)), side) in end.x.iter_mut().zip(&program.bounds).zip(sides) {
        match side {
            -1 => *v = lo,
            1 => *v = hi,
            _ => {}
        }
    }
    // The end's values: the last run's when it was at the end, else one more run; then the end's
    // whole record (events, warnings) for the report, one more.
    let mut extra_runs = 1;
    let at_end = match last {
        Some((x, outcome)) if x == end.x => outcome,
        _ => {
            extra_runs += 1;
            evaluate::evaluate(&mut simulator, info, layout, &with_free(&end.x))
        }
    };
    let params = with_free(&end.x);
    let run = simulator.run(&params).ok();
    let mut result = LocalResult {
        index: 0,
        start: x0.clone(),
        x: end.x.clone(),
        params,
        values: Vec::new(),
        kkt: None,
        verdict: Verdict::Stalled,
        status: end.status.clone(),
        runs: trials.len() + extra_runs,
        probe_runs: 0,
        non_finite,
        trials,
        changes,
        cusp_notes: run.as_ref().map(cusp_notes).unwrap_or_default(),
        run,
    };
    let evaluated = match at_end {
        Ok(e) => e,
        Err(r) => {
            result.verdict = Verdict::RunsFailing { message: r.to_string() };
            return result;
        }
    };
    let tolerances = constraint_tolerances(layout, &evaluated.values, &problem.sim);
    let kkt = kkt::measure(
        &end.x,
        &x0,
        &program.bounds,
        &evaluated.point,
        layout.n_eq,
        &tolerances,
        &start_gradient,
    );
    result.verdict = verdict(&kkt, opts, &end, &result.trials, &evaluated.events, non_finite);
    if result.verdict == Verdict::Converged {
        // Stationary: a minimum, or a maximum or saddle? (`curvature.rs`)
        let mut at = |x: &[f64]| {
            evaluate::evaluate(&mut simulator, info, layout, &with_free(x)).ok().map(|e| (e.point, e.events))
        };
        let probe = curvature::probe(
            &end.x,
            &x0,
            &program.bounds,
            &evaluated.point,
            &evaluated.events,
            &kkt,
            problem.sim.rtol,
            &mut at,
        );
        result.probe_runs = probe.runs;
        result.runs += probe.runs;
        if let Some(d) = probe.descent {
            result.verdict = Verdict::NotAMinimum { curvature: d.curvature, drop: d.drop };
        }
    }
    result.values = evaluated.values;
    result.kkt = Some(kkt);
    result
}

/// The largest violation of the program's constraints at a point.
fn violation(point: &SmoothPoint, n_eq: usize) -> f64 {
    point
        .constraints
        .iter()
        .enumerate()
        .map(|(i, &c)| if i < n_eq { c.abs() } else { c.max(0.0) })
        .fold(0.0, f64::max)
}

/// How many of the last runs are searched for another event sequence or a failure when a solve
/// stops short: the optimiser's last line search.
const RECENT_RUNS: usize = 10;

/// The verdict on a solve's end, first match wins:
/// 1. converged: every constraint met to its tolerance and stationary to `kkt_tol` (then the
///    caller's second-order check may still find it no minimum);
/// 2. stalled at a cusp: a recent run on another event sequence;
/// 3. infeasible, when a constraint is not met and either the violation cannot fall within the
///    box (`Kkt::violation_stationary`: a local minimum of the violation) or the optimiser's
///    search broke down (it asked for a non-finite point) or it stopped on its own;
/// 4. max iterations; 5. runs failing nearby; 6. stalled.
fn verdict(
    kkt: &Kkt,
    opts: &OptimizeOptions,
    end: &solver::SolverEnd,
    trials: &[Trial],
    events: &[usize],
    non_finite: usize,
) -> Verdict {
    if kkt.violation_ratio <= 1.0 && kkt.stationarity <= opts.kkt_tol {
        return Verdict::Converged;
    }
    let recent = &trials[trials.len().saturating_sub(RECENT_RUNS)..];
    // A recent run on another piece: compare its event count, the only part of its sequence kept.
    // Checked before the evaluation count: a solve that spent its evaluations stepping back and
    // forth over a cusp stalled there, which says more than that it ran out.
    if let Some(t) =
        recent.iter().rev().find(|t| t.events.is_some_and(|n| n != events.len()) || t.new_sequence)
    {
        return Verdict::StalledAtCusp { run: t.run };
    }
    if kkt.violation_ratio > 1.0 && (kkt.violation_stationary || non_finite > 0) {
        return Verdict::Infeasible;
    }
    if end.out_of_evals && non_finite == 0 {
        return Verdict::MaxIterations;
    }
    if let Some(t) = recent.iter().rev().find(|t| t.failure.is_some()) {
        return Verdict::RunsFailing { message: t.failure.clone().unwrap_or_default() };
    }
    if kkt.violation_ratio > 1.0 {
        return Verdict::Infeasible;
    }
    Verdict::Stalled
}

/// The warnings of a run that make its gradients hold only locally.
fn cusp_notes(run: &SimResult) -> Vec<String> {
    let mut notes: Vec<String> = run
        .warnings
        .iter()
        .filter(|w| {
            matches!(
                w,
                SimWarning::Grazing { .. }
                    | SimWarning::NearGrazing { .. }
                    | SimWarning::NearBreakpoint { .. }
                    | SimWarning::ResetOntoGuard { .. }
                    | SimWarning::EventAtKnot { .. }
            )
        })
        .map(|w| w.to_string())
        .collect();
    for s in run.samples.iter().filter(|s| s.near_event.is_some()) {
        if let Some(e) = s.near_event.and_then(|i| run.events.get(i)) {
            notes.push(format!(
                "the value at t = {} is within the time resolution of event `{}` at t = {}: a parameter change moves the event across it",
                s.time, e.name, e.time
            ));
        }
    }
    if matches!(run.stopped_by, StopReason::TEnd) && run.end_cusp.is_some() {
        notes.push("events fire at t_end itself: the final values are a cusp in the parameters".to_string());
    }
    notes
}

/// Groups converged ends into distinct optima, best objective first.
fn distinct_optima(locals: &[LocalResult], bounds: &[Bounds]) -> Vec<Vec<usize>> {
    let ends: Vec<End<usize>> = locals
        .iter()
        .map(|l| End {
            converged: l.converged(),
            objective: l.values.first().copied(),
            events: l.events(),
            x: &l.x,
        })
        .collect();
    group_optima(&ends, bounds)
}

/// What the grouping of optima reads of one local solve's end (`E`: how its events are named).
pub(crate) struct End<'a, E> {
    pub converged: bool,
    pub objective: Option<f64>,
    pub events: Vec<E>,
    pub x: &'a [f64],
}

/// The converged ends grouped into distinct optima, best first (ties by start order): two ends
/// are the same optimum when they have the same event sequence and every free parameter agrees
/// to 1e-6 of its scale (its bounds' width, else its size). Indices into `ends`.
pub(crate) fn group_optima<E: PartialEq>(ends: &[End<'_, E>], bounds: &[Bounds]) -> Vec<Vec<usize>> {
    let objective = |i: usize| ends[i].objective.unwrap_or(f64::NAN);
    let mut order: Vec<usize> = (0..ends.len()).filter(|&i| ends[i].converged).collect();
    order.sort_by(|&a, &b| objective(a).total_cmp(&objective(b)).then(a.cmp(&b)));
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for i in order {
        let same = |g: &Vec<usize>| {
            let r = &ends[g[0]];
            r.events == ends[i].events
                && r.x.iter().zip(ends[i].x).zip(bounds).all(|((a, b), bd)| {
                    let width = bd.upper - bd.lower;
                    let scale = if width.is_finite() { width } else { a.abs().max(b.abs()).max(1.0) };
                    (a - b).abs() <= 1e-6 * scale
                })
        };
        match groups.iter_mut().find(|g| same(g)) {
            Some(g) => g.push(i),
            None => groups.push(vec![i]),
        }
    }
    groups
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kkt(stationarity: f64, violation_ratio: f64, violation_stationary: bool) -> Kkt {
        Kkt {
            multipliers: vec![0.0],
            active: vec![true],
            at_bound: vec![1],
            stationarity,
            scale: 1.0,
            violation_ratio,
            violation: violation_ratio * 1e-8,
            violation_stationary,
        }
    }

    fn end(out_of_evals: bool) -> solver::SolverEnd {
        solver::SolverEnd { x: vec![1.0], status: "MaxEvalReached".into(), out_of_evals }
    }

    fn trial(run: usize) -> Trial {
        Trial {
            run,
            free: vec![1.0],
            objective: Some(1.0),
            violation: Some(0.05),
            events: Some(4),
            new_sequence: false,
            failure: None,
        }
    }

    #[test]
    fn a_violation_no_move_lowers_or_a_broken_search_is_infeasible_not_max_iterations() {
        let opts = OptimizeOptions::default();
        let trials = [trial(0)];
        let v = |k: &Kkt, out: bool, non_finite: usize| {
            verdict(k, &opts, &end(out), &trials, &[0; 4], non_finite)
        };
        // Met and stationary: converged, however the optimiser stopped.
        assert_eq!(v(&kkt(1e-9, 0.5, true), true, 0), Verdict::Converged);
        // Not met, and the violation cannot fall within the box: infeasible even out of evaluations.
        assert_eq!(v(&kkt(1.0, 1e6, true), true, 0), Verdict::Infeasible);
        // Not met, the violation could fall, the evaluations spent: max iterations ...
        assert_eq!(v(&kkt(1.0, 1e6, false), true, 0), Verdict::MaxIterations);
        // ... unless they were spent asking for non-finite points: the search broke down.
        assert_eq!(v(&kkt(1.0, 1e6, false), true, 187), Verdict::Infeasible);
        // Met but not stationary when the search broke down: stalled, not max iterations.
        assert_eq!(v(&kkt(1.0, 0.5, true), true, 187), Verdict::Stalled);
        // A run on another piece nearby still comes first.
        let mut across = vec![trial(0), trial(1)];
        across[1].events = Some(3);
        let k = kkt(1.0, 1e6, true);
        assert_eq!(verdict(&k, &opts, &end(true), &across, &[0; 4], 0), Verdict::StalledAtCusp { run: 1 });
    }
}
