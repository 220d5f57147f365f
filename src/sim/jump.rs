//! Stage 5 (sim): what happens to the state and its sensitivities at one event: the event-time
//! gradient, the reset and the saltation jump. Knows the `HybridSystem` functions; knows nothing
//! of stepping, interpolation or root finding.
//!
//! With `g` the guard, `f-` the old mode's flow at the pre-event state and `f+` the new mode's flow
//! at the post-event state (layouts as in `system.rs`, `S` column per parameter):
//! - crossing speed `d = g_x f- + g_t`, event-time gradient `dt_e/dp = -(g_x S- + g_p) / d`
//!   (implicit function theorem on `g(t_e, x(t_e; p), p) = 0`);
//! - saltation `S+ = R_x S- + R_p + (R_x f- + R_t - f+) dt_e/dp`;
//! - for a stop event the total derivative of the final state `R(t_e, x(t_e), p)` is
//!   `R_x (S- + f- dt_e/dp) + R_p + R_t dt_e/dp`.
//!
//! A flow switch (`apply_switch`) is the same jump with `R` the identity, `f-` and `f+` read just
//! before and just past the switch (the flow itself jumps there, not the mode).
//!
//! Grazing: when `|d| <= graze_tol (|g_x| |f-| + |g_t|)` (Euclidean norms; the factor never below
//! 1e-8) the crossing is tangential, `dt_e/dp` does not exist and dividing by `d` would produce
//! huge or NaN numbers.

use super::events::dot;
use super::system::HybridSystem;

/// A time and the state at that time.
pub(crate) type TimedState<'a> = (f64, &'a [f64]);

fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

/// Relative crossing speed below which an event always counts as grazing.
const MIN_RELATIVE_SPEED: f64 = 1e-8;

pub(crate) struct Jump {
    n: usize,
    m: usize,
    gx: Vec<f64>,
    gp: Vec<f64>,
    rx: Vec<f64>,
    rp: Vec<f64>,
    rt: Vec<f64>,
    f_minus: Vec<f64>,
    f_plus: Vec<f64>,
    x_plus: Vec<f64>,
    s_plus: Vec<f64>,
    v: Vec<f64>,
    /// `dt_e/dp` of the last jump (meaningful unless it grazed).
    pub dte: Vec<f64>,
    /// Total derivative of the post-event state (filled when asked for).
    pub total: Vec<f64>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct JumpOutcome {
    pub denominator: f64,
    pub scale: f64,
    pub grazing: bool,
}

impl Jump {
    pub fn new(n: usize, m: usize) -> Jump {
        Jump {
            n,
            m,
            gx: vec![0.0; n],
            gp: vec![0.0; m],
            rx: vec![0.0; n * n],
            rp: vec![0.0; n * m],
            rt: vec![0.0; n],
            f_minus: vec![0.0; n],
            f_plus: vec![0.0; n],
            x_plus: vec![0.0; n],
            s_plus: vec![0.0; n * m],
            v: vec![0.0; n],
            dte: vec![0.0; m],
            total: vec![0.0; n * m],
        }
    }

