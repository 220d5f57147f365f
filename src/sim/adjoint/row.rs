//! Stage 5 (sim): the transpose of a Rosenbrock step (Rodas5P, Rodas4, `auto`'s stiff
//! segments), the other implementation of `backward::step_backward` (docs/design.md, "The
//! adjoint", for the derivation).
//!
//! The step is recomputed from its start by the stepper itself (`Rosenbrock::attempt` on the
//! states alone, as the recorded run took it: the same stages, the same factorisation of
//! `W = I - h gamma J`), then walked backward. Per stage `i`, from last to first, with
//! `kbar_i` the stage's cotangent:
//! - `lambda_i = W^{-T} kbar_i` (the same factors, transposed: `LinSolve::solve_transposed`);
//! - the flow at the stage, `f(t + c_i h, u_i)`: `ubar_i = f_x^T lambda_i`, `pbar += f_p^T
//!   lambda_i`; `u_i = y + h sum_j alpha_ij k_j` hands `ubar_i` to the start and `h alpha_ij
//!   ubar_i` to the earlier stages (for stage 0 the flow is read at the start itself);
//! - `h J g_i` with `g_i = sum_j Gamma_ij k_j`: `h Gamma_ij J^T lambda_i` to the earlier stages;
//! - `J` and `F_t`, functions of the start and the parameters, in `W k_i = ... + h J g_i + d_i h
//!   F_t`: the gradient of `lambda_i^T (J(x0, p) h (g_i + gamma k_i) + d_i h F_t(x0, p))` in
//!   `(x0, p)` (`HybridSystem::flow_vjp_dir`, the transpose of the forward coupling `sens_dir`).
//!
//! The sums are the forward pass's centred forms (`rosenbrock::combine2`): a weight row `w` with
//! total `T` is `T k_0 + sum_{j>0} w_j (k_j - k_0)`, transposed as such.

use super::backward::{add_vjp, Step, StepEnd};
use super::plain::WithoutSens;
use crate::sim::linalg::linsolve::LinearSolver;
use crate::sim::method::rosenbrock::Rosenbrock;
use crate::sim::method::row_tableau::{RowTableau, RODAS4, RODAS5P};
use crate::sim::method::stepper::{Stepper, TapePair};
use crate::sim::mode_rhs::rhs_for;
use crate::sim::system::HybridSystem;

/// The tableau of a Rosenbrock method; `None` for an explicit pair.
pub(super) fn tableau(pair: TapePair) -> Option<&'static RowTableau> {
    match pair {
        TapePair::Rodas5p => Some(&RODAS5P),
        TapePair::Rodas4 => Some(&RODAS4),
        TapePair::Dopri5 | TapePair::Dop853 => None,
    }
}

/// Scratch of the Rosenbrock steps' backward pass, kept between steps.
#[derive(Default)]
pub(super) struct RowScratch {
    /// The stepper that recomputes the steps, by method and size.
    ros: Option<(TapePair, usize, Rosenbrock)>,
    /// The factorisation the recorded run used (`SimOptions::linear_solver`).
    pub solver: LinearSolver,
    kbar: Vec<f64>,
    x0bar: Vec<f64>,
    lam: Vec<f64>,
    ubar: Vec<f64>,
    gbar: Vec<f64>,
    g: Vec<f64>,
    dir: Vec<f64>,
    gx: Vec<f64>,
    f0: Vec<f64>,
}

