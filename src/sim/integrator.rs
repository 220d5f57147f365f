//! Stage 5 (sim): the integrator. It owns the state of a run (`t`, `z = [x, S]`, the mode) and
//! advances it one [`Integrator::step`] at a time: a step is attempted by the [`Stepper`] under
//! its error control; an accepted step is searched for events, which are located on the dense
//! output, fired in a group (resets, mode switches, saltation of the sensitivities) and watched
//! for Zeno behaviour and faults. Breakpoints (`t_end`, ...) are landed on exactly; a
//! [`Recorder`] sees every point. `sim::run` is a loop over `step`; a caller (a binding, a future
//! adjoint pass) can drive the loop itself.
//!
//! Generic over `S: HybridSystem + ?Sized` (monomorphised; `&dyn HybridSystem` works too); after
//! setup the step loop allocates nothing unless a trajectory is recorded or an event fires.
//! Knows nothing of Cranelift, expressions or the model's text.

use std::sync::Arc;

use super::breakpoints::Breakpoints;
use super::event::detect::{clear_side, moves_across, Crossing, Detector, Pending, Selection};
use super::event::jump::{dot_nonzero, CrossingContext, Jump, JumpOutcome};
use super::event::zeno;
use super::method::rk::Rk;
use super::method::stepper::{Interpolant, Rhs, Stepper};
use super::options::SimOptions;
use super::recorder::{Point, PointKind, Recorder};
use super::result::{
    EndCusp, EventRecord, FinalState, MethodSegment, Samples, SimError, SimResult, SimStats, SimWarning,
    StopReason,
};
use super::samples;
use super::system::{Direction, GuardShape, HybridSystem, SystemInfo};

const EPS: f64 = f64::EPSILON;
/// Largest ratio of the first step after an event to Hairer's initial estimate at the
/// post-event state, when the event switched the mode (the controller's proposal was learnt on
/// another vector field) and when it did not. Measured (`closed_forms` tests, thermostat, 30
/// mode switches at rtol 1e-10): the largest relative error of the event-time gradients is
/// 6.4e-10 with 10 (as with no continuation at all), 1.1e-8 with 30 and 8.6e-9 with 100: long
/// first steps in a new mode each spend the whole local tolerance, and over many events that
/// adds up. Within one mode the proposal was learnt on the same vector field, and the error
/// control still rejects a step the reset made too long. There 1000 loses nothing measurable
/// against 10 (ball, tilted floor, dosing: event-time gradients 5.2e-12, 2.5e-10 and 3.6e-12 with
/// either) and takes the ball in 9 steps (17 with 10, 10 with 100: after its first bounce the
/// estimate is 4.1e-3 and the flight 0.72 long); no shipped model rejects more steps with it.
const AFTER_SWITCH_GROWTH: f64 = 10.0;
const AFTER_RESET_GROWTH: f64 = 1000.0;
/// Trial points, at 1, 2, 4, ... floating-point spacings past a flow switch's located time,
/// for one where its guard is strictly past zero (there the flow is the new branch's).
const SWITCH_SIDE_TRIES: usize = 40;
/// Retries of one step landing before a flow switch it crossed (each lands earlier than the last).
const SWITCH_RETRIES: u8 = 4;
/// Events this close to a breakpoint, relative to `max(|t|, 1)`, are flagged: their derivatives
/// hold only while they stay on their side of it (the resolution at which Zeno tells instants
/// apart, `zeno::ACCUMULATION_RESOLUTION`).
const NEAR_BREAKPOINT: f64 = 1e-9;
/// A switch this many spacings of `t` past a step that landed before it (by the guard's value
/// over its speed) is crossed at the step's end.
const SWITCH_NEAR: f64 = 64.0;
/// Rejections in a row with a non-finite trial state before the run gives up on shrinking.
const MAX_NONFINITE_REJECTS: usize = 30;
/// A step this short relative to `max(|t|, 1)` is taken even when a nonlinear guard is not
/// resolved by it, with the guard checked at its samples only: a guard with a kink (`abs`, `min`,
/// `max`) is not resolved by a cubic however short the step.
const GUARD_RESOLUTION_FLOOR: f64 = 1e-9;
/// After an instant, the next step reaches this far past the next crossing the last step saw
/// (relative to the distance to it): past it despite the error of its estimate, not far beyond.
const NEXT_CROSSING_REACH: f64 = 1.5;
/// Growth of the step size allowed by a resolved nonlinear guard, per step.
const GUARD_GROWTH: f64 = 4.0;
/// The largest Newton correction of a landed event instant, relative to the landed step: the
/// dense output's error moves the root by far less; more means something else went wrong, and
/// the dense output's state is taken.
const LANDING_CORRECTION: f64 = 1e-3;
/// Floating-point spacings of `t` a landed instant moves on at most until every guard of its
/// group is on the crossed side.
const LANDING_NUDGES: usize = 8;
/// Rounds of cascading events at one instant before the run stops as stuck.
pub(crate) const MAX_CASCADE_ROUNDS: usize = 100;

/// A step retried to land just before a flow switch it crossed (see `retry_before_switch`).
#[derive(Clone, Copy, Debug)]
struct SwitchLanding {
    /// The last time before the switch, on the crossing attempt's interpolant: the step lands here.
    t_pre: f64,
    /// Retries of this step so far.
    retries: u8,
    /// The switch's position in the mode's events and its pre-crossing sign.
    pos: usize,
    sigma: f64,
}

/// What one [`Integrator::step`] did.
#[derive(Clone, Debug, PartialEq)]
pub enum StepOutcome {
    /// The attempt failed the error test; the step size shrank and the state did not move.
    Rejected,
    /// The state moved to the end of the step; nothing fired.
    Accepted,
    /// The step was cut at an event instant and a group fired there: the run's events
    /// `first..first + count` (flow switches are not events, so `count` may be 0).
    Fired { first: usize, count: usize },
    /// The run is over: this is why. Further calls return the same.
    Done(StopReason),
}

/// The scratch state of a run, sized by the model and the options; kept by a `Simulator`
/// between runs so that a run allocates only what its result holds.
pub(crate) struct Workspace<St: Stepper = Rk> {
    pub(crate) stepper: St,
    pub(crate) det: Detector,
    pub(crate) jump: Jump,
    pub(crate) breakpoints: Breakpoints,
    /// The integrated vector `[x, S]`.
    pub(crate) z: Vec<f64>,
    /// The events of the last group that fired: id, pre-crossing sign, crossing speed.
    pub(crate) fired: Vec<(usize, f64, f64)>,
    /// The output Jacobians `y_x`, `y_p`, `y_t` at the final state.
    pub(crate) output_jac: (Vec<f64>, Vec<f64>, Vec<f64>),
    /// The states on either side of a flow switch.
    pub(crate) x_sides: (Vec<f64>, Vec<f64>),
    /// Outputs and an interpolated `z` for recorded points.
    pub(crate) record_buf: (Vec<f64>, Vec<f64>),
    /// The state before a round of events at one instant, and the guards there.
    pub(crate) before: (Vec<f64>, Vec<f64>),
    /// `dt/dp` of the instant being fired (the first event's), for cascading events.
    pub(crate) instant_dte: Vec<f64>,
    /// Which sensitivities are known not to exist (NaN), for warning once about new ones.
    pub(crate) void: Vec<bool>,
}

/// Derivatives as a result reports them: `None` when none exists (every entry NaN, and there is
/// at least one), else every entry, NaN where that one does not exist.
fn existing(d: &[f64]) -> Option<Vec<f64>> {
    (d.is_empty() || d.iter().any(|v| !v.is_nan())).then(|| d.to_vec())
}

/// The flow of `mode` with its sensitivities as one right-hand side over `z = [x, S]`, with the
/// model's Jacobians for an implicit stepper.
struct ModeRhs<'a, S: HybridSystem + ?Sized> {
    sys: &'a S,
    p: &'a [f64],
    n: usize,
    mode: usize,
}

fn rhs_for<'a, S: HybridSystem + ?Sized>(sys: &'a S, p: &'a [f64], n: usize, mode: usize) -> ModeRhs<'a, S> {
    ModeRhs { sys, p, n, mode }
}

