//! The verdict on a point: do the Karush-Kuhn-Tucker conditions hold there? The optimiser does
//! not report Lagrange multipliers, so they are estimated here by least squares on the gradients
//! of the active constraints, over the variables not held at a bound:
//! `min |grad f + sum_i lambda_i grad c_i|` (equalities always active, an inequality when it is
//! within its tolerance of its bound). An inequality's multiplier must be >= 0; one that comes out
//! negative is released (its constraint is not holding the point) and the estimate repeated.
//! What is left of the Lagrangian's gradient, projected on the box (at a lower bound only its
//! negative part counts, at an upper bound its positive part), is the stationarity residual. It
//! is measured against an absolute scale, the largest gradient the solve has seen at its two
//! ends: the objective's gradient at the start, and the terms that make up the Lagrangian's
//! gradient at the end (`grad f` and each `lambda_i grad c_i`). Not against the end's terms
//! alone: with no active constraint that is `|grad f|` over itself, 1 at every point where the
//! gradient is not exactly zero, so an unconstrained optimum met to round-off read as a failure.

use nalgebra::{DMatrix, DVector};

use super::solver::SmoothPoint;

/// The KKT conditions measured at one point.
#[derive(Clone, Debug, PartialEq)]
pub struct Kkt {
    /// One per constraint: the estimated multiplier (0 for an inactive inequality).
    pub multipliers: Vec<f64>,
    /// One per constraint: within its tolerance of its bound (equalities: always).
    pub active: Vec<bool>,
    /// One per variable: -1 held at its lower bound, 1 at its upper, 0 free.
    pub at_bound: Vec<i8>,
    /// `|P(grad L)|_inf / scale` (0 when the scale is 0: every gradient vanishes).
    pub stationarity: f64,
    /// What stationarity is measured against: `max(|grad f(x0)|_inf, |grad f|_inf,
    /// max_i |lambda_i grad c_i|_inf)`, the objective's gradient at the start `x0` and the terms
    /// of the Lagrangian's gradient at the point.
    pub scale: f64,
    /// Largest violation of a constraint divided by its tolerance (<= 1: every one is met).
    pub violation_ratio: f64,
    /// Largest violation of a constraint, in its own units.
    pub violation: f64,
    /// Whether the violation cannot fall within the box to first order: the gradient of
    /// `phi = sum_i v_i^2 / 2` (`v_i` a constraint's violation: `c_i` for an equality,
    /// `max(c_i, 0)` for an inequality), projected on the box as the Lagrangian's is, is at most
    /// 1e-6 of its largest term `|v_i grad c_i|_inf`. With a constraint not met, the point is
    /// then a local minimum of the violation: no move nearby meets the constraints better.
    pub violation_stationary: bool,
}

