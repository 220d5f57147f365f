//! Stage 5 (sim): dense output of the last accepted Runge-Kutta step: a polynomial in
//! `s = (t - t0) / h` for every component, with its time derivative. Knows the stepper's stage
//! layout, nothing of events or models.
//!
//! Both methods use Hairer's nested form in which the coefficient vectors `r_0 .. r_K` are
//! multiplied alternately by `s` and `1 - s`:
//! `P(s) = r0 + s (r1 + (1-s) (r2 + s (r3 + (1-s) (r4 + ...))))`,
//! with `r0 = y0`, `r1 = y1 - y0`, `r2 = h f0 - r1`, `r3 = r1 - h f1 - r2` (cubic Hermite
//! interpolation of both ends and their derivatives) and the remaining vectors `h sum_j d_ij k_j`.
//! Dormand-Prince 5(4) has one correction (4th-order accurate), DOP853 four, built from three extra
//! stages (7th-order accurate). Because of the Hermite part, `P'` matches `f` at both ends.

use super::poly::CAP;
use super::stepper::Interpolant;
use super::sums::{centred_sum, centred_sum_at};
use super::tableau::{DenseKind, Tableau};

/// Most coefficient vectors of any method (DOP853; Dopri5 uses 5).
const MAX_COEF: usize = 8;

/// The dense output of one explicit Runge-Kutta step (an [`Interpolant`]).
pub struct Dense {
    pub(crate) t0: f64,
    pub(crate) h: f64,
    nz: usize,
    n_coef: usize,
    /// Component-major: the coefficients of component `i` are `r[i * MAX_COEF..][..n_coef]`, so
    /// one evaluation reads one short contiguous run per component.
    r: Vec<f64>,
    /// One correction vector before it is spread into `r`.
    row: Vec<f64>,
    /// The components built (the first `valid`): all of them, or the states alone
    /// (`Stepper::build_states_interpolant`) until the rest is built.
    valid: usize,
}

impl Dense {
    pub(crate) fn new(nz: usize) -> Dense {
        // Until the first build the interpolant is the zero constant, never an out-of-range read.
        Dense { t0: 0.0, h: 0.0, nz, n_coef: 1, r: vec![0.0; MAX_COEF * nz], row: vec![0.0; nz], valid: nz }
    }

