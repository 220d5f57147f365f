//! Stage 5 (sim): the Rosenbrock (ROW) methods Rodas5P and Rodas4 as a [`Stepper`], for stiff
//! flows. Linearly implicit: one LU factorisation of `W = I - h gamma f_x` per attempted step
//! (dense, or banded or sparse for large models with a known Jacobian pattern: `linalg/linsolve.rs`), no Newton
//! iteration; the stages (Hairer & Wanner's original form, not the transformed one: a clock is
//! then exact to an ulp per step) and coefficients are in `row_tableau.rs`.
//!
//! Sensitivities. The integrated vector is `z = [x, S]`, and the method is applied to the whole
//! system `z' = F(t, z) = [f, f_x S + f_p]`, whose Jacobian is block lower triangular:
//! `[[f_x, 0], [B, I (x) f_x]]` with `B v = d/dx (f_x s_j + f_p_j) v` per column `j`. So every
//! stage solves the state block with the LU of `W`, then every sensitivity column with the same
//! LU, its right-hand side increased by `h B (g_x + gamma k_x)` (`Rhs::sens_coupling`, the
//! compiled `f_xx[s_j, v] + f_xp_j v`; `g = sum_j Gamma_ij k_j`). Evaluated, like `f_x` and `F_t`, at the step's start
//! `(t0, x0, S0)`, this is exactly what differentiating the state's own stage equations with
//! respect to the parameters gives (`W k_i = h f(u_i) + h f_x g_i + ...` differentiated: `dW/dp k_i`
//! is `-h gamma B k_i`, `d(h f_x g_i)/dp` has `h B g_i`, `d(f_t)/dp` is `f_xt s + f_pt`): the sensitivities are the derivatives of the
//! computed discrete solution for the step sizes taken, to round-off, whatever the tolerance.
//! Their error with respect to the true sensitivities is the method's error on the augmented
//! system, controlled like the states' when `sens_error_control` is on.
//!
//! Error control: the embedded solution's difference is `sum_j e_j k_j`;
//! `err = sqrt(mean_i (e_i / sc_i)^2)` with `sc_i = atol + rtol max(|z0_i|, |z1_i|)` over the
//! controlled components, accepted when `<= 1`. Step sizes: `h 0.9 err^(-1/q)` with `q` the
//! embedded order plus one, bounded to `[0.2 h, 6 h]` as in Hairer's RODAS, no growth after a
//! rejection. The Jacobian is evaluated once per start point and kept across rejected attempts.
//!
//! Dense output: the method's own interpolation (order 4 for Rodas5P, 3 for Rodas4) for every
//! component, sensitivities included, built with the step (it costs a few vector sums).

use super::errnorm::{controlled, BlockNorm};
use super::poly::CAP;
use super::row_tableau::{RowTableau, RODAS4, RODAS5P};
use super::stepper::{Interpolant, Rhs, Stepper, TapePair};
use crate::sim::linalg::linsolve::{LinSolve, LinearSolver};

const SAFETY: f64 = 0.9;
const FAC_MIN: f64 = 0.2;
const FAC_MAX: f64 = 6.0;
/// Most dense-output rows of any method (Rodas5P's three).
const MAX_DENSE: usize = 3;
/// A Rosenbrock method with its controller and dense output (a [`Stepper`]).
pub struct Rosenbrock {
    tab: &'static RowTableau,
    nz: usize,
    n: usize,
    n_err: usize,
    rtol: f64,
    atol: f64,
    masked: bool,
    /// Stages (as slopes, see `stages`), `stages` blocks of `nz`.
    k: Vec<f64>,
    /// `F` at the start point and at the end of the last attempt.
    f0: Vec<f64>,
    f1: Vec<f64>,
    /// `f_x` (in `lin`: dense or the pattern's values) and `F_t` (nz) at the start point;
    /// `jac_fresh` while they belong to it.
    lin: Box<LinSolve>,
    solver: LinearSolver,
    /// States left out of the error norm (the quadrature states); empty: none.
    excluded: Vec<bool>,
    /// The last attempt's largest scaled error among them, and the state (`BlockNorm::outside`).
    outside: (f64, usize),
    ft: Vec<f64>,
    jac_fresh: bool,
    /// Scratch: a stage input, a stage right-hand side, `sum_j Gamma_ij k_j`, `[x0, v]`, and
    /// `B v`.
    u: Vec<f64>,
    g: Vec<f64>,
    r: Vec<f64>,
    xv: Vec<f64>,
    dir: Vec<f64>,
    h: f64,
    y_new: Vec<f64>,
    /// The error estimate's vector `y1 - y1^` of the last attempt.
    err: Vec<f64>,
    pub(crate) dense: RowDense,
    /// The dense output a landing step builds (`Stepper::land`), so that the last attempt's
    /// stays.
    landed: RowDense,
    /// The states of the last attempt's stages `1..` (`n` each, stage `i` at `(i - 1) n`):
    /// `Stepper::visit_stage_states`.
    stage_x: Vec<f64>,
    rhs_calls: usize,
    jac_calls: usize,
}

