//! The second-order check on a point the KKT conditions call stationary: is it a minimum? A
//! strict maximum (`-(p - 1)^2` at `p = 1`) and a saddle meet the first-order conditions as
//! exactly as a minimum does. At a local minimum the Lagrangian's curvature is not negative along
//! any direction the point may move in: the variables off their bounds, tangent to the active
//! constraints (the null space `Z` of their gradients). So:
//!
//! 1. The Lagrangian's Hessian `H` (multipliers fixed at the end's estimate) along directions
//!    `d` of `Z`, by differences of the exact gradients: one run per direction at a step of
//!    `STEP` of the variables' scales (a variable's scale: the larger of its magnitude at the end
//!    and at the start, else its box's width, else 1). The directions are the columns of `Z`
//!    when it has at most `MAX_DIRECTIONS`; else a Krylov sequence of `MAX_DIRECTIONS` in `Z`
//!    (Lanczos with full reorthogonalisation) from a seeded random direction: `d_1`, then each
//!    next `H d_k` orthogonalised against the ones before. That finds the extreme curvatures of
//!    a large space in few runs (a maximum: every direction), but can miss a saddle whose few
//!    negative curvatures are small.
//! 2. The smallest eigenvalue of the symmetric part of `D^T H D` (`D` the directions). Not
//!    negative: a minimum as far as second order can tell (a zero curvature, a flat valley,
//!    passes).
//! 3. Negative: confirmed by values, two runs at `x -/+ CONFIRM v` along its eigenvector `v`. The
//!    Lagrangian's second difference there must be negative beyond round-off and at least half of
//!    what the eigenvalue predicts: two measurements (gradients, then values) that agree, so noise
//!    in either does not demote a minimum. Only then is the point "not a minimum".
//!
//! A probe run that fails, or lands on another event sequence (another smooth piece), gives no
//! evidence; its direction is left out. The check costs one run per direction of `Z` (none when
//! the constraints and bounds leave no direction free) and two more when a negative curvature is
//! found.

use nalgebra::{DMatrix, DVector};
use rand_chacha::ChaCha8Rng;
use rand_core::{Rng as _, SeedableRng as _};

use super::kkt::Kkt;
use super::solver::SmoothPoint;

/// The step of the Hessian's differences, in units of each variable's scale.
const STEP: f64 = 1e-4;

/// The step of the confirming runs, in units of each variable's scale.
const CONFIRM: f64 = 1e-3;

/// The most directions (runs) the Hessian is probed along.
pub const MAX_DIRECTIONS: usize = 12;

/// A direction along which a stationary point is not a minimum.
#[derive(Clone, Debug, PartialEq)]
pub struct Descent {
    /// The smallest eigenvalue of the reduced Hessian in scaled variables (negative): the
    /// second derivative of the Lagrangian along the unit direction, in the objective's units.
    pub curvature: f64,
    /// How much lower the Lagrangian is at the better of the two confirming points.
    pub drop: f64,
    /// The better confirming point (all free variables).
    pub lower_at: Vec<f64>,
}

/// The outcome of the check: the runs it made, and the direction of descent it found, if any.
#[derive(Clone, Debug, PartialEq)]
pub struct Probe {
    /// Simulation runs made.
    pub runs: usize,
    /// `Some` when the point is not a minimum.
    pub descent: Option<Descent>,
}

/// One probe evaluation: the smooth point and the run's event sequence, `None` if the run failed.
pub type ProbeEval<'e> = dyn FnMut(&[f64]) -> Option<(SmoothPoint, Vec<usize>)> + 'e;

/// The scale of each variable: the larger of its magnitude at `x` and at the start `x0`, else its
/// box's width when that is finite and positive, else 1.
pub fn scales(x: &[f64], x0: &[f64], bounds: &[(f64, f64)]) -> Vec<f64> {
    x.iter()
        .zip(x0)
        .zip(bounds)
        .map(|((&v, &v0), &(lo, hi))| {
            let s = v.abs().max(v0.abs());
            if s > 0.0 && s.is_finite() {
                s
            } else if (hi - lo).is_finite() && hi > lo {
                hi - lo
            } else {
                1.0
            }
        })
        .collect()
}

/// The Lagrangian's value and gradient at a point, with multipliers `lambda`.
fn lagrangian(p: &SmoothPoint, lambda: &[f64]) -> (f64, Vec<f64>) {
    let mut value = p.objective;
    let mut gradient = p.gradient.clone();
    for ((&l, &c), row) in lambda.iter().zip(&p.constraints).zip(&p.jacobian) {
        if l != 0.0 {
            value += l * c;
            gradient.iter_mut().zip(row).for_each(|(g, d)| *g += l * d);
        }
    }
    (value, gradient)
}