    /// Builds the interpolant of a step of size `h` from `(t0, y0)` to `y1` with the stage
    /// derivatives `k` (all of them, DOP853's three extra stages included), for its first `upto`
    /// components (`nz` for all: the others are then not to be read).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn build(
        &mut self,
        tab: &Tableau,
        t0: f64,
        h: f64,
        y0: &[f64],
        y1: &[f64],
        k: &[f64],
        upto: usize,
    ) {
        let nz = self.nz;
        let upto = upto.min(nz);
        self.valid = upto;
        let (y0, y1) = (&y0[..upto], &y1[..upto]);
        self.t0 = t0;
        self.h = h;
        self.n_coef = match tab.dense {
            DenseKind::Dopri5 => 5,
            DenseKind::Dop853 => 8,
        };
        let f0 = &k[..nz];
        let f1 = &k[(tab.stages - 1) * nz..tab.stages * nz];
        let ends = y0.iter().zip(y1).zip(f0.iter().zip(f1));
        for (r, ((&y0, &y1), (&f0, &f1))) in self.r.chunks_exact_mut(MAX_COEF).zip(ends) {
            let ydiff = y1 - y0;
            let bspl = h * f0 - ydiff;
            r[..4].copy_from_slice(&[y0, ydiff, bspl, ydiff - h * f1 - bspl]);
        }
        for (row, d) in tab.d.iter().enumerate() {
            centred_sum(k, nz, d, &mut self.row[..upto]);
            for (r, v) in self.r.chunks_exact_mut(MAX_COEF).zip(&self.row[..upto]) {
                r[4 + row] = h * v;
            }
        }
    }

    /// Builds the interpolant of the same step as [`Self::build`] for the components `comps`
    /// alone (ascending, each below `y0.len()`), with the same arithmetic per component, so their
    /// polynomials are [`Self::build`]'s to the bit; the other components among the first
    /// `y0.len()` read as the constant `y0` (a finite stand-in, never stale values, for the
    /// readers of whole states that do not depend on them: a guard that does not read them).
    /// The first `y0.len()` components are declared readable; [`Self::build`] completes them.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn build_some(
        &mut self,
        tab: &Tableau,
        t0: f64,
        h: f64,
        y0: &[f64],
        y1: &[f64],
        k: &[f64],
        comps: &[u32],
    ) {
        let nz = self.nz;
        let upto = y0.len().min(nz);
        self.valid = upto;
        self.t0 = t0;
        self.h = h;
        self.n_coef = match tab.dense {
            DenseKind::Dopri5 => 5,
            DenseKind::Dop853 => 8,
        };
        let nc = self.n_coef;
        for (r, &y) in self.r.chunks_exact_mut(MAX_COEF).zip(&y0[..upto]) {
            r[0] = y;
            r[1..nc].fill(0.0);
        }
        let f1 = (tab.stages - 1) * nz;
        for &i in comps {
            let i = i as usize;
            let r = &mut self.r[i * MAX_COEF..(i + 1) * MAX_COEF];
            let (y0, y1, f0, f1) = (y0[i], y1[i], k[i], k[f1 + i]);
            let ydiff = y1 - y0;
            let bspl = h * f0 - ydiff;
            r[..4].copy_from_slice(&[y0, ydiff, bspl, ydiff - h * f1 - bspl]);
            for (row, d) in tab.d.iter().enumerate() {
                r[4 + row] = h * centred_sum_at(k, nz, d, i);
            }
        }
    }

    /// Declares only the first `valid` components readable (the others were summed along, for
    /// speed, from stages that are not theirs).
    pub(crate) fn restrict(&mut self, valid: usize) {
        self.valid = self.valid.min(valid);
    }

    /// `s = (t - t0) / h`, zero before the first build.
    fn unit_time(&self, t: f64) -> f64 {
        if self.h != 0.0 {
            (t - self.t0) / self.h
        } else {
            0.0
        }
    }

    /// Interpolated values of the first `out.len()` components at time `t`.
    ///
    /// The nested form is evaluated two levels at a time: with `u = s (1 - s)`,
    /// `r1 + (1-s) (r2 + s Q) = (r1 + (1-s) r2) + u Q`, so the chain of dependent operations is
    /// half as long (the root searches evaluate the interpolant several times per event, and each
    /// evaluation waited on seven multiply-adds in a row).
    pub fn eval(&self, t: f64, out: &mut [f64]) {
        // A dense output built for the states alone is completed before the rest is read: an
        // invariant of the integrator, checked (a stale sensitivity would be a silent error).
        assert!(out.len() <= self.valid, "the dense output read past the components built");
        let s = self.unit_time(t);
        let s1 = 1.0 - s;
        let u = s * s1;
        let nc = self.n_coef;
        // `r1 .. r_{nc-1}` in pairs from the top; an odd one out is the innermost term.
        let pairs = (nc - 1) / 2;
        let odd = (nc - 1) % 2 == 1;
        for (o, r) in out.iter_mut().zip(self.r.chunks_exact(MAX_COEF)) {
            let mut acc = if odd { r[nc - 1] } else { 0.0 };
            for k in (0..pairs).rev().map(|p| 1 + 2 * p) {
                acc = (r[k] + s1 * r[k + 1]) + u * acc;
            }
            *o = r[0] + s * acc;
        }
    }

    /// Interpolated time derivatives of the first `out.len()` components at time `t`: the
    /// derivative of [`Self::eval`]'s form, with `u' = 1 - 2 s` and `(r_k + (1-s) r_{k+1})' =
    /// -r_{k+1}`.
    pub fn eval_deriv(&self, t: f64, out: &mut [f64]) {
        assert!(out.len() <= self.valid, "the dense output read past the components built");
        if self.h == 0.0 {
            out.fill(0.0);
            return;
        }
        let s = self.unit_time(t);
        let s1 = 1.0 - s;
        let (u, du) = (s * s1, 1.0 - 2.0 * s);
        let nc = self.n_coef;
        let pairs = (nc - 1) / 2;
        let odd = (nc - 1) % 2 == 1;
        for (o, r) in out.iter_mut().zip(self.r.chunks_exact(MAX_COEF)) {
            let (mut acc, mut dacc) = (if odd { r[nc - 1] } else { 0.0 }, 0.0);
            for k in (0..pairs).rev().map(|p| 1 + 2 * p) {
                dacc = -r[k + 1] + du * acc + u * dacc;
                acc = (r[k] + s1 * r[k + 1]) + u * acc;
            }
            *o = (acc + s * dacc) / self.h;
        }
    }
}

