//! Stage 5 (sim): the transposes of the pieces a run is made of, each the exact transpose of the
//! linear map the forward sensitivities apply there (docs/design.md, "The adjoint"):
//! - a step of a Rosenbrock method: `row.rs`;
//! - a step of an explicit pair: its stages recomputed from the step's start (states only, the
//!   same stage sums as the forward run, so the same numbers), then walked backward, each stage's
//!   cotangent taken through the flow's vector-Jacobian products `f_x^T w`, `f_p^T w`;
//! - the state at an instant: the step's end, a landed step's end moved by `dt F`, or its dense
//!   output at `theta` (Hairer's nested form as a weighted sum of the ends, their derivatives and
//!   the stages, transposed);
//! - an event's saltation `S+ = R_x S- + R_p + v dt/dp`, `dt/dp = -(g_x S- + g_p) / d`.

use super::row::{self, RowScratch};
use crate::sim::method::stepper::TapePair;
use crate::sim::method::sums::stage_sum;
use crate::sim::method::tableau::{Tableau, DOP853, DOPRI5};
use crate::sim::system::HybridSystem;

/// The tableau of an explicit pair (a Rosenbrock method's steps go to `row.rs`).
fn tableau(pair: TapePair) -> &'static Tableau {
    match pair {
        TapePair::Dopri5 => &DOPRI5,
        TapePair::Dop853 => &DOP853,
        TapePair::Rodas5p | TapePair::Rodas4 => unreachable!("a Rosenbrock step is transposed in row.rs"),
    }
}

/// How the state a step hands on was made from it.
#[derive(Clone, Copy, Debug)]
pub(super) enum StepEnd {
    /// Its end.
    End,
    /// Its end moved by `dt` along its end derivative (a landed instant).
    Landed(f64),
    /// Its dense output at this time.
    Dense(f64),
}

/// A step as the backward pass recomputes it.
#[derive(Clone, Copy, Debug)]
pub(super) struct Step<'a> {
    pub pair: TapePair,
    pub t0: f64,
    pub h: f64,
    pub ceiling: f64,
    pub mode: usize,
    pub x0: &'a [f64],
    pub end: StepEnd,
}

/// Scratch of the backward pass, kept between pieces.
#[derive(Default)]
pub(super) struct Scratch {
    k: Vec<f64>,
    xs: Vec<f64>,
    kbar: Vec<f64>,
    xbar: Vec<f64>,
    gx: Vec<f64>,
    /// The Rosenbrock steps' own.
    pub row: RowScratch,
}

/// The flow's vector-Jacobian products at a stage, added into `xbar` (n) and `pbar` (m)
/// (`HybridSystem::flow_vjp_add`: a control's knots cost only the two read there).
#[allow(clippy::too_many_arguments)]
pub(super) fn add_vjp<S: HybridSystem + ?Sized>(
    sys: &S,
    mode: usize,
    t: f64,
    x: &[f64],
    w: &[f64],
    p: &[f64],
    gx: &mut [f64],
    xbar: &mut [f64],
    pbar: &mut [f64],
) {
    if w.iter().all(|&v| v == 0.0) {
        return;
    }
    sys.flow_vjp_add(mode, t, x, w, p, gx, pbar);
    for (a, b) in xbar.iter_mut().zip(gx.iter()) {
        *a += b;
    }
}

/// The weights of the nested dense form `r0 + s (r1 + (1-s) (r2 + s (r3 + ...)))` on each
/// coefficient vector: `w_0 = 1`, `w_1 = s`, then alternately times `1 - s` and `s`.
fn nested_weights(s: f64, count: usize) -> [f64; 8] {
    let mut w = [0.0; 8];
    w[0] = 1.0;
    if count > 1 {
        w[1] = s;
    }
    for k in 2..count {
        w[k] = w[k - 1] * if k % 2 == 0 { 1.0 - s } else { s };
    }
    w
}

