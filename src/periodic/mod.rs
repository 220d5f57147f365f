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
//! A fixed point is verified before it is reported: a run of the model as written (the section
//! no `stop`, its firings counted as they come) from the fixed point must come back to it
//! after the section's K-th firing, within the same tolerance (`verify`).
//!
//! Code map: `section` (the three models, derived from the checked model: sema in, sema out),
//! this file (Newton on the return map over any systems), `verdict` (the multipliers, the
//! stability verdict, the verification run), `report` (`PeriodicReport`: table, JSON; the JSON
//! of a search that found nothing). The door's `PeriodicRequest` (`api/request/periodic.rs`)
//! compiles the section's models and runs [`find`] on them. Knows runs and their results; no
//! compiler, no IO.

use nalgebra::DMatrix;

use crate::sema::ParamIdx;
use crate::sim::{HybridSystem, Runner, SimOptions, SimResult, StopReason};

mod report;
mod section;
mod verdict;

pub use report::{failure_json, PeriodicReport};
pub use section::{
    parse_section, returns_after, section_models, Section, SectionModels, MAX_FIRING, START_WINDOW,
};
pub use verdict::{multipliers, Stability, Verification, NEUTRAL_BAND, TRIVIAL_MULTIPLIER};

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
    /// The verdict on the multipliers above [`TRIVIAL_MULTIPLIER`]: inside the unit circle,
    /// outside it, or on it to within `neutral_band`.
    pub stability: Stability,
    /// How close to 1 a multiplier's magnitude is taken as 1: [`NEUTRAL_BAND`] times the runs'
    /// `rtol`.
    pub neutral_band: f64,
    /// Whether the verdict is [`Stability::Stable`].
    pub stable: bool,
    /// The largest `|x(section) - x0|` component after each Newton iterate (the start first).
    pub residuals: Vec<f64>,
    /// The events fired on the orbit, the section last.
    pub events: usize,
    /// The run of the model as written from the fixed point that verified it.
    pub verification: Verification,
}

/// Where a search that found no orbit ended: the last iterate's parameters and the residuals so
/// far (the JSON of a failed search reports them).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Attempt {
    /// The Newton steps made before it ended.
    pub iterations: usize,
    /// All parameter values of the last iterate (the free ones as Newton left them).
    pub params: Vec<f64>,
    /// The largest `|x(section) - x0|` component after each iterate that reached the section.
    pub residuals: Vec<f64>,
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
        /// Where the search was.
        attempt: Attempt,
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
        /// Where the search was.
        attempt: Attempt,
    },
    /// The return map's Jacobian with respect to the free parameters is not finite.
    #[error("the return map's Jacobian with respect to the free parameters is not finite")]
    Singular {
        /// Where the search was.
        attempt: Attempt,
    },
    /// Newton's iterate returned within the tolerance, but a run of the model as written from it
    /// did not: it is not reported as a fixed point.
    #[error("no fixed point found: the return map closed within tolerance, but {how}")]
    NotVerified {
        /// What the verifying run did.
        how: String,
        /// Its largest `|x - x0|` component after the section's K-th firing, when it got there.
        residual: Option<f64>,
        /// Where the search was (the iterate that failed the check).
        attempt: Attempt,
    },
}

impl PeriodicError {
    /// Where the search was, for the errors of a search that ran (`None` for a refusal).
    pub fn attempt(&self) -> Option<&Attempt> {
        match self {
            PeriodicError::Missed { attempt, .. }
            | PeriodicError::NotConverged { attempt, .. }
            | PeriodicError::Singular { attempt }
            | PeriodicError::NotVerified { attempt, .. } => Some(attempt),
            _ => None,
        }
    }

    /// The JSON's `reason` for a search that found no orbit (`None` for a refusal).
    pub fn reason(&self) -> Option<&'static str> {
        Some(match self {
            PeriodicError::Missed { .. } => "missed_section",
            PeriodicError::NotConverged { .. } => "not_converged",
            PeriodicError::Singular { .. } => "jacobian_not_finite",
            PeriodicError::NotVerified { .. } => "not_verified",
            _ => return None,
        })
    }
}

/// One run of the return map: the state right after the section, the monodromy matrix, the
/// period and the number of events; or how it missed the section.
struct Return {
    x1: Vec<f64>,
    monodromy: Option<DMatrix<f64>>,
    period: f64,
    events: usize,
}