impl<S: HybridSystem + ?Sized> Rhs for ModeRhs<'_, S> {
    #[inline(always)]
    fn eval(&mut self, t: f64, z: &[f64], dz: &mut [f64]) {
        let (x, s) = z.split_at(self.n);
        let (dx, ds) = dz.split_at_mut(self.n);
        self.sys.flow_sens(self.mode, t, x, s, self.p, dx, ds);
    }

    fn jacobian(&mut self, t: f64, z: &[f64], fx: &mut [f64], ft: &mut [f64]) {
        let (x, s) = z.split_at(self.n);
        let (ftx, fts) = ft.split_at_mut(self.n);
        self.sys.flow_jac(self.mode, t, x, s, self.p, fx, ftx, fts);
    }

    fn jac_pattern(&self) -> Option<(usize, &[(u32, u32)])> {
        self.sys.jac_pattern(self.mode).map(|p| (self.mode, p))
    }

    fn jacobian_values(&mut self, t: f64, z: &[f64], vals: &mut [f64], ft: &mut [f64]) {
        let (x, s) = z.split_at(self.n);
        let (ftx, fts) = ft.split_at_mut(self.n);
        self.sys.flow_jac_values(self.mode, t, x, s, self.p, vals, ftx, fts);
    }

    fn sens_coupling(&mut self, t: f64, xv: &[f64], z: &[f64], out: &mut [f64]) {
        self.sys.sens_dir(self.mode, t, xv, &z[self.n..], self.p, out);
    }

    fn prepare(&mut self) -> bool {
        self.sys.prepare_jacobians().is_ok()
    }
}

/// One run in progress. Made by `Simulator::integrator`; [`Self::step`] advances it,
/// [`Self::finish`] turns it into the run's result.
pub struct Integrator<'a, S: HybridSystem + ?Sized, R: Recorder, St: Stepper = Rk> {
    /// The values at `SimOptions::at` taken so far (the next one due is `samples.len()`).
    samples: Samples,
    sys: &'a S,
    info: &'a SystemInfo,
    p: &'a [f64],
    opts: &'a SimOptions,
    n: usize,
    m: usize,
    t: f64,
    mode: usize,
    z: &'a mut Vec<f64>,
    stepper: &'a mut St,
    det: &'a mut Detector,
    jump: &'a mut Jump,
    breakpoints: &'a mut Breakpoints,
    fired: &'a mut Vec<(usize, f64, f64)>,
    output_jac: &'a mut (Vec<f64>, Vec<f64>, Vec<f64>),
    x_sides: &'a mut (Vec<f64>, Vec<f64>),
    record_buf: &'a mut (Vec<f64>, Vec<f64>),
    before: &'a mut (Vec<f64>, Vec<f64>),
    instant_dte: &'a mut Vec<f64>,
    void: &'a mut Vec<bool>,
    recorder: &'a mut R,
    /// The step size the next attempt tries.
    h: f64,
    attempts: usize,
    nonfinite_rejects: usize,
    /// Accepted steps on which a running cost left out of the error test had a scaled error
    /// above 1 (`Stepper::outside_error`): how many, the worst, its time and state.
    unresolved_cost: Option<UnresolvedCost>,
    /// A group prepared at the current instant (events that start on their guard), fired by the
    /// next `step` before any integration.
    immediate: bool,
    /// Whether `instant_dte` holds the current instant's `dt/dp`, and its crossing speed.
    instant: Option<f64>,
    /// The mode the last step integrated in (the detector's speeds belong to its guards).
    step_mode: usize,
    events: Vec<EventRecord>,
    warnings: Vec<SimWarning>,
    stats: SimStats,
    /// Total derivative of the final state and `dt/dp` of a stop event.
    stop_total: Option<(Vec<f64>, Vec<f64>)>,
    done: Option<StopReason>,
    /// A step that crossed a flow switch is retried landing just before it (the last time on
    /// the old branch): the time to land on, and how often this step has been retried so.
    land_before_switch: Option<SwitchLanding>,
    /// The first time past the flow switches crossed at the current instant where their new
    /// branches hold (see `cross_switch`).
    switch_post: Option<f64>,
    /// Events of the next cascade round whose guard the last round reset onto zero to round-off
    /// (firing because the flow carries them across): their time derivative does not exist.
    reset_onto_guard: Vec<usize>,
    /// Their `dt/dp` (NaN where a parameter moves the instant or the guard).
    onto_guard_dte: Vec<f64>,
    /// The state and sensitivities just before an instant at `t_end` (for `SimResult::end_cusp`).
    before_end: Option<(Vec<f64>, usize)>,
}

impl<'a, S: HybridSystem + ?Sized, R: Recorder, St: Stepper> Integrator<'a, S, R, St> {
    /// Starts a run of `sys` at `p` (checked by the caller: `n_params` long) with options checked
    /// by the caller: the initial state and sensitivities, the first step size, the first
    /// recorded point.
    pub(crate) fn new(
        sys: &'a S,
        p: &'a [f64],
        opts: &'a SimOptions,
        work: &'a mut Workspace<St>,
        recorder: &'a mut R,
    ) -> Self {
        let info = sys.info();
        let (n, m) = (info.n_states(), info.n_grad());
        let Workspace {
            stepper,
            det,
            jump,
            breakpoints,
            z,
            fired,
            output_jac,
            x_sides,
            record_buf,
            before,
            instant_dte,
            void,
        } = work;
        stepper.reset();
        breakpoints.reset(opts.t_end);
        sys.initial_state(p, &mut z[..n]);
        sys.initial_sens(p, &mut z[n..]);
        void.fill(false);
        let mut it = Integrator {
            sys,
            info,
            p,
            opts,
            n,
            m,
            t: opts.t_start,
            mode: info.initial_mode,
            z,
            stepper,
            det,
            jump,
            breakpoints,
            fired,
            output_jac,
            x_sides,
            record_buf,
            before,
            instant_dte,
            void,
            recorder,
            h: 0.0,
            attempts: 0,
            nonfinite_rejects: 0,
            unresolved_cost: None,
            immediate: false,
            instant: None,
            step_mode: info.initial_mode,
            events: Vec::new(),
            warnings: Vec::new(),
            stats: SimStats::default(),
            stop_total: None,
            done: None,
            land_before_switch: None,
            switch_post: None,
            reset_onto_guard: Vec::new(),
            onto_guard_dte: Vec::new(),
            before_end: None,
            samples: Samples::with_capacity((n, m, info.n_outputs()), opts.at.len()),
        };
        if it.z[..n].iter().any(|v| !v.is_finite()) {
            it.done = Some(it.fault_nonfinite());
            return it;
        }
        let t0 = it.t;
        it.note_new_voids(t0);
        it.add_time_events();
        it.h = it.restart();
        // A reused detector may remember bounces of an earlier run.
        it.det.clear_bounces();
        it.record(PointKind::Start);
        it.record_due_samples_at_current_point();
        it.start_on_guards();
        it
    }

    /// Time events (`t >= expression of parameters`) land on their time exactly: their times in
    /// `(t_start, t_end)` become breakpoints.
    fn add_time_events(&mut self) {
        let n = self.n;
        for mode in 0..self.info.modes.len() {
            let evs = &self.info.modes[mode].events;
            if !evs.iter().any(|&ev| self.info.events[ev].guard == GuardShape::Time) {
                continue;
            }
            // A time event's guard is `slope t + c`: its value at t = 0 is `c`.
            let ne = evs.len();
            let (gx, g) = &mut *self.before;
            g.resize(ne, 0.0);
            gx.resize(n, 0.0);
            self.instant_dte.resize(self.m, 0.0);
            self.sys.guards(mode, 0.0, &self.z[..n], self.p, &mut g[..ne]);
            let mut switches = Vec::new();
            for (pos, &ev) in evs.iter().enumerate() {
                if self.info.events[ev].guard != GuardShape::Time {
                    continue;
                }
                let slope =
                    self.sys.guard_grad(ev, 0.0, &self.z[..n], self.p, &mut gx[..n], self.instant_dte);
                let t_event = -g[pos] / slope;
                if self.info.events[ev].implicit && t_event.is_finite() {
                    switches.push((pos, t_event, slope));
                } else if t_event > self.opts.t_start && t_event < self.opts.t_end {
                    self.breakpoints.add(t_event);
                }
            }
            for (pos, t_est, slope) in switches {
                let t_event = self.first_time_across(mode, pos, t_est, slope);
                if t_event > self.opts.t_start && t_event < self.opts.t_end {
                    self.breakpoints.add(t_event);
                }
            }
        }
        self.breakpoints.sort();
    }