/// `lams` (rows of n): on entry the cotangents of the state the step hands on, on return those
/// of its start; `pbars` (rows of m) gain the parameters' share. The stages are recomputed once
/// for every row. One operation, two implementations: an explicit pair's step here, a
/// Rosenbrock method's in `row.rs`.
pub(super) fn step_backward<S: HybridSystem + ?Sized>(
    sys: &S,
    p: &[f64],
    step: &Step<'_>,
    lams: &mut [f64],
    pbars: &mut [f64],
    w: &mut Scratch,
) {
    let (n, rows) = (step.x0.len(), lams.len() / step.x0.len().max(1));
    if n == 0 || rows == 0 {
        return;
    }
    if let Some(tab) = row::tableau(step.pair) {
        row::step_backward(sys, p, step, tab, lams, pbars, &mut w.row);
        return;
    }
    let m = pbars.len() / rows;
    let stages = recompute_stages(sys, p, step, w);
    for r in 0..rows {
        let (lam, pbar) = (&mut lams[r * n..(r + 1) * n], &mut pbars[r * m..(r + 1) * m]);
        row_backward(sys, p, step, stages, lam, pbar, w);
    }
}

/// The step's stage inputs and derivatives (states only) into the scratch; returns how many.
fn recompute_stages<S: HybridSystem + ?Sized>(sys: &S, p: &[f64], step: &Step<'_>, w: &mut Scratch) -> usize {
    let n = step.x0.len();
    let tab = tableau(step.pair);
    let s = tab.stages;
    let stages = match step.end {
        StepEnd::Dense(_) => tab.all_stages,
        _ => s,
    };
    let at = |t: f64| if t > step.ceiling { step.ceiling } else { t };
    let (t0, h) = (step.t0, step.h);
    w.k.clear();
    w.k.resize(stages * n, 0.0);
    w.xs.clear();
    w.xs.resize(stages * n, 0.0);
    w.xs[..n].copy_from_slice(step.x0);
    sys.flow(step.mode, at(t0), step.x0, p, &mut w.k[..n]);
    for i in 1..stages {
        let xi = &mut w.xs[i * n..(i + 1) * n];
        stage_sum(&w.k, n, &tab.a[i], h, |c| step.x0[c], xi);
        sys.flow(step.mode, at(t0 + tab.c[i] * h), xi, p, &mut w.k[i * n..(i + 1) * n]);
    }
    stages
}

/// One row of [`step_backward`], over the stages [`recompute_stages`] left in the scratch.
fn row_backward<S: HybridSystem + ?Sized>(
    sys: &S,
    p: &[f64],
    step: &Step<'_>,
    stages: usize,
    lam: &mut [f64],
    pbar: &mut [f64],
    w: &mut Scratch,
) {
    let n = step.x0.len();
    let tab = tableau(step.pair);
    let s = tab.stages;
    let at = |t: f64| if t > step.ceiling { step.ceiling } else { t };
    let (t0, h) = (step.t0, step.h);
    w.kbar.clear();
    w.kbar.resize(stages * n, 0.0);
    w.xbar.clear();
    w.xbar.resize(stages * n, 0.0);
    let mut x0bar = vec![0.0; n];
    let last = (s - 1) * n;
    match step.end {
        StepEnd::End => w.xbar[last..last + n].copy_from_slice(lam),
        StepEnd::Landed(dt) => {
            w.xbar[last..last + n].copy_from_slice(lam);
            for (kb, l) in w.kbar[last..last + n].iter_mut().zip(lam.iter()) {
                *kb += dt * l;
            }
        }
        StepEnd::Dense(t) => {
            // r0 = y0, r1 = y1 - y0, r2 = h f0 - r1, r3 = 2 (y1 - y0) - h f0 - h f1,
            // r_{4+row} = h sum_j d_row,j (k_j - k_0) (the centred sums of `Dense::build`).
            let theta = (t - t0) / h;
            let count = 4 + tab.d.len();
            let wt = nested_weights(theta, count);
            let (c0, c1) = (wt[0] - wt[1] + wt[2] - 2.0 * wt[3], wt[1] - wt[2] + 2.0 * wt[3]);
            let (cf0, cf1) = (h * (wt[2] - wt[3]), -h * wt[3]);
            for i in 0..n {
                x0bar[i] += c0 * lam[i];
                w.xbar[last + i] += c1 * lam[i];
                w.kbar[i] += cf0 * lam[i];
                w.kbar[last + i] += cf1 * lam[i];
            }
            for (row, d) in tab.d.iter().enumerate() {
                let c = h * wt[4 + row];
                let mut total = 0.0;
                for (&j, &dj) in d.stages().iter().zip(d.weights()) {
                    total += dj;
                    for (kb, l) in w.kbar[j * n..(j + 1) * n].iter_mut().zip(lam.iter()) {
                        *kb += c * dj * l;
                    }
                }
                for (kb, l) in w.kbar[..n].iter_mut().zip(lam.iter()) {
                    *kb -= c * total * l;
                }
            }
        }
    }
    w.gx.resize(n, 0.0);
    for i in (1..stages).rev() {
        let (xs, kbar, xbar) =
            (&w.xs[i * n..(i + 1) * n], &w.kbar[i * n..(i + 1) * n], &mut w.xbar[i * n..(i + 1) * n]);
        let ti = at(t0 + tab.c[i] * h);
        add_vjp(sys, step.mode, ti, xs, kbar, p, &mut w.gx, xbar, pbar);
        for (x0b, xb) in x0bar.iter_mut().zip(xbar.iter()) {
            *x0b += xb;
        }
        let row = &tab.a[i];
        for (&j, &a) in row.stages().iter().zip(row.weights()) {
            for c in 0..n {
                w.kbar[j * n + c] += h * a * w.xbar[i * n + c];
            }
        }
    }
    add_vjp(sys, step.mode, at(t0), step.x0, &w.kbar[..n], p, &mut w.gx, &mut x0bar, pbar);
    lam.copy_from_slice(&x0bar);
}

