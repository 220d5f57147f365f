//! The solver: Levenberg-Marquardt on a piecewise-smooth least-squares objective, with box bounds.
//! Knows evaluations (residuals, Jacobian, event sequence), not models or runs, so it is tested on
//! hand-written residual functions.
//!
//! Why not the `levenberg-marquardt` crate: it ends the minimisation when a trial point gives no
//! residuals, where a fit through events must reject the trial and shorten the step (a target
//! event that does not fire, a Zeno run), and it has neither bounds nor a hook to notice that a
//! trial lies on another smooth piece of the objective.
//!
//! Each iteration: columns scaled to the largest norms seen so far (Moré's scaling, so the
//! damping is unit-free); parameters at a bound whose gradient points outwards held fixed; the
//! damped step `-sum sigma_i / (sigma_i^2 + lambda) (u_i . r) v_i` from the SVD of the scaled free
//! columns; the trial projected onto the box; accepted when the objective fell by at least
//! `ETA` of what the linear model predicts for the projected step. Damping follows Nielsen:
//! shrinks with good agreement, grows 2, 4, 8... fold on consecutive rejections. On a cusp (the
//! trial's event sequence differs) the linear model says nothing about the other piece: the trial
//! is kept only on a real decrease, and then the damping is not relaxed, so the next step stays
//! as short.

use nalgebra::{DMatrix, DVector, SVD};

use super::{Bounds, Cusp, Evaluation, FitOptions, FitStop, Iteration, Outcome, Rejection, StallCause};

/// Smallest accepted ratio of actual to predicted decrease.
const ETA: f64 = 1e-4;
/// Initial damping relative to the largest squared singular value of the scaled Jacobian.
const TAU: f64 = 1e-3;

pub(super) struct Solved {
    pub x: Vec<f64>,
    pub evaluation: Evaluation,
    pub iterations: Vec<Iteration>,
    pub cusps: Vec<Cusp>,
    pub stop: FitStop,
}