impl Interpolant for Dense {
    fn t0(&self) -> f64 {
        self.t0
    }
    fn h(&self) -> f64 {
        self.h
    }
    #[inline]
    fn eval(&self, t: f64, out: &mut [f64]) {
        Dense::eval(self, t, out)
    }
    #[inline]
    fn eval_deriv(&self, t: f64, out: &mut [f64]) {
        Dense::eval_deriv(self, t, out)
    }
    fn degree(&self) -> usize {
        self.n_coef - 1
    }
    /// From the nested form: `P(s) - P(0) = s (r1 + (1-s) (r2 + s (r3 + (1-s) (r4 + ...))))`,
    /// combined over the components first (`n` multiply-adds per coefficient), then expanded
    /// from the innermost term out (`O(K^2)` for `K` coefficients).
    fn linear_form(&self, w: &[f64], coef: &mut [f64; CAP]) -> usize {
        let nc = self.n_coef;
        let mut rho = [0.0; CAP];
        for (r, &wi) in self.r.chunks_exact(MAX_COEF).zip(w) {
            if wi != 0.0 {
                for (acc, &rk) in rho[1..nc].iter_mut().zip(&r[1..nc]) {
                    *acc += wi * rk;
                }
            }
        }
        expand_nested(&rho, nc, coef)
    }
    /// From the nested form: with `s` and `1 - s` both in `[0, 1]`, the innermost coefficient
    /// out, `I <- rho_k + [0, 1] I` and finally `[0, 1] I` (exact in real arithmetic for any
    /// polynomial in this form, and tight where the motion is monotone or its extremum lies at
    /// an end). The rounding: each `rho_k` is a sum of at most `entries + 1` products and each
    /// level adds one rounding, so `4 (entries + K) eps` times the coefficients' magnitudes bounds
    /// both this computation's error and that of evaluating the polynomial.
    fn affine_motion_hull(&self, entries: &[(u32, f64)], slope: f64) -> Option<(f64, f64)> {
        let nc = self.n_coef;
        if nc < 2 {
            return None;
        }
        let (mut rho, mut size) = ([0.0; MAX_COEF], 0.0);
        for &(i, w) in entries {
            let i = i as usize;
            if i >= self.valid {
                return None;
            }
            for (acc, &rk) in rho[1..nc].iter_mut().zip(&self.r[i * MAX_COEF + 1..i * MAX_COEF + nc]) {
                *acc += w * rk;
                size += (w * rk).abs();
            }
        }
        rho[1] += slope;
        size += slope.abs();
        let (mut lo, mut hi) = (rho[nc - 1], rho[nc - 1]);
        for &r in rho[1..nc - 1].iter().rev() {
            lo = r + lo.min(0.0);
            hi = r + hi.max(0.0);
        }
        let err = 4.0 * (entries.len() + nc) as f64 * f64::EPSILON * size;
        Some((lo.min(0.0) - err, hi.max(0.0) + err))
    }
    fn component_form(&self, i: usize, coef: &mut [f64; CAP]) -> usize {
        let nc = self.n_coef;
        let mut rho = [0.0; CAP];
        rho[1..nc].copy_from_slice(&self.r[i * MAX_COEF + 1..i * MAX_COEF + nc]);
        expand_nested(&rho, nc, coef)
    }
}