    /// The first time, within a few spacings of `t` from `t_est`, where the time-event guard at
    /// `pos` of `mode` (moving with `slope`) is across zero (`>= 0` rising). `-g(0) / slope`
    /// rounds: a flow switch landed on an ulp short of it (a `pwc` knot at
    /// `(t - 0.1) * 4 / 0.8 = 0.9999999999999999` at t = 0.3) would be crossed just inside the
    /// next step, whose first stage then reads the old branch and later ones the new.
    fn first_time_across(&mut self, mode: usize, pos: usize, t_est: f64, slope: f64) -> f64 {
        const NUDGES: usize = 64;
        let n = self.n;
        let ne = self.info.modes[mode].events.len();
        let mut g = vec![0.0; ne];
        let mut across = |sys: &S, t: f64, z: &[f64]| {
            sys.guards(mode, t, &z[..n], self.p, &mut g);
            slope.signum() * g[pos] >= 0.0
        };
        let mut t = t_est;
        for _ in 0..NUDGES {
            if across(self.sys, t, self.z) {
                break;
            }
            t = t.next_up();
        }
        for _ in 0..NUDGES {
            let before = t.next_down();
            if !across(self.sys, before, self.z) {
                break;
            }
            t = before;
        }
        t
    }

    /// Events whose guard the run starts on, with the flow carrying it to the crossed side, fire
    /// at the start (the first `step`); with no clear speed the first step decides.
    fn start_on_guards(&mut self) {
        if self.done.is_some() {
            return;
        }
        self.det.group.clear();
        let (t, n) = (self.t, self.n);
        let evs = &self.info.modes[self.mode].events;
        let mut enabled = false;
        for (pos, &ev) in evs.iter().enumerate() {
            let einfo = &self.info.events[ev];
            if einfo.implicit || self.det.g0[pos].is_nan() {
                continue;
            }
            let (noise, speed_noise) = self.det.noise0(self.sys, self.info, self.mode, pos, self.p);
            if self.det.g0[pos].abs() > noise {
                if einfo.direction != Direction::Either
                    && clear_side(einfo.direction, self.det.g0[pos], noise) == Some(true)
                {
                    let (name, guard) = (einfo.name.clone(), self.det.g0[pos]);
                    self.warnings.push(SimWarning::StartsAcross { event: ev, name, time: t, guard });
                }
                continue;
            }
            match moves_across(einfo.direction, self.det.dg0[pos], speed_noise) {
                Some(sigma) => {
                    // As in every group, each condition is judged when its event's turn comes.
                    enabled |= self.sys.condition(ev, t, &self.z[..n], self.p);
                    let c = Crossing { t, sigma, touch: false, t_pre: t, on_guard: true };
                    self.det.group.push((ev, c));
                }
                None if self.det.dg0[pos].abs() <= speed_noise => {
                    self.det.pending[pos] = Pending::OnGuard;
                }
                None => {}
            }
        }
        if !enabled {
            self.det.group.clear();
        }
        self.immediate = enabled;
    }

    /// Branch locking by cutting: a step whose stages straddle a flow switch evaluated the flow
    /// past it on the other branch, and its whole polynomial (the state at every time of the
    /// step, events before the switch included) carries that error: a pulse narrower than a step
    /// was lost whole. Such a step is retried landing exactly on the last time before the switch
    /// (the first located on the interpolant), where every stage is on the branch of the step's
    /// start; the next step then crosses the switch within its first floating-point spacings.
    /// Returns whether to retry. A switch within a resolvable distance of the start is crossed as
    /// before; the landing time must fall at each retry (at most [`SWITCH_RETRIES`]), so this
    /// ends.
    fn retry_before_switch(&mut self, t0: f64) -> bool {
        let Some((pos, crossing)) =
            self.det.earliest_switch(self.sys, self.info, self.mode, self.stepper.interpolant(), self.p)
        else {
            return false;
        };
        let t_pre = crossing.t_pre;
        let resolvable = t_pre - t0 > 8.0 * EPS * t0.abs().max(f64::MIN_POSITIVE);
        let retries = match self.land_before_switch {
            Some(l) if l.t_pre > t0 => {
                if t_pre >= l.t_pre || l.retries >= SWITCH_RETRIES {
                    return false;
                }
                l.retries + 1
            }
            _ => 1,
        };
        if !resolvable {
            return false;
        }
        self.det.forget_findings();
        self.land_before_switch = Some(SwitchLanding { t_pre, retries, pos, sigma: crossing.sigma });
        self.h = t_pre - t0;
        true
    }

    /// After an attempt rejected by its error test in a mode with flow switches: whether it
    /// crossed one, found as for an accepted step (the attempt's interpolant is only as good as
    /// the attempt, but good enough to aim the retry at the switch), then as
    /// `retry_before_switch`.
    fn retry_after_rejected_switch<F: Rhs>(&mut self, t0: f64, t1: f64, rhs: &mut F) -> bool {
        let evs = &self.info.modes[self.mode].events;
        if !evs.iter().any(|&ev| self.info.events[ev].implicit) {
            return false;
        }
        let n = self.n;
        self.det.eval_end(self.sys, self.info, self.mode, t1, &*self.stepper, n, self.p);
        if !self.det.mark_candidates(self.info, self.mode) {
            return false;
        }
        self.stepper.build_interpolant(t0, self.z, rhs);
        self.det.check_resolution(self.sys, self.info, self.mode, self.stepper.interpolant(), self.p);
        self.det.scan(self.sys, self.info, self.mode, self.stepper.interpolant(), self.p, t1);
        let retry = self.retry_before_switch(t0);
        self.det.forget_findings();
        retry
    }

    /// A step that landed just before the flow switch it was retried for, with the switch still
    /// a few spacings of `t` ahead: the switch is crossed right there (`group` holds it), rather
    /// than by a next step whose first stage would be on the old branch and the others on the
    /// new (its error estimate would reject it again and again, creeping up on the switch).
    fn switch_at_landing(&mut self, t1: f64) -> bool {
        let Some(landing) = self.land_before_switch.filter(|l| l.t_pre == t1) else {
            return false;
        };
        let (g, speed) = (self.det.g1[landing.pos], self.det.dg1[landing.pos]);
        let spacing = t1.abs().next_up() - t1.abs();
        let near =
            g.is_finite() && landing.sigma * g >= 0.0 && g.abs() <= SWITCH_NEAR * spacing * speed.abs();
        // With a breakpoint (a time event) before the predicted crossing, the next step lands on
        // it and crosses the switch there, with the event, in time order.
        let t_cross = t1 + g.abs() / speed.abs() + spacing;
        if !near || self.breakpoints.next_after(t1) <= t_cross {
            return false;
        }
        let ev = self.info.modes[self.mode].events[landing.pos];
        // Not crossed yet (the guard is a few spacings short of zero): like a touch, it fires
        // without its guard on the crossed side, which `fire_group` would otherwise take for a
        // state moved back by an earlier reset and skip. Skipped, the switch was left to the next
        // step, whose error estimate straddles the jump of the flow: with sensitivities at zero
        // (scaled by atol) it shrank to an underflow (the soft ball's first contact, issue #25).
        let crossing = Crossing { t: t1, sigma: landing.sigma, touch: true, t_pre: t1, on_guard: false };
        self.det.group.clear();
        self.det.group.push((ev, crossing));
        true
    }

    /// At the end of the run's last step: events whose crossing is at `t_end` to round-off fire
    /// there (`Detector::on_guard_at_end`), when the first of them to fire has its condition.
    fn end_on_guards(&mut self) -> bool {
        if !self.det.on_guard_at_end(self.sys, self.info, self.mode, self.p) {
            return false;
        }
        let x = &self.stepper.end_state()[..self.n];
        let t = self.opts.t_end;
        let enabled = self.det.group.iter().any(|&(ev, _)| self.sys.condition(ev, t, x, self.p));
        if !enabled {
            self.det.group.clear();
        }
        enabled
    }

    /// The current time.
    pub fn t(&self) -> f64 {
        self.t
    }

    /// The current mode.
    pub fn mode(&self) -> usize {
        self.mode
    }

    /// The current state.
    pub fn state(&self) -> &[f64] {
        &self.z[..self.n]
    }

    /// The current sensitivities, column per parameter (`s[j * n + i] = dx_i/dp_j`).
    pub fn sensitivities(&self) -> &[f64] {
        &self.z[self.n..]
    }

    /// The events fired so far.
    pub fn events(&self) -> &[EventRecord] {
        &self.events
    }

    /// Attempts one step and says what happened.
    pub fn step(&mut self) -> StepOutcome {
        if let Some(stop) = &self.done {
            return StepOutcome::Done(stop.clone());
        }
        let outcome = self.advance();
        if let StepOutcome::Done(stop) = &outcome {
            self.done = Some(stop.clone());
        }
        outcome
    }