/// Measures the KKT conditions at `x` from the point's gradients. `n_eq` constraints are
/// equalities; `tolerances` says how far each may be off; `x0` is the solve's start and
/// `start_gradient` the objective's gradient there (parts of the scales of "on a bound" and of
/// stationarity).
pub fn measure(
    x: &[f64],
    x0: &[f64],
    bounds: &[(f64, f64)],
    point: &SmoothPoint,
    n_eq: usize,
    tolerances: &[f64],
    start_gradient: &[f64],
) -> Kkt {
    let n = x.len();
    let m = point.constraints.len();
    let at_bound = held(x, x0, bounds);
    let mut violation: f64 = 0.0;
    let mut violation_ratio: f64 = 0.0;
    let mut active = vec![false; m];
    for i in 0..m {
        let c = point.constraints[i];
        let v = if i < n_eq { c.abs() } else { c.max(0.0) };
        violation = violation.max(v);
        violation_ratio = violation_ratio.max(v / tolerances[i]);
        active[i] = i < n_eq || c >= -tolerances[i];
    }
    let free: Vec<usize> = (0..n).filter(|&k| at_bound[k] == 0).collect();
    let mut multipliers = vec![0.0; m];
    loop {
        let columns: Vec<usize> = (0..m).filter(|&i| active[i]).collect();
        multipliers.iter_mut().for_each(|l| *l = 0.0);
        if !columns.is_empty() && !free.is_empty() {
            let a = DMatrix::from_fn(free.len(), columns.len(), |r, c| point.jacobian[columns[c]][free[r]]);
            let b = DVector::from_fn(free.len(), |r, _| -point.gradient[free[r]]);
            let svd = a.svd(true, true);
            let eps = 1e-12 * svd.singular_values.max();
            if let Ok(lambda) = svd.solve(&b, eps) {
                for (c, &i) in columns.iter().enumerate() {
                    multipliers[i] = lambda[c];
                }
            }
        }
        // An inequality pulling the wrong way does not hold the point: release the worst.
        let wrong = (n_eq..m)
            .filter(|&i| active[i] && multipliers[i] < 0.0)
            .min_by(|&a, &b| multipliers[a].total_cmp(&multipliers[b]));
        match wrong {
            Some(i) => active[i] = false,
            None => break,
        }
    }
    let mut residual = point.gradient.clone();
    let mut scale = inf_norm(&point.gradient).max(inf_norm(start_gradient));
    for (&lambda, row) in multipliers.iter().zip(&point.jacobian) {
        if lambda != 0.0 {
            let term: Vec<f64> = row.iter().map(|d| lambda * d).collect();
            scale = scale.max(inf_norm(&term));
            residual.iter_mut().zip(&term).for_each(|(r, t)| *r += t);
        }
    }
    let projected = project(&residual, &at_bound);
    let stationarity = if scale > 0.0 { projected / scale } else { 0.0 };
    // The violation's own descent: `grad phi = sum_i v_i grad c_i`, projected on the box.
    let mut phi_gradient = vec![0.0; n];
    let mut phi_scale: f64 = 0.0;
    for (i, row) in point.jacobian.iter().enumerate() {
        let c = point.constraints[i];
        let v = if i < n_eq { c } else { c.max(0.0) };
        if v != 0.0 {
            let term: Vec<f64> = row.iter().map(|d| v * d).collect();
            phi_scale = phi_scale.max(inf_norm(&term));
            phi_gradient.iter_mut().zip(&term).for_each(|(r, t)| *r += t);
        }
    }
    let phi_projected = project(&phi_gradient, &at_bound);
    let violation_stationary = phi_projected <= VIOLATION_STATIONARY * phi_scale;
    Kkt {
        multipliers,
        active,
        at_bound,
        stationarity,
        scale,
        violation_ratio,
        violation,
        violation_stationary,
    }
}

/// Per variable: -1 held at its lower bound, 1 at its upper, 0 free. SLSQP clips to the box only
/// to round-off of the step it solves for (a thrust held at 0 comes back as 3.5e-15 next to one
/// of 23), so "on the bound" means within 1e-12 of the variable's scale: its bound's and its own
/// magnitude, or that of the largest variable at the end or at the start `x0` when its box is
/// wider than that. Not the box's width alone: in [0, 1e13] that called k = 5 held at 0 and
/// projected away the gradient of k^2. Not the end's variables alone: a lone `p` in [0, 2] that
/// came down from 0.76 to 8.9e-16 was its own scale, and an optimum at the bound read as stalled.
pub(super) fn held(x: &[f64], x0: &[f64], bounds: &[(f64, f64)]) -> Vec<i8> {
    let largest = inf_norm(x).max(inf_norm(x0));
    x.iter()
        .zip(bounds)
        .map(|(&v, &(lo, hi))| {
            let scale = |bound: f64| bound.abs().max(v.abs()).max((hi - lo).min(largest)).max(1e-300);
            if lo.is_finite() && v - lo <= 1e-12 * scale(lo) {
                -1
            } else if hi.is_finite() && hi - v <= 1e-12 * scale(hi) {
                1
            } else {
                0
            }
        })
        .collect()
}

