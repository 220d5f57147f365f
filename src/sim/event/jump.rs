//! Stage 5 (sim): what happens to the state and its sensitivities at one event: the event-time
//! gradient, the reset and the saltation jump. Knows the `HybridSystem` functions; knows nothing
//! of stepping, interpolation or root finding.
//!
//! With `g` the guard, `f-` the old mode's flow at the pre-event state and `f+` the new mode's flow
//! at the post-event state (layouts as in `sim/system.rs`, `S` column per parameter):
//! - crossing speed `d = g_x f- + g_t`, event-time gradient `dt_e/dp = -(g_x S- + g_p) / d`
//!   (implicit function theorem on `g(t_e, x(t_e; p), p) = 0`);
//! - saltation `S+ = R_x S- + R_p + (R_x f- + R_t - f+) dt_e/dp`;
//! - for a stop event the total derivative of the final state `R(t_e, x(t_e), p)` is
//!   `R_x (S- + f- dt_e/dp) + R_p + R_t dt_e/dp`.
//!
//! A flow switch (`apply_switch`) is the same jump with `R` the identity, `f-` and `f+` read just
//! before and just past the switch (the flow itself jumps there, not the mode).
//!
//! Grazing, from the crossing's conditioning (ARCHITECTURE.md, "Grazing"): near the crossing the
//! guard along the solution is `d (t - t_e) + g'' (t - t_e)^2 / 2`, and the guard is known only to
//! `delta = sum_i |g_x,i| (atol + rtol |x_i|)` plus its round-off (per component). The crossing is
//! resolved when `d^2` is large against `|g''| delta`: with `kappa = |g''| delta / d^2`,
//! - `kappa < graze_tol^2`: transversal, `dt_e/dp` exact;
//! - `graze_tol^2 <= kappa < graze_tol`: near-grazing: exact, but valid only while parameter
//!   changes move the guard's extremum, `d^2 / (2 |g''|)` from zero, by less: kept, with a warning;
//! - `kappa >= graze_tol`, or `d` within round-off of zero: grazing, `dt_e/dp` does not exist.
//!
//! A grazing flow switch can still have a saltation that exists: its term `(f- - f+) dt_e/dp` is
//! `-(J / d) (g_x S + g_p)` with the flow's jump `J = f- - f+`, and when `J` vanishes with the
//! crossing speed (a damper `if y < 0 then c v` switched at a guard `y` whose speed is `v`),
//! `J / d` has a finite limit `c` however badly `d` itself is resolved. `benign_graze` measures
//! that on an affine guard: it reads the flow on both sides at two points along the guard's
//! surface where the speed differs, fits `J = c d + J0` per component, and takes `-c (g_x S + g_p)`
//! when the jump left at zero speed, `J0`, is negligible against `c` times the speeds probed.
//!
//! A derivative that does not exist is NaN in `dte` and in `S`, and it voids exactly what depends
//! on it: every product below skips exact zeros, so `0 * NaN` is never formed and a reset that
//! removes the dependence (`v := 0` into a mode with no flow) gives derivatives that exist.

use super::detect::dot;
use crate::sim::system::{GuardShape, HybridSystem};

/// A time and the state at that time.
pub(crate) type TimedState<'a> = (f64, &'a [f64]);

/// `sum_i a_i b_i` over the `a_i` that are not exactly zero: a missing derivative (NaN) in `b`
/// reaches the sum only through a coefficient that is not zero.
pub(crate) fn dot_nonzero(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).filter(|(a, _)| **a != 0.0).map(|(a, b)| a * b).sum()
}

/// Whether `a` and `b` are one number up to the round-off of computing them in different ways
/// (an event's time derivative and an input knot's motion).
pub(crate) fn same(a: f64, b: f64) -> bool {
    a == b || (a - b).abs() <= 64.0 * f64::EPSILON * a.abs().max(b.abs())
}

/// `a b`, or zero when `a` is exactly zero (whatever `b`, NaN included).
fn times_nonzero(a: f64, b: f64) -> f64 {
    if a == 0.0 {
        0.0
    } else {
        a * b
    }
}