    fn advance(&mut self) -> StepOutcome {
        if self.immediate {
            self.immediate = false;
            let estimate = self.h;
            self.record(PointKind::BeforeEvents);
            return self.fire_instant(estimate);
        }
        let t_end = self.opts.t_end;
        if self.t >= t_end {
            return StepOutcome::Done(StopReason::TEnd);
        }
        if self.attempts >= self.opts.max_steps {
            return StepOutcome::Done(StopReason::Fault {
                error: SimError::TooManySteps {
                    t: self.t,
                    max_steps: self.opts.max_steps,
                    mode: self.mode,
                    state: self.fault_state(),
                },
            });
        }
        let t0 = self.t;
        let mut t_land = self.breakpoints.next_after(t0);
        if let Some(landing) = self.land_before_switch.filter(|l| l.t_pre > t0) {
            t_land = t_land.min(landing.t_pre);
        }
        let mut h_try = self.h.min(self.opts.h_max);
        let lands = t0 + 1.01 * h_try >= t_land;
        if lands {
            h_try = t_land - t0;
        }
        // A step that lands on a breakpoint is taken however short: two events a few spacings of
        // `t` apart (a state event just before a time event, time events at `0.1 + 0.2` and
        // `0.3`) fire in time order (rule 8). Breakpoints are finitely many and each step passes
        // one, so this cannot stall; only the error control's own shrinking is an underflow.
        let h_resolvable = (h_try > 8.0 * EPS * t0.abs() || lands) && h_try > 0.0;
        if !h_resolvable {
            return StepOutcome::Done(StopReason::Fault {
                error: SimError::StepTooSmall {
                    t: t0,
                    h: h_try,
                    mode: self.mode,
                    state: self.fault_state(),
                    rtol: self.opts.rtol,
                    atol: self.opts.atol,
                },
            });
        }
        self.attempts += 1;
        let mut rhs = rhs_for(self.sys, self.p, self.n, self.mode);
        let err = self.stepper.attempt(t0, self.z, h_try, &mut rhs);
        if err > 1.0 || err.is_nan() {
            self.stats.rejected += 1;
            if err.is_finite() {
                self.nonfinite_rejects = 0;
            } else {
                self.nonfinite_rejects += 1;
                if self.nonfinite_rejects > MAX_NONFINITE_REJECTS {
                    return StepOutcome::Done(self.fault_nonfinite());
                }
            }
            self.h = self.stepper.shrink(err);
            // A step that failed its error test because it crossed a flow switch: shrinking by
            // the error alone would creep up on the switch in many rejected steps.
            let t1 = if lands { t_land } else { t0 + h_try };
            if err.is_finite() {
                // Sets `h` to land before the switch when there is one.
                self.retry_after_rejected_switch(t0, t1, &mut rhs);
            }
            return StepOutcome::Rejected;
        }
        self.nonfinite_rejects = 0;
        let t1 = if lands { t_land } else { t0 + h_try };
        let n = self.n;
        self.det.eval_end(self.sys, self.info, self.mode, t1, &*self.stepper, n, self.p);
        let for_events = self.det.mark_candidates(self.info, self.mode);
        let sample_due = self.sample_due(t1);
        if for_events || sample_due {
            self.stepper.build_interpolant(t0, self.z, &mut rhs);
        }
        let mut guard_factor = f64::INFINITY;
        if for_events {
            let control =
                self.det.check_resolution(self.sys, self.info, self.mode, self.stepper.interpolant(), self.p);
            if !control.resolved && h_try > GUARD_RESOLUTION_FLOOR * t0.abs().max(1.0) {
                // A guard not resolved by the step: shorter, as for an error estimate.
                self.stats.rejected += 1;
                self.h = h_try * control.factor.min(0.9);
                return StepOutcome::Rejected;
            }
            if control.factor.is_finite() {
                guard_factor = control.factor.min(GUARD_GROWTH);
            }
        }
        self.note_cost_error(t0);
        let h_next = self.stepper.grow(err).min(h_try * guard_factor);
        self.stats.steps += 1;
        let mut selection = if for_events {
            self.det.scan(self.sys, self.info, self.mode, self.stepper.interpolant(), self.p, t1);
            if let Some(pos) = self.det.stuck() {
                return StepOutcome::Done(self.stuck_on_guard(self.info.modes[self.mode].events[pos]));
            }
            if self.retry_before_switch(t0) {
                self.stats.rejected += 1;
                return StepOutcome::Rejected;
            }
            self.det.select(self.sys, self.info, self.mode, self.stepper.interpolant(), self.p)
        } else {
            Selection::Nothing
        };
        if matches!(selection, Selection::Nothing) && lands && self.switch_at_landing(t1) {
            if !(for_events || sample_due) {
                self.stepper.build_interpolant(t0, self.z, &mut rhs);
            }
            selection = Selection::Fire(t1);
        }
        if matches!(selection, Selection::Nothing) && lands && t1 >= self.opts.t_end && self.end_on_guards() {
            if !(for_events || sample_due) {
                self.stepper.build_interpolant(t0, self.z, &mut rhs);
            }
            selection = Selection::Fire(t1);
        }
        match selection {
            Selection::Nothing if self.det.penetrated().is_some() => {
                // Stop where the last bounce left the state (the step is not taken).
                StepOutcome::Done(zeno::stop(&self.events))
            }
            Selection::Nothing => {
                if sample_due {
                    self.record_samples(t1, false);
                }
                let singular_at_start = self.stepper.masked() && self.start_derivative_not_finite();
                self.stepper.accept(self.z);
                self.t = t1;
                self.land_before_switch = None;
                if self.stepper.masked() {
                    self.note_new_voids(if singular_at_start { t0 } else { t1 });
                }
                self.det.advance();
                self.record(PointKind::Step);
                self.h = h_next;
                StepOutcome::Accepted
            }
            Selection::NotFinite { pos, t } => {
                if sample_due || self.sample_due(t) {
                    self.record_samples(t, true);
                }
                self.stepper.interpolant().eval(t, self.z);
                self.t = t;
                let event = self.info.events[self.info.modes[self.mode].events[pos]].name.clone();
                let error = SimError::GuardNotFinite { event, t, mode: self.mode, state: self.fault_state() };
                StepOutcome::Done(StopReason::Fault { error })
            }
            Selection::Fire(t_fire) => {
                if sample_due || self.sample_due(t_fire) {
                    self.record_samples(t_fire, true);
                }
                let singular_at_start = self.stepper.masked() && self.start_derivative_not_finite();
                let t_fire = if t_fire == t1 {
                    // On the step's end: the step's own end state. The dense output reproduces
                    // it only to round-off, and a guard found across there by the end values (an
                    // event at `t_end`, `x = 0.3 t` reaching 0.3) could be read back on its
                    // pre-crossing side and skipped as moved back by an earlier reset.
                    self.z.copy_from_slice(self.stepper.end_state());
                    t_fire
                } else if let Some(t_landed) = self.land_on_event(t0, t_fire, &mut rhs) {
                    t_landed
                } else {
                    self.stepper.interpolant().eval(t_fire, self.z);
                    t_fire
                };
                self.t = t_fire;
                self.land_before_switch = None;
                if self.stepper.masked() {
                    self.note_new_voids(if singular_at_start { t0 } else { t_fire });
                }
                self.record(PointKind::BeforeEvents);
                self.fire_instant(h_next)
            }
        }
    }