impl Rosenbrock {
    pub(crate) fn new(
        tab: &'static RowTableau,
        nz: usize,
        n_states: usize,
        n_err: usize,
        rtol: f64,
        atol: f64,
    ) -> Rosenbrock {
        let n = n_states;
        let m = (nz - n).checked_div(n).unwrap_or(0);
        Rosenbrock {
            tab,
            nz,
            n,
            n_err,
            rtol,
            atol,
            masked: false,
            k: vec![0.0; tab.stages * nz],
            f0: vec![0.0; nz],
            f1: vec![0.0; nz],
            lin: Box::new(LinSolve::new(n)),
            solver: LinearSolver::Auto,
            excluded: Vec::new(),
            outside: (0.0, 0),
            ft: vec![0.0; nz],
            jac_fresh: false,
            u: vec![0.0; nz],
            g: vec![0.0; nz],
            r: vec![0.0; nz],
            xv: vec![0.0; 2 * n],
            dir: vec![0.0; n * m],
            h: 0.0,
            y_new: vec![0.0; nz],
            err: vec![0.0; nz],
            dense: RowDense::new(nz),
            landed: RowDense::new(nz),
            stage_x: vec![0.0; tab.stages.saturating_sub(1) * n],
            rhs_calls: 0,
            jac_calls: 0,
        }
    }

    /// The factorisation to use (`SimOptions::linear_solver`).
    pub(crate) fn with_linear_solver(mut self, solver: LinearSolver) -> Rosenbrock {
        self.solver = solver;
        self
    }

    /// Leaves the states `excluded` marks out of the error norm (empty: none).
    pub(crate) fn with_excluded(mut self, excluded: Vec<bool>) -> Rosenbrock {
        self.excluded = excluded;
        self
    }

    /// `h ||f_x||_inf` for the last attempt: an upper bound of `h` times the spectral radius of
    /// the state Jacobian (`auto::Auto` switches back to an explicit method when it stays inside
    /// the explicit method's stability region).
    pub(crate) fn stiffness(&self) -> f64 {
        self.h.abs() * self.lin.row_abs_max()
    }

    /// Takes `f0` as the derivative at a new start point (another method's end derivative
    /// there: `auto::Auto` switching); the Jacobian is evaluated at the next attempt.
    pub(crate) fn restart_from(&mut self, f0: &[f64]) {
        self.f0.copy_from_slice(f0);
        self.jac_fresh = false;
    }

    /// Jacobian evaluations (one per start point that an attempt was made from).
    pub fn jac_calls(&self) -> usize {
        self.jac_calls
    }

    /// The exponent of the controller: the error estimate is `O(h^q)`.
    fn q(&self) -> f64 {
        (self.tab.embedded + 1) as f64
    }

    /// All stages of a step of size `h` from `(t, y)`; `false` when `W` is singular.
    ///
    /// The original form (`row_tableau`) divided by `h`, with stages `k_i` that are slopes
    /// (as an explicit method's): `W k_i = F(t + c_i h, y + h sum_j alpha_ij k_j) + h J g_i
    /// + d_i h F_t` with `g_i = sum_{j<i} Gamma_ij k_j`, `W = I - h gamma J`, and
    /// `y1 = y + h sum_j b_j k_j`. On a clock every `k_i` is exactly 1, so its step is `h` times
    /// the f64 sum of the weights, which is 1. On the augmented system
    /// (`J = [[f_x, 0], [B, I (x) f_x]]`) the state block is solved first, then every
    /// sensitivity column with `h f_x g_S + h B (g_x + gamma k_x)` added (the coupling rows of
    /// `h J g_i` and of `W`, one `sens_coupling` call).
    fn stages<R: Rhs>(&mut self, t: f64, y: &[f64], h: f64, rhs: &mut R) -> bool {
        let (n, nz, tab) = (self.n, self.nz, self.tab);
        if !self.lin.factor(h * tab.gamma) {
            return false;
        }
        self.xv[..n].copy_from_slice(&y[..n]);
        for i in 0..tab.stages {
            // Stage `i` is formed in its own slot of `k`: the earlier stages are read, never
            // copied.
            let (done, rest) = self.k.split_at_mut(i * nz);
            let ki = &mut rest[..nz];
            if i == 0 {
                ki.copy_from_slice(&self.f0);
            } else {
                // The stage input (its increment first, then the start point: a clock's stage
                // input is then `y + c_i h` to an ulp) and `g` in one pass over the stages.
                let (u, g) = (&mut self.u, &mut self.g);
                combine2(
                    [(tab.alpha[i], tab.c[i]), (tab.gam[i], tab.d[i] - tab.gamma)],
                    done,
                    nz,
                    [u, g],
                    |e, [u, _]| *u = y[e] + h * *u,
                );
                self.stage_x[(i - 1) * n..i * n].copy_from_slice(&self.u[..n]);
                rhs.eval(t + tab.c[i] * h, &self.u, ki);
                self.rhs_calls += 1;
                // `+= h f_x g` on the state block and on every sensitivity column.
                self.lin.mul_add(h, &self.g, ki);
            }
            if tab.d[i] != 0.0 {
                axpy(h * tab.d[i], &self.ft, ki);
            }
            // The state block, then every sensitivity column with the coupling added.
            let (rx, rs) = ki.split_at_mut(n);
            if !self.lin.solve(rx, 1) {
                return false;
            }
            if !rs.is_empty() {
                for ((v, g), k) in self.xv[n..].iter_mut().zip(&self.g[..n]).zip(rx.iter()) {
                    *v = if i > 0 { g + tab.gamma * k } else { tab.gamma * k };
                }
                rhs.sens_coupling(t, &self.xv, y, &mut self.dir);
                for (r, d) in rs.iter_mut().zip(&mut self.dir) {
                    finite_or_zero(d);
                    *r += h * *d;
                }
                let cols = rs.len() / n;
                if !self.lin.solve(rs, cols) {
                    return false;
                }
            }
        }
        // The solution and the error estimate `y1 - y1^ = sum_j e_j k_j` in one pass,
        // increments first.
        combine2(
            [(tab.b, 1.0), (tab.e, 0.0)],
            &self.k,
            nz,
            [&mut self.y_new, &mut self.err],
            |e, [y1, err]| {
                *y1 = y[e] + h * *y1;
                *err *= h;
            },
        );
        true
    }