/// Minimises `0.5 |r(x)|^2` from `x0` inside `bounds`; an error only when `x0` itself cannot be
/// evaluated.
pub(super) fn minimize(
    x0: Vec<f64>,
    bounds: &[Bounds],
    opts: &FitOptions,
    mut eval: impl FnMut(&[f64]) -> Result<Evaluation, Rejection>,
) -> Result<Solved, Rejection> {
    let mut x = x0;
    let mut cur = eval(&x)?;
    let mut objective = cur.objective();
    let mut iterations = vec![Iteration {
        iteration: 0,
        free: x.clone(),
        objective: Some(objective),
        step_norm: 0.0,
        events: Some(cur.events.len()),
        damping: None,
        cusp: false,
        outcome: Outcome::Start,
    }];
    let mut cusps = Vec::new();
    let mut scale = vec![0.0; x.len()];
    let mut lambda: Option<f64> = None;
    let mut nu = 2.0;
    let mut last_nonsmooth: Option<StallCause> = None;
    let mut model = LocalModel::new(&cur, &x, bounds, &mut scale);

    let stop = loop {
        let Some(m) = &model else { break FitStop::Stalled(StallCause::Singular) };
        if let Some(stop) = m.converged(opts) {
            break stop;
        }
        let lam = *lambda.get_or_insert_with(|| TAU * m.largest_singular_value().powi(2));
        let step = project(&x, &m.step(lam), bounds);
        if small(&step, &x, &scale, opts.xtol) {
            let gauss_newton = project(&x, &m.step(0.0), bounds);
            break if small(&gauss_newton, &x, &scale, opts.xtol) {
                FitStop::Step
            } else if last_nonsmooth.is_none() && at_floor(&cur, &gauss_newton, objective, opts.ftol) {
                // The trials were refused on noise: even the Gauss-Newton step predicts a
                // relative decrease below `ftol` (MINPACK's test on the predicted reduction), so
                // the objective is at its floor, where the simulation's round-off decides
                // whether a trial decreases it.
                FitStop::Objective
            } else {
                FitStop::Stalled(last_nonsmooth.clone().unwrap_or(StallCause::NoDecrease))
            };
        }
        let predicted = predicted_decrease(&cur, &step);
        if predicted <= 0.0 {
            // Projection onto the box can spoil the damped step; a shorter one is closer to the
            // (inward) gradient direction.
            lambda = Some(lam * nu);
            nu *= 2.0;
            continue;
        }
        // `iterations` holds the start and one entry per trial.
        if iterations.len() > opts.max_iter {
            break FitStop::MaxIterations;
        }
        let trial_x: Vec<f64> = x.iter().zip(&step).map(|(a, d)| a + d).collect();
        let iteration = iterations.len();
        let mut record = Iteration {
            iteration,
            free: trial_x.clone(),
            objective: None,
            step_norm: step.iter().map(|d| d * d).sum::<f64>().sqrt(),
            events: None,
            damping: Some(lam),
            cusp: false,
            outcome: Outcome::Rejected,
        };
        match eval(&trial_x) {
            Err(rejection) => {
                record.outcome = Outcome::Failed(rejection.clone());
                last_nonsmooth = Some(StallCause::Failed { iteration, rejection });
                lambda = Some(lam * nu);
                nu *= 2.0;
            }
            Ok(trial) => {
                let trial_objective = trial.objective();
                let decrease = actual_decrease(&cur, &trial);
                let rho = decrease / predicted;
                record.objective = Some(trial_objective);
                record.events = Some(trial.events.len());
                record.cusp = trial.events != cur.events;
                let accepted = rho > ETA;
                if record.cusp {
                    let cusp = Cusp {
                        iteration,
                        events_before: cur.events.len(),
                        events_after: trial.events.len(),
                        accepted,
                    };
                    if !accepted {
                        last_nonsmooth = Some(StallCause::Cusp(cusp.clone()));
                    }
                    cusps.push(cusp);
                }
                if accepted {
                    record.outcome = Outcome::Accepted;
                    if !record.cusp {
                        lambda = Some(lam * (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0));
                    }
                    nu = 2.0;
                    x = trial_x;
                    cur = trial;
                    objective = trial_objective;
                    iterations.push(record);
                    if decrease <= opts.ftol * (objective + decrease) {
                        break FitStop::Objective;
                    }
                    model = LocalModel::new(&cur, &x, bounds, &mut scale);
                    continue;
                }
                lambda = Some(lam * nu);
                nu *= 2.0;
            }
        }
        iterations.push(record);
    };
    Ok(Solved { x, evaluation: cur, iterations, cusps, stop })
}

/// The linearisation at the current point, restricted to the parameters free to move.
struct LocalModel {
    /// Number of parameters.
    n: usize,
    /// Indices of the parameters not held at a bound.
    free: Vec<usize>,
    /// Column scale of each free parameter.
    scale: Vec<f64>,
    /// SVD of the scaled free columns; `None` when no parameter is free.
    svd: Option<SVD<f64, nalgebra::Dyn, nalgebra::Dyn>>,
    /// `U^T r`.
    utr: DVector<f64>,
    /// Largest cosine between the residuals and a free column; `None` when the residuals vanish.
    cosine: Option<f64>,
}