    /// Retakes the step from `(t0, z)` landing on the event instant `t_fire` located inside it
    /// on the dense output (`Stepper::land`), so that the state and sensitivities the events jump
    /// from come from a step end under the error control, not from the dense output, which no
    /// error test controls (a Rosenbrock interpolant is of order 3 to 4; an explicit one is poor
    /// for components at the stability boundary). The landed state's guards are then off zero by
    /// the dense output's error: the instant moves by one Newton step with the guards' speeds
    /// there (the latest of the group's, so that every guard has crossed), and the state and
    /// sensitivities with it to first order, `z + dt F(z)` (an error of order `dt^2`), then by
    /// floating-point spacings until every guard of the group is on its crossed side (rule 1:
    /// the first time found there). Writes that state into `z` and returns the instant; `None`
    /// (the caller takes the dense output's state at `t_fire`, as without landing) when landing
    /// is off, when the group holds a touch, an event fired on its guard at the step's start or a
    /// flow switch (their state and sides are the dense output's: `cross_switch`), when the
    /// landed step fails its error test (it is shorter, so rarely) or when the correction is not
    /// small against the step.
    fn land_on_event<F: Rhs>(&mut self, t0: f64, t_fire: f64, rhs: &mut F) -> Option<f64> {
        if t_fire <= t0 || !self.lands_on_events() {
            return None;
        }
        let evs = &self.info.modes[self.mode].events;
        let plain = |&(ev, c): &(usize, Crossing)| !(c.touch || c.on_guard || self.info.events[ev].implicit);
        if !self.det.group.iter().all(plain) {
            return None;
        }
        let h = t_fire - t0;
        let err = self.stepper.land(t0, self.z, h, rhs);
        // A NaN error (nothing finite) fails too.
        if err.is_nan() || err > 1.0 {
            return None;
        }
        let n = self.n;
        self.z.copy_from_slice(self.stepper.end_state());
        let f = self.stepper.end_derivative();
        let mut dt = f64::NEG_INFINITY;
        for gi in 0..self.det.group.len() {
            let (ev, _) = self.det.group[gi];
            let pos = evs.iter().position(|&e| e == ev)?;
            let (g, speed) =
                self.det.guard_and_speed(self.sys, self.mode, pos, ev, t_fire, &self.z[..n], &f[..n], self.p);
            dt = dt.max(-g / speed);
        }
        if !(dt.is_finite() && dt.abs() <= LANDING_CORRECTION * h) {
            return None;
        }
        let end = self.stepper.end_state();
        let mut t = t_fire + dt;
        for _ in 0..LANDING_NUDGES {
            let dt = t - t_fire;
            for ((z, &e), &d) in self.z.iter_mut().zip(end).zip(f) {
                *z = e + dt * d;
            }
            let mut crossed = true;
            for gi in 0..self.det.group.len() {
                let (ev, c) = self.det.group[gi];
                let pos = evs.iter().position(|&e| e == ev)?;
                let g = self.det.guard_now(self.sys, self.mode, pos, t, &self.z[..n], self.p);
                crossed &= c.sigma * g <= 0.0;
            }
            if crossed {
                return (t > t0).then_some(t);
            }
            t = t.next_up();
        }
        None
    }

    /// Whether event instants inside a step are landed on ([`Self::land_on_event`]).
    fn lands_on_events(&mut self) -> bool {
        match self.opts.land_events {
            Some(land) => land,
            None => self.stepper.lands_on_events(self.z),
        }
    }

    /// Fires the group selected at the current instant, then the events that cascade from it
    /// (rounds at the same instant), and applies the rules that follow an instant: contacts left
    /// on their guard, bounces, guards reset onto zero, `max_events`, Zeno. `h_next` is the
    /// controller's proposal from the step that led here.
    fn fire_instant(&mut self, h_next: f64) -> StepOutcome {
        let n = self.n;
        let first = self.events.len();
        let mode_before = self.mode;
        self.step_mode = self.mode;
        self.instant = None;
        self.switch_post = None;
        self.fired.clear();
        self.before.0.clear();
        self.before.0.extend_from_slice(&self.z[..n]);
        if on_breakpoint(self.t, self.opts.t_end) {
            // An instant at t_end: the other side of the cusp is the run without it.
            self.before_end = Some((self.z.to_vec(), first));
        }
        let mut rounds = 0;
        let mut estimate;
        let mut reset_onto: Vec<usize> = Vec::new();
        loop {
            let round_start = self.fired.len();
            if let Some(stop) = self.fire_group(rounds > 0) {
                return StepOutcome::Done(stop);
            }
            if self.z[..n].iter().any(|v| !v.is_finite()) {
                return StepOutcome::Done(self.fault_nonfinite());
            }
            if rounds == 0 {
                self.restart_past_switches();
            }
            estimate = self.restart();
            reset_onto.clear();
            if !self.cascade(round_start, &mut reset_onto) {
                break;
            }
            rounds += 1;
            if rounds > MAX_CASCADE_ROUNDS {
                let ev = self.det.group.first().map_or(0, |&(ev, _)| ev);
                return StepOutcome::Done(StopReason::Stuck {
                    time: self.t,
                    event: ev,
                    name: self.info.events[ev].name.clone(),
                    rounds: MAX_CASCADE_ROUNDS,
                });
            }
            self.before.0.clear();
            self.before.0.extend_from_slice(&self.z[..n]);
        }
        self.record(PointKind::AfterEvents);
        self.record_at_current_point();
        for (void, s) in self.void.iter_mut().zip(&self.z[self.n..]) {
            *void |= s.is_nan();
        }
        if self.events.len() >= self.opts.max_events {
            return StepOutcome::Done(StopReason::MaxEvents { time: self.t, count: self.events.len() });
        }
        if let Some(stop) = zeno::accumulating(&self.events) {
            return StepOutcome::Done(stop);
        }
        if let Some(stop) = self.after_instant(&reset_onto) {
            return StepOutcome::Done(stop);
        }
        let growth = if self.mode == mode_before { AFTER_RESET_GROWTH } else { AFTER_SWITCH_GROWTH };
        self.h = self.continue_step(h_next, estimate, growth);
        // The step that found this instant saw further crossings: the next step reaches just past
        // the earliest of them rather than over all of them again (each would be bracketed and
        // scanned only for the earliest to fire).
        if let Some(t_next) =
            self.det.next_crossing.take().filter(|&t| t > self.t && self.mode == mode_before)
        {
            // At least a resolvable step: a crossing a few spacings of `t` ahead is then inside it.
            let floor = 16.0 * EPS * self.t.abs();
            self.h = self.h.min((NEXT_CROSSING_REACH * (t_next - self.t)).max(floor));
        }
        StepOutcome::Fired { first, count: self.events.len() - first }
    }

    /// After a round of events (`before.0` holds the state before it, the detector the guards
    /// after it; the round's events are `fired[round_start..]`): the events whose guard the round moved from strictly its pre-crossing side to
    /// its crossed side, or onto zero with the flow carrying it across, fill the next group (the
    /// next round at this instant). Guards moved onto zero with no clear speed go to
    /// `reset_onto`, for the next step to decide. Returns whether there is a next round.
    fn cascade(&mut self, round_start: usize, reset_onto: &mut Vec<usize>) -> bool {
        let (t, n) = (self.t, self.n);
        let evs = &self.info.modes[self.mode].events;
        let ne = evs.len();
        self.det.group.clear();
        // The events that just fired were at their crossing before the round, never strictly on
        // their pre-crossing side: when they are all the mode has, nothing can cascade.
        let fired_now = &self.fired[round_start..];
        if evs.iter().all(|ev| fired_now.iter().any(|f| f.0 == *ev)) {
            return false;
        }
        let mut enabled = false;
        self.reset_onto_guard.clear();
        let (x_before, g_before) = &mut *self.before;
        g_before.resize(ne, 0.0);
        self.sys.guards(self.mode, t, x_before, self.p, &mut g_before[..ne]);
        for (pos, &ev) in evs.iter().enumerate() {
            let einfo = &self.info.events[ev];
            // A guard the round did not move cannot have been moved across.
            if einfo.implicit || g_before[pos] == self.det.g0[pos] {
                continue;
            }
            let dir = einfo.direction;
            let (noise, speed_noise) = self.det.noise0(self.sys, self.info, self.mode, pos, self.p);
            if clear_side(dir, g_before[pos], noise) != Some(false) {
                continue;
            }
            let after = self.det.g0[pos];
            let sigma = match clear_side(dir, after, noise) {
                Some(true) => g_before[pos].signum(),
                Some(false) => continue,
                None => match moves_across(dir, self.det.dg0[pos], speed_noise) {
                    Some(sigma) => {
                        self.reset_onto_guard.push(ev);
                        sigma
                    }
                    None => {
                        if self.det.dg0[pos].abs() <= speed_noise {
                            reset_onto.push(pos);
                        }
                        continue;
                    }
                },
            };
            // Every moved guard joins the round, its condition judged when its turn comes (an
            // earlier event of the round may make it true); the round happens when the first
            // event to fire, which sees the state as the last round left it, has its condition.
            enabled |= self.sys.condition(ev, t, &self.z[..n], self.p);
            self.det.group.push((ev, Crossing { t, sigma, touch: false, t_pre: t, on_guard: true }));
        }
        if !enabled {
            self.det.group.clear();
        }
        enabled
    }