    /// The scaled norm of the error estimate over the controlled components;
    /// `MASKED` leaves out sensitivities that are not finite (as `Rk::error`).
    fn error<const MASKED: bool>(&mut self, y: &[f64]) -> f64 {
        let e = &self.err;
        let mut norm = BlockNorm::new(self.n, &self.excluded);
        for i in 0..self.n_err {
            let (y0, y1, ei) = (y[i], self.y_new[i], e[i]);
            let skip = MASKED && i >= self.n && !(y0.is_finite() && y1.is_finite() && ei.is_finite());
            let r = ei / (self.atol + self.rtol * y0.abs().max(y1.abs()));
            norm.add(i, (!skip).then_some((r, 0.0)), false);
        }
        self.outside = norm.outside();
        norm.finish(false)
    }
}

/// `out_r = sum_j w_rj k_j` for two weight rows `(w_r, total_r)` over the stages `k` (blocks of
/// `nz`; `w_r` weighs the first `w_r.len()` of them), for weights that sum to `total_r` (exactly,
/// as `row_tableau`'s tests check), formed as `total k_0 + sum_{j>0} w_j (k_j - k_0)`: the slope
/// common to all stages is weighted once, so a component moving at a constant rate `K` (any `K`,
/// not only 1) gets exactly `total K`, as `sums::centred_sum` does for the explicit pairs' zero-sum
/// rows. Then `finish(component, [out_0, out_1])` per component. Both rows are summed block by
/// block in one pass over the stages, each difference `k_j - k_0` formed once (each component's
/// sums in the order of the stages, the zero weights skipped, so the result does not depend on
/// the blocking).
fn combine2(
    rows: [(&[f64], f64); 2],
    k: &[f64],
    nz: usize,
    out: [&mut [f64]; 2],
    mut finish: impl FnMut(usize, [&mut f64; 2]),
) {
    let [o0, o1] = out;
    let k0 = &k[..nz];
    let stages = rows[0].0.len().max(rows[1].0.len());
    for start in (0..nz).step_by(BLOCK) {
        let end = (start + BLOCK).min(nz);
        let (o0, o1, k0) = (&mut o0[start..end], &mut o1[start..end], &k0[start..end]);
        for ((a, b), &k) in o0.iter_mut().zip(o1.iter_mut()).zip(k0) {
            (*a, *b) = (rows[0].1 * k, rows[1].1 * k);
        }
        for j in 1..stages {
            let kj = &k[j * nz + start..j * nz + end];
            let weight = |r: usize| rows[r].0.get(j).copied().unwrap_or(0.0);
            // A zero weight adds nothing (not even `0 * NaN` from a sensitivity that does not
            // exist).
            let (a, b) = (weight(0), weight(1));
            if a != 0.0 && b != 0.0 {
                for (((o0, o1), kj), k0) in o0.iter_mut().zip(o1.iter_mut()).zip(kj).zip(k0) {
                    let d = kj - k0;
                    *o0 += a * d;
                    *o1 += b * d;
                }
            } else if a != 0.0 {
                add_weighted(a, kj, k0, o0);
            } else if b != 0.0 {
                add_weighted(b, kj, k0, o1);
            }
        }
        for (e, (a, b)) in o0.iter_mut().zip(o1.iter_mut()).enumerate() {
            finish(start + e, [a, b]);
        }
    }
}

/// Components per block of [`combine2`]: its outputs and the stages' blocks stay in the L1 cache
/// while every stage is added.
const BLOCK: usize = 256;

/// `o += a (kj - k0)`.
fn add_weighted(a: f64, kj: &[f64], k0: &[f64], o: &mut [f64]) {
    for ((o, kj), k0) in o.iter_mut().zip(kj).zip(k0) {
        *o += a * (kj - k0);
    }
}

/// `y += a x`.
fn axpy(a: f64, x: &[f64], y: &mut [f64]) {
    for (y, x) in y.iter_mut().zip(x) {
        *y += a * x;
    }
}

/// A second-order term of the sensitivities' stages (the coupling `f_xx[s, v] + f_xp v`, the
/// sensitivities' `F_t`) that is not finite is left out: 0. Such a term is the method's, not the
/// derivative's: `der(y) = x^p` from x = 0 at p = 1 has `f_xp = 1 + ln x`, -inf there, while
/// the sensitivities' own flow `f_x s + f_p` and dy/dp = -1/(p+1)^2 are finite. Without it that
/// stage is a W-method's (an inexact Jacobian), which the step's error estimate judges. A
/// derivative that does not exist shows in the sensitivities' flow itself, which this leaves
/// alone.
fn finite_or_zero(v: &mut f64) {
    if !v.is_finite() {
        *v = 0.0;
    }
}

fn all_finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

impl Stepper for Rosenbrock {
    type Interpolant = RowDense;

    fn reset(&mut self) {
        self.h = 0.0;
        self.rhs_calls = 0;
        self.jac_calls = 0;
        self.jac_fresh = false;
    }

    fn restart<R: Rhs>(&mut self, t: f64, z: &[f64], rhs: &mut R) {
        rhs.eval(t, z, &mut self.f0);
        self.rhs_calls += 1;
        self.jac_fresh = false;
    }

    fn start_derivative(&self) -> &[f64] {
        &self.f0
    }

