//! Stage 5 (sim): branch locking by cutting, the flow-switch landing the integrator owns. A step
//! whose stages straddle a flow switch evaluated the flow past it on the other branch, and its
//! whole polynomial (the state at every time of the step, events before the switch included)
//! carries that error: a pulse narrower than a step was lost whole. Such a step is retried
//! landing exactly on the last time before the switch (the first located on the interpolant),
//! where every stage is on the branch of the step's start; the next step then crosses the switch
//! within its first floating-point spacings.
//!
//! Knows the detector's findings and the stepper's interpolant; the integrator decides when to
//! ask and applies the step size returned.

use super::breakpoints::Breakpoints;
use super::event::detect::{Crossing, Detector};
use super::event::guards::Guards;
use super::method::stepper::{Interpolant, Rhs, Stepper};
use super::system::HybridSystem;

const EPS: f64 = f64::EPSILON;
/// Retries of one step landing before a flow switch it crossed or a stage of it strayed across
/// (each lands earlier than the last).
const SWITCH_RETRIES: u8 = 8;
/// A switch this many spacings of `t` past a step that landed before it (by the guard's value
/// over its speed) is crossed at the step's end.
const SWITCH_NEAR: f64 = 64.0;

/// The switch a step is being retried to land before.
#[derive(Clone, Copy, Debug)]
struct Target {
    /// The last time before the switch, on the crossing attempt's interpolant: the step lands here.
    t_pre: f64,
    /// Retries of this step so far.
    retries: u8,
    /// The switch's position in the mode's events and its pre-crossing sign.
    pos: usize,
    sigma: f64,
}

/// A step retried to land just before a flow switch it crossed, and how often it was retried so.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct SwitchLanding {
    target: Option<Target>,
}

impl SwitchLanding {
    /// The time a step from `t0` lands on, when it is retried for a switch ahead of it.
    pub fn limit(&self, t0: f64) -> Option<f64> {
        self.target.filter(|l| l.t_pre > t0).map(|l| l.t_pre)
    }

    /// Forgets the target: the step moved on (accepted or cut at an event).
    pub fn clear(&mut self) {
        self.target = None;
    }

    /// After a step from `t0` whose scan (`det`) found a flow switch crossed inside it, or one of
    /// whose stages left a switch's side (`stray`: position, side, the time to land before it,
    /// from `Detector::stray_stage`): the step size of the retry landing just before the earlier
    /// of the two, or `None` to go on as it is. A switch within a resolvable distance of the
    /// start is crossed as before; the landing time must fall at each retry (at most
    /// [`SWITCH_RETRIES`]), so this ends.
    pub fn retry<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        det: &mut Detector,
        cx: &Guards<S>,
        dense: &I,
        t0: f64,
        stray: Option<(usize, f64, f64)>,
    ) -> Option<f64> {
        // A switch on zero at the start that the step carries across crosses there: no retry.
        let crossed = det
            .earliest_switch(cx, dense)
            .filter(|&(pos, _)| !det.crosses_at_start(cx, pos))
            .map(|(pos, c)| (pos, c.sigma, c.t_pre));
        let (pos, sigma, t_pre) = match (crossed, stray) {
            (Some(a), Some(b)) => {
                if b.2 < a.2 {
                    b
                } else {
                    a
                }
            }
            (a, b) => a.or(b)?,
        };
        let resolvable = t_pre - t0 > 8.0 * EPS * t0.abs().max(f64::MIN_POSITIVE);
        let retries = match self.target {
            Some(l) if l.t_pre > t0 => {
                if t_pre >= l.t_pre || l.retries >= SWITCH_RETRIES {
                    return None;
                }
                l.retries + 1
            }
            _ => 1,
        };
        if !resolvable {
            return None;
        }
        det.forget_findings();
        self.target = Some(Target { t_pre, retries, pos, sigma });
        Some(t_pre - t0)
    }

    /// After an attempt over `(t0, t1)` from `z` rejected by its error test, in a mode with flow
    /// switches: whether it crossed one, found as for an accepted step (the attempt's
    /// interpolant is only as good as the attempt, but good enough to aim the retry at the
    /// switch), then as [`Self::retry`].
    pub fn retry_rejected<S: HybridSystem + ?Sized, St: Stepper, F: Rhs>(
        &mut self,
        det: &mut Detector,
        cx: &Guards<S>,
        stepper: &mut St,
        z: &[f64],
        (t0, t1): (f64, f64),
        rhs: &mut F,
    ) -> Option<f64> {
        if !cx.events().iter().any(|&ev| cx.info.events[ev].implicit) {
            return None;
        }
        det.eval_end(cx, t1, &*stepper);
        if !det.mark_candidates(cx) {
            return None;
        }
        // The states' part alone: the scan and the aim read guards, never sensitivities, and the
        // attempt is thrown away (on the soft ball, 43% of this function's cost was the rest).
        stepper.build_states_interpolant(t0, z, rhs);
        det.scan(cx, stepper.interpolant(), t1);
        let retry = self.retry(det, cx, stepper.interpolant(), t0, None);
        det.forget_findings();
        retry
    }

    /// A step that landed (at `t1`) just before the flow switch it was retried for, with the
    /// switch still a few spacings of `t` ahead: the switch is crossed right there (`det.group`
    /// holds it), rather than by a next step whose first stage would be on the old branch and
    /// the others on the new (its error estimate would reject it again and again, creeping up on
    /// the switch).
    pub fn cross_at_landing<S: HybridSystem + ?Sized>(
        &self,
        det: &mut Detector,
        cx: &Guards<S>,
        breakpoints: &Breakpoints,
        t1: f64,
    ) -> bool {
        let Some(landing) = self.target.filter(|l| l.t_pre == t1) else {
            return false;
        };
        let (g, speed) = (det.g1[landing.pos], det.dg1[landing.pos]);
        let spacing = super::spacing(t1);
        let near =
            g.is_finite() && landing.sigma * g >= 0.0 && g.abs() <= SWITCH_NEAR * spacing * speed.abs();
        // With a breakpoint (a time event) before the predicted crossing, the next step lands on
        // it and crosses the switch there, with the event, in time order.
        let t_cross = t1 + g.abs() / speed.abs() + spacing;
        if !near || breakpoints.peek_after(t1, cx.mode) <= t_cross {
            return false;
        }
        let ev = cx.events()[landing.pos];
        // Not crossed yet (the guard is a few spacings short of zero): like a touch, it fires
        // without its guard on the crossed side, which `fire_group` would otherwise take for a
        // state moved back by an earlier reset and skip. Skipped, the switch was left to the next
        // step, whose error estimate straddles the jump of the flow: with sensitivities at zero
        // (scaled by atol) it shrank to an underflow (the soft ball's first contact, issue #25).
        let crossing = Crossing { t: t1, sigma: landing.sigma, touch: true, t_pre: t1, on_guard: false };
        det.group.clear();
        det.group.push((ev, crossing));
        true
    }
}