/// `16 eps (sum_i |a_i b_i| + |c d|)`, as `events::round_off`.
fn round_off(a: &[f64], b: &[f64], c: f64, d: f64) -> f64 {
    16.0 * f64::EPSILON * (a.iter().zip(b).map(|(a, b)| (a * b).abs()).sum::<f64>() + (c * d).abs())
}

/// What the integrator tells a jump about its crossing and the run's tolerances.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct CrossingContext {
    /// The step the crossing was found in, with the guard's speeds at its ends:
    /// `(t0, g'0, t1, g'1)`, from which `|g''|` at the crossing is estimated as the larger secant
    /// slope of the speed between the crossing and either end. `None` for a crossing at a step's
    /// start (its curvature is then taken as 0).
    pub step: Option<(f64, f64, f64, f64)>,
    /// The flow jumps at this crossing (a flow switch): the speed after it belongs to the other
    /// branch, so only the step's start enters the curvature.
    pub flow_jumps: bool,
    pub rtol: f64,
    pub atol: f64,
    pub graze_tol: f64,
    /// The instant is on input knots (their times are the first where the inputs take their new
    /// values): the flows on both sides of the event are read just before it, on the knots'
    /// earlier side, and the knots are crossed after the event (`knot_order`).
    pub left_of_knot: bool,
}

pub(crate) struct Jump {
    n: usize,
    m: usize,
    gx: Vec<f64>,
    gp: Vec<f64>,
    /// `R_x`: the values of the system's pattern (`reset_jac_pattern`), or the dense matrix
    /// (`n^2`, sized on first use) for a system without one.
    rx: Vec<f64>,
    /// `R_x`'s nonzero entries row by row in column order (`(column, value)`, row `i` at
    /// `rx_rows[i]..rx_rows[i + 1]`): a reset touches few states, so the products below run over
    /// these instead of `n^2` entries per sensitivity column.
    rx_nz: Vec<(usize, f64)>,
    rx_rows: Vec<usize>,
    /// Scratch: the nonzero entries `(row, column, value)` of a pattern, sorted.
    rx_sorted: Vec<(usize, usize, f64)>,
    rp: Vec<f64>,
    rt: Vec<f64>,
    f_minus: Vec<f64>,
    f_plus: Vec<f64>,
    /// The trajectory's velocity before the event where it was measured
    /// (`Integrator::landed_velocity`), with the time, mode and state it holds for: it replaces
    /// `f-` in the crossing speed and in the total derivative, not in the velocity jump.
    velocity: Vec<f64>,
    velocity_at: Option<(f64, usize, Vec<f64>)>,
    x_plus: Vec<f64>,
    s_plus: Vec<f64>,
    v: Vec<f64>,
    /// Scratch: `R_x` times the flow's jump at input knots (`knot_order`).
    rj: Vec<f64>,
    /// The guard's curvature `|g''|` and accuracy `delta` at the last crossing judged.
    curvature: f64,
    accuracy: f64,
    /// `dt_e/dp` of the last jump (meaningful unless it grazed).
    pub dte: Vec<f64>,
    /// Total derivative of the post-event state (filled when asked for).
    pub total: Vec<f64>,
    /// Whether the last flow switch applied grazed with a jump that vanishes with the speed
    /// (`benign_graze`): its saltation is the limit, not the formula the adjoint transposes.
    pub benign: bool,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct JumpOutcome {
    pub denominator: f64,
    /// `kappa = |g''| delta / d^2` (see the module documentation).
    pub conditioning: f64,
    pub grazing: bool,
    /// For a near-grazing crossing: how far the guard's extremum is from zero.
    pub margin: Option<f64>,
    /// How well the crossing time is known: the guard's accuracy at the tolerances over its
    /// crossing speed (0 where the event takes another's instant, or the speed is zero).
    pub resolution: f64,
}

impl Jump {
    pub fn new(n: usize, m: usize) -> Jump {
        Jump {
            n,
            m,
            gx: vec![0.0; n],
            gp: vec![0.0; m],
            rx: Vec::new(),
            rx_nz: Vec::new(),
            rx_rows: vec![0; n + 1],
            rx_sorted: Vec::new(),
            rp: vec![0.0; n * m],
            rt: vec![0.0; n],
            f_minus: vec![0.0; n],
            f_plus: vec![0.0; n],
            velocity: vec![0.0; n],
            velocity_at: None,
            x_plus: vec![0.0; n],
            s_plus: vec![0.0; n * m],
            v: vec![0.0; n],
            rj: vec![0.0; n],
            curvature: 0.0,
            accuracy: 0.0,
            dte: vec![0.0; m],
            total: vec![0.0; n * m],
            benign: false,
        }
    }