    /// Hairer's estimate (as `Rk::initial_step`): `h0 = 0.01 |z0| / |f0|` in the scaled norm,
    /// one explicit Euler step for the second derivative, `h1 = (0.01 / max(d1, d2))^(1/q)`.
    fn initial_step<R: Rhs>(&mut self, t: f64, z: &[f64], h_max: f64, rhs: &mut R) -> f64 {
        let ne = self.n_err;
        let inv = |y: f64| 1.0 / (self.atol + self.rtol * y.abs());
        // Over the components in the step-size control (a running cost is not).
        let counted = (0..ne).filter(|&i| controlled(&self.excluded, self.n, i)).count().max(1) as f64;
        let rms = |v: &dyn Fn(usize) -> f64| {
            ((0..ne)
                .filter(|&i| controlled(&self.excluded, self.n, i))
                .map(|i| (v(i) * inv(z[i])).powi(2))
                .sum::<f64>()
                / counted)
                .sqrt()
        };
        let d0 = rms(&|i| z[i]);
        let d1 = rms(&|i| self.f0[i]);
        let mut h0 =
            if !(d0.is_finite() && d1.is_finite()) || d0 < 1.0 || d1 < 1e-5 { 1e-6 } else { 0.01 * d0 / d1 };
        h0 = h0.min(h_max);
        for ((u, &y), &f) in self.u.iter_mut().zip(z).zip(&self.f0) {
            *u = y + h0 * f;
        }
        rhs.eval(t + h0, &self.u, &mut self.r);
        self.rhs_calls += 1;
        let d2 = rms(&|i| self.r[i] - self.f0[i]) / h0;
        let dmax = d1.max(d2);
        let h1 = if dmax <= 1e-15 || !dmax.is_finite() {
            (h0 * 1e-3).max(1e-6)
        } else {
            (0.01 / dmax).powf(1.0 / self.q())
        };
        (100.0 * h0).min(h1).min(h_max)
    }

    fn attempt<R: Rhs>(&mut self, t: f64, z: &[f64], h: f64, rhs: &mut R) -> f64 {
        self.h = h;
        if !self.jac_fresh {
            let n = self.n;
            if self.lin.select(self.solver, rhs.jac_pattern()) {
                rhs.jacobian_values(t, z, &mut self.lin.fx, &mut self.ft);
            } else {
                rhs.jacobian(t, z, &mut self.lin.fx, &mut self.ft);
            }
            self.jac_calls += 1;
            self.jac_fresh = true;
            // The state block's Jacobian must be finite for `W`'s LU.
            if !all_finite(&self.lin.fx) || !all_finite(&self.ft[..n]) {
                self.masked = false;
                return f64::INFINITY;
            }
            // The sensitivities' part of `F_t` (`f_xt s + f_pt`) is the method's own second-order
            // term, as the coupling is (`stages`): where it is not finite at a point where the
            // flow is, it is left out (see `finite_or_zero`).
            self.ft[n..].iter_mut().for_each(finite_or_zero);
        }
        self.masked = false;
        if !self.stages(t, z, h, rhs) || !all_finite(&self.y_new[..self.n]) {
            return f64::INFINITY;
        }
        rhs.eval(t + h, &self.y_new, &mut self.f1);
        self.rhs_calls += 1;
        let mut err = self.error::<false>(z);
        if !(err.is_finite() && all_finite(&self.y_new)) {
            // A sensitivity that is not finite at a finite state is a derivative that does not
            // exist (NaN from here on, see `sim::jump`): the step is judged without it.
            self.masked = true;
            err = self.error::<true>(z);
            if !err.is_finite() {
                return f64::INFINITY;
            }
        }
        self.dense.build(self.tab, t, h, z, &self.y_new, &self.k);
        err
    }

    fn end_state(&self) -> &[f64] {
        &self.y_new
    }

    fn end_derivative(&self) -> &[f64] {
        &self.f1
    }

    fn grow(&mut self, err: f64) -> f64 {
        let fac = SAFETY * err.max(1e-10).powf(-1.0 / self.q());
        self.h * fac.clamp(FAC_MIN, FAC_MAX)
    }

    fn shrink(&self, err: f64) -> f64 {
        let fac = if err.is_finite() { SAFETY * err.powf(-1.0 / self.q()) } else { FAC_MIN };
        self.h * fac.clamp(FAC_MIN, 1.0)
    }

    /// An attempt builds its dense output with it: the landing step's goes to `landed`. The
    /// Jacobian at the start is still fresh (nothing was accepted), so this costs the stages and
    /// one factorisation.
    fn land<R: Rhs>(&mut self, t: f64, z: &[f64], h: f64, rhs: &mut R) -> f64 {
        std::mem::swap(&mut self.dense, &mut self.landed);
        let err = self.attempt(t, z, h, rhs);
        std::mem::swap(&mut self.dense, &mut self.landed);
        err
    }

    /// By default: the dense output is of order 3 (Rodas4) or 4 (Rodas5P).
    fn lands_on_events(&mut self, _z: &[f64]) -> bool {
        true
    }

    /// The dense output was built with the attempt.
    fn build_interpolant<R: Rhs>(&mut self, _t0: f64, _z: &[f64], _rhs: &mut R) {}

    fn interpolant(&self) -> &RowDense {
        &self.dense
    }

    fn accept(&mut self, z: &mut [f64]) {
        z.copy_from_slice(&self.y_new);
        self.f0.copy_from_slice(&self.f1);
        self.jac_fresh = false;
    }

    fn rhs_calls(&self) -> usize {
        self.rhs_calls
    }

    fn masked(&self) -> bool {
        self.masked
    }

    fn outside_error(&self) -> (f64, usize) {
        self.outside
    }