/// `lams` (rows of n): on entry the cotangents of the state the step hands on, on return those
/// of its start; `pbars` (rows of m) gain the parameters' share. The step is recomputed once for
/// every row.
pub(super) fn step_backward<S: HybridSystem + ?Sized>(
    sys: &S,
    p: &[f64],
    step: &Step<'_>,
    tab: &'static RowTableau,
    lams: &mut [f64],
    pbars: &mut [f64],
    w: &mut RowScratch,
) {
    let n = step.x0.len();
    let rows = lams.len() / n.max(1);
    if n == 0 || rows == 0 {
        return;
    }
    let m = pbars.len() / rows;
    let at = |t: f64| if t > step.ceiling { step.ceiling } else { t };
    let fresh = !matches!(&w.ros, Some((pair, size, _)) if *pair == step.pair && *size == n);
    if fresh {
        let ros = Rosenbrock::new(tab, n, n, n, 1.0, 1.0).with_linear_solver(w.solver);
        w.ros = Some((step.pair, n, ros));
    }
    let Some((pair, size, mut ros)) = w.ros.take() else { return };
    // The stage 0 slope is the flow at the start (what the forward step took from the step
    // before, or from the other method at a switch: the same function of the start).
    w.f0.resize(n, 0.0);
    sys.flow(step.mode, at(step.t0), step.x0, p, &mut w.f0);
    ros.restart_from(&w.f0);
    let plain = WithoutSens::new(sys);
    let mut rhs = rhs_for(&plain, p, n, step.mode).with_ceiling(step.ceiling);
    let err = ros.attempt(step.t0, step.x0, step.h, &mut rhs);
    if err.is_finite() {
        let last = ros.last_attempt();
        let parts = Parts { tab, k: last.k, stage_x: last.stage_x, end: last.end };
        for r in 0..rows {
            let (lam, pbar) = (&mut lams[r * n..(r + 1) * n], &mut pbars[r * m..(r + 1) * m]);
            row_backward(sys, p, step, &parts, last.lin, lam, pbar, w);
        }
    } else {
        // The recorded run accepted this step: it cannot fail here but by a bug.
        lams.fill(f64::NAN);
    }
    w.ros = Some((pair, size, ros));
}

/// The recomputed step's values the backward pass reads.
struct Parts<'a> {
    tab: &'static RowTableau,
    k: &'a [f64],
    stage_x: &'a [f64],
    end: &'a [f64],
}

/// `out += a (T k_0 + sum_{0<j<len} w_j (k_j - k_0))`'s transpose: the cotangent `bar` of such
/// a sum, scaled by `a`, into the stages' cotangents `kbar`.
fn centred_transposed(weights: &[f64], total: f64, a: f64, bar: &[f64], kbar: &mut [f64]) {
    let n = bar.len();
    let mut k0 = a * total;
    for (j, &wj) in weights.iter().enumerate().skip(1) {
        if wj != 0.0 {
            for (kb, b) in kbar[j * n..(j + 1) * n].iter_mut().zip(bar) {
                *kb += a * wj * b;
            }
            k0 -= a * wj;
        }
    }
    for (kb, b) in kbar[..n].iter_mut().zip(bar) {
        *kb += k0 * b;
    }
}