    /// The trajectory's velocity `v` at `(t, mode, x)`, measured along the computed trajectory:
    /// an event applied there takes its crossing speed from it instead of from the flow at `x`.
    /// In a stiff phase the flow carries the state's error times the stiffness, which can be the
    /// size of a slow crossing's speed; the velocity jump `R_x f- + R_t - f+` keeps the flows on
    /// both sides, whose errors cancel where the reset and the flow leave the motion unchanged.
    pub fn set_velocity(&mut self, t: f64, mode: usize, x: &[f64], v: &[f64]) {
        self.velocity.copy_from_slice(v);
        match &mut self.velocity_at {
            Some((t_at, mode_at, x_at)) => {
                (*t_at, *mode_at) = (t, mode);
                x_at.copy_from_slice(x);
            }
            None => self.velocity_at = Some((t, mode, x.to_vec())),
        }
    }

    /// Forgets the velocity of [`Self::set_velocity`].
    pub fn clear_velocity(&mut self) {
        if let Some((t_at, _, _)) = &mut self.velocity_at {
            *t_at = f64::NAN;
        }
    }

    /// The velocity of [`Self::set_velocity`] where it holds at `(t, mode, x)` (the one an event
    /// applied there takes): what the adjoint tape records of it.
    pub fn measured_velocity(&self, t: f64, mode: usize, x: &[f64]) -> Option<&[f64]> {
        self.velocity_holds(t, mode, x).then_some(&self.velocity[..])
    }

    /// Whether the velocity of [`Self::set_velocity`] holds at `(t, mode, x)`.
    fn velocity_holds(&self, t: f64, mode: usize, x: &[f64]) -> bool {
        matches!(&self.velocity_at, Some((t_at, mode_at, x_at)) if *t_at == t && *mode_at == mode && x_at[..] == x[..])
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
        context: CrossingContext,
        want_total: bool,
        given: Option<(&[f64], f64)>,
    ) -> JumpOutcome {
        let (n, m) = (self.n, self.m);
        // On input knots the flows are the knots' earlier side's (see `knot_order`).
        let t_flow = if context.left_of_knot { t.next_down() } else { t };
        sys.flow(mode_old, t_flow, x, p, &mut self.f_minus);
        let measured = self.velocity_holds(t, mode_old, x);
        let outcome = match given {
            Some((dte, _)) => {
                self.dte.copy_from_slice(dte);
                // The event's own crossing speed, for the record and the bounce rule; its time
                // gradient is the instant's.
                let gt = sys.guard_grad(ev, t, x, p, &mut self.gx, &mut self.gp);
                let velocity = if measured { &self.velocity } else { &self.f_minus };
                let denominator = dot(&self.gx, velocity) + gt;
                JumpOutcome { denominator, conditioning: 0.0, grazing: false, margin: None, resolution: 0.0 }
            }
            None => self.event_time_gradient(sys, ev, t, x, s, p, context, measured),
        };
        sys.reset(ev, t, x, p, &mut self.x_plus);
        self.reset_jacobian(sys, ev, t, x, p);
        sys.flow(mode_new, t_flow, &self.x_plus, p, &mut self.f_plus);
        // The products over a row's nonzeros, in column order: the sums of `dot_nonzero` over
        // the whole row, term for term.
        let (nz, rows) = (&self.rx_nz, &self.rx_rows);
        let row_dot =
            |i: usize, b: &[f64]| -> f64 { nz[rows[i]..rows[i + 1]].iter().map(|&(c, v)| v * b[c]).sum() };
        // v = R_x f- + R_t - f+, the jump of the velocity seen through the reset.
        for i in 0..n {
            self.v[i] = row_dot(i, &self.f_minus) + self.rt[i] - self.f_plus[i];
        }
        for j in 0..m {
            let sj = &s[j * n..(j + 1) * n];
            for i in 0..n {
                let rs = row_dot(i, sj);
                self.s_plus[j * n + i] = rs + self.rp[j * n + i] + times_nonzero(self.v[i], self.dte[j]);
                if want_total {
                    let rf = row_dot(i, if measured { &self.velocity } else { &self.f_minus });
                    self.total[j * n + i] =
                        rs + self.rp[j * n + i] + times_nonzero(rf + self.rt[i], self.dte[j]);
                }
            }
        }
        x.copy_from_slice(&self.x_plus);
        s.copy_from_slice(&self.s_plus);
        outcome
    }