    fn visit_stage_states<V: FnMut(f64, &[f64])>(&self, mut visit: V) {
        let n = self.n;
        for (i, x) in self.stage_x.chunks_exact(n.max(1)).enumerate() {
            visit(self.tab.c[i + 1], x);
        }
    }

    fn tape_pair(&self) -> Option<TapePair> {
        if std::ptr::eq(self.tab, &RODAS5P) {
            Some(TapePair::Rodas5p)
        } else if std::ptr::eq(self.tab, &RODAS4) {
            Some(TapePair::Rodas4)
        } else {
            None
        }
    }
}

/// What the adjoint's backward pass reads of a Rosenbrock stepper's last attempt
/// ([`Rosenbrock::last_attempt`], `sim/adjoint/row.rs`).
pub(crate) struct LastAttempt<'a> {
    /// The stages as slopes, `stages` blocks of `nz`.
    pub k: &'a [f64],
    /// The states of the stages `1..` (`n` each, stage `i` at `(i - 1) n`).
    pub stage_x: &'a [f64],
    /// The end state.
    pub end: &'a [f64],
    /// The factorisation of its `W` (whose `fx` holds the step's `J`).
    pub lin: &'a mut LinSolve,
}

impl Rosenbrock {
    /// The last attempt's stages, stage states, end state and factorisation.
    pub(crate) fn last_attempt(&mut self) -> LastAttempt<'_> {
        LastAttempt { k: &self.k, stage_x: &self.stage_x, end: &self.y_new, lin: &mut self.lin }
    }
}

/// The dense output of one Rosenbrock step (an [`Interpolant`]): with `theta = (t - t0) / h`,
/// `z(theta) = (1 - theta) z0 + theta (z1 + (1 - theta) Q(theta))`,
/// `Q = q_0 + theta (q_1 + theta q_2)`, `q_r = h sum_j H_rj k_j` (`row_tableau`; `k_j` the
/// stages as slopes), evaluated as
/// `z0 + theta ((z1 - z0) + (1 - theta) Q)`: a component that does not move stays exactly
/// where it is (a counter read at an event time), as with the explicit pairs' form.
pub struct RowDense {
    t0: f64,
    h: f64,
    n_q: usize,
    /// Component-major: `[z0, z1 - z0, q_0 .. q_{n_q - 1}]` per component, stride `2 + MAX_DENSE`.
    coef: Vec<f64>,
}

const STRIDE: usize = 2 + MAX_DENSE;
/// Components whose dense rows [`RowDense::build`] sums together in registers.
const DENSE_REGS: usize = 4;

impl RowDense {
    pub(crate) fn new(nz: usize) -> RowDense {
        // Until the first build the interpolant is the zero constant.
        RowDense { t0: 0.0, h: 0.0, n_q: 0, coef: vec![0.0; STRIDE * nz] }
    }

    fn build(&mut self, tab: &RowTableau, t0: f64, h: f64, z0: &[f64], z1: &[f64], k: &[f64]) {
        let nz = z0.len();
        self.t0 = t0;
        self.h = h;
        self.n_q = tab.dense.len();
        let mut i0 = 0;
        while i0 + DENSE_REGS <= nz {
            self.build_block::<DENSE_REGS>(tab, h, z0, z1, k, i0);
            i0 += DENSE_REGS;
        }
        for i in i0..nz {
            self.build_block::<1>(tab, h, z0, z1, k, i);
        }
    }

    /// Components `i0..i0 + W` of [`Self::build`]: every dense row's sum held in registers while
    /// each stage's block is read once, the stage's difference formed once for all rows.
    #[inline(always)]
    fn build_block<const W: usize>(
        &mut self,
        tab: &RowTableau,
        h: f64,
        z0: &[f64],
        z1: &[f64],
        k: &[f64],
        i0: usize,
    ) {
        let nz = z0.len();
        let k0: [f64; W] = k[i0..i0 + W].try_into().expect("a block of W");
        // Centred (each row sums to zero): a constant slope leaves exactly nothing. The sums
        // start from -0.0 as `Iterator::sum` does.
        let mut acc = [[-0.0f64; W]; MAX_DENSE];
        for j in 1..tab.stages {
            let kj: [f64; W] = k[j * nz + i0..j * nz + i0 + W].try_into().expect("a block of W");
            let d: [f64; W] = std::array::from_fn(|l| kj[l] - k0[l]);
            for (acc, row) in acc.iter_mut().zip(tab.dense) {
                let w = row[j];
                for (a, d) in acc.iter_mut().zip(&d) {
                    *a += w * d;
                }
            }
        }
        let coef = &mut self.coef[i0 * STRIDE..(i0 + W) * STRIDE];
        for (l, c) in coef.chunks_exact_mut(STRIDE).enumerate() {
            let i = i0 + l;
            c[0] = z0[i];
            c[1] = z1[i] - z0[i];
            for (r, acc) in acc.iter().enumerate().take(tab.dense.len()) {
                c[2 + r] = h * acc[l];
            }
        }
    }

    fn theta(&self, t: f64) -> f64 {
        if self.h != 0.0 {
            (t - self.t0) / self.h
        } else {
            0.0
        }
    }

    /// `Q(theta)` and `Q'(theta)` of one component's coefficients.
    fn q(&self, c: &[f64], th: f64) -> (f64, f64) {
        let (mut q, mut dq) = (0.0, 0.0);
        for r in (0..self.n_q).rev() {
            dq = q + th * dq;
            q = c[2 + r] + th * q;
        }
        (q, dq)
    }
}