/// One run of the return map from `x0` (`Err`: how it missed the section).
fn return_map<M: HybridSystem>(
    sim: &mut Runner<&M>,
    params: &[f64],
    x0: &[f64],
    section: usize,
) -> Result<Return, String> {
    let n = x0.len();
    let mut p = params.to_vec();
    p.extend_from_slice(x0);
    let r: SimResult = sim.run(&p).map_err(|e| e.to_string())?;
    match &r.stopped_by {
        StopReason::Event { event, .. } if *event == section => {}
        StopReason::Event { name: other, .. } => return Err(format!("the stop event `{other}` fired first")),
        StopReason::TEnd => {
            return Err(format!("the run reached t_end = {} first (raise --t-end)", sim.options().t_end))
        }
        other => return Err(format!("the run stopped early ({})", other.name())),
    }
    let f = &r.final_state;
    // Column j of `d` is the derivative with respect to x0_j.
    let monodromy = f
        .dstate_total
        .as_ref()
        .map(|d| DMatrix::from_fn(n, n, |i, j| d[j * n + i]))
        .filter(|m| m.iter().all(|v| v.is_finite()));
    Ok(Return {
        x1: f.state.clone(),
        monodromy,
        period: f.time - sim.options().t_start,
        events: r.events.len(),
    })
}

/// Finds the periodic orbit `search` asks for through `section`, and its multipliers. `initial`
/// is the section's stopping model compiled with the free parameters as its gradient parameters
/// (its initial state and sensitivities start each iterate), `map` the seeded model compiled
/// with the seeds as its gradient parameters (a run of it is the return map, its total
/// derivatives the monodromy matrix), `verify` the verifying model compiled the same way (a run
/// of it from the fixed point verifies it).
pub fn find<S: HybridSystem, M: HybridSystem, V: HybridSystem>(
    initial: &S,
    map: &M,
    verify: &V,
    section: &Section,
    search: &Search,
) -> Result<PeriodicResult, PeriodicError> {
    let problem = search;
    if problem.free.is_empty() {
        return Err(PeriodicError::NoFree);
    }
    let (n, orbit) = (section.n_states, section.orbit.clone());
    let k_orbit = orbit.len();
    let mut params = problem.params.clone();
    let mut residuals = Vec::new();
    let missed = |how: String, iterations: usize, params: &[f64], residuals: &[f64]| PeriodicError::Missed {
        section: section.name.clone(),
        how,
        attempt: Attempt { iterations, params: params.to_vec(), residuals: residuals.to_vec() },
    };
    let mut sim =
        Runner::new(map, &problem.sim).map_err(|e| missed(e.to_string(), 0, &params, &residuals))?;
    let n_all = initial.info().n_states();
    let (mut x0, mut x0p) = (vec![0.0; n_all], vec![0.0; n_all * problem.free.len()]);
    for iteration in 0..=problem.max_iter {
        initial.initial_state(&params, &mut x0);
        let back = return_map(&mut sim, &params, &x0, section.index)
            .map_err(|how| missed(how, iteration, &params, &residuals))?;
        // The counter (if any) and the quadrature states are no part of the orbit.
        let r: Vec<f64> = orbit.iter().map(|&i| back.x1[i] - x0[i]).collect();
        residuals.push(r.iter().map(|v| v.abs()).fold(0.0, f64::max));
        let attempt =
            || Attempt { iterations: iteration, params: params.clone(), residuals: residuals.clone() };
        let m = back.monodromy.ok_or_else(|| PeriodicError::Singular { attempt: attempt() })?;
        let m = DMatrix::from_fn(k_orbit, k_orbit, |i, j| m[(orbit[i], orbit[j])]);
        if r.iter().zip(&orbit).all(|(ri, &i)| ri.abs() <= problem.tol * (1.0 + x0[i].abs())) {
            let verification = verdict::verify(verify, &params, &x0, back.period, section, problem).map_err(
                |(how, residual)| PeriodicError::NotVerified { how, residual, attempt: attempt() },
            )?;
            let multipliers = multipliers(&m);
            let neutral_band = NEUTRAL_BAND * problem.sim.rtol;
            let stability = Stability::of(&multipliers, neutral_band);
            x0.truncate(n);
            return Ok(PeriodicResult {
                params,
                fixed_point: x0,
                period: back.period,
                monodromy: m,
                orbit,
                multipliers,
                stable: stability == Stability::Stable,
                stability,
                neutral_band,
                residuals,
                events: back.events,
                verification,
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
        let step = step
            .ok()
            .filter(|s| s.iter().all(|v| v.is_finite()))
            .ok_or_else(|| PeriodicError::Singular { attempt: attempt() })?;
        for (p, d) in problem.free.iter().zip(step.iter()) {
            params[p.0 as usize] += d;
        }
    }
    Err(PeriodicError::NotConverged {
        iterations: problem.max_iter,
        residual: residuals.last().copied().unwrap_or(f64::NAN),
        tol: problem.tol,
        attempt: Attempt { iterations: problem.max_iter, params, residuals },
    })
}