    /// The rules after an instant: a contact that fired and is left on its guard is stuck when
    /// the flow carries it across (or pending when the speed is round-off), a reset that reversed
    /// a guard's speed is a bounce watched for penetration, guards reset onto zero are pending.
    fn after_instant(&mut self, reset_onto: &[usize]) -> Option<StopReason> {
        self.det.clear_bounces();
        for &pos in reset_onto {
            self.det.pending[pos] = Pending::OnGuard;
        }
        let evs = &self.info.modes[self.mode].events;
        for &(ev, sigma, speed_before) in self.fired.iter() {
            let Some(pos) = evs.iter().position(|&e| e == ev) else { continue };
            let einfo = &self.info.events[ev];
            // Within round-off, or within what locating the crossing to adjacent floats leaves
            // (the speed before the event times a few spacings of `t`).
            let located = 4.0 * speed_before.abs() * (self.t.abs().next_up() - self.t.abs());
            let (noise, speed_noise) = self.det.noise0(self.sys, self.info, self.mode, pos, self.p);
            let on_guard = self.det.g0[pos].abs() <= noise + located;
            // Only a speed the reset left within round-off can be stuck: the first step decides
            // (`Pending::Contact`). A clear speed that keeps the crossing's direction is a
            // pass-through (a gear shift that changes the rate driving its own guard), one that
            // turns around is a bounce. Stopping on the first (round 2's rule) stopped every
            // gear shift, thermostat and dose that changes its own clearance.
            if einfo.contact && on_guard && self.det.dg0[pos].abs() <= speed_noise {
                self.det.pending[pos] = Pending::Contact;
                continue;
            }
            self.det.note_bounce(pos, sigma, speed_before);
        }
        None
    }

    /// A contact stuck on its guard at the current instant.
    fn stuck_on_guard(&self, ev: usize) -> StopReason {
        StopReason::Stuck { time: self.t, event: ev, name: self.info.events[ev].name.clone(), rounds: 0 }
    }

    fn fault_state(&self) -> Vec<f64> {
        self.z[..self.n].to_vec()
    }

    /// New start point (beginning, after events): derivative, guards and Hairer's step estimate
    /// for the new state.
    fn restart(&mut self) -> f64 {
        let mut rhs = rhs_for(self.sys, self.p, self.n, self.mode);
        self.stepper.restart(self.t, self.z, &mut rhs);
        let n = self.n;
        self.det.eval_start(
            self.sys,
            self.info,
            self.mode,
            self.t,
            &self.z[..n],
            &self.stepper.start_derivative()[..n],
            self.p,
        );
        self.stepper.initial_step(self.t, self.z, self.opts.h_max, &mut rhs)
    }

    /// The first step after an event: the controller's proposal from before the event, which
    /// knows the solution's scales far better than a fresh estimate (restarting from the
    /// estimate costs several steps of growth per event), but at most `growth` times the
    /// estimate for the post-event state ([`AFTER_RESET_GROWTH`], [`AFTER_SWITCH_GROWTH`]), in
    /// case the reset or the new mode made the dynamics much faster. The controller's memory is
    /// reset either way.
    fn continue_step(&self, proposal: f64, estimate: f64, growth: f64) -> f64 {
        if proposal.is_finite() && proposal > estimate {
            proposal.min(growth * estimate).min(self.opts.h_max)
        } else {
            estimate
        }
    }

    fn fault_nonfinite(&self) -> StopReason {
        StopReason::Fault {
            error: SimError::NonFinite { t: self.t, mode: self.mode, state: self.fault_state() },
        }
    }

    /// Fires the selected events at the current point in declaration order, each seeing the
    /// state the previous one left; `cascade` for a round after the first at this instant (its
    /// events take the instant's `dt/dp`). Returns a stop reason for a stop event.
    fn fire_group(&mut self, cascade: bool) -> Option<StopReason> {
        let (n, t) = (self.n, self.t);
        let group_len = self.det.group.len();
        let declared_before = self.fired.len();
        for gi in 0..group_len {
            let (ev, crossing): (usize, Crossing) = self.det.group[gi];
            let Some(pos) = self.info.modes[self.mode].events.iter().position(|&e| e == ev) else {
                // An earlier event of the group switched to a mode without this event.
                continue;
            };
            let context = self.crossing_context(pos, crossing, self.mode == self.step_mode);
            let (x, s) = self.z.split_at_mut(n);
            if !(crossing.touch || crossing.on_guard) {
                let g = self.det.guard_now(self.sys, self.mode, pos, t, x, self.p);
                if crossing.sigma * g > 0.0 {
                    // An earlier reset moved the state back before this guard.
                    continue;
                }
            }
            if !self.sys.condition(ev, t, x, self.p) {
                continue;
            }
            // Through the `&'a SystemInfo` itself, so that it does not hold `self` borrowed.
            let info: &'a SystemInfo = self.info;
            let einfo = &info.events[ev];
            if einfo.implicit {
                self.cross_switch(ev, pos, crossing, self.fired.len() > declared_before || cascade);
                continue;
            }
            let mode_before = self.mode;
            let mode_after = einfo.target_mode.unwrap_or(mode_before);
            let onto_guard = cascade && self.reset_onto_guard.contains(&ev);
            if onto_guard {
                // Put on its guard by a reset, to round-off: a parameter change lands the state
                // before the guard (the event fires later, by the flow) or across it (now), with
                // different derivatives on the two sides. None exists where the parameter moves
                // the instant or this guard; where it moves neither, 0.
                let (mut gx, mut gp) = (vec![0.0; n], vec![0.0; self.m]);
                self.sys.guard_grad(ev, t, x, self.p, &mut gx, &mut gp);
                self.onto_guard_dte.clear();
                for j in 0..self.m {
                    let moved = dot_nonzero(&gx, &s[j * n..(j + 1) * n]) + gp[j];
                    let still = moved == 0.0 && self.instant_dte.get(j).is_none_or(|&d| d == 0.0);
                    self.onto_guard_dte.push(if still { 0.0 } else { f64::NAN });
                }
                self.warnings.push(SimWarning::ResetOntoGuard {
                    event: ev,
                    name: einfo.name.clone(),
                    time: t,
                });
            }
            let given = match self.instant {
                Some(speed) if onto_guard => Some((&self.onto_guard_dte[..], speed)),
                Some(speed) if cascade => Some((&self.instant_dte[..], speed)),
                _ => None,
            };
            let out = self.jump.apply(
                self.sys,
                ev,
                mode_before,
                mode_after,
                t,
                x,
                s,
                self.p,
                context,
                einfo.is_stop,
                given,
            );
            if self.instant.is_none() && !cascade {
                self.instant = Some(out.denominator);
                self.instant_dte.clear();
                self.instant_dte.extend_from_slice(&self.jump.dte);
            }
            self.note_conditioning(ev, t, out);
            self.events.push(EventRecord {
                index: self.events.len(),
                event: ev,
                name: einfo.name.clone(),
                time: t,
                mode_before,
                mode_after,
                dtime: existing(&self.jump.dte),
                grazing: out.grazing,
                denominator: out.denominator,
                margin: out.margin,
                resolution: out.resolution,
            });
            self.stats.events += 1;
            self.fired.push((ev, crossing.sigma, out.denominator));
            self.mode = mode_after;
            if einfo.is_stop {
                self.stop_total = Some((self.jump.total.clone(), self.jump.dte.clone()));
                return Some(StopReason::Event { event: ev, name: einfo.name.clone() });
            }
        }
        None
    }