impl Interpolant for RowDense {
    fn t0(&self) -> f64 {
        self.t0
    }
    fn h(&self) -> f64 {
        self.h
    }
    fn eval(&self, t: f64, out: &mut [f64]) {
        let th = self.theta(t);
        for (o, c) in out.iter_mut().zip(self.coef.chunks_exact(STRIDE)) {
            let (q, _) = self.q(c, th);
            *o = c[0] + th * (c[1] + (1.0 - th) * q);
        }
    }
    fn eval_deriv(&self, t: f64, out: &mut [f64]) {
        if self.h == 0.0 {
            out.fill(0.0);
            return;
        }
        let th = self.theta(t);
        for (o, c) in out.iter_mut().zip(self.coef.chunks_exact(STRIDE)) {
            let (q, dq) = self.q(c, th);
            *o = (c[1] + (1.0 - 2.0 * th) * q + th * (1.0 - th) * dq) / self.h;
        }
    }
    /// `theta (1 - theta) Q(theta)` with `Q` of degree `n_q - 1`: `n_q + 1` (the guard polynomial
    /// of `Interpolant::linear_form` is then sampled at that many points plus one).
    fn degree(&self) -> usize {
        self.n_q + 1
    }
    /// Exactly from the coefficients (no sampling, whose round-off put a clock's crossing ulps
    /// off): with `delta = sum_i w_i (z1_i - z0_i)` and `rho_r = sum_i w_i q_r,i`,
    /// `P(s) - P(0) = s (delta + (1 - s) sum_r rho_r s^r)`, whose coefficient of `s^(k+1)` is
    /// `rho_k - rho_(k-1)` (plus `delta` for `k = 0`).
    fn linear_form(&self, w: &[f64], coef: &mut [f64; CAP]) -> usize {
        let nq = self.n_q;
        let (mut delta, mut rho) = (0.0, [0.0; MAX_DENSE + 1]);
        for (c, &wi) in self.coef.chunks_exact(STRIDE).zip(w) {
            if wi != 0.0 {
                delta += wi * c[1];
                for (acc, q) in rho[..nq].iter_mut().zip(&c[2..2 + nq]) {
                    *acc += wi * q;
                }
            }
        }
        self.expand(delta, &rho, coef)
    }
    fn component_form(&self, i: usize, coef: &mut [f64; CAP]) -> usize {
        let c = &self.coef[i * STRIDE..(i + 1) * STRIDE];
        let mut rho = [0.0; MAX_DENSE + 1];
        rho[..self.n_q].copy_from_slice(&c[2..2 + self.n_q]);
        self.expand(c[1], &rho, coef)
    }
}

impl RowDense {
    /// The power-basis coefficients of `s (delta + (1 - s) sum_r rho_r s^r)`.
    fn expand(&self, delta: f64, rho: &[f64; MAX_DENSE + 1], coef: &mut [f64; CAP]) -> usize {
        let nq = self.n_q;
        coef.fill(0.0);
        for k in 0..=nq {
            coef[k + 1] = rho[k] - if k > 0 { rho[k - 1] } else { 0.0 };
        }
        coef[1] += delta;
        nq + 2
    }
}

#[cfg(test)]
mod tests {
    use super::super::row_tableau::{RODAS4, RODAS5P};
    use super::*;

    /// `y' = lambda y + cos t` with `y(0) = 1`, `lambda = -2`, in closed form; the exact Jacobian
    /// and time derivative (no sensitivities).
    struct Linear;
    const LAMBDA: f64 = -2.0;
    fn linear_exact(t: f64) -> f64 {
        // y = C e^(lambda t) + (-lambda cos t + sin t) / (1 + lambda^2)
        let p = |t: f64| (-LAMBDA * t.cos() + t.sin()) / (1.0 + LAMBDA * LAMBDA);
        (1.0 - p(0.0)) * (LAMBDA * t).exp() + p(t)
    }
    impl Rhs for Linear {
        fn eval(&mut self, t: f64, z: &[f64], dz: &mut [f64]) {
            dz[0] = LAMBDA * z[0] + t.cos();
        }
        fn jacobian(&mut self, t: f64, _z: &[f64], fx: &mut [f64], ft: &mut [f64]) {
            fx[0] = LAMBDA;
            ft[0] = -t.sin();
        }
    }

    /// `y' = -y^2 + t` (nonlinear, non-autonomous), reference by many small steps of Rodas5P.
    struct Nonlinear;
    impl Rhs for Nonlinear {
        fn eval(&mut self, t: f64, z: &[f64], dz: &mut [f64]) {
            dz[0] = -z[0] * z[0] + t;
        }
        fn jacobian(&mut self, _t: f64, z: &[f64], fx: &mut [f64], ft: &mut [f64]) {
            fx[0] = -2.0 * z[0];
            ft[0] = 1.0;
        }
    }

    /// Integrates from 0 to 1 with `steps` fixed steps; the end value.
    fn fixed_steps<R: Rhs>(tab: &'static RowTableau, rhs: &mut R, y0: f64, steps: usize) -> f64 {
        let mut ros = Rosenbrock::new(tab, 1, 1, 1, 1e-6, 1e-6);
        let h = 1.0 / steps as f64;
        let mut z = [y0];
        ros.reset();
        ros.restart(0.0, &z, rhs);
        for i in 0..steps {
            let err = ros.attempt(i as f64 * h, &z, h, rhs);
            assert!(err.is_finite());
            ros.accept(&mut z);
        }
        z[0]
    }

