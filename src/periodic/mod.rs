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
//! model's own.
//!
//! Code map: `section` (the two models, derived from the checked model: sema in, sema out),
//! this file (Newton on the return map over any two systems, the multipliers), `report`
//! (`PeriodicReport`: table, JSON). The door's `PeriodicRequest` (`api/request/periodic.rs`)
//! compiles the section's models and runs [`find`] on them. Knows runs and their results; no
//! compiler, no IO.

use nalgebra::DMatrix;

use crate::sema::ParamIdx;
use crate::sim::{HybridSystem, Runner, SimOptions, SimResult, StopReason};

mod report;
mod section;

pub use report::PeriodicReport;
pub use section::{parse_section, section_models, Section, SectionModels, MAX_FIRING};

/// Multipliers of at most this magnitude are the section's trivial ones: a perturbation along
/// the flow reaches the section at another time but at the same point, and the state right after
/// a reset lies on the reset's image; both map to zero exactly, so their multipliers are zero to
/// round-off. They take no part in the stability verdict.
pub const TRIVIAL_MULTIPLIER: f64 = 1e-8;

/// How to search for the orbit: what the user asks.
#[derive(Clone, Debug)]
pub struct Search {
    /// The parameters to solve for (they set the initial state).
    pub free: Vec<ParamIdx>,
    /// All parameter values; the free ones are the starting guess.
    pub params: Vec<f64>,
    /// The options of every run of the return map.
    pub sim: SimOptions,
    /// The most Newton iterations (one run each).
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

/// Why no periodic orbit was found, or the question was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PeriodicError {
    /// The section names no event.
    #[error("model has no event `{name}`; its events are {known}")]
    NoSection {
        /// The name given.
        name: String,
        /// The model's events.
        known: String,
    },
    /// No free parameters to solve for.
    #[error("no free parameters: name the parameters that set the initial state")]
    NoFree,
    /// A firing number outside 1 to `MAX_FIRING`.
    #[error("the section's firing must be 1 to {max}, found {firing}")]
    BadFiring {
        /// The firing asked for.
        firing: usize,
        /// The most.
        max: usize,
    },
    /// A section that is neither `EVENT` nor `EVENT#K`.
    #[error("`{text}`: expected EVENT or EVENT#K with K from 1 to {MAX_FIRING}")]
    BadSection {
        /// The section as written.
        text: String,
    },
    /// A section's model could not be compiled (the code generator's message).
    #[error("cannot compile the model: {0}")]
    Compile(String),
    /// A run of the return map did not reach the section.
    #[error("the run from the initial state does not reach the section `{section}`: {how}")]
    Missed {
        /// The section's name.
        section: String,
        /// How the run ended instead.
        how: String,
    },
    #[error(
        "no fixed point found: after {iterations} Newton iterations the run returns {residual:e} away from its \
         initial state (tolerance {tol:e}); try another start (--set) or other free parameters"
    )]
    /// Newton did not converge in `max_iter` iterations.
    NotConverged {
        /// The iterations made.
        iterations: usize,
        /// The last residual.
        residual: f64,
        /// The tolerance.
        tol: f64,
    },
    /// The return map's Jacobian with respect to the free parameters is not finite.
    #[error("the return map's Jacobian with respect to the free parameters is not finite")]
    Singular,
}

/// One run of the return map from `x0`: the state right after the section, the monodromy
/// matrix, the period and the number of events.
fn return_map<M: HybridSystem>(
    sim: &mut Runner<&M>,
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

/// Finds the periodic orbit `search` asks for through `section`, and its multipliers. `initial`
/// is the section's
/// stopping model compiled with the free parameters as its gradient parameters (its initial
/// state and sensitivities start each iterate), `map` the seeded model compiled with the seeds as
/// its gradient parameters (a run of it is the return map, its total derivatives the monodromy
/// matrix).
pub fn find<S: HybridSystem, M: HybridSystem>(
    initial: &S,
    map: &M,
    section: &Section,
    search: &Search,
) -> Result<PeriodicResult, PeriodicError> {
    let problem = search;
    if problem.free.is_empty() {
        return Err(PeriodicError::NoFree);
    }
    let (n, orbit) = (section.n_states, section.orbit.clone());
    let k_orbit = orbit.len();
    let mut sim = Runner::new(map, &problem.sim)
        .map_err(|e| PeriodicError::Missed { section: section.name.clone(), how: e.to_string() })?;
    let mut params = problem.params.clone();
    let n_all = initial.info().n_states();
    let (mut x0, mut x0p) = (vec![0.0; n_all], vec![0.0; n_all * problem.free.len()]);
    let mut residuals = Vec::new();
    for iteration in 0..=problem.max_iter {
        initial.initial_state(&params, &mut x0);
        let (x1, m, period, events) = return_map(&mut sim, &params, &x0, section.index, &section.name)?;
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