/// The power-basis coefficients of `s (rho1 + (1-s) (rho2 + s (rho3 + (1-s) (rho4 + ...))))`
/// (`rho[1..nc]`) into `coef`; returns their count.
fn expand_nested(rho: &[f64; CAP], nc: usize, coef: &mut [f64; CAP]) -> usize {
    // q = rho[nc-1]; then q = rho[k] + m_k q with m_k = (1 - s) for odd k, s for even k.
    let mut q = [0.0; CAP];
    q[0] = rho[nc - 1];
    let mut len = 1;
    for k in (1..nc - 1).rev() {
        // Multiply q by s (shift up), and for odd k by (1 - s) = 1 - s: q - s q.
        let mut shifted = [0.0; CAP];
        shifted[1..=len].copy_from_slice(&q[..len]);
        if k % 2 == 1 {
            for (a, b) in q.iter_mut().zip(&shifted).take(len + 1) {
                *a -= b;
            }
        } else {
            q = shifted;
        }
        len += 1;
        q[0] += rho[k];
    }
    // Times s.
    coef.fill(0.0);
    coef[1..=len].copy_from_slice(&q[..len]);
    len + 1
}

#[cfg(test)]
mod tests {
    use super::super::rk::Rk;
    use super::super::stepper::Stepper;
    use super::super::tableau::{Tableau, DOP853, DOPRI5};

    /// One step of y' = cos t (y = sin t) and the interpolant inside it, value and derivative.
    fn interpolation_error(tab: &'static Tableau, h: f64) -> (f64, f64) {
        let mut rk = Rk::new(tab, 1, 1, 1, 1e-8, 1e-8);
        let mut rhs = |t: f64, _y: &[f64], dy: &mut [f64]| dy[0] = t.cos();
        let y0 = [0.3f64.sin()];
        rk.restart(0.3, &y0, &mut rhs);
        rk.attempt(0.3, &y0, h, &mut rhs);
        rk.build_interpolant(0.3, &y0, &mut rhs);
        let dense = rk.interpolant();
        let (mut ev, mut ed) = (0.0f64, 0.0f64);
        for i in 0..=10 {
            let t = 0.3 + h * i as f64 / 10.0;
            let (mut v, mut d) = ([0.0], [0.0]);
            dense.eval(t, &mut v);
            dense.eval_deriv(t, &mut d);
            ev = ev.max((v[0] - t.sin()).abs());
            ed = ed.max((d[0] - t.cos()).abs());
        }
        (ev, ed)
    }

    #[test]
    fn dopri5_dense_output_is_fourth_order() {
        let (e1, _) = interpolation_error(&DOPRI5, 0.2);
        let (e2, d2) = interpolation_error(&DOPRI5, 0.1);
        // Local interpolation error O(h^5): halving h divides it by about 32.
        assert!(e1 / e2 > 20.0, "ratio {}", e1 / e2);
        assert!(e2 < 1e-7 && d2 < 1e-5, "{e2} {d2}");
    }

    #[test]
    fn dop853_dense_output_is_seventh_order() {
        let (e1, _) = interpolation_error(&DOP853, 0.4);
        let (e2, d2) = interpolation_error(&DOP853, 0.2);
        // O(h^8): halving h divides the error by about 256.
        assert!(e1 / e2 > 120.0, "ratio {}", e1 / e2);
        assert!(e2 < 1e-11 && d2 < 1e-9, "{e2} {d2}");
    }