/// How far the violation's projected gradient may be from 0, relative to its largest term, for
/// the point to count as a local minimum of the violation.
const VIOLATION_STATIONARY: f64 = 1e-6;

/// `|P g|_inf`: the gradient `g` projected on the box (at a lower bound only its negative part
/// counts, at an upper bound its positive part: a descent direction must point into the box).
fn project(g: &[f64], at_bound: &[i8]) -> f64 {
    g.iter()
        .zip(at_bound)
        .map(|(&r, &b)| match b {
            -1 => r.min(0.0),
            1 => r.max(0.0),
            _ => r,
        })
        .fold(0.0_f64, |a, r| a.max(r.abs()))
}

fn inf_norm(v: &[f64]) -> f64 {
    v.iter().fold(0.0_f64, |a, x| a.max(x.abs()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(gradient: &[f64], constraints: &[f64], jacobian: &[&[f64]]) -> SmoothPoint {
        SmoothPoint {
            objective: 0.0,
            gradient: gradient.to_vec(),
            constraints: constraints.to_vec(),
            jacobian: jacobian.iter().map(|r| r.to_vec()).collect(),
        }
    }

    const FREE: [(f64, f64); 2] = [(f64::NEG_INFINITY, f64::INFINITY); 2];

    /// A point the solve stopped at without moving: its own gradient is the start's.
    fn at_start(x: &[f64], bounds: &[(f64, f64)], p: &SmoothPoint, n_eq: usize, tolerances: &[f64]) -> Kkt {
        measure(x, x, bounds, p, n_eq, tolerances, &p.gradient)
    }

    #[test]
    fn an_active_inequality_balances_the_gradient_with_a_positive_multiplier() {
        // min x + y subject to 1 - x - y <= 0, at x + y = 1.
        let k = at_start(&[0.5, 0.5], &FREE, &point(&[1.0, 1.0], &[0.0], &[&[-1.0, -1.0]]), 0, &[1e-8]);
        assert_eq!(k.multipliers, vec![1.0]);
        assert!(k.stationarity < 1e-15 && k.violation_ratio == 0.0);
    }

    #[test]
    fn an_inequality_pulling_the_wrong_way_is_released_and_the_point_is_not_stationary() {
        // min x + y subject to x + y - 1 <= 0 at x + y = 1: the objective wants to go down, the
        // constraint does not stop it.
        let k = at_start(&[0.5, 0.5], &FREE, &point(&[1.0, 1.0], &[0.0], &[&[1.0, 1.0]]), 0, &[1e-8]);
        assert_eq!(k.multipliers, vec![0.0]);
        assert!(!k.active[0]);
        assert_eq!(k.stationarity, 1.0);
    }

    #[test]
    fn a_bound_holds_only_a_gradient_pointing_out_of_the_box() {
        let bounds = [(0.0, 1.0), (0.0, 1.0)];
        // At x = 0 with df/dx = 1 > 0: held; with df/dx = -1: it should move in.
        let held = at_start(&[0.0, 0.5], &bounds, &point(&[1.0, 0.0], &[], &[]), 0, &[]);
        assert_eq!((held.at_bound[0], held.stationarity), (-1, 0.0));
        let loose = at_start(&[0.0, 0.5], &bounds, &point(&[-1.0, 0.0], &[], &[]), 0, &[]);
        assert_eq!(loose.stationarity, 1.0);
    }

    #[test]
    fn on_a_bound_means_within_round_off_of_the_variables_scale_not_of_the_boxs_width() {
        // SLSQP's clipping noise next to a large variable: held.
        assert_eq!(held(&[3.5e-15, 23.4], &[3.5e-15, 23.4], &[(0.0, 100.0), (0.0, 100.0)]), vec![-1, 0]);
        // A wide box does not make an interior point held: k = 5 in [0, 1e13] is free, and the
        // gradient of k^2 there is not projected away.
        assert_eq!(held(&[5.0], &[5.0], &[(0.0, 1e13)]), vec![0]);
        let k = at_start(&[5.0], &[(0.0, 1e13)], &point(&[10.0], &[], &[]), 0, &[]);
        assert_eq!(k.stationarity, 1.0);
        // Nor does a half-infinite or unbounded box.
        assert_eq!(held(&[5.0, 5.0], &[5.0, 5.0], &[(0.0, f64::INFINITY), FREE[0]]), vec![0, 0]);
        // Exactly on a bound, and at either end of a tiny box.
        assert_eq!(held(&[0.0, 1e-6], &[0.0, 1e-6], &[(0.0, 1.0), (0.0, 1e-6)]), vec![-1, 1]);
        assert_eq!(held(&[-2.0 - 1e-13], &[-2.0 - 1e-13], &[(-2.0 - 1e-13, 0.0)]), vec![-1]);
        // A lone variable come down to round-off of its bound from a start of its box's size:
        // held (on its own it was its own scale), and a start of round-off size leaves it free.
        assert_eq!(held(&[8.9e-16], &[0.76], &[(0.0, 2.0)]), vec![-1]);
        assert_eq!(held(&[8.9e-16], &[1e-15], &[(0.0, 2.0)]), vec![0]);
    }

    #[test]
    fn an_equality_counts_its_violation_against_its_tolerance() {
        let k = at_start(&[1.0], &FREE[..1], &point(&[2.0], &[3e-8], &[&[1.0]]), 1, &[1e-8]);
        approx::assert_relative_eq!(k.violation_ratio, 3.0);
        approx::assert_relative_eq!(k.multipliers[0], -2.0);
    }

    /// `f(u) = (a . u - 1)^2 + lam |u|^2`, its gradient `2 (a . u - 1) a + 2 lam u`: a least-squares
    /// objective with a non-zero residual at its optimum `u* = a / (|a|^2 + lam)` (`lam > 0`)
    /// and a zero residual (`lam = 0`, every `u` with `a . u = 1`).
    fn ridge(a: &[f64], lam: f64, u: &[f64]) -> SmoothPoint {
        let r = a.iter().zip(u).map(|(a, u)| a * u).sum::<f64>() - 1.0;
        let gradient = a.iter().zip(u).map(|(a, u)| 2.0 * r * a + 2.0 * lam * u).collect();
        let objective = r * r + lam * u.iter().map(|u| u * u).sum::<f64>();
        SmoothPoint { objective, gradient, constraints: Vec::new(), jacobian: Vec::new() }
    }

    #[test]
    fn a_violation_held_by_a_bound_is_a_local_minimum_of_the_violation_and_one_that_can_fall_is_not() {
        // touchdown#1 >= 0.5 as 0.5 - t(h0) <= 0 with dt/dh0 > 0: at the upper bound h0 = 1 the
        // violation would fall only by raising h0, which the box forbids.
        let p = point(&[1.0], &[0.048], &[&[-0.23]]);
        let k = at_start(&[1.0], &[(0.1, 1.0)], &p, 0, &[5e-9]);
        assert!(k.violation_ratio > 1.0 && k.violation_stationary);
        // Inside the box it can fall: not stationary.
        let k = at_start(&[0.5], &[(0.1, 1.0)], &p, 0, &[5e-9]);
        assert!(!k.violation_stationary);
        // An equality missed on either side is the same: c = 0.38 with dc/de = 4 inside the box.
        let k = at_start(&[0.87], &[(0.0, 1.0)], &point(&[1.0], &[-0.38], &[&[4.0]]), 1, &[3.5e-8]);
        assert!(!k.violation_stationary);
    }

    #[test]
    fn an_unconstrained_optimum_is_stationary_on_the_scale_of_the_starts_gradient() {
        let a = [0.3, -1.2, 0.7, 2.5];
        let free = [FREE[0]; 4];
        let start = ridge(&a, 0.1, &[0.0; 4]);
        // Non-zero residual: the closed-form optimum. Its gradient is round-off of the terms
        // 2 r a and 2 lam u, which the relative measure divided by themselves (reading 1).
        let norm2: f64 = a.iter().map(|a| a * a).sum();
        let optimum: Vec<f64> = a.iter().map(|a| a / (norm2 + 0.1)).collect();
        let end = ridge(&a, 0.1, &optimum);
        assert!(end.gradient.iter().any(|&g| g != 0.0), "round-off is left: {:?}", end.gradient);
        let k = measure(&optimum, &optimum, &free, &end, 0, &[], &start.gradient);
        assert!(k.stationarity < 1e-14, "stationarity {}", k.stationarity);
        assert_eq!(k.scale, 2.0 * 2.5);
        // Zero residual: a point on a . u = 1 (u = a / |a|^2, to round-off).
        let zero_start = ridge(&a, 0.0, &[0.0; 4]);
        let on: Vec<f64> = a.iter().map(|a| a / norm2).collect();
        let k = measure(&on, &on, &free, &ridge(&a, 0.0, &on), 0, &[], &zero_start.gradient);
        assert!(k.stationarity < 1e-14, "stationarity {}", k.stationarity);
    }

    #[test]
    fn a_point_short_of_the_optimum_is_not_stationary() {
        let a = [0.3, -1.2, 0.7, 2.5];
        let free = [FREE[0]; 4];
        let start = ridge(&a, 0.1, &[0.0; 4]);
        let norm2: f64 = a.iter().map(|a| a * a).sum();
        // The small miss: a tenth of a percent short of the optimum along the way from the
        // start, where the gradient is 1e-3 of the start's.
        let short: Vec<f64> = a.iter().map(|a| 0.999 * a / (norm2 + 0.1)).collect();
        let k = measure(&short, &short, &free, &ridge(&a, 0.1, &short), 0, &[], &start.gradient);
        approx::assert_relative_eq!(k.stationarity, 1e-3, max_relative = 1e-9);
        // Zero residual, 1e-4 short of a . u = 1: the gradient is 1e-4 of the start's.
        let zero_start = ridge(&a, 0.0, &[0.0; 4]);
        let near: Vec<f64> = a.iter().map(|a| (1.0 - 1e-4) * a / norm2).collect();
        let k = measure(&near, &near, &free, &ridge(&a, 0.0, &near), 0, &[], &zero_start.gradient);
        approx::assert_relative_eq!(k.stationarity, 1e-4, max_relative = 1e-9);
    }

    #[test]
    fn with_an_active_constraint_the_scale_is_the_largest_term_or_the_starts_gradient() {
        // min x^2 + y^2 subject to 1 - x - y <= 0 at (0.5, 0.5): grad f = (1, 1) balanced by the
        // multiplier 1 on grad c = (-1, -1). From a start with gradient (4, 0) the scale is 4.
        let end = point(&[1.0, 1.0], &[0.0], &[&[-1.0, -1.0]]);
        let k = measure(&[0.5, 0.5], &[0.5, 0.5], &FREE, &end, 0, &[1e-8], &[4.0, 0.0]);
        assert_eq!((k.multipliers.clone(), k.scale, k.stationarity), (vec![1.0], 4.0, 0.0));
        // Off the optimum along the constraint, (0.6, 0.4): grad f = (1.2, 0.8), the best
        // multiplier 1 leaves (0.2, -0.2); 0.2 of the term 1.2, 0.05 of the start's 4.
        let off = point(&[1.2, 0.8], &[0.0], &[&[-1.0, -1.0]]);
        let k = measure(&[0.6, 0.4], &[0.6, 0.4], &FREE, &off, 0, &[1e-8], &[1.2, 0.8]);
        approx::assert_relative_eq!(k.stationarity, 0.2 / 1.2, max_relative = 1e-12);
        let k = measure(&[0.6, 0.4], &[0.6, 0.4], &FREE, &off, 0, &[1e-8], &[4.0, 0.0]);
        approx::assert_relative_eq!(k.stationarity, 0.2 / 4.0, max_relative = 1e-12);
    }
}