/// One row of [`step_backward`].
#[allow(clippy::too_many_arguments)]
fn row_backward<S: HybridSystem + ?Sized>(
    sys: &S,
    p: &[f64],
    step: &Step<'_>,
    parts: &Parts<'_>,
    lin: &mut crate::sim::linalg::linsolve::LinSolve,
    lam: &mut [f64],
    pbar: &mut [f64],
    w: &mut RowScratch,
) {
    let n = step.x0.len();
    let tab = parts.tab;
    let s = tab.stages;
    let (t0, h, mode) = (step.t0, step.h, step.mode);
    let at = |t: f64| if t > step.ceiling { step.ceiling } else { t };
    w.kbar.clear();
    w.kbar.resize(s * n, 0.0);
    for v in [&mut w.x0bar, &mut w.lam, &mut w.ubar, &mut w.gbar, &mut w.g, &mut w.dir, &mut w.gx] {
        v.clear();
        v.resize(n, 0.0);
    }
    // The cotangent of the step's end `y1` (in `w.ubar` for now).
    let ybar = &mut w.ubar;
    match step.end {
        StepEnd::End => ybar.copy_from_slice(lam),
        StepEnd::Landed(dt) => {
            // `z = y1 + dt f(t0 + h, y1)`.
            ybar.copy_from_slice(lam);
            let scaled: Vec<f64> = lam.iter().map(|l| dt * l).collect();
            add_vjp(sys, mode, at(t0 + h), parts.end, &scaled, p, &mut w.gx, ybar, pbar);
        }
        StepEnd::Dense(t) => {
            // `z = (1 - theta) y0 + theta y1 + theta (1 - theta) sum_r theta^r q_r`,
            // `q_r = h (sum_{j>0} H_rj (k_j - k_0))` (`RowDense`).
            let theta = if h != 0.0 { (t - t0) / h } else { 0.0 };
            for ((y, x0b), l) in ybar.iter_mut().zip(w.x0bar.iter_mut()).zip(lam.iter()) {
                *y = theta * l;
                *x0b += (1.0 - theta) * l;
            }
            let mut c = theta * (1.0 - theta);
            for row in tab.dense {
                centred_transposed(row, 0.0, h * c, lam, &mut w.kbar);
                c *= theta;
            }
        }
    }
    // `y1 = y0 + h (k_0 + sum_{j>0} b_j (k_j - k_0))`.
    for (x0b, y) in w.x0bar.iter_mut().zip(ybar.iter()) {
        *x0b += y;
    }
    let ybar = std::mem::take(&mut w.ubar);
    centred_transposed(tab.b, 1.0, h, &ybar, &mut w.kbar);
    w.ubar = ybar;
    for i in (0..s).rev() {
        let lam_i = &mut w.lam;
        lam_i.copy_from_slice(&w.kbar[i * n..(i + 1) * n]);
        if lam_i.iter().all(|&v| v == 0.0) {
            continue;
        }
        if !lin.solve_transposed(lam_i) {
            lam.fill(f64::NAN);
            return;
        }
        let lam_i = &w.lam;
        w.g.fill(0.0);
        if i == 0 {
            add_vjp(sys, mode, at(t0), step.x0, lam_i, p, &mut w.gx, &mut w.x0bar, pbar);
        } else {
            let ui = &parts.stage_x[(i - 1) * n..i * n];
            w.ubar.fill(0.0);
            add_vjp(sys, mode, at(t0 + tab.c[i] * h), ui, lam_i, p, &mut w.gx, &mut w.ubar, pbar);
            // `u_i = y0 + h (c_i k_0 + sum_{0<j<i} alpha_ij (k_j - k_0))`.
            for (x0b, u) in w.x0bar.iter_mut().zip(&w.ubar) {
                *x0b += u;
            }
            centred_transposed(tab.alpha[i], tab.c[i], h, &w.ubar, &mut w.kbar);
            // `h J g_i`, `g_i = (d_i - gamma) k_0 + sum_{0<j<i} Gamma_ij (k_j - k_0)`.
            w.gbar.fill(0.0);
            lin.mul_add_transposed(h, lam_i, &mut w.gbar);
            let total = tab.d[i] - tab.gamma;
            centred_transposed(tab.gam[i], total, 1.0, &w.gbar, &mut w.kbar);
            // `g_i` itself, for the coupling below.
            let k0 = &parts.k[..n];
            for (g, k0) in w.g.iter_mut().zip(k0) {
                *g = total * k0;
            }
            for (j, &gj) in tab.gam[i].iter().enumerate().skip(1) {
                if gj != 0.0 {
                    for (g, (kj, k0)) in w.g.iter_mut().zip(parts.k[j * n..(j + 1) * n].iter().zip(k0)) {
                        *g += gj * (kj - k0);
                    }
                }
            }
        }
        // `J` and `F_t` at the start: the gradient of `lambda_i^T (J v + a F_t)` with
        // `v = h (g_i + gamma k_i)`, `a = d_i h`.
        let ki = &parts.k[i * n..(i + 1) * n];
        for ((d, g), k) in w.dir.iter_mut().zip(&w.g).zip(ki) {
            *d = h * (g + tab.gamma * k);
        }
        sys.flow_vjp_dir(mode, at(t0), step.x0, &w.dir, tab.d[i] * h, lam_i, p, &mut w.x0bar, pbar);
    }
    lam.copy_from_slice(&w.x0bar);
}
