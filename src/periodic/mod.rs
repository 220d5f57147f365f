//! Periodic orbits through events (`hybc periodic`): the initial values that a run returns to
//! right after a section event fires, found by Newton's method on the return map with its exact
//! Jacobian, and the orbit's Floquet multipliers (the eigenvalues of the monodromy matrix, the
//! return map's Jacobian, saltation matrices included).
//!
//! The return map is a run from the initial state to the first firing of the section event,
//! made a `stop` event for the analysis (in a copy of the checked model): the final state then is
//! the state right after it, and the run's total derivatives (`dstate_total`, with the motion of
//! the stopping time) are the return map's Jacobian. The
//! monodromy matrix needs the derivative with respect to every initial state, also those that no
//! free parameter moves alone (the walker's swing angle starts at twice its stance angle): the
//! model is compiled a second time with one extra parameter per state as that state's initial
//! value (the identity as the initial sensitivities), so every derivative is the compiled
//! model's own. Knows models, runs and their results; no IO.

use nalgebra::DMatrix;

use crate::codegen::{compile, CompileOptions, CompiledModel};
use crate::lower::{lower, system_info};
use crate::sema::{self, Expr, ParamIdx};
use crate::sim::{HybridSystem, SimOptions, SimResult, Simulator, StopReason};

/// Multipliers of at most this magnitude are the section's trivial ones: a perturbation along
/// the flow reaches the section at another time but at the same point, and the state right after
/// a reset lies on the reset's image; both map to zero exactly, so their multipliers are zero to
/// round-off. They take no part in the stability verdict.
pub const TRIVIAL_MULTIPLIER: f64 = 1e-8;

/// What to solve for.
#[derive(Clone, Debug)]
pub struct PeriodicProblem<'m> {
    pub model: &'m sema::Model,
    /// The section: an event; the orbit returns to its initial state right after its
    /// `firing`-th firing (the event is made a `stop` event there for the analysis).
    pub section: String,
    /// Which firing of the section closes the orbit (1-based): 2 for a gait whose period holds
    /// two impacts.
    pub firing: usize,
    /// The parameters to solve for (they set the initial state).
    pub free: Vec<ParamIdx>,
    /// All parameter values; the free ones are the starting guess.
    pub params: Vec<f64>,
    pub sim: SimOptions,
    pub max_iter: usize,
    /// Converged when every component of `x(section) - x0` is within `tol (1 + |x0|)`.
    pub tol: f64,
}

/// A fixed point of the return map and its stability.
#[derive(Clone, Debug)]
pub struct PeriodicResult {
    /// All parameter values at the fixed point (the free ones solved for).
    pub params: Vec<f64>,
    /// The initial state, which the run returns to right after the section.
    pub fixed_point: Vec<f64>,
    /// The time from the start to the section.
    pub period: f64,
    /// `d x(section+) / d x0` over the orbit's states (`orbit`).
    pub monodromy: DMatrix<f64>,
    /// The states of the orbit, the rows and columns of `monodromy`: every state but the
    /// quadrature ones (`sema::quadrature_states`: a running cost that no flow, guard or other
    /// state reads grows from period to period and is no part of the orbit).
    pub orbit: Vec<usize>,
    /// Eigenvalues of the monodromy matrix as `(re, im)`, by decreasing magnitude.
    pub multipliers: Vec<(f64, f64)>,
    /// Whether every multiplier above [`TRIVIAL_MULTIPLIER`] lies strictly inside the unit circle.
    pub stable: bool,
    /// The largest `|x(section) - x0|` component after each Newton iterate (the start first).
    pub residuals: Vec<f64>,
    /// The events fired on the orbit, the section last.
    pub events: usize,
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PeriodicError {
    #[error("model has no event `{name}`; its events are {known}")]
    NoSection { name: String, known: String },
    #[error("no free parameters: name the parameters that set the initial state")]
    NoFree,
    #[error("the section's firing must be 1 to {max}, found {firing}")]
    BadFiring { firing: usize, max: usize },
    #[error("cannot compile the model: {0}")]
    Compile(String),
    #[error("the run from the initial state does not reach the section `{section}`: {how}")]
    Missed { section: String, how: String },
    #[error(
        "no fixed point found: after {iterations} Newton iterations the run returns {residual:e} away from its \
         initial state (tolerance {tol:e}); try another start (--set) or other free parameters"
    )]
    NotConverged { iterations: usize, residual: f64, tol: f64 },
    #[error("the return map's Jacobian with respect to the free parameters is not finite")]
    Singular,
}

/// The most firings of the section an orbit may hold (`--section EVENT#K`).
pub const MAX_FIRING: usize = 1000;