    /// Applies event `ev` at time `t` to `x` and `s` in place, switching from `mode_old` to
    /// `mode_new`. With `given`, the event takes that `dt/dp` and crossing speed instead of its
    /// own guard's: an event that cascades from another at the same instant moves with that
    /// instant (its guard was jumped across by a reset, not crossed by the flow), and composing
    /// the saltation jumps with one `dt/dp` is exact.
    #[allow(clippy::too_many_arguments)]
    pub fn apply<S: HybridSystem + ?Sized>(
        &mut self,
        sys: &S,
        ev: usize,
        mode_old: usize,
        mode_new: usize,
        t: f64,
        x: &mut [f64],
        s: &mut [f64],
        p: &[f64],
        graze_tol: f64,
        want_total: bool,
        given: Option<(&[f64], f64)>,
    ) -> JumpOutcome {
        let (n, m) = (self.n, self.m);
        sys.flow(mode_old, t, x, p, &mut self.f_minus);
        let outcome = match given {
            Some((dte, speed)) => {
                self.dte.copy_from_slice(dte);
                JumpOutcome { denominator: speed, scale: 0.0, grazing: false }
            }
            None => self.event_time_gradient(sys, ev, t, x, s, p, graze_tol),
        };
        sys.reset(ev, t, x, p, &mut self.x_plus);
        sys.reset_jac(ev, t, x, p, &mut self.rx, &mut self.rp, &mut self.rt);
        sys.flow(mode_new, t, &self.x_plus, p, &mut self.f_plus);
        // v = R_x f- + R_t - f+, the jump of the velocity seen through the reset.
        for i in 0..n {
            let row = &self.rx[i * n..(i + 1) * n];
            self.v[i] = dot(row, &self.f_minus) + self.rt[i] - self.f_plus[i];
        }
        for j in 0..m {
            let sj = &s[j * n..(j + 1) * n];
            for i in 0..n {
                let row = &self.rx[i * n..(i + 1) * n];
                let rs = dot(row, sj);
                self.s_plus[j * n + i] = rs + self.rp[j * n + i] + self.v[i] * self.dte[j];
                if want_total {
                    let rf = dot(row, &self.f_minus);
                    self.total[j * n + i] = rs + self.rp[j * n + i] + (rf + self.rt[i]) * self.dte[j];
                }
            }
        }
        x.copy_from_slice(&self.x_plus);
        s.copy_from_slice(&self.s_plus);
        outcome
    }

    /// Applies the flow switch `ev` (an implicit event: no reset, no mode change) at time `t`,
    /// where the state is `x`: `sides` are a time and state just before the switch, where the
    /// flow is `f-`, and just past it, where it is `f+`. Only `s` changes:
    /// `S+ = S- + (f- - f+) dt_e/dp`.
    #[allow(clippy::too_many_arguments)]
    pub fn apply_switch<S: HybridSystem + ?Sized>(
        &mut self,
        sys: &S,
        ev: usize,
        mode: usize,
        t: f64,
        x: &[f64],
        ((t_pre, x_pre), (t_post, x_post)): (TimedState, TimedState),
        s: &mut [f64],
        p: &[f64],
        graze_tol: f64,
    ) -> JumpOutcome {
        let n = self.n;
        sys.flow(mode, t_pre, x_pre, p, &mut self.f_minus);
        let outcome = self.event_time_gradient(sys, ev, t, x, s, p, graze_tol);
        sys.flow(mode, t_post, x_post, p, &mut self.f_plus);
        for (j, &dte) in self.dte.iter().enumerate() {
            for ((s, f_minus), f_plus) in
                s[j * n..(j + 1) * n].iter_mut().zip(&self.f_minus).zip(&self.f_plus)
            {
                *s += (f_minus - f_plus) * dte;
            }
        }
        outcome
    }

    /// The crossing speed `d = g_x f- + g_t` (with `f-` already in `f_minus`) and `dt_e/dp` into
    /// `dte` (zero when grazing).
    #[allow(clippy::too_many_arguments)]
    fn event_time_gradient<S: HybridSystem + ?Sized>(
        &mut self,
        sys: &S,
        ev: usize,
        t: f64,
        x: &[f64],
        s: &[f64],
        p: &[f64],
        graze_tol: f64,
    ) -> JumpOutcome {
        let n = self.n;
        let gt = sys.guard_grad(ev, t, x, p, &mut self.gx, &mut self.gp);
        let d = dot(&self.gx, &self.f_minus) + gt;
        let scale = norm(&self.gx) * norm(&self.f_minus) + gt.abs();
        // A NaN speed also counts as grazing (the comparison is false for NaN). Below a relative
        // speed of about sqrt(eps) the located time itself is unreliable (its error is the
        // guard's round-off divided by d), so even `graze_tol = 0` does not go below that.
        let crossing_fast_enough = d.abs() > graze_tol.max(MIN_RELATIVE_SPEED) * scale;
        let grazing = !crossing_fast_enough;
        for (j, dte) in self.dte.iter_mut().enumerate() {
            *dte = if grazing {
                // No time correction: S is carried on as if the event time were fixed, the
                // one-sided limit that keeps the numbers finite. The caller marks every later
                // gradient as not meaningful, so this S is never reported as a derivative.
                0.0
            } else {
                -(dot(&self.gx, &s[j * n..(j + 1) * n]) + self.gp[j]) / d
            };
        }
        JumpOutcome { denominator: d, scale, grazing }
    }
}