/// An event's jump as the backward pass recomputes it.
#[derive(Clone, Copy, Debug)]
pub(super) struct Jump<'a> {
    pub event: usize,
    pub t: f64,
    /// Where the flows on both sides are read: `t`, or just before it on input knots (forward
    /// mode's `CrossingContext::left_of_knot`).
    pub t_flow: f64,
    pub mode_before: usize,
    pub mode_after: usize,
    pub x: &'a [f64],
    pub velocity: Option<&'a [f64]>,
}

/// `lam` (n): on entry the cotangent of the state after the jump, on return that of the state
/// before it; `time_bar` is the cotangent of the event's time itself (an `EVENT#K` quantity, an
/// output's time derivative at a stop). `total`: the jump is a stop event's whose total
/// derivative is asked for (the state carried to the stop's time: `f+` left out, the measured
/// velocity in the velocity jump). `given`: the event cascades from its instant's first event and
/// takes that event's `dt/dp`, not its own: then nothing goes through its guard, and the
/// cotangent of that `dt/dp` is returned for the first event (else 0).
#[allow(clippy::too_many_arguments)]
pub(super) fn jump_backward<S: HybridSystem + ?Sized>(
    sys: &S,
    p: &[f64],
    jump: &Jump<'_>,
    time_bar: f64,
    total: bool,
    given: bool,
    lam: &mut [f64],
    pbar: &mut [f64],
) -> f64 {
    let n = jump.x.len();
    let m = pbar.len();
    let (t, x) = (jump.t, jump.x);
    let mut f_minus = vec![0.0; n];
    sys.flow(jump.mode_before, jump.t_flow, x, p, &mut f_minus);
    let velocity = jump.velocity.unwrap_or(&f_minus);
    let (mut gx, mut gp) = (vec![0.0; n], vec![0.0; m]);
    let gt = sys.guard_grad(jump.event, t, x, p, &mut gx, &mut gp);
    let d = gx.iter().zip(velocity).map(|(a, b)| a * b).sum::<f64>() + gt;
    let mut x_plus = vec![0.0; n];
    sys.reset(jump.event, t, x, p, &mut x_plus);
    let (mut rx, mut rp, mut rt) = (vec![0.0; n * n], vec![0.0; n * m], vec![0.0; n]);
    sys.reset_jac(jump.event, t, x, p, &mut rx, &mut rp, &mut rt);
    let mut f_plus = vec![0.0; n];
    if !total {
        sys.flow(jump.mode_after, jump.t_flow, &x_plus, p, &mut f_plus);
    }
    let through = if total { velocity } else { &f_minus };
    // u = v . lam + time_bar, with v = R_x f- + R_t - f+ the velocity's jump through the reset.
    let mut u = time_bar;
    for i in 0..n {
        let rf: f64 = (0..n).map(|c| rx[i * n + c] * through[c]).sum();
        u += (rf + rt[i] - f_plus[i]) * lam[i];
    }
    // dt/dp = -(g_x S- + g_p) / d, its cotangent u; a cascading event's is its instant's.
    let scale = if given { 0.0 } else { u / d };
    for (j, pb) in pbar.iter_mut().enumerate() {
        let rpl: f64 = (0..n).map(|i| rp[j * n + i] * lam[i]).sum();
        *pb += rpl - gp[j] * scale;
    }
    let before: Vec<f64> =
        (0..n).map(|c| (0..n).map(|i| rx[i * n + c] * lam[i]).sum::<f64>() - gx[c] * scale).collect();
    lam.copy_from_slice(&before);
    if given {
        u
    } else {
        0.0
    }
}