    /// The event just applied (by [`Self::apply`], with its own time gradient and crossing speed
    /// `d`) met input knots at its instant, on their earlier side: there the flow jumps by
    /// `j_old` in the mode the event was met in (at the state before it), the knots moving by
    /// `dt_old` (`dt_k/dp`), and by `j_new` in the mode after it (at the state after it, moving by
    /// `dt_new`), and `s` already holds that jump, `+ j_new dt_new`, crossed after the event. A
    /// parameter that moves the event with the knots keeps this order on both sides of it. One
    /// that moves them apart has the other order on one side: the knots first (`S + j_old
    /// dt_old`), then the event on their later side, where its crossing speed is
    /// `d - g_x j_old`, so its time's derivative is
    /// `b = (a d - g_x j_old dt_old) / (d - g_x j_old)` against this side's `a`. The two sides'
    /// sensitivities differ by `v (a - b) + (R_x j_old) (b - dt_old) - j_new (b - dt_new)`, with
    /// `v = R_x f- + R_t - f+`: the entries where that is more than round-off do not exist, nor
    /// does the event time's derivative where `a` and `b` differ (NaN in `s` and in `dte`); a
    /// parameter for which neither order holds on one side (`a` and `b` on two sides of the
    /// knots' motion) keeps no derivative. Returns whether any derivative was found not to exist.
    /// A reset that commutes with the flow's jump (`R_x j_old = j_new`) and a guard that does
    /// not read it (`g_x j_old = 0`) keep every derivative: a time event on a knot that does not
    /// move, or a counter at a rate's switch.
    pub fn knot_order(
        &mut self,
        (j_old, dt_old): (&[f64], &[f64]),
        (j_new, dt_new): (&[f64], &[f64]),
        d: f64,
        s: &mut [f64],
    ) -> bool {
        const EPS: f64 = f64::EPSILON;
        let n = self.n;
        let jumps = |j: &[f64]| j.iter().any(|&v| v != 0.0);
        let (old_jumps, new_jumps) = (jumps(j_old), jumps(j_new));
        let gj = dot_nonzero(&self.gx, j_old);
        let (nz, rows) = (&self.rx_nz, &self.rx_rows);
        for (i, rj) in self.rj.iter_mut().enumerate() {
            *rj = nz[rows[i]..rows[i + 1]]
                .iter()
                .filter(|&&(c, _)| j_old[c] != 0.0)
                .map(|&(c, v)| v * j_old[c])
                .sum();
        }
        let mut voided = false;
        for j in 0..self.m {
            let a = self.dte[j];
            let together = (!old_jumps || same(a, dt_old[j])) && (!new_jumps || same(a, dt_new[j]));
            if a.is_nan() || together {
                continue;
            }
            let b = if gj == 0.0 { a } else { (a * d - gj * dt_old[j]) / (d - gj) };
            let dt = if old_jumps { dt_old[j] } else { dt_new[j] };
            let knots_apart = old_jumps && new_jumps && !same(dt_old[j], dt_new[j]);
            let column = &mut s[j * n..(j + 1) * n];
            // Both orders must hold on a side each: `a` and `b` on one side of the knots' motion
            // (a NaN `b`, from a crossing speed that vanishes on the later side, holds neither).
            let one_side = (a - dt) * (b - dt) > 0.0;
            if knots_apart || !one_side {
                column.fill(f64::NAN);
                self.dte[j] = f64::NAN;
                voided = true;
                continue;
            }
            if !same(a, b) {
                self.dte[j] = f64::NAN;
                voided = true;
            }
            for (i, s) in column.iter_mut().enumerate() {
                let (v, rj, jn) = (self.v[i], self.rj[i], j_new[i]);
                let diff = v * (a - b) + rj * (b - dt_old[j]) - jn * (b - dt_new[j]);
                let scale = v.abs() * (a.abs() + b.abs())
                    + rj.abs() * (b.abs() + dt_old[j].abs())
                    + jn.abs() * (b.abs() + dt_new[j].abs());
                // NaN-safe: a difference that is not a number is not round-off.
                let round_off = diff.abs() <= 64.0 * EPS * scale;
                if !round_off {
                    *s = f64::NAN;
                    voided = true;
                }
            }
        }
        voided
    }