    #[test]
    fn a_linear_form_in_the_power_basis_is_the_dense_output_combined() {
        // Two components (y' = cos t, z' = t^2 sin t), combined as 2 y - 3 z: the power basis
        // from the nested form agrees with the interpolant at eleven points, for both methods.
        use super::super::poly::{Poly, CAP};
        use super::super::stepper::Interpolant;
        for tab in [&DOPRI5, &DOP853] {
            let mut rk = Rk::new(tab, 2, 2, 2, 1e-8, 1e-8);
            let mut rhs = |t: f64, _y: &[f64], dy: &mut [f64]| {
                dy[0] = t.cos();
                dy[1] = t * t * t.sin();
            };
            let (t0, h, y0) = (0.3, 0.7, [0.1, -0.4]);
            rk.restart(t0, &y0, &mut rhs);
            rk.attempt(t0, &y0, h, &mut rhs);
            rk.build_interpolant(t0, &y0, &mut rhs);
            let dense = rk.interpolant();
            let w = [2.0, -3.0];
            let mut coef = [0.0; CAP];
            let len = dense.linear_form(&w, &mut coef);
            assert_eq!(len, dense.degree() + 1);
            let form = Poly::from_coefficients(&coef, len);
            let combine = |t: f64| {
                let mut v = [0.0; 2];
                dense.eval(t, &mut v);
                w[0] * v[0] + w[1] * v[1]
            };
            for i in 0..=10 {
                let s = i as f64 / 10.0;
                let want = combine(t0 + s * h) - combine(t0);
                assert!((form.eval(s) - want).abs() < 1e-14, "{s}: {} vs {want}", form.eval(s));
            }
        }
    }

    #[test]
    fn the_affine_motion_hull_holds_the_motion_and_is_tight_where_it_is_monotone() {
        // Two components with interior extrema (y' = cos(5t), z' = t^2 sin(3t)) and a monotone
        // one (u' = 1 + t^2), combined with a slope: the hull holds the motion at 2001 points of
        // the step; for the monotone motion its ends are the motion's ends within round-off.
        use super::super::stepper::Interpolant;
        for tab in [&DOPRI5, &DOP853] {
            let mut rk = Rk::new(tab, 3, 3, 3, 1e-8, 1e-8);
            let mut rhs = |t: f64, _y: &[f64], dy: &mut [f64]| {
                dy[0] = (5.0 * t).cos();
                dy[1] = t * t * (3.0 * t).sin();
                dy[2] = 1.0 + t * t;
            };
            let (t0, h, y0) = (0.3, 0.9, [0.1, -0.4, 2.0]);
            rk.restart(t0, &y0, &mut rhs);
            rk.attempt(t0, &y0, h, &mut rhs);
            rk.build_interpolant(t0, &y0, &mut rhs);
            let dense = rk.interpolant();
            let motion = |w: &[(u32, f64)], slope: f64, s: f64| {
                let (mut v, mut v0) = ([0.0; 3], [0.0; 3]);
                dense.eval(t0 + s * h, &mut v);
                dense.eval(t0, &mut v0);
                w.iter().map(|&(i, wi)| wi * (v[i as usize] - v0[i as usize])).sum::<f64>() + slope * s
            };
            for (w, slope) in
                [(vec![(0, 2.0), (1, -3.0)], 0.25), (vec![(1, 1.0)], -0.1), (vec![(0, 1.0)], 0.0)]
            {
                let (lo, hi) = dense.affine_motion_hull(&w, slope).expect("a hull");
                let (mut min, mut max) = (f64::INFINITY, f64::NEG_INFINITY);
                for i in 0..=2000 {
                    let m = motion(&w, slope, i as f64 / 2000.0);
                    (min, max) = (min.min(m), max.max(m));
                }
                assert!(lo <= min && max <= hi, "{w:?}: [{lo}, {hi}] against [{min}, {max}]");
            }
            let w = [(2, 1.5)];
            let (lo, hi) = dense.affine_motion_hull(&w, 0.0).expect("a hull");
            let end = motion(&w, 0.0, 1.0);
            // Within the widening for round-off, `4 (1 + K) eps` times the coefficients.
            assert!(lo.abs() < 1e-13 && (hi - end).abs() < 1e-13 * end, "[{lo}, {hi}] against [0, {end}]");
        }
    }
}