/// `model` with the section's `firing`-th firing a `stop` event, and that event's index. For the
/// first, the section itself stops. For a later one, a counter state (`der = 0`, starting at 0)
/// counts the firings: the section fires as declared (and adds 1) while fewer than `firing - 1`
/// have fired, and a copy of it that stops fires instead at the `firing`-th crossing (an
/// enabling condition on the counter, evaluated just before the event, picks one of the two).
/// The counter is the last state; the analysis leaves it out of the orbit. A section declared
/// `stop` no longer stops before its `firing`-th firing.
fn stop_at_firing(model: &sema::Model, section: usize, firing: usize) -> (sema::Model, usize) {
    let mut m = model.clone();
    if firing == 1 {
        m.events[section].is_stop = true;
        return (m, section);
    }
    let count = sema::StateIdx(m.states.len() as u32);
    m.states.push(sema::State {
        name: format!("{}#count", m.events[section].name),
        init: Expr::Num(0.0),
        span: m.events[section].span,
    });
    for mode in &mut m.modes {
        mode.flows.push(Expr::Num(0.0));
    }
    // The counter is an integer: compare it half-way between two counts.
    let threshold = Expr::Num(firing as f64 - 1.5);
    let enabled = |op, own: &Option<sema::Cond>| {
        let on_count = sema::Cond::Cmp(op, Expr::State(count), threshold.clone());
        Some(match own {
            Some(c) => sema::Cond::And(Box::new(c.clone()), Box::new(on_count)),
            None => on_count,
        })
    };
    let mut last = m.events[section].clone();
    last.condition = enabled(sema::CmpOp::Gt, &last.condition);
    last.is_stop = true;
    let counted = &mut m.events[section];
    // A section declared `stop` walks on until its `firing`-th firing, which the copy stops.
    counted.is_stop = false;
    counted.condition = enabled(sema::CmpOp::Lt, &counted.condition);
    let plus_one = Expr::Binary(sema::BinOp::Add, Box::new(Expr::State(count)), Box::new(Expr::Num(1.0)));
    counted.resets.push((count, plus_one));
    let stop = m.events.len();
    m.events.push(last);
    let stop_idx = sema::EventIdx(stop as u32);
    for mode in &mut m.modes {
        if mode.events.contains(&sema::EventIdx(section as u32)) {
            mode.events.push(stop_idx);
        }
    }
    (m, stop)
}

/// The model with one parameter per state as its initial value (named `NAME(0)`): its
/// gradient with respect to those is the monodromy matrix.
fn seeded(model: &sema::Model) -> (sema::Model, Vec<ParamIdx>) {
    let mut m = model.clone();
    let mut seeds = Vec::with_capacity(m.states.len());
    for i in 0..m.states.len() {
        let idx = ParamIdx(m.params.len() as u32);
        m.params.push(sema::Param {
            name: format!("{}(0)", m.states[i].name),
            default: 0.0,
            range: None,
            span: m.states[i].span,
        });
        m.states[i].init = Expr::Param(idx);
        seeds.push(idx);
    }
    (m, seeds)
}

fn compiled(model: &sema::Model, grad: &[ParamIdx]) -> Result<CompiledModel, PeriodicError> {
    compile(&lower(model), system_info(model, grad), &CompileOptions::default())
        .map_err(|e| PeriodicError::Compile(e.to_string()))
}

/// One run of the return map from `x0`: the state right after the section, the monodromy
/// matrix, the period and the number of events.
fn return_map(
    sim: &mut Simulator<&CompiledModel>,
    params: &[f64],
    x0: &[f64],
    section: usize,
    name: &str,
) -> Result<(Vec<f64>, DMatrix<f64>, f64, usize), PeriodicError> {
    let n = x0.len();
    let mut p = params.to_vec();
    p.extend_from_slice(x0);
    let missed = |how: String| PeriodicError::Missed { section: name.to_string(), how };
    let r: SimResult = sim.run(&p).map_err(|e| missed(e.to_string()))?;
    match &r.stopped_by {
        StopReason::Event { event, .. } if *event == section => {}
        StopReason::Event { name: other, .. } => {
            return Err(missed(format!("the stop event `{other}` fired first")))
        }
        StopReason::TEnd => {
            return Err(missed(format!(
                "the run reached t_end = {} first (raise --t-end)",
                sim.options().t_end
            )))
        }
        other => return Err(missed(format!("the run stopped early ({})", other.name()))),
    }
    let f = &r.final_state;
    let d = f.dstate_total.as_ref().ok_or(PeriodicError::Singular)?;
    // Column j of `d` is the derivative with respect to x0_j.
    let m = DMatrix::from_fn(n, n, |i, j| d[j * n + i]);
    if m.iter().any(|v| !v.is_finite()) {
        return Err(PeriodicError::Singular);
    }
    Ok((f.state.clone(), m, f.time - sim.options().t_start, r.events.len()))
}