    /// `R_x` (into `rx_nz`, `rx_rows`), `R_p` and `R_t` of event `ev` at `(t, x)`.
    fn reset_jacobian<S: HybridSystem + ?Sized>(&mut self, sys: &S, ev: usize, t: f64, x: &[f64], p: &[f64]) {
        let n = self.n;
        self.rx_nz.clear();
        match sys.reset_jac_pattern(ev) {
            Some(pattern) => {
                self.rx.resize(pattern.len(), 0.0);
                sys.reset_jac_values(ev, t, x, p, &mut self.rx, &mut self.rp, &mut self.rt);
                self.rx_sorted.clear();
                self.rx_sorted.extend(
                    pattern
                        .iter()
                        .zip(&self.rx)
                        .filter(|(_, v)| **v != 0.0)
                        .map(|(&(r, c), &v)| (r as usize, c as usize, v)),
                );
                self.rx_sorted.sort_unstable_by_key(|&(r, c, _)| (r, c));
                let mut k = 0;
                for i in 0..n {
                    self.rx_rows[i] = self.rx_nz.len();
                    while k < self.rx_sorted.len() && self.rx_sorted[k].0 == i {
                        self.rx_nz.push((self.rx_sorted[k].1, self.rx_sorted[k].2));
                        k += 1;
                    }
                }
            }
            None => {
                self.rx.resize(n * n, 0.0);
                sys.reset_jac(ev, t, x, p, &mut self.rx, &mut self.rp, &mut self.rt);
                for (i, row) in self.rx.chunks_exact(n.max(1)).take(n).enumerate() {
                    self.rx_rows[i] = self.rx_nz.len();
                    self.rx_nz
                        .extend(row.iter().enumerate().filter(|(_, v)| **v != 0.0).map(|(c, &v)| (c, v)));
                }
            }
        }
        self.rx_rows[n] = self.rx_nz.len();
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
        context: CrossingContext,
    ) -> JumpOutcome {
        let n = self.n;
        self.benign = false;
        sys.flow(mode, t_pre, x_pre, p, &mut self.f_minus);
        let outcome = self.event_time_gradient(sys, ev, t, x, s, p, context, false);
        sys.flow(mode, t_post, x_post, p, &mut self.f_plus);
        if outcome.grazing
            && sys.info().events[ev].guard == GuardShape::Affine
            && self.benign_graze(
                sys,
                ev,
                mode,
                ((t_pre, x_pre), (t_post, x_post)),
                p,
                outcome.denominator,
                context.graze_tol,
            )
        {
            // `self.v` holds the limit `c` of `J / d`: the jump `-c (g_x S + g_p)` exists.
            self.benign = true;
            for j in 0..self.m {
                let sj = &mut s[j * n..(j + 1) * n];
                let numerator = dot_nonzero(&self.gx, sj) + self.gp[j];
                for (s, c) in sj.iter_mut().zip(&self.v) {
                    *s -= times_nonzero(*c, numerator);
                }
            }
            return JumpOutcome { grazing: false, margin: None, ..outcome };
        }
        for (j, &dte) in self.dte.iter().enumerate() {
            for ((s, f_minus), f_plus) in
                s[j * n..(j + 1) * n].iter_mut().zip(&self.f_minus).zip(&self.f_plus)
            {
                *s += times_nonzero(f_minus - f_plus, dte);
            }
        }
        outcome
    }