impl LocalModel {
    /// `None` when the SVD does not converge (a Jacobian this ill-conditioned gives no step).
    fn new(cur: &Evaluation, x: &[f64], bounds: &[Bounds], scale: &mut [f64]) -> Option<LocalModel> {
        let j = &cur.jacobian;
        let r = DVector::from_column_slice(&cur.residuals);
        let gradient = j.transpose() * &r;
        for (c, s) in scale.iter_mut().enumerate() {
            let norm = j.column(c).norm();
            // Moré: never shrink a scale, so steps cannot grow without bound where a column
            // momentarily vanishes; a column that was always zero gets scale 1.
            *s = s.max(norm);
            if *s == 0.0 {
                *s = 1.0;
            }
        }
        let free: Vec<usize> = (0..x.len())
            .filter(|&c| {
                let (b, g) = (bounds[c], gradient[c]);
                // Descent is along -g: held at the lower bound if it wants to go lower.
                !((x[c] <= b.lower && g > 0.0) || (x[c] >= b.upper && g < 0.0))
            })
            .collect();
        let r_norm = r.norm();
        let cosine = (r_norm > 0.0).then(|| {
            free.iter()
                .map(|&c| {
                    let norm = j.column(c).norm();
                    if norm == 0.0 {
                        0.0
                    } else {
                        gradient[c].abs() / (norm * r_norm)
                    }
                })
                .fold(0.0, f64::max)
        });
        let scaled = DMatrix::from_fn(j.nrows(), free.len(), |i, k| j[(i, free[k])] / scale[free[k]]);
        // nalgebra refuses an empty matrix; with every parameter held there is no step to take.
        let (svd, utr) = if free.is_empty() {
            (None, DVector::zeros(0))
        } else {
            let svd = SVD::try_new(scaled, true, true, f64::EPSILON, 10_000)?;
            let utr = svd.u.as_ref()?.transpose() * &r;
            (Some(svd), utr)
        };
        Some(LocalModel {
            n: x.len(),
            scale: free.iter().map(|&c| scale[c]).collect(),
            free,
            svd,
            utr,
            cosine,
        })
    }

    fn converged(&self, opts: &FitOptions) -> Option<FitStop> {
        match self.cosine {
            None => Some(FitStop::Objective),
            _ if self.free.is_empty() => Some(FitStop::Gradient),
            Some(c) if c <= opts.gtol => Some(FitStop::Gradient),
            Some(_) => None,
        }
    }

    fn largest_singular_value(&self) -> f64 {
        self.svd.as_ref().map_or(0.0, |svd| svd.singular_values.iter().copied().fold(0.0, f64::max))
    }

    /// The step for damping `lambda` in parameter units (zero for held parameters); `lambda = 0`
    /// gives the minimum-norm Gauss-Newton step, ignoring singular values at round-off level.
    fn step(&self, lambda: f64) -> Vec<f64> {
        let mut scaled = DVector::zeros(self.free.len());
        if let Some((svd, v_t)) = self.svd.as_ref().and_then(|svd| Some((svd, svd.v_t.as_ref()?))) {
            let sigma = &svd.singular_values;
            let cutoff = sigma.len() as f64 * f64::EPSILON * self.largest_singular_value();
            for (i, &s) in sigma.iter().enumerate() {
                let factor = if lambda > 0.0 {
                    s / (s * s + lambda)
                } else if s > cutoff {
                    1.0 / s
                } else {
                    0.0
                };
                scaled -= v_t.row(i).transpose() * (factor * self.utr[i]);
            }
        }
        let mut step = vec![0.0; self.n];
        for (k, &c) in self.free.iter().enumerate() {
            step[c] = scaled[k] / self.scale[k];
        }
        step
    }
}

/// `x + step` projected onto the box, as a step.
fn project(x: &[f64], step: &[f64], bounds: &[Bounds]) -> Vec<f64> {
    x.iter().zip(step).zip(bounds).map(|((&a, &d), b)| (a + d).clamp(b.lower, b.upper) - a).collect()
}

/// Whether `|D step| <= xtol (|D x| + xtol)` with the column scales `D`.
fn small(step: &[f64], x: &[f64], scale: &[f64], xtol: f64) -> bool {
    let norm = |v: &[f64]| v.iter().zip(scale).map(|(a, s)| (a * s).powi(2)).sum::<f64>().sqrt();
    norm(step) <= xtol * (norm(x) + xtol)
}

/// `0.5 (|r|^2 - |r_trial|^2)`, summed as `(a - b)(a + b)` per residual: near the minimum the
/// objectives agree to round-off while the residuals that still move differ exactly.
fn actual_decrease(cur: &Evaluation, trial: &Evaluation) -> f64 {
    0.5 * cur.residuals.iter().zip(&trial.residuals).map(|(a, b)| (a - b) * (a + b)).sum::<f64>()
}