/// Checks whether the stationary point `x` (with its evaluation `end`, event sequence `events`
/// and KKT measures `kkt`) is a minimum. `x0` is the solve's start (for the variables' scales),
/// `rtol` the runs' relative tolerance (the round-off floor of the confirming values).
#[allow(clippy::too_many_arguments)]
pub fn probe(
    x: &[f64],
    x0: &[f64],
    bounds: &[(f64, f64)],
    end: &SmoothPoint,
    events: &[usize],
    kkt: &Kkt,
    rtol: f64,
    evaluate: &mut ProbeEval<'_>,
) -> Probe {
    let mut probe = Probe { runs: 0, descent: None };
    let free: Vec<usize> = (0..x.len()).filter(|&k| kkt.at_bound[k] == 0).collect();
    if free.is_empty() {
        return probe;
    }
    let s = scales(x, x0, bounds);
    // The null space of the active constraints' gradients over the free variables, scaled.
    let active: Vec<usize> = (0..end.constraints.len()).filter(|&i| kkt.active[i]).collect();
    // `None`: no active constraint, every free direction, the identity (never formed: with the
    // many variables L-BFGS-B takes it would be their count squared).
    let z = if active.is_empty() {
        None
    } else {
        let a =
            DMatrix::from_fn(active.len(), free.len(), |r, c| end.jacobian[active[r]][free[c]] * s[free[c]]);
        let eigen = (a.transpose() * &a).symmetric_eigen();
        let largest = eigen.eigenvalues.amax();
        let null: Vec<usize> = (0..free.len()).filter(|&k| eigen.eigenvalues[k] <= 1e-12 * largest).collect();
        Some(DMatrix::from_fn(free.len(), null.len(), |r, c| eigen.eigenvectors[(r, null[c])]))
    };
    let z_cols = z.as_ref().map_or(free.len(), |z| z.ncols());
    if z_cols == 0 {
        return probe;
    }
    let z_times = |q: &DVector<f64>| -> Vec<f64> {
        match &z {
            Some(z) => (z * q).iter().copied().collect(),
            None => q.iter().copied().collect(),
        }
    };
    let z_t_times = |v: DVector<f64>| -> DVector<f64> {
        match &z {
            Some(z) => z.transpose() * v,
            None => v,
        }
    };
    let (l_end, g_end) = lagrangian(end, &kkt.multipliers);
    let inside = |y: &[f64]| y.iter().zip(bounds).all(|(&v, &(lo, hi))| v >= lo && v <= hi && v.is_finite());
    let along = |direction: &[f64], t: f64| -> Vec<f64> {
        let mut y = x.to_vec();
        for (c, &k) in free.iter().enumerate() {
            y[k] += t * s[k] * direction[c];
        }
        y
    };
    // H d along each direction, in scaled variables. A direction whose run gives no evidence is
    // left out (and ends a Krylov sequence, which needs every product).
    let krylov = z_cols > MAX_DIRECTIONS;
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut next: Option<DVector<f64>> = krylov.then(|| {
        let q = DVector::from_fn(z_cols, |_, _| (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64 - 0.5);
        q.normalize()
    });
    let mut basis: Vec<DVector<f64>> = Vec::new();
    let mut directions: Vec<Vec<f64>> = Vec::new();
    let mut hd: Vec<Vec<f64>> = Vec::new();
    for j in 0..z_cols.min(MAX_DIRECTIONS) {
        let q = match next.take() {
            Some(q) => q,
            None if krylov => break,
            None => DVector::from_fn(z_cols, |r, _| if r == j { 1.0 } else { 0.0 }),
        };
        let direction: Vec<f64> = z_times(&q);
        let Some(sign) = [1.0, -1.0].into_iter().find(|&sg| inside(&along(&direction, sg * STEP))) else {
            continue;
        };
        probe.runs += 1;
        let Some((p, e)) = evaluate(&along(&direction, sign * STEP)) else { continue };
        if e != events {
            continue;
        }
        let (_, g) = lagrangian(&p, &kkt.multipliers);
        let product: Vec<f64> = free.iter().map(|&k| s[k] * (g[k] - g_end[k]) / (sign * STEP)).collect();
        if krylov {
            // The next direction: Z^T H d, orthogonalised twice against the basis so far.
            basis.push(q);
            let mut w = z_t_times(DVector::from_column_slice(&product));
            for _ in 0..2 {
                for b in &basis {
                    w -= b * b.dot(&w);
                }
            }
            let norm = w.norm();
            let largest = product.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
            if norm > 1e-12 * largest && norm.is_finite() {
                next = Some(w / norm);
            }
        }
        directions.push(direction);
        hd.push(product);
    }
    if directions.is_empty() {
        return probe;
    }
    // D^T H D over the directions kept, symmetrised.
    let r = directions.len();
    let dth =
        DMatrix::from_fn(r, r, |a, b| directions[a].iter().zip(&hd[b]).map(|(d, h)| d * h).sum::<f64>());
    let reduced = (&dth + dth.transpose()) * 0.5;
    let eigen = reduced.symmetric_eigen();
    let (lowest, &curvature) =
        eigen.eigenvalues.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1)).expect("r >= 1");
    // Not negative (or NaN): no evidence of a descent.
    if curvature >= 0.0 || curvature.is_nan() {
        return probe;
    }
    // Its direction over the free variables, and the two confirming runs.
    let w = eigen.eigenvectors.column(lowest);
    let v: Vec<f64> = (0..free.len()).map(|c| (0..r).map(|a| directions[a][c] * w[a]).sum()).collect();
    let (plus, minus) = (along(&v, CONFIRM), along(&v, -CONFIRM));
    if !(inside(&plus) && inside(&minus)) {
        return probe;
    }
    let mut value = |y: &[f64]| -> Option<f64> {
        probe.runs += 1;
        let (p, e) = evaluate(y)?;
        (e == events).then(|| lagrangian(&p, &kkt.multipliers).0)
    };
    let (Some(l_plus), Some(l_minus)) = (value(&plus), value(&minus)) else { return probe };
    let second = l_plus + l_minus - 2.0 * l_end;
    let floor = 100.0 * rtol.max(f64::EPSILON) * l_plus.abs().max(l_minus.abs()).max(l_end.abs());
    if second < -floor && second <= 0.5 * curvature * CONFIRM * CONFIRM {
        let (lower, lower_at) = if l_plus <= l_minus { (l_plus, plus) } else { (l_minus, minus) };
        probe.descent = Some(Descent { curvature, drop: l_end - lower, lower_at });
    }
    probe
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A quadratic `f(x) = 0.5 x^T Q x + b^T x` and linear constraints `c(x) = A x - d`, exactly.
    fn quadratic(q: &[&[f64]], b: &[f64], a: &[&[f64]], d: &[f64]) -> impl Fn(&[f64]) -> SmoothPoint {
        let q: Vec<Vec<f64>> = q.iter().map(|r| r.to_vec()).collect();
        let a: Vec<Vec<f64>> = a.iter().map(|r| r.to_vec()).collect();
        let (b, d) = (b.to_vec(), d.to_vec());
        move |x: &[f64]| {
            let qx: Vec<f64> = q.iter().map(|r| r.iter().zip(x).map(|(q, x)| q * x).sum()).collect();
            let objective = 0.5 * qx.iter().zip(x).map(|(a, b)| a * b).sum::<f64>()
                + b.iter().zip(x).map(|(a, b)| a * b).sum::<f64>();
            let gradient = qx.iter().zip(&b).map(|(a, b)| a + b).collect();
            let constraints =
                a.iter().zip(&d).map(|(r, d)| r.iter().zip(x).map(|(a, x)| a * x).sum::<f64>() - d).collect();
            SmoothPoint { objective, gradient, constraints, jacobian: a.clone() }
        }
    }

    fn check(f: &dyn Fn(&[f64]) -> SmoothPoint, x: &[f64], bounds: &[(f64, f64)], kkt: &Kkt) -> Probe {
        let end = f(x);
        let mut eval = |y: &[f64]| Some((f(y), Vec::new()));
        probe(x, x, bounds, &end, &[], kkt, 1e-10, &mut eval)
    }

    fn free_kkt(n: usize, multipliers: Vec<f64>) -> Kkt {
        Kkt {
            active: vec![true; multipliers.len()],
            multipliers,
            at_bound: vec![0; n],
            stationarity: 0.0,
            scale: 0.0,
            violation_ratio: 0.0,
            violation: 0.0,
            violation_stationary: true,
        }
    }

    const FREE: (f64, f64) = (f64::NEG_INFINITY, f64::INFINITY);

    #[test]
    fn a_strict_maximum_is_not_a_minimum_and_a_strict_minimum_is() {
        // -(p - 1)^2 at p = 1: Q = -2, b = 2 (the constant left out); the scale of p is 1.
        let peak = quadratic(&[&[-2.0]], &[2.0], &[], &[]);
        let p = check(&peak, &[1.0], &[(0.0, 2.0)], &free_kkt(1, vec![]));
        let d = p.descent.expect("not a minimum");
        approx::assert_relative_eq!(d.curvature, -2.0, max_relative = 1e-9);
        approx::assert_relative_eq!(d.drop, CONFIRM * CONFIRM, max_relative = 1e-6);
        assert_eq!(p.runs, 3);
        // (p - 1)^2 at p = 1: one run, no descent.
        let bowl = quadratic(&[&[2.0]], &[-2.0], &[], &[]);
        let p = check(&bowl, &[1.0], &[(0.0, 2.0)], &free_kkt(1, vec![]));
        assert_eq!((p.runs, p.descent), (1, None));
    }

    #[test]
    fn a_saddle_is_found_along_a_direction_that_is_no_coordinate() {
        // f = x y at 0: zero curvature along each axis, -1 along (1, -1) / sqrt 2; in variables
        // scaled by the boxes' width 2, -4.
        let saddle = quadratic(&[&[0.0, 1.0], &[1.0, 0.0]], &[0.0, 0.0], &[], &[]);
        let p = check(&saddle, &[0.0, 0.0], &[(-1.0, 1.0), (-1.0, 1.0)], &free_kkt(2, vec![]));
        let d = p.descent.expect("a saddle");
        approx::assert_relative_eq!(d.curvature, -4.0, max_relative = 1e-9);
        assert_eq!(p.runs, 4);
        // Flat along one variable, a minimum along the other: no descent (zero curvature passes).
        let valley = quadratic(&[&[2.0, 0.0], &[0.0, 0.0]], &[0.0, 0.0], &[], &[]);
        assert_eq!(check(&valley, &[0.0, 0.0], &[(-1.0, 1.0); 2], &free_kkt(2, vec![])).descent, None);
    }

    #[test]
    fn only_the_directions_the_constraints_leave_free_count() {
        // f = y^2 - x^2 subject to x = 0: on the constraint
        // the curvature is +2, so (0, 0) is a constrained minimum; without it, a saddle.
        let f = quadratic(&[&[-2.0, 0.0], &[0.0, 2.0]], &[0.0, 0.0], &[&[1.0, 0.0]], &[0.0]);
        let bounds = [(-1.0, 1.0); 2];
        let p = check(&f, &[0.0, 0.0], &bounds, &free_kkt(2, vec![0.0]));
        assert_eq!((p.runs, p.descent), (1, None));
        let mut released = free_kkt(2, vec![0.0]);
        released.active = vec![false];
        assert!(check(&f, &[0.0, 0.0], &bounds, &released).descent.is_some());
        // A variable held at its bound is not a direction: x held, y free with positive curvature.
        let mut held = free_kkt(2, vec![0.0]);
        held.active = vec![false];
        held.at_bound = vec![-1, 0];
        assert_eq!(check(&f, &[0.0, 0.0], &bounds, &held).descent, None);
    }

    #[test]
    fn a_probe_on_another_event_sequence_or_a_failed_run_is_no_evidence() {
        let peak = quadratic(&[&[-2.0]], &[2.0], &[], &[]);
        let end = peak(&[1.0]);
        let kkt = free_kkt(1, vec![]);
        let mut other = |y: &[f64]| Some((peak(y), vec![0]));
        let p = probe(&[1.0], &[1.0], &[(0.0, 2.0)], &end, &[], &kkt, 1e-10, &mut other);
        assert_eq!((p.runs, p.descent), (1, None));
        let mut failing = |_: &[f64]| None;
        let p = probe(&[1.0], &[1.0], &[(0.0, 2.0)], &end, &[], &kkt, 1e-10, &mut failing);
        assert_eq!((p.runs, p.descent), (1, None));
    }

    #[test]
    fn a_large_space_is_probed_along_a_krylov_sequence_of_few_runs() {
        // 40 variables: a bowl with curvatures 1..40 (the scale of each is its box's width 1),
        // then the same with one curvature -30: a saddle whose negative direction is a strong one.
        let n = 40;
        let diagonal = |k: usize, negative: bool| if negative && k == 7 { -30.0 } else { (k + 1) as f64 };
        for negative in [false, true] {
            let rows: Vec<Vec<f64>> = (0..n)
                .map(|i| (0..n).map(|j| if i == j { diagonal(i, negative) } else { 0.0 }).collect())
                .collect();
            let refs: Vec<&[f64]> = rows.iter().map(Vec::as_slice).collect();
            let f = quadratic(&refs, &vec![0.0; n], &[], &[]);
            let p = check(&f, &vec![0.0; n], &vec![(-0.5, 0.5); n], &free_kkt(n, vec![]));
            if negative {
                let d = p.descent.expect("the saddle");
                assert!(d.curvature < -15.0, "{}", d.curvature);
                assert_eq!(p.runs, MAX_DIRECTIONS + 2);
            } else {
                assert_eq!((p.runs, p.descent), (MAX_DIRECTIONS, None));
            }
        }
    }

    #[test]
    fn scales_are_the_magnitudes_else_the_box_else_one() {
        let bounds = [FREE, (0.0, 4.0), FREE, (0.0, 1.0)];
        assert_eq!(scales(&[2.0, 0.0, 0.0, -3.0], &[-5.0, 0.0, 0.0, 0.5], &bounds), vec![5.0, 4.0, 1.0, 3.0]);
    }
}