    /// The limit `c` of `J / d` at the last flow switch applied, where it grazed benignly
    /// ([`Self::benign`]): what the adjoint tape keeps to transpose `-c (g_x S + g_p)`.
    pub fn benign_limit(&self) -> &[f64] {
        &self.v
    }

    /// The crossing speed `d = g_x f- + g_t` (with `f-` already in `f_minus`, or the measured
    /// velocity when `measured`), its conditioning, and `dt_e/dp` into `dte`: NaN where it does
    /// not exist (a grazing crossing, or a missing derivative in `S` that the guard reads), 0
    /// where nothing moves the time (`g_x S + g_p` is exactly 0 for that parameter, grazing or
    /// not).
    #[allow(clippy::too_many_arguments)]
    fn event_time_gradient<S: HybridSystem + ?Sized>(
        &mut self,
        sys: &S,
        ev: usize,
        t: f64,
        x: &[f64],
        s: &[f64],
        p: &[f64],
        context: CrossingContext,
        measured: bool,
    ) -> JumpOutcome {
        let n = self.n;
        let gt = sys.guard_grad(ev, t, x, p, &mut self.gx, &mut self.gp);
        let velocity = if measured { &self.velocity } else { &self.f_minus };
        let d = dot(&self.gx, velocity) + gt;
        let accuracy = self
            .gx
            .iter()
            .zip(x)
            .map(|(g, x)| g.abs() * (context.atol + context.rtol * x.abs()))
            .sum::<f64>()
            + round_off(&self.gx, x, gt, t);
        let speed_noise = round_off(&self.gx, velocity, gt, 1.0);
        let mut curvature = 0.0f64;
        if let Some((t0, d0, t1, d1)) = context.step {
            if t > t0 {
                curvature = curvature.max((d - d0).abs() / (t - t0));
            }
            if t1 > t && !context.flow_jumps {
                curvature = curvature.max((d1 - d).abs() / (t1 - t));
            }
        }
        (self.curvature, self.accuracy) = (curvature, accuracy);
        let conditioning = if d == 0.0 { f64::INFINITY } else { curvature * accuracy / (d * d) };
        // A NaN speed or conditioning also counts as grazing (the comparisons are false for NaN).
        let resolved = d.abs() > speed_noise && conditioning < context.graze_tol;
        let grazing = !resolved;
        let margin = (resolved && conditioning >= context.graze_tol * context.graze_tol)
            .then(|| d * d / (2.0 * curvature));
        for (j, dte) in self.dte.iter_mut().enumerate() {
            let numerator = dot_nonzero(&self.gx, &s[j * n..(j + 1) * n]) + self.gp[j];
            *dte = if !grazing {
                -numerator / d
            } else if numerator == 0.0 {
                0.0
            } else {
                f64::NAN
            };
        }
        let resolution = if d != 0.0 && (accuracy / d).is_finite() { (accuracy / d).abs() } else { 0.0 };
        JumpOutcome { denominator: d, conditioning, grazing, margin, resolution }
    }