/// `0.5 (|r|^2 - |r + J step|^2)`: the decrease the linear model promises for `step`, summed as
/// `-(J step)_i (r_i + (J step)_i / 2)` for the same reason as [`actual_decrease`].
fn predicted_decrease(cur: &Evaluation, step: &[f64]) -> f64 {
    let change = &cur.jacobian * DVector::from_column_slice(step);
    -cur.residuals.iter().zip(change.iter()).map(|(r, c)| c * (r + 0.5 * c)).sum::<f64>()
}

/// Whether `step` predicts a relative decrease of `objective` of at most `ftol` (and not a rise).
fn at_floor(cur: &Evaluation, step: &[f64], objective: f64, ftol: f64) -> bool {
    (0.0..=ftol * objective).contains(&predicted_decrease(cur, step))
}

/// `sigma_max / sigma_min` of `j`; infinite when it has fewer rows than columns or is singular.
pub(super) fn condition_number(j: &DMatrix<f64>) -> f64 {
    if j.nrows() < j.ncols() {
        return f64::INFINITY;
    }
    match SVD::try_new(j.clone(), false, false, f64::EPSILON, 10_000) {
        Some(svd) => {
            let s = &svd.singular_values;
            let (max, min) = (s.max(), s.min());
            if min > 0.0 {
                max / min
            } else {
                f64::INFINITY
            }
        }
        None => f64::INFINITY,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock as least squares: r = (10 (x1 - x0^2), 1 - x0), minimum 0 at (1, 1).
    fn rosenbrock(x: &[f64]) -> Result<Evaluation, Rejection> {
        let residuals = vec![10.0 * (x[1] - x[0] * x[0]), 1.0 - x[0]];
        let jacobian = DMatrix::from_row_slice(2, 2, &[-20.0 * x[0], 10.0, -1.0, 0.0]);
        Ok(Evaluation { values: residuals.clone(), residuals, jacobian, events: Vec::new() })
    }

    #[test]
    fn rosenbrock_from_the_textbook_start_reaches_its_minimum() {
        let solved = minimize(vec![-1.2, 1.0], &[Bounds::NONE; 2], &FitOptions::default(), rosenbrock)
            .expect("start evaluates");
        assert!(solved.stop.is_converged(), "{:?}", solved.stop);
        assert!((solved.x[0] - 1.0).abs() < 1e-10 && (solved.x[1] - 1.0).abs() < 1e-10, "{:?}", solved.x);
    }

    #[test]
    fn an_upper_bound_below_the_minimum_holds_the_parameter() {
        // With x0 <= 0.5 the constrained minimum is x0 = 0.5, x1 = 0.25 (r1 = 0, r2 = 0.5).
        let bounds = [Bounds { lower: -2.0, upper: 0.5 }, Bounds::NONE];
        let solved = minimize(vec![-1.2, 1.0], &bounds, &FitOptions::default(), rosenbrock).expect("start");
        assert!(solved.stop.is_converged(), "{:?}", solved.stop);
        assert_eq!(solved.x[0], 0.5);
        assert!((solved.x[1] - 0.25).abs() < 1e-10, "{:?}", solved.x);
    }

    #[test]
    fn trials_that_fail_shorten_the_step_instead_of_ending_the_fit() {
        // r = x - 3 on x < 2.5 only (beyond it the "run" fails): the fit stalls at the edge and
        // names the failure.
        let eval = |x: &[f64]| {
            if x[0] >= 2.5 {
                return Err(Rejection::RunStopped { message: "beyond the edge".into() });
            }
            let r = vec![x[0] - 3.0];
            Ok(Evaluation {
                values: r.clone(),
                residuals: r,
                jacobian: DMatrix::from_element(1, 1, 1.0),
                events: Vec::new(),
            })
        };
        let solved = minimize(vec![0.0], &[Bounds::NONE], &FitOptions::default(), eval).expect("start");
        assert!(matches!(solved.stop, FitStop::Stalled(StallCause::Failed { .. })), "{:?}", solved.stop);
        assert!(solved.x[0] < 2.5 && solved.x[0] > 2.5 - 1e-8, "{:?}", solved.x);
    }
}