    /// The observed order `log2(e(h) / e(h/2))` at two step sizes.
    fn observed_order(
        _tab: &'static RowTableau,
        exact: f64,
        run: impl Fn(usize) -> f64,
        steps: usize,
    ) -> f64 {
        let e1 = (run(steps) - exact).abs();
        let e2 = (run(2 * steps) - exact).abs();
        (e1 / e2).log2()
    }

    #[test]
    fn linear_problem_converges_at_the_methods_order() {
        for (tab, steps) in [(&RODAS5P, 8), (&RODAS4, 8)] {
            let exact = linear_exact(1.0);
            let q = observed_order(tab, exact, |s| fixed_steps(tab, &mut Linear, 1.0, s), steps);
            // Global order p: halving h divides the error by 2^p (within 0.3 at these sizes).
            assert!((q - tab.order as f64).abs() < 0.3, "{}: observed order {q}", tab.name);
        }
    }

    #[test]
    fn nonlinear_problem_converges_at_the_methods_order() {
        let exact = fixed_steps(&RODAS5P, &mut Nonlinear, 0.5, 4096);
        for (tab, steps) in [(&RODAS5P, 8), (&RODAS4, 8)] {
            let q = observed_order(tab, exact, |s| fixed_steps(tab, &mut Nonlinear, 0.5, s), steps);
            assert!((q - tab.order as f64).abs() < 0.3, "{}: observed order {q}", tab.name);
        }
    }

    /// The embedded solution (the last stage's input) has its own order: the error estimate
    /// `|k_s|` of one step shrinks as `h^(embedded + 1)`.
    #[test]
    fn error_estimate_has_the_embedded_order() {
        for tab in [&RODAS5P, &RODAS4] {
            let est = |h: f64| {
                let mut ros = Rosenbrock::new(tab, 1, 1, 1, 0.0, 1.0);
                let z = [0.5];
                ros.restart(0.0, &z, &mut Nonlinear);
                ros.attempt(0.0, &z, h, &mut Nonlinear)
            };
            let q = (est(0.1) / est(0.05)).log2();
            assert!((q - (tab.embedded + 1) as f64).abs() < 0.35, "{}: {q}", tab.name);
        }
    }

    /// The dense output inside one step: error `O(h^(d + 1))` for dense order `d` (4 for
    /// Rodas5P, 3 for Rodas4), so halving the step divides it by about `2^(d + 1)`.
    #[test]
    fn dense_output_has_its_order() {
        for (tab, d) in [(&RODAS5P, 4), (&RODAS4, 3)] {
            let worst = |h: f64| {
                let mut ros = Rosenbrock::new(tab, 1, 1, 1, 1e-6, 1e-6);
                let z = [1.0];
                ros.restart(0.0, &z, &mut Linear);
                ros.attempt(0.0, &z, h, &mut Linear);
                let mut e = 0.0f64;
                for i in 1..10 {
                    let t = h * i as f64 / 10.0;
                    let mut v = [0.0];
                    ros.interpolant().eval(t, &mut v);
                    e = e.max((v[0] - linear_exact(t)).abs());
                }
                e
            };
            let q = (worst(0.2) / worst(0.1)).log2();
            assert!(q > d as f64 + 0.6, "{}: interpolation error ratio 2^{q}", tab.name);
        }
    }

    /// A clock is exact to the ulp: `y' = 1` one step of `h` from `y0` lands within half an ulp
    /// of `y0 + h` (every stage slope is exactly 1 and the weights sum to exactly 1 in f64), with
    /// an error estimate of zero; `y' = t` lands within the round-off of its terms: two ulps of
    /// the result plus an ulp of each weighted slope `h |b_j| (t + (c_j + |d_j|) h)`. With the transformed form a clock was off by up to 109 ulps.
    #[test]
    fn a_clock_is_exact_to_the_ulp() {
        struct Clock(bool);
        impl Rhs for Clock {
            fn eval(&mut self, t: f64, _z: &[f64], dz: &mut [f64]) {
                dz[0] = if self.0 { t } else { 1.0 };
            }
            fn jacobian(&mut self, _t: f64, _z: &[f64], fx: &mut [f64], ft: &mut [f64]) {
                fx[0] = 0.0;
                ft[0] = if self.0 { 1.0 } else { 0.0 };
            }
        }
        for tab in [&RODAS5P, &RODAS4] {
            let mut ros = Rosenbrock::new(tab, 1, 1, 1, 1e-6, 1e-6);
            for i in 0..2000 {
                // Times and steps spread over [0, 10) and [1e-3, 1), irrational ratios.
                let t = (i as f64 * 0.618_033_988_749_894_8).fract() * 10.0;
                let h = 1e-3 + (i as f64 * 0.414_213_562_373_095).fract();
                let z = [t];
                ros.restart(t, &z, &mut Clock(false));
                assert_eq!(ros.attempt(t, &z, h, &mut Clock(false)), 0.0, "{}: a clock's error", tab.name);
                assert_eq!(ros.end_state()[0], t + h, "{}: {t} + {h}", tab.name);
                let z = [t * t / 2.0];
                ros.restart(t, &z, &mut Clock(true));
                ros.attempt(t, &z, h, &mut Clock(true));
                let y1 = ros.end_state()[0];
                let want = z[0] + t * h + h * h / 2.0;
                // The slopes `t + c_j h + d_j h` and their weighted sum round at their sizes;
                // the result and `want` at theirs.
                let terms: f64 =
                    (0..tab.stages).map(|j| tab.b[j].abs() * (t + (tab.c[j] + tab.d[j].abs()) * h)).sum();
                let bound = f64::EPSILON * (2.0 * want + h * terms);
                assert!((y1 - want).abs() <= bound, "{}: {y1} vs {want}", tab.name);
            }
        }
    }