    /// Crosses the flow switch `ev` (at position `pos` of the mode's events) located at
    /// `crossing`; the state is already at the group's time. The sensitivities take the jump of
    /// the flow, read on the interpolant at the last time found before the switch and at the
    /// first time strictly past it (on the switch itself an `if` or `sign` may still give the
    /// old branch or neither). When a declared event of the same group has already fired, the
    /// state before the switch is not on the interpolant any more: the gradients are then marked
    /// as not meaningful instead.
    fn cross_switch(&mut self, ev: usize, pos: usize, crossing: Crossing, after_an_event: bool) {
        // A `pwl` knot: the flow is continuous across it, so nothing jumps; but its derivative
        // (the sensitivities' right-hand side, when the knot moves with a parameter) does, so
        // the run goes on past it like past a switch.
        let kink = self.info.events[ev].kink;
        let (n, t) = (self.n, self.t);
        if kink && (after_an_event || crossing.on_guard) {
            return;
        }
        if !kink {
            self.stats.switches += 1;
        }
        if after_an_event || crossing.on_guard {
            // The flow before the switch is not known: no sensitivity survives it.
            if self.z[n..].iter().any(|v| !v.is_nan()) {
                self.z[n..].fill(f64::NAN);
                let name = self.info.events[ev].name.clone();
                self.warnings.push(SimWarning::SwitchAtEvent { name, time: t });
            }
            return;
        }
        let context = self.crossing_context(pos, crossing, true);
        let dense = self.stepper.interpolant();
        let (x_pre, x_post) = &mut *self.x_sides;
        dense.eval(crossing.t_pre, x_pre);
        let mut t_post = t;
        let mut gap = 0.0;
        // The dense output holds within its step: the search for the far side reads it at most a
        // step length past the step's end, or 64 spacings of `t` past the crossing for a step
        // shorter than that (a step ending on the crossing finds the far side some ulps on).
        // Unbounded, a step of 2e-15 on the soft ball at wc = 1e5 had its dense output read 6e-5
        // past its end, and DOP853 went on from `y = 7.2e41`.
        let ulp = t.abs().max(f64::MIN_POSITIVE).next_up() - t.abs().max(f64::MIN_POSITIVE);
        let reach = (dense.t0() + 2.0 * dense.h()).max(t + 64.0 * ulp);
        for _ in 0..SWITCH_SIDE_TRIES {
            dense.eval(t_post, x_post);
            let g = self.det.guard_now(self.sys, self.mode, pos, t_post, x_post, self.p);
            if crossing.sigma * g < 0.0 || t_post >= reach {
                break;
            }
            gap = if gap == 0.0 { t_post.next_up() - t_post } else { 2.0 * gap };
            t_post = (t + gap).min(reach);
        }
        self.switch_post = Some(self.switch_post.map_or(t_post, |tp| tp.max(t_post)));
        if kink {
            return;
        }
        let (x, s) = self.z.split_at_mut(n);
        let sides = ((crossing.t_pre, &x_pre[..]), (t_post, &x_post[..]));
        let out = self.jump.apply_switch(self.sys, ev, self.mode, t, x, sides, s, self.p, context);
        self.note_conditioning(ev, t, out);
    }

    /// After an instant of flow switches alone: the run goes on from the first time where every
    /// new branch holds (a few spacings of `t` on), with the state there on the interpolant. At
    /// the located time itself the comparison can still give the old branch (`if x < 1` at
    /// `x = 1`), and a restart there took the old branch's derivative as the next step's first
    /// stage: an error of that step's length times the jump. Not after a declared event of the
    /// instant, whose reset the interpolant does not know.
    fn restart_past_switches(&mut self) {
        let Some(t_post) = self.switch_post.take() else { return };
        if !self.fired.is_empty() || t_post <= self.t || t_post >= self.opts.t_end {
            return;
        }
        let n = self.n;
        let x_post = &mut self.x_sides.1;
        self.stepper.interpolant().eval(t_post, x_post);
        self.z[..n].copy_from_slice(&x_post[..n]);
        self.t = t_post;
    }

    /// Whether the derivative at the step's start has sensitivities that are not finite where the
    /// sensitivities themselves are: the flow's derivative is singular right there.
    fn start_derivative_not_finite(&self) -> bool {
        let n = self.n;
        let k0 = &self.stepper.start_derivative()[n..];
        k0.iter().zip(&self.z[n..]).any(|(d, s)| !d.is_finite() && s.is_finite())
    }

    /// Sensitivities that are not finite at a finite state, and not yet known to be missing:
    /// derivatives that do not exist (NaN from here on), with one warning naming the first and
    /// the time `t` from which they are missing.
    fn note_new_voids(&mut self, t: f64) {
        let n = self.n;
        let mut first: Option<usize> = None;
        let mut count = 0;
        for (k, (void, s)) in self.void.iter_mut().zip(&mut self.z[n..]).enumerate() {
            if !s.is_finite() {
                *s = f64::NAN;
                if !*void {
                    *void = true;
                    count += 1;
                    first.get_or_insert(k);
                }
            }
        }
        if let Some(k) = first {
            let (j, i) = (k / n, k % n);
            let param = &self.info.param_names[self.info.grad_params[j]];
            self.warnings.push(SimWarning::NotDifferentiable {
                time: t,
                state: self.info.state_names[i].as_str().into(),
                param: param.as_str().into(),
                count,
            });
        }
    }

    /// What a jump needs to judge its crossing: the guard's curvature from the speeds over the
    /// step the crossing was found in (none for a crossing at a step's start, or after a mode
    /// switch in the group), and the run's tolerances.
    fn crossing_context(&self, pos: usize, crossing: Crossing, same_mode: bool) -> CrossingContext {
        let step = if same_mode && !crossing.on_guard { self.det.step_speeds(pos) } else { None };
        let flow_jumps = self.info.events[self.info.modes[self.mode].events[pos]].implicit;
        CrossingContext {
            step,
            flow_jumps,
            rtol: self.opts.rtol,
            atol: self.opts.atol,
            graze_tol: self.opts.graze_tol,
        }
    }

    /// A grazing or near-grazing crossing of event `ev` at `t`: a warning.
    fn note_conditioning(&mut self, ev: usize, t: f64, out: JumpOutcome) {
        let name = self.info.events[ev].name.clone();
        if out.grazing {
            let (denominator, conditioning) = (out.denominator, out.conditioning);
            self.warnings.push(SimWarning::Grazing { event: ev, name, time: t, denominator, conditioning });
        } else if let Some(margin) = out.margin {
            self.warnings.push(SimWarning::NearGrazing { event: ev, name, time: t, margin });
        }
    }

    /// Whether the recorder wants a sample from the dense output of the step ending at `t_seg_end`.
    fn sample_due(&self, t_seg_end: f64) -> bool {
        self.recorder.next_sample().is_some_and(|ts| ts <= t_seg_end) || self.at_due(t_seg_end, false)
    }

    /// Whether the next time of `SimOptions::at` is at most `t` (before `t` when `strict`).
    fn at_due(&self, t: f64, strict: bool) -> bool {
        self.opts.at.get(self.samples.len()).is_some_and(|&ts| ts < t || (!strict && ts == t))
    }

    /// The recorder's samples up to `t_seg_end`, and those of `SimOptions::at` up to it (before
    /// it when `before_instant`: a sample at an event instant is taken after the events), from
    /// the dense output of the step just attempted.
    fn record_samples(&mut self, t_seg_end: f64, before_instant: bool) {
        let n = self.n;
        while let Some(ts) = self.recorder.next_sample().filter(|&ts| ts <= t_seg_end) {
            let (outputs, z) = &mut *self.record_buf;
            self.stepper.interpolant().eval(ts, z);
            self.sys.outputs(ts, &z[..n], self.p, outputs);
            let point =
                Point { kind: PointKind::Sample, t: ts, mode: self.mode, x: &z[..n], s: &z[n..], outputs };
            self.recorder.record(&point);
        }
        while self.at_due(t_seg_end, before_instant) {
            let ts = self.opts.at[self.samples.len()];
            let (z, _, _) = self.samples.push(ts, self.mode);
            self.stepper.interpolant().eval(ts, z);
            self.fill_sample_outputs();
        }
    }

    /// The samples of `SimOptions::at` due at the current point (after an instant's events, or
    /// where the run stops).
    fn record_at_current_point(&mut self) {
        while self.at_due(self.t, false) {
            let ts = self.opts.at[self.samples.len()];
            let (z, _, _) = self.samples.push(ts, self.mode);
            z.copy_from_slice(&self.z[..]);
            self.fill_sample_outputs();
        }
    }

    /// Fills the outputs of the sample just pushed, and their derivatives `y_x S + y_p` at that
    /// fixed time, from its state and sensitivities.
    fn fill_sample_outputs(&mut self) {
        let (n, m, k) = (self.n, self.m, self.info.n_outputs());
        let row = self.samples.len() - 1;
        let (z, outputs, doutputs) = self.samples.row_mut(row);
        let (x, s) = z.split_at(n);
        let ts = self.opts.at[row];
        self.sys.outputs(ts, x, self.p, outputs);
        if m > 0 {
            let (yx, yp, yt) = &mut *self.output_jac;
            self.sys.output_jac(ts, x, self.p, yx, yp, yt);
            output_sens_into((n, m, k), &*self.output_jac, s, None, doutputs);
        }
    }

    /// Samples due at the current point itself (the start of the run).
    fn record_due_samples_at_current_point(&mut self) {
        let n = self.n;
        while let Some(ts) = self.recorder.next_sample().filter(|&ts| ts <= self.t) {
            let outputs = &mut self.record_buf.0;
            self.sys.outputs(ts, &self.z[..n], self.p, outputs);
            let (x, s) = self.z.split_at(n);
            let point = Point { kind: PointKind::Sample, t: ts, mode: self.mode, x, s, outputs };
            self.recorder.record(&point);
        }
    }