/// Finds the periodic orbit of `problem` and its multipliers.
pub fn find(problem: &PeriodicProblem<'_>) -> Result<PeriodicResult, PeriodicError> {
    let model = problem.model;
    let section = model.events.iter().position(|e| e.name == problem.section).ok_or_else(|| {
        let known: Vec<&str> = model.events.iter().filter(|e| !e.implicit).map(|e| e.name.as_str()).collect();
        PeriodicError::NoSection { name: problem.section.clone(), known: known.join(", ") }
    })?;
    if problem.firing == 0 || problem.firing > MAX_FIRING {
        return Err(PeriodicError::BadFiring { firing: problem.firing, max: MAX_FIRING });
    }
    // A run of the return map ends right after the section's `firing`-th firing.
    let (stopping, section) = stop_at_firing(model, section, problem.firing);
    let model = &stopping;
    if problem.free.is_empty() {
        return Err(PeriodicError::NoFree);
    }
    // The model's own states; a counter of the section's firings may follow them. The orbit is
    // every one of them but the quadrature states.
    let n = problem.model.states.len();
    let quadrature = sema::quadrature_states(problem.model);
    let orbit: Vec<usize> = (0..n).filter(|&i| !quadrature[i]).collect();
    let k_orbit = orbit.len();
    let initial = compiled(model, &problem.free)?;
    let (augmented, seeds) = seeded(model);
    let map = compiled(&augmented, &seeds)?;
    let mut sim = Simulator::new(&map, &problem.sim)
        .map_err(|e| PeriodicError::Missed { section: problem.section.clone(), how: e.to_string() })?;
    let mut params = problem.params.clone();
    let n_all = model.states.len();
    let (mut x0, mut x0p) = (vec![0.0; n_all], vec![0.0; n_all * problem.free.len()]);
    let mut residuals = Vec::new();
    for iteration in 0..=problem.max_iter {
        initial.initial_state(&params, &mut x0);
        let (x1, m, period, events) = return_map(&mut sim, &params, &x0, section, &problem.section)?;
        // The counter (if any) and the quadrature states are no part of the orbit.
        let m = DMatrix::from_fn(k_orbit, k_orbit, |i, j| m[(orbit[i], orbit[j])]);
        let r: Vec<f64> = orbit.iter().map(|&i| x1[i] - x0[i]).collect();
        let worst = r.iter().map(|v| v.abs()).fold(0.0, f64::max);
        residuals.push(worst);
        if r.iter().zip(&orbit).all(|(ri, &i)| ri.abs() <= problem.tol * (1.0 + x0[i].abs())) {
            let multipliers = multipliers(&m);
            let stable = multipliers.iter().all(|&(re, im)| {
                let size = re.hypot(im);
                size <= TRIVIAL_MULTIPLIER || size < 1.0
            });
            x0.truncate(n);
            return Ok(PeriodicResult {
                params,
                fixed_point: x0,
                period,
                monodromy: m,
                orbit,
                multipliers,
                stable,
                residuals,
                events,
            });
        }
        if iteration == problem.max_iter {
            break;
        }
        // r(p) = P(x0(p)) - x0(p): dr/dp = (M - I) dx0/dp. Least squares (the free parameters
        // may be fewer than the states), by the SVD.
        initial.initial_sens(&params, &mut x0p);
        let k = problem.free.len();
        let x0p = DMatrix::from_fn(k_orbit, k, |i, j| x0p[j * n_all + orbit[i]]);
        let jac = (&m - DMatrix::identity(k_orbit, k_orbit)) * &x0p;
        let step =
            jac.svd(true, true).solve(&nalgebra::DVector::from_vec(r.iter().map(|v| -v).collect()), 1e-14);
        let step = step.map_err(|_| PeriodicError::Singular)?;
        if step.iter().any(|v| !v.is_finite()) {
            return Err(PeriodicError::Singular);
        }
        for (p, d) in problem.free.iter().zip(step.iter()) {
            params[p.0 as usize] += d;
        }
    }
    Err(PeriodicError::NotConverged {
        iterations: problem.max_iter,
        residual: residuals.last().copied().unwrap_or(f64::NAN),
        tol: problem.tol,
    })
}

/// The eigenvalues of `m` as `(re, im)`, by decreasing magnitude (a complex pair stays together).
pub fn multipliers(m: &DMatrix<f64>) -> Vec<(f64, f64)> {
    let mut values: Vec<(f64, f64)> = m.complex_eigenvalues().iter().map(|c| (c.re, c.im)).collect();
    values.sort_by(|a, b| b.0.hypot(b.1).total_cmp(&a.0.hypot(a.1)).then(b.1.total_cmp(&a.1)));
    values
}