/// A flow switch as the backward pass recomputes it.
#[derive(Clone, Copy, Debug)]
pub(super) struct Switch<'a> {
    pub event: usize,
    pub t: f64,
    pub mode: usize,
    pub x: &'a [f64],
    pub pre: (f64, &'a [f64]),
    pub post: (f64, &'a [f64]),
}

/// A flow switch's jump `S+ = S- + (f- - f+) dt/dp`, `dt/dp = -(g_x S- + g_p) / d` with
/// `d = g_x f- + g_t`, transposed: `lam` from after the switch to before it.
pub(super) fn switch_backward<S: HybridSystem + ?Sized>(
    sys: &S,
    p: &[f64],
    switch: &Switch<'_>,
    lam: &mut [f64],
    pbar: &mut [f64],
) {
    let n = switch.x.len();
    let (mut f_minus, mut f_plus) = (vec![0.0; n], vec![0.0; n]);
    sys.flow(switch.mode, switch.pre.0, switch.pre.1, p, &mut f_minus);
    sys.flow(switch.mode, switch.post.0, switch.post.1, p, &mut f_plus);
    let (mut gx, mut gp) = (vec![0.0; n], vec![0.0; pbar.len()]);
    let gt = sys.guard_grad(switch.event, switch.t, switch.x, p, &mut gx, &mut gp);
    let d = gx.iter().zip(&f_minus).map(|(a, b)| a * b).sum::<f64>() + gt;
    let u: f64 = (0..n).map(|i| (f_minus[i] - f_plus[i]) * lam[i]).sum();
    let scale = u / d;
    for (l, g) in lam.iter_mut().zip(&gx) {
        *l -= g * scale;
    }
    for (pb, g) in pbar.iter_mut().zip(&gp) {
        *pb -= g * scale;
    }
}

/// The `pwc` knots' jump `S+ = S- + J dt_k/dp` (`J` the flow's jump, `dt_k/dp = -s_p / s_t`
/// from the knot positions `s`: the knots of `sets` met at `t` in `mode` move together, or
/// apart with a NaN motion, as forward mode reads it, `knots::motion`), transposed: `lam` passes
/// unchanged, the parameters that move the knots gain `(J . lam) dt_k/dp`. A parameter that
/// moves knots of one instant apart has no derivative where `J . lam` is not zero (forward
/// mode's column is NaN where the flow jumps).
#[allow(clippy::too_many_arguments)]
pub(super) fn knot_backward<S: HybridSystem + ?Sized>(
    sys: &S,
    p: &[f64],
    sets: &[(f64, u32)],
    mode: usize,
    t: f64,
    jump: &[f64],
    lam: &[f64],
    pbar: &mut [f64],
) {
    let m = pbar.len();
    let (mut sp, mut dt) = (vec![0.0; m], vec![0.0; m]);
    crate::sim::knots::motion(sys, p, mode, t, sets, &mut sp, &mut dt);
    let u: f64 = jump.iter().zip(lam).map(|(a, b)| a * b).sum();
    for (pb, &dt) in pbar.iter_mut().zip(&dt) {
        if dt != 0.0 && !(dt.is_nan() && u == 0.0) {
            *pb += u * dt;
        }
    }
}