    /// Whether the flow's jump at the grazing switch `ev` (affine guard, gradient in `gx`)
    /// vanishes with the crossing speed; if so, its limit `c = lim J / d` is left in `self.v`.
    /// Runs only at a graze, so it allocates.
    ///
    /// The sides `(t_pre, x_pre)` and `(t_post, x_post)` are moved along the guard's surface, by
    /// `+-h` times the tangential part of the flow: the guard keeps its value and side (it is
    /// affine; a probe that changes side is refused), while its speed moves by about `|g''| h`,
    /// with `h` chosen to move it by a tenth of the crossing's speed scale
    /// `max(|d|, sqrt(|g''| delta))`. From the jumps `J+-` and speeds `d+-` there, per component,
    /// `c = (J+ - J-) / (d+ - d-)` and the jump left at zero speed
    /// `J0 = (J+ + J-) / 2 - c (d+ + d-) / 2`. The limit is taken when every `|J0|` is below
    /// `graze_tol |c (d+ - d-)| / 2` plus what `J0` holds that is not a jump: the flows' round-off
    /// (`16 eps` of their values) and their change over the `t_post - t_pre` between the sides
    /// (twice that time times the flow's rate along the surface, read from the same probes). A
    /// jump that stays finite at zero speed (a force switched on at contact) leaves `J0` at its
    /// size and is refused: the crossing stays grazing.
    #[allow(clippy::too_many_arguments)]
    fn benign_graze<S: HybridSystem + ?Sized>(
        &mut self,
        sys: &S,
        ev: usize,
        mode: usize,
        ((t_pre, x_pre), (t_post, x_post)): (TimedState, TimedState),
        p: &[f64],
        d: f64,
        graze_tol: f64,
    ) -> bool {
        let n = self.n;
        let gg = dot(&self.gx, &self.gx);
        let Some(pos) = sys.info().modes[mode].events.iter().position(|&e| e == ev) else {
            return false;
        };
        if !(self.curvature > 0.0 && self.curvature.is_finite() && d.is_finite() && gg > 0.0) {
            return false;
        }
        let gt = d - dot(&self.gx, &self.f_minus);
        let h = 0.1 * d.abs().max((self.curvature * self.accuracy).sqrt()) / self.curvature;
        // The tangential part of the flow before the switch: the trajectory's own direction along
        // the surface, along which the speed changes at the guard's curvature.
        let normal = dot(&self.gx, &self.f_minus) / gg;
        let tangent: Vec<f64> = self.f_minus.iter().zip(&self.gx).map(|(f, g)| f - normal * g).collect();
        if !(h.is_finite() && h > 0.0) || tangent.iter().all(|v| *v == 0.0) {
            return false;
        }
        let mut guards = vec![0.0; sys.info().modes[mode].events.len()];
        let mut guard_at = |t: f64, x: &[f64]| {
            sys.guards(mode, t, x, p, &mut guards);
            guards[pos]
        };
        // flows[side][k]: the flow on the side before (0) or past (1) the switch, probed at -h (0)
        // or +h (1) along the surface.
        let mut flows = [[vec![0.0; n], vec![0.0; n]], [vec![0.0; n], vec![0.0; n]]];
        for (side, (t_side, x_side)) in [(t_pre, x_pre), (t_post, x_post)].into_iter().enumerate() {
            let g_side = guard_at(t_side, x_side);
            for (k, sign) in [-1.0, 1.0].into_iter().enumerate() {
                let probe: Vec<f64> = x_side.iter().zip(&tangent).map(|(x, v)| x + sign * h * v).collect();
                if guard_at(t_side, &probe) * g_side <= 0.0 {
                    return false;
                }
                sys.flow(mode, t_side, &probe, p, &mut flows[side][k]);
            }
        }
        let speeds = [0, 1].map(|k| dot(&self.gx, &flows[0][k]) + gt);
        let span = speeds[1] - speeds[0];
        if !(span.is_finite() && span != 0.0) {
            return false;
        }
        let mid = 0.5 * (speeds[0] + speeds[1]);
        let gap = (t_post - t_pre).abs();
        for i in 0..n {
            let (lo, hi) = (flows[0][0][i] - flows[1][0][i], flows[0][1][i] - flows[1][1][i]);
            let round_off = 16.0 * f64::EPSILON * flows.iter().flatten().map(|f| f[i].abs()).sum::<f64>();
            let rate = flows.iter().map(|f| (f[1][i] - f[0][i]).abs() / (2.0 * h)).fold(0.0, f64::max);
            let not_a_jump = round_off + 2.0 * gap * rate;
            let c = if (hi - lo).abs() <= round_off { 0.0 } else { (hi - lo) / span };
            let left = 0.5 * (lo + hi) - c * mid;
            if !(c.is_finite() && left.abs() <= graze_tol * (c * span).abs() * 0.5 + not_a_jump) {
                return false;
            }
            self.v[i] = c;
        }
        true
    }
}