    /// The exact `linear_form` is the polynomial the dense output evaluates: it agrees with
    /// values of `eval` at a few points to round-off (1e-15 of the step's motion).
    #[test]
    fn the_linear_form_is_the_dense_output() {
        for tab in [&RODAS5P, &RODAS4] {
            let mut ros = Rosenbrock::new(tab, 2, 1, 2, 1e-6, 1e-6);
            let mut rhs = WithSens { p: 1.3 };
            let z = [1.0, 0.0];
            ros.restart(0.0, &z, &mut rhs);
            ros.attempt(0.0, &z, 0.3, &mut rhs);
            let dense = ros.interpolant();
            let w = [2.0, -0.5];
            let mut coef = [0.0; CAP];
            let len = dense.linear_form(&w, &mut coef);
            assert_eq!(len, dense.degree() + 1);
            let at = |t: f64| {
                let mut v = [0.0; 2];
                dense.eval(t, &mut v);
                w[0] * v[0] + w[1] * v[1]
            };
            for s in [0.1, 0.5, 0.9, 1.0] {
                let poly: f64 = coef[..len].iter().rev().fold(0.0, |acc, c| acc * s + c);
                let want = at(0.3 * s) - at(0.0);
                assert!(
                    (poly - want).abs() <= 1e-15 * (at(0.3) - at(0.0)).abs(),
                    "{}: {poly} vs {want}",
                    tab.name
                );
            }
        }
    }

    /// L-stability in practice: a very stiff linear decay `y' = -1e8 (y - cos t)` with a step of
    /// 0.1 follows the slow manifold `y ~ cos t` instead of blowing up.
    #[test]
    fn stiff_decay_follows_the_slow_manifold() {
        struct Stiff;
        impl Rhs for Stiff {
            fn eval(&mut self, t: f64, z: &[f64], dz: &mut [f64]) {
                dz[0] = -1e8 * (z[0] - t.cos());
            }
            fn jacobian(&mut self, t: f64, _z: &[f64], fx: &mut [f64], ft: &mut [f64]) {
                fx[0] = -1e8;
                ft[0] = -1e8 * t.sin();
            }
        }
        for tab in [&RODAS5P, &RODAS4] {
            let y = fixed_steps(tab, &mut Stiff, 0.0, 10);
            assert!((y - 1f64.cos()).abs() < 1e-7, "{}: {y}", tab.name);
        }
    }

    /// `y' = -p y^2 + sin t` with its sensitivity `s = dy/dp`, `s' = -2 p y s - y^2`, as the
    /// integrator builds it (`z = [y, s]`), with the exact Jacobian, time derivative and coupling
    /// `B v = (-2 p s - 2 y) v`.
    struct WithSens {
        p: f64,
    }
    impl Rhs for WithSens {
        fn eval(&mut self, t: f64, z: &[f64], dz: &mut [f64]) {
            dz[0] = -self.p * z[0] * z[0] + t.sin();
            if z.len() > 1 {
                dz[1] = -2.0 * self.p * z[0] * z[1] - z[0] * z[0];
            }
        }
        fn jacobian(&mut self, t: f64, z: &[f64], fx: &mut [f64], ft: &mut [f64]) {
            fx[0] = -2.0 * self.p * z[0];
            ft[0] = t.cos();
            if ft.len() > 1 {
                ft[1] = 0.0;
            }
        }
        fn sens_coupling(&mut self, _t: f64, xv: &[f64], z: &[f64], out: &mut [f64]) {
            out[0] = (-2.0 * self.p * z[1] - 2.0 * z[0]) * xv[1];
        }
    }

    /// `steps` fixed steps of `h` from `z0`; the end state.
    fn fixed<const N: usize>(
        tab: &'static RowTableau,
        p: f64,
        z0: [f64; N],
        h: f64,
        steps: usize,
    ) -> [f64; N] {
        let mut ros = Rosenbrock::new(tab, N, 1, N, 1e-6, 1e-6);
        let mut rhs = WithSens { p };
        let mut z = z0;
        ros.restart(0.0, &z, &mut rhs);
        for i in 0..steps {
            assert!(ros.attempt(i as f64 * h, &z, h, &mut rhs).is_finite());
            ros.accept(&mut z);
        }
        z
    }

    /// The sensitivity the stepper integrates is the derivative of the discrete solution itself:
    /// with 8 fixed steps of 0.25 it matches central differences of the computed state (same
    /// steps) to 1e-9, while it differs from the true derivative (the same sensitivity with
    /// 4096 steps) by the method's error, over 100 times more.
    #[test]
    fn sensitivities_are_the_derivative_of_the_discrete_solution() {
        for tab in [&RODAS5P, &RODAS4] {
            let p = 1.3;
            let [_, s] = fixed(tab, p, [1.0, 0.0], 0.25, 8);
            let d = 1e-5;
            let [yp] = fixed(tab, p + d, [1.0], 0.25, 8);
            let [ym] = fixed(tab, p - d, [1.0], 0.25, 8);
            let discrete = (yp - ym) / (2.0 * d);
            let [_, exact] = fixed(tab, p, [1.0, 0.0], 2.0 / 4096.0, 4096);
            let (to_discrete, to_exact) = ((s - discrete).abs(), (s - exact).abs());
            assert!(to_discrete <= 1e-9 * s.abs(), "{}: {s} vs discrete {discrete}", tab.name);
            assert!(to_exact > 100.0 * to_discrete, "{}: {to_exact:e} vs {to_discrete:e}", tab.name);
        }
    }
}