    /// Records the current point as `kind`, if the recorder wants it.
    fn record(&mut self, kind: PointKind) {
        if !(self.recorder.is_active() && self.recorder.wants(kind)) {
            return;
        }
        let n = self.n;
        let outputs = &mut self.record_buf.0;
        self.sys.outputs(self.t, &self.z[..n], self.p, outputs);
        let (x, s) = self.z.split_at(n);
        self.recorder.record(&Point { kind, t: self.t, mode: self.mode, x, s, outputs });
    }

    /// Runs until the run is over (the loop `sim::run` is) and returns the result.
    pub fn run_to_end(mut self) -> SimResult {
        loop {
            if let StepOutcome::Done(stop) = self.step() {
                return self.finish(stop);
            }
        }
    }

    /// Keeps count of the accepted steps (from `t0`) on which a running cost out of the error
    /// test was not resolved: its own scaled error above 1, where a controlled state's step
    /// would have been rejected (docs/language.md, "Running costs and the step size").
    fn note_cost_error(&mut self, t0: f64) {
        let (e, state) = self.stepper.outside_error();
        if e > 1.0 {
            let u =
                self.unresolved_cost.get_or_insert(UnresolvedCost { steps: 0, worst: 0.0, time: t0, state });
            u.steps += 1;
            if e > u.worst {
                (u.worst, u.time, u.state) = (e, t0, state);
            }
        }
    }

    /// The run's result, ended by `stopped_by`: events, the final state with its sensitivities
    /// and the outputs' (chained through the output Jacobians), warnings, statistics. The
    /// trajectory is the recorder's to give.
    pub fn finish(mut self, stopped_by: StopReason) -> SimResult {
        self.record_at_current_point();
        let mut samples = std::mem::take(&mut self.samples);
        samples::complete(&mut samples, &self.opts.at, &self.events);
        let (n, m, k) = (self.n, self.m, self.info.n_outputs());
        let t = self.t;
        let x = &self.z[..n];
        let s = &self.z[n..];
        let mut outputs = vec![0.0; k];
        self.sys.outputs(t, x, self.p, &mut outputs);
        let (yx, yp, yt) = &mut *self.output_jac;
        self.sys.output_jac(t, x, self.p, yx, yp, yt);
        let chain = |jac: &(Vec<f64>, Vec<f64>, Vec<f64>), sens: &[f64], dte: Option<&[f64]>| {
            output_sens((n, m, k), jac, sens, dte)
        };
        let (dstate, doutputs) = (existing(s), existing(&chain(&*self.output_jac, s, None)));
        let (dstate_total, doutputs_total) = match self.stop_total {
            Some((total, dte)) => {
                let dy = chain(&*self.output_jac, &total, Some(&dte));
                (existing(&total), existing(&dy))
            }
            None => (None, None),
        };
        let mut stats = self.stats;
        stats.rhs_calls = self.stepper.rhs_calls();
        let methods = self.stepper.segments(t).unwrap_or_else(|| {
            let method = self.opts.method.resolve(self.opts.rtol);
            let (steps, rejected) = (stats.steps, stats.rejected);
            vec![MethodSegment { from: self.opts.t_start, to: t, method, steps, rejected }]
        });
        let mut warnings = self.warnings;
        if let Some(UnresolvedCost { steps, worst, time, state }) = self.unresolved_cost {
            let state: Arc<str> = self.info.state_names[state].as_str().into();
            warnings.push(SimWarning::CostUnresolved { state, steps, worst, time });
        }
        near_breakpoints(self.info, &self.events, self.opts.t_end, &mut warnings);
        let end_cusp = match self.before_end {
            Some((z, first)) if matches!(stopped_by, StopReason::TEnd) && first < self.events.len() => {
                let (xb, sb) = z.split_at(n);
                let mut outputs = vec![0.0; k];
                self.sys.outputs(t, xb, self.p, &mut outputs);
                let (yx, yp, yt) = &mut *self.output_jac;
                self.sys.output_jac(t, xb, self.p, yx, yp, yt);
                let doutputs = existing(&chain(&*self.output_jac, sb, None));
                let events = self.events[first..].iter().map(|e| e.event).collect();
                Some(EndCusp { events, state: xb.to_vec(), dstate: existing(sb), outputs, doutputs })
            }
            _ => None,
        };
        SimResult {
            events: self.events,
            final_state: FinalState {
                time: t,
                mode: self.mode,
                state: x.to_vec(),
                dstate,
                outputs,
                doutputs,
                dstate_total,
                doutputs_total,
            },
            stopped_by,
            warnings,
            stats,
            trajectory: None,
            end_cusp,
            samples,
            methods,
        }
    }
}

/// Whether `t` is on the breakpoint `at` to round-off (16 spacings of `t`, as the guards'
/// round-off of rule 11: an event at `t_end` is located a few spacings before it when round-off
/// in the state puts the guard across early): there the event is on the breakpoint itself, a cusp.
fn on_breakpoint(t: f64, at: f64) -> bool {
    (at - t).abs() <= 16.0 * (at.abs().next_up() - at.abs())
}

/// `y_x S_j + y_p_j` (`+ y_t dt_j` for totals), column per parameter, for `k` outputs of `n`
/// states and `m` parameters, from the output Jacobians `(y_x, y_p, y_t)`.
fn output_sens(
    shape: (usize, usize, usize),
    jac: &(Vec<f64>, Vec<f64>, Vec<f64>),
    sens: &[f64],
    dte: Option<&[f64]>,
) -> Vec<f64> {
    let mut out = vec![0.0; shape.2 * shape.1];
    output_sens_into(shape, jac, sens, dte, &mut out);
    out
}

/// [`output_sens`] into `out` (k * m).
fn output_sens_into(
    (n, m, k): (usize, usize, usize),
    (yx, yp, yt): &(Vec<f64>, Vec<f64>, Vec<f64>),
    sens: &[f64],
    dte: Option<&[f64]>,
    out: &mut [f64],
) {
    for j in 0..m {
        for i in 0..k {
            let row = &yx[i * n..(i + 1) * n];
            let mut v = yp[j * k + i];
            v += dot_nonzero(row, &sens[j * n..(j + 1) * n]);
            if let Some(d) = dte {
                if yt[i] != 0.0 {
                    v += yt[i] * d[j];
                }
            }
            out[j * k + i] = v;
        }
    }
}

/// Events within the resolution at which instants are told apart (`1e-9 max(|t|, 1)`, as for
/// Zeno) before `t_end`, or of a time event they are not a time event with: their derivatives
/// hold only while they stay on their side (`SimWarning::NearBreakpoint`). Time events fire on
/// their breakpoint by construction and are not warned about themselves.
fn near_breakpoints(info: &SystemInfo, events: &[EventRecord], t_end: f64, warnings: &mut Vec<SimWarning>) {
    let near = |a: f64, b: f64| (a - b).abs() <= NEAR_BREAKPOINT * a.abs().max(b.abs()).max(1.0);
    let is_time = |e: &EventRecord| info.events[e.event].guard == GuardShape::Time;
    // Only the events near the end or near a time event matter: scan the neighbours in time.
    for (k, e) in events.iter().enumerate() {
        if is_time(e) {
            continue;
        }
        let mut breakpoint: Option<(Arc<str>, f64)> = None;
        if near(e.time, t_end) {
            breakpoint = Some(("t_end".into(), t_end));
        }
        let neighbours = events[k.saturating_sub(8)..(k + 9).min(events.len())].iter();
        // Not one at the very same instant: a cascade from the time event's reset moves with
        // the instant (rule 7), and a group fires in declaration order either way.
        for other in neighbours.filter(|o| is_time(o) && o.time != e.time && near(o.time, e.time)) {
            if breakpoint.is_none() {
                breakpoint = Some((format!("the time event `{}`", other.name).into(), other.time));
            }
        }
        if let Some((name, at)) = breakpoint {
            let margin = if on_breakpoint(e.time, at) { 0.0 } else { (at - e.time).abs() };
            warnings.push(SimWarning::NearBreakpoint {
                event: e.event,
                name: e.name.clone(),
                time: e.time,
                breakpoint: name,
                margin,
            });
        }
    }
}

/// Accepted steps on which a running cost left out of the error test had a scaled error above 1.
#[derive(Clone, Copy, Debug)]
struct UnresolvedCost {
    steps: usize,
    /// The largest scaled error, the start of its step and the state's index.
    worst: f64,
    time: f64,
    state: usize,
}
