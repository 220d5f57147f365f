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

use super::breakpoints::{near_breakpoints, on_breakpoint, Breakpoints};
use super::event::detect::{clear_side, dot, moves_across, Crossing, Detector, Pending, Selection};
use super::event::guards::Guards;
use super::event::jump::{dot_nonzero, same, CrossingContext, Jump, JumpOutcome};
use super::event::zeno;
use super::fp_mode::IeeeArithmetic;
use super::knots::Knots;
use super::method::rk::Rk;
use super::method::stepper::{Interpolant, Rhs, Stepper};
use super::mode_rhs::rhs_for;
use super::options::SimOptions;
use super::recorder::{Point, PointKind, Recorder, TapeEntry, TapeSample, TapeStep};
use super::result::{
    EndCusp, EventRecord, FinalState, MethodSegment, SimError, SimResult, SimStats, SimWarning, StopReason,
    VoidCause,
};
use super::samples::{output_sens, OutputJac, Sampler};
use super::spacing;
use super::switch_landing::SwitchLanding;
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
/// Rejections in a row with a non-finite trial state before the run gives up on shrinking.
const MAX_NONFINITE_REJECTS: usize = 30;
/// A step this short relative to `max(|t|, 1)` is taken even when a guard's walk over it examined
/// its most pieces (`event::enclose::MAX_PIECES`), with what the walk found: longer ones are
/// retried a quarter as long.
const GUARD_WALK_FLOOR: f64 = 1e-9;
/// A step this short relative to `max(|t|, 1)` is kept even when a running cost's own error
/// exceeds its tolerance (an integrable singularity, `1 / sqrt(t)` at 0): the run warns instead.
const COST_FLOOR: f64 = 1e-9;
/// After an instant, the next step reaches this far past the next crossing the last step saw
/// (relative to the distance to it): past it despite the error of its estimate, not far beyond.
const NEXT_CROSSING_REACH: f64 = 1.5;
/// The largest Newton correction of a landed event instant, relative to the landed step: the
/// dense output's error moves the root by far less where it is accurate; more (a stiff phase,
/// where its error times the stiffness is the crossing speed's) retries the step shorter.
const LANDING_CORRECTION: f64 = 1e-3;
/// Landings on one event instant at most: the first, then secant steps until the instant is
/// resolved to a few spacings of `t`.
const LANDINGS: usize = 6;
/// A first landing whose Newton correction is at most this fraction of the landed step is
/// finished by that step (its error, of second order in it, is far below the tolerances).
const LANDING_EXACT: f64 = 1e-6;
/// Spacings of `t` within which a landed instant counts as resolved.
const LANDING_RESOLVED: f64 = 64.0;
/// A step whose landed instant needed a larger correction is retried this much shorter.
const LANDING_RETRY: f64 = 0.25;
/// Floating-point spacings of `t` a landed instant moves on at most until every guard of its
/// group is on the crossed side.
const LANDING_NUDGES: usize = 8;
/// The half-width of the central difference of two landings that measures the trajectory's
/// velocity at a landed instant, relative to the landed step ([`Integrator::landed_velocity`]):
/// its truncation error (`delta^2 x''' / 6`) and its round-off (`eps |x| / delta`) are both far
/// below the tolerances' share of a crossing speed.
const VELOCITY_HALF_WIDTH: f64 = 1.0 / 8192.0;
/// How much larger the flow's error at a landed state must be than a difference's
/// (`h |f(x + d) - f(x)|` against `|d| + eps |x| / VELOCITY_HALF_WIDTH`) for the trajectory's
/// velocity to replace it: a stiff phase has `h |lambda|` in the thousands, an ordinary long step
/// a few, where the flow is the better of the two.
const STIFF_LANDING: f64 = 16.0;
/// What landing on an event instant found ([`Integrator::land_on_event`]).
enum Landing {
    /// The instant, the state landed there.
    Landed(f64),
    /// Not landed: the dense output's state is taken.
    Dense,
    /// The dense output was off where it was read: a shorter step.
    Retry,
}

/// Rounds of cascading events at one instant before the run stops as stuck.
pub(crate) const MAX_CASCADE_ROUNDS: usize = 100;

/// A step as planned: from `t0`, of size `h`, ending at `t1` (exactly the breakpoint it lands on
/// when `lands`; an input knot of the mode when `on_knot`, the flow then read on the knot's
/// earlier side at the step's end).
#[derive(Clone, Copy, Debug)]
struct Plan {
    t0: f64,
    h: f64,
    t1: f64,
    lands: bool,
    on_knot: bool,
}

/// What an accepted attempt needs: its dense output for the events (`for_events`) or for samples
/// (`sample_due`).
#[derive(Clone, Copy, Debug)]
struct Look {
    for_events: bool,
    sample_due: bool,
}

/// How a step that ends at an event instant gave the state there (for the adjoint tape).
#[derive(Clone, Copy, Debug)]
enum Cut {
    /// The step's own end.
    End,
    /// The step retaken to end on the instant, its end moved on by this `dt`.
    Landed(f64),
    /// The dense output, read at this time.
    Dense(f64),
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
    Fired {
        /// The first of them, in the run's event record.
        first: usize,
        /// How many fired.
        count: usize,
    },
    /// The run is over: this is why. Further calls return the same.
    Done(StopReason),
}

/// The scratch state of a run, sized by the model and the options; kept by a `Runner`
/// between runs so that a run allocates only what its result holds.
pub(crate) struct Workspace<St: Stepper = Rk> {
    pub(crate) stepper: St,
    pub(crate) det: Detector,
    pub(crate) jump: Jump,
    pub(crate) breakpoints: Breakpoints,
    /// The input knots' scratch, and the knots met at the current instant (`(time, knot set)`).
    pub(crate) knots: Knots,
    pub(crate) knot_sets: Vec<(f64, u32)>,
    /// The integrated vector `[x, S]`.
    pub(crate) z: Vec<f64>,
    /// The events of the last group that fired: id, pre-crossing sign, crossing speed, and the
    /// guard's accuracy at the tolerances there (0 for an event that took another's instant).
    pub(crate) fired: Vec<(usize, f64, f64, f64)>,
    /// The output Jacobians `y_x`, `y_p`, `y_t` at the final state.
    pub(crate) output_jac: OutputJac,
    /// The states on either side of a flow switch.
    pub(crate) x_sides: (Vec<f64>, Vec<f64>),
    /// The flow before a flow switch (where the far side is found along it), and the state on the
    /// far side of the switches of an instant, where the run restarts (`restart_past_switches`).
    pub(crate) switch_flow: (Vec<f64>, Vec<f64>),
    /// Outputs and an interpolated `z` for recorded points.
    pub(crate) record_buf: (Vec<f64>, Vec<f64>),
    /// The state before a round of events at one instant, and the guards there.
    pub(crate) before: (Vec<f64>, Vec<f64>),
    /// The state at the start of the step, for samples taken from steps retaken to end on them
    /// after the run's state moved to an event instant.
    pub(crate) z_start: Vec<f64>,
    /// `dt/dp` of the instant being fired (the first event's), for cascading events.
    pub(crate) instant_dte: Vec<f64>,
    /// Scratch: the trajectory's velocity at a landed instant and a probe state
    /// (`Integrator::landed_velocity`).
    pub(crate) landed_velocity: (Vec<f64>, Vec<f64>),
    /// Which sensitivities are known not to exist (NaN), for warning once about new ones.
    pub(crate) void: Vec<bool>,
    /// Guards of the current round that its reset moved onto zero with no clear speed (their
    /// positions), left for the next step to decide.
    pub(crate) reset_onto: Vec<usize>,
    /// Events of the next cascade round whose guard the last round reset onto zero to round-off
    /// (firing because the flow carries them across): their time derivative does not exist.
    pub(crate) reset_onto_guard: Vec<usize>,
    /// Their `dt/dp` (NaN where a parameter moves the instant or the guard).
    pub(crate) onto_guard_dte: Vec<f64>,
    /// A guard's gradient `(g_x, g_p)` for an event reset onto its guard.
    pub(crate) onto_guard_grad: (Vec<f64>, Vec<f64>),
    /// Scratch of an instant's lateness (`Integrator::move_to_crossing`): a flow (n), its
    /// sensitivities' derivative (n * m), and a guard's gradient (n, m) or a moved state (n).
    pub(crate) lateness: (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>),
    /// The new mode's guards before and after the move past the crossing.
    pub(crate) lateness_guards: (Vec<f64>, Vec<f64>),
}

/// How many spacings of `t` past the crossing the instant may lie for its lateness to be carried
/// (`Integrator::move_to_crossing`): rule 1 puts it less than one past on the dense output, and a
/// landed instant within 64; a guard that says more speaks of the state's error, not of the
/// instant's lateness.
const LATENESS_SPACINGS: f64 = 64.0;

/// The fraction of a state's tolerance `atol + rtol |x|` that the lateness must move it by to be
/// carried (`Integrator::move_to_crossing`): below, the move is lost in the run's error, and the
/// runs at ordinary times, whose spacings are 1e-16, keep the state the reset gave.
const LATENESS_RELEVANCE: f64 = 1e-2;

/// The fraction of a state's tolerance `atol + rtol |x|` that the rounding of a step's end time
/// to the time grid must move it by for the step to take the rounded size (`Integrator::plan`).
const CLOCK_ROUNDING: f64 = 1e-2;

/// Derivatives as a result reports them: `None` when none exists (every entry NaN, and there is
/// at least one), else every entry, NaN where that one does not exist.
fn existing(d: &[f64]) -> Option<Vec<f64>> {
    (d.is_empty() || d.iter().any(|v| !v.is_nan())).then(|| d.to_vec())
}

/// One run in progress. Made by `Runner::integrator`; [`Self::step`] advances it,
/// [`Self::finish`] turns it into the run's result.
pub struct Integrator<'a, S: HybridSystem + ?Sized, R: Recorder, St: Stepper = Rk> {
    /// The values at `SimOptions::at` taken so far, and the recorder's dense-output samples.
    sampler: Sampler<'a, S>,
    sys: &'a S,
    info: &'a SystemInfo,
    p: &'a [f64],
    opts: &'a SimOptions,
    n: usize,
    m: usize,
    t: f64,
    mode: usize,
    /// The stepper, the detector, `z` and every scratch buffer: the `Runner`'s, kept between
    /// runs.
    work: &'a mut Workspace<St>,
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
    /// Whether the events accumulate (rule 10), watched round by round.
    zeno: zeno::Watch,
    warnings: Vec<SimWarning>,
    stats: SimStats,
    /// Total derivative of the final state and `dt/dp` of a stop event.
    stop_total: Option<(Vec<f64>, Vec<f64>)>,
    done: Option<StopReason>,
    /// A step that crossed a flow switch is retried landing just before it (the last time on
    /// the old branch).
    landing: SwitchLanding,
    /// The first time past the flow switches crossed at the current instant where their new
    /// branches hold (see `cross_switch`).
    switch_post: Option<f64>,
    /// The state and sensitivities just before an instant at `t_end` (for `SimResult::end_cusp`).
    before_end: Option<(Vec<f64>, usize)>,
    /// The current instant is on input knots: its events read the flows on the knots' earlier
    /// side.
    left_of_knot: bool,
    /// The recorder keeps an adjoint tape (`Recorder::keeps_tape`).
    tapes: bool,
    /// The run carries sensitivities, or keeps a tape for an adjoint that will: what such a run
    /// measures (a landed instant's velocity, a restart on a `pwl` knot) it measures too.
    sens_like: bool,
    /// The tape's scratch: the states at the start of a step cut at an instant, and the retaken
    /// step's size and the move along its end derivative of a landed instant.
    tape_x0: Vec<f64>,
    tape_landing: (f64, f64),
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
        // Every entry of a run computes in IEEE arithmetic, whatever mode the caller's thread is in.
        let _ieee = IeeeArithmetic::enter();
        let info = sys.info();
        let (n, m) = (info.n_states(), info.n_grad());
        work.stepper.reset();
        work.breakpoints.reset(opts.t_end, info.modes.len());
        sys.initial_state(p, &mut work.z[..n]);
        sys.initial_sens(p, &mut work.z[n..]);
        work.void.fill(false);
        // The affine guards' gradients are the parameters' of this run.
        work.det.start_run();
        let mut it = Integrator {
            sys,
            info,
            p,
            opts,
            n,
            m,
            t: opts.t_start,
            mode: info.initial_mode,
            work,
            recorder,
            h: 0.0,
            attempts: 0,
            nonfinite_rejects: 0,
            unresolved_cost: None,
            immediate: false,
            instant: None,
            step_mode: info.initial_mode,
            events: Vec::new(),
            zeno: zeno::Watch::default(),
            warnings: Vec::new(),
            stats: SimStats::default(),
            stop_total: None,
            done: None,
            landing: SwitchLanding::default(),
            switch_post: None,
            before_end: None,
            left_of_knot: false,
            tapes: false,
            sens_like: m > 0,
            tape_x0: Vec::new(),
            tape_landing: (0.0, 0.0),
            sampler: Sampler::new(sys, p, &opts.at),
        };
        if it.recorder.keeps_tape() {
            (it.tapes, it.sens_like) = (true, true);
            it.tape_x0.resize(n, 0.0);
        }
        if it.work.z[..n].iter().any(|v| !v.is_finite()) {
            it.done = Some(it.fault_nonfinite());
            return it;
        }
        let t0 = it.t;
        it.note_new_voids(t0, VoidCause::NotFinite);
        it.add_time_events();
        it.h = it.restart();
        // A reused detector may remember bounces of an earlier run.
        it.work.det.clear_bounces();
        it.record(PointKind::Start);
        it.sampler.record_here(it.recorder, &mut it.work.record_buf.0, t0, it.mode, &it.work.z[..]);
        it.start_on_guards();
        it
    }

    /// Time events (`t >= expression of parameters`) land on their time exactly: their times in
    /// `(t_start, t_end)` become breakpoints, and so do the input knots of every mode (of that
    /// mode only).
    fn add_time_events(&mut self) {
        let n = self.n;
        for mode in 0..self.info.modes.len() {
            let evs = &self.info.modes[mode].events;
            if !evs.iter().any(|&ev| self.info.events[ev].guard == GuardShape::Time) {
                continue;
            }
            // A time event's guard is `slope t + c`: its value at t = 0 is `c`.
            let ne = evs.len();
            let (gx, g) = &mut self.work.before;
            g.resize(ne, 0.0);
            gx.resize(n, 0.0);
            self.work.instant_dte.resize(self.m, 0.0);
            self.sys.guards(mode, 0.0, &self.work.z[..n], self.p, &mut g[..ne]);
            let mut switches = Vec::new();
            for (pos, &ev) in evs.iter().enumerate() {
                if self.info.events[ev].guard != GuardShape::Time {
                    continue;
                }
                let slope = self.sys.guard_grad(
                    ev,
                    0.0,
                    &self.work.z[..n],
                    self.p,
                    &mut gx[..n],
                    &mut self.work.instant_dte,
                );
                let t_event = -g[pos] / slope;
                if self.info.events[ev].implicit && t_event.is_finite() {
                    switches.push((pos, t_event, slope));
                } else if t_event > self.opts.t_start && t_event < self.opts.t_end {
                    self.work.breakpoints.add(t_event);
                }
            }
            for (pos, t_est, slope) in switches {
                let t_event = self.first_time_across(mode, pos, t_est, slope);
                if t_event > self.opts.t_start && t_event < self.opts.t_end {
                    self.work.breakpoints.add(t_event);
                }
            }
        }
        let span = (self.opts.t_start, self.opts.t_end);
        self.work.knots.queue(self.sys, self.p, span, &mut self.work.breakpoints);
        self.work.breakpoints.sort();
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
            if across(self.sys, t, &self.work.z) {
                break;
            }
            t = t.next_up();
        }
        for _ in 0..NUDGES {
            let before = t.next_down();
            if !across(self.sys, before, &self.work.z) {
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
        self.work.det.group.clear();
        let (t, n) = (self.t, self.n);
        let evs = &self.info.modes[self.mode].events;
        let mut enabled = false;
        for (pos, &ev) in evs.iter().enumerate() {
            let einfo = &self.info.events[ev];
            if einfo.implicit || self.work.det.g0[pos].is_nan() {
                continue;
            }
            let (noise, speed_noise) = self.work.det.noise0(&self.guards(), pos);
            if self.work.det.g0[pos].abs() > noise {
                if einfo.direction != Direction::Either
                    && clear_side(einfo.direction, self.work.det.g0[pos], noise) == Some(true)
                {
                    let (name, guard) = (einfo.name.clone(), self.work.det.g0[pos]);
                    self.warnings.push(SimWarning::StartsAcross { event: ev, name, time: t, guard });
                }
                continue;
            }
            match moves_across(einfo.direction, self.work.det.dg0[pos], speed_noise) {
                Some(sigma) => {
                    // As in every group, each condition is judged when its event's turn comes.
                    enabled |= self.sys.condition(ev, t, &self.work.z[..n], self.p);
                    let c = Crossing { t, sigma, touch: false, t_pre: t, on_guard: true };
                    self.work.det.group.push((ev, c));
                }
                None if self.work.det.dg0[pos].abs() <= speed_noise => {
                    self.work.det.set_pending(pos, Pending::OnGuard, noise);
                }
                None => {}
            }
        }
        if !enabled {
            self.work.det.group.clear();
        }
        self.immediate = enabled;
    }

    /// At the end of the run's last step: events whose crossing is at `t_end` to round-off fire
    /// there (`Detector::on_guard_at_end`), when the first of them to fire has its condition.
    fn end_on_guards(&mut self) -> bool {
        if !self.work.det.on_guard_at_end(&self.guards()) {
            return false;
        }
        let x = &self.work.stepper.end_state()[..self.n];
        let t = self.opts.t_end;
        let enabled = self.work.det.group.iter().any(|&(ev, _)| self.sys.condition(ev, t, x, self.p));
        if !enabled {
            self.work.det.group.clear();
        }
        enabled
    }

    /// The guards of the current mode, for the detector.
    fn guards(&self) -> Guards<'a, S> {
        Guards::new(self.sys, self.info, self.p, self.mode)
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
        &self.work.z[..self.n]
    }

    /// The current sensitivities, column per parameter (`s[j * n + i] = dx_i/dp_j`).
    pub fn sensitivities(&self) -> &[f64] {
        &self.work.z[self.n..]
    }

    /// The events fired so far.
    pub fn events(&self) -> &[EventRecord] {
        &self.events
    }

    /// Attempts one step and says what happened.
    pub fn step(&mut self) -> StepOutcome {
        let _ieee = IeeeArithmetic::enter();
        if let Some(stop) = &self.done {
            return StepOutcome::Done(stop.clone());
        }
        let outcome = self.advance();
        if let StepOutcome::Done(stop) = &outcome {
            self.done = Some(stop.clone());
        }
        outcome
    }

    /// One turn of the state machine (ARCHITECTURE.md, "Inside `sim`"): a group prepared at the
    /// current point fires first; otherwise a step is planned, attempted, examined and either
    /// rejected, accepted or cut at the instant of the events selected in it.
    fn advance(&mut self) -> StepOutcome {
        if self.immediate {
            self.immediate = false;
            let estimate = self.h;
            self.record(PointKind::BeforeEvents);
            return self.fire_instant(estimate);
        }
        let plan = match self.plan() {
            Ok(plan) => plan,
            Err(stop) => return StepOutcome::Done(stop),
        };
        self.attempts += 1;
        // The mode's guards, for every detection call of this step.
        let cx = self.guards();
        let ceiling = if plan.on_knot { plan.t1.next_down() } else { f64::INFINITY };
        let mut rhs = rhs_for(self.sys, self.p, self.n, self.mode).with_ceiling(ceiling);
        // The stages' states are read only where a flow switch's stray stages are checked.
        let keep = self.work.det.checks_stages(&cx);
        self.work.stepper.keep_stage_states(keep);
        let err = self.work.stepper.attempt(plan.t0, &self.work.z, plan.h, &mut rhs);
        if err > 1.0 && !self.rounding_explains(plan, err) || err.is_nan() {
            return self.reject(&cx, plan, err, &mut rhs);
        }
        // A running cost takes no part in the error test's norm, but a step that leaves it less
        // accurate than the tolerance is not kept: its own scaled error rejects the step, down
        // to the floor below which the run goes on and warns (`SimWarning::CostUnresolved`).
        let (cost_err, _) = self.work.stepper.outside_error();
        if cost_err > 1.0 && cost_err.is_finite() && plan.h > COST_FLOOR * plan.t0.abs().max(1.0) {
            return self.reject(&cx, plan, cost_err, &mut rhs);
        }
        self.nonfinite_rejects = 0;
        let look = match self.examine(&cx, plan, &mut rhs) {
            Ok(look) => look,
            Err(outcome) => return outcome,
        };
        // The controller learns from the step (and counts it) only once it stands: a step retried
        // to land before a flow switch is a rejection, for the step statistics as for `auto`'s.
        let selection = match self.select_events(&cx, plan, look, &mut rhs) {
            Ok(selection) => selection,
            Err(StepOutcome::Done(stop)) => {
                self.work.stepper.grow(err);
                self.stats.steps += 1;
                return StepOutcome::Done(stop);
            }
            Err(outcome) => return outcome,
        };
        let h_next = self.work.stepper.grow(err);
        self.stats.steps += 1;
        // Only a step that stands counts: one retried to land before a flow switch it straddled
        // carried the other branch's error.
        self.note_cost_error(plan.t0);
        if !matches!(selection, Selection::Nothing) {
            // The step is cut at an instant: what jumps there is read off its dense output.
            self.work.stepper.complete_interpolant(plan.t0, &self.work.z, &mut rhs);
        }
        match selection {
            Selection::Nothing if self.work.det.penetrated().is_some() => {
                // Stop where the last bounce left the state (the step is not taken).
                StepOutcome::Done(zeno::stop(&self.events))
            }
            Selection::Nothing => self.accept(plan, look, h_next, &mut rhs),
            Selection::NotFinite { pos, t } => self.stop_not_finite(pos, t, look),
            Selection::Fire(t_fire) => self.cut_at_instant(t_fire, plan, look, h_next, &mut rhs),
        }
    }

    /// The next step from the current point: its size, clipped to land on the next breakpoint
    /// (or just before a flow switch it is retried for), or why the run cannot take one.
    fn plan(&mut self) -> Result<Plan, StopReason> {
        let t_end = self.opts.t_end;
        if self.t >= t_end {
            return Err(StopReason::TEnd);
        }
        if self.attempts >= self.opts.max_steps {
            return Err(StopReason::Fault {
                error: SimError::TooManySteps {
                    t: self.t,
                    max_steps: self.opts.max_steps,
                    mode: self.mode,
                    state: self.fault_state(),
                },
            });
        }
        if let Some(set) = self.work.knots.broken.get(self.mode).copied().flatten() {
            return Err(StopReason::Fault {
                error: SimError::KnotsNotFinite {
                    input: self.info.knots[set as usize].name.clone(),
                    t: self.t,
                    mode: self.mode,
                    state: self.fault_state(),
                },
            });
        }
        let t0 = self.t;
        let mut t_land = self.work.breakpoints.next_after(t0, self.mode);
        let knot = self.work.breakpoints.knot_after(t0, self.mode);
        if let Some(t_pre) = self.landing.limit(t0) {
            t_land = t_land.min(t_pre);
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
            return Err(StopReason::Fault {
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
        let t1 = if lands { t_land } else { t0 + h_try };
        // The step the states take is the one the clock takes: `t0 + h` is rounded to the time
        // grid, by up to half a spacing of `t` (6e-11 at `t = 1e6`, against a step of 2e-4), and a
        // step of `h` ending at the rounded time would put that on the states' phase at every step.
        // Where that moves no state by `CLOCK_ROUNDING` of its tolerance (at ordinary times, a
        // rounding of 1e-16 of the step), the step keeps its size: those runs keep their values
        // to the bit, and their steps do not move with the parameters by spacings of `t`.
        let taken = t1 - t0;
        let h = if !lands && taken != h_try && self.clock_rounding_matters(taken - h_try) {
            taken
        } else {
            h_try
        };
        Ok(Plan { t0, h, t1, lands, on_knot: lands && knot == Some(t_land) })
    }

    /// Whether moving a step's end by `dh` (the rounding of its end time) moves some state, at
    /// the start's derivative, by more than [`CLOCK_ROUNDING`] of its tolerance.
    fn clock_rounding_matters(&self, dh: f64) -> bool {
        let n = self.n;
        let (rtol, atol) = (self.opts.rtol, self.opts.atol);
        let f = &self.work.stepper.start_derivative()[..n];
        // Branch-free over chunks (it runs on nearly every step, over every state): the compiler
        // vectorises a fold of `|`, not `any`'s early exit per element.
        f.chunks(64).zip(self.work.z[..n].chunks(64)).any(|(f, x)| {
            f.iter().zip(x).fold(false, |moved, (f, x)| {
                moved | ((dh * f).abs() > CLOCK_ROUNDING * (atol + rtol * x.abs()))
            })
        })
    }

    /// Whether the error estimate `err` (above 1) of the attempt just made, which lands on a
    /// breakpoint, is no more than the rounding of its stage times explains. A stage at
    /// `t0 + c h` is read at a time off by up to half a spacing of `t`, which moves its
    /// derivative by the derivative's rate of change times that: over the step, about
    /// `|F_i(t1) - F_i(t0)| spacing / h` in component `i`, and an error estimate (`h` times
    /// weights summing to less than one) by less than `|F_i(t1) - F_i(t0)| spacing`. Where that,
    /// in units of the tolerance, reaches `err`, the estimate measures the times' rounding, not
    /// the step: a shorter step rounds worse, and this one lands on its breakpoint, so it is
    /// taken. Only a very short step with a fast-changing derivative gets there: an input window
    /// of `1e-12`, whose sensitivities with respect to its ends change at `1e24` a unit of time.
    fn rounding_explains(&self, plan: Plan, err: f64) -> bool {
        let n = self.n;
        if !plan.lands || !err.is_finite() || n == 0 {
            return false;
        }
        let spacing = spacing(plan.t1.abs().max(plan.t0.abs()));
        let stepper = &self.work.stepper;
        let (f0, f1, z0, z1) =
            (stepper.start_derivative(), stepper.end_derivative(), &self.work.z, stepper.end_state());
        // The components in the error test: the running costs are out, unless every state is one
        // or the options put them in (`run::error_test_exclusions`).
        let q = &self.info.quadrature;
        let costs_out = !self.opts.quadrature_error_control && q.len() == n && !q.iter().all(|&c| c);
        let controlled = |i: usize| !(i >= n && !self.opts.sens_error_control || costs_out && q[i % n]);
        let floor = (0..z0.len())
            .filter(|&i| controlled(i))
            .map(|i| {
                let scale = self.opts.atol + self.opts.rtol * z0[i].abs().max(z1[i].abs());
                (f1[i] - f0[i]).abs() * spacing / scale
            })
            .filter(|noise| noise.is_finite())
            .fold(0.0, f64::max);
        err <= floor
    }

    /// An attempt that failed its error test (`err`): a shorter step, aimed just before a flow
    /// switch the attempt crossed; too many non-finite attempts in a row stop the run.
    fn reject<F: Rhs>(&mut self, cx: &Guards<'a, S>, plan: Plan, err: f64, rhs: &mut F) -> StepOutcome {
        self.stats.rejected += 1;
        if err.is_finite() {
            self.nonfinite_rejects = 0;
        } else {
            self.nonfinite_rejects += 1;
            if self.nonfinite_rejects > MAX_NONFINITE_REJECTS {
                return StepOutcome::Done(self.fault_nonfinite());
            }
        }
        self.h = self.work.stepper.shrink(err);
        // A step that failed its error test because it crossed a flow switch: shrinking by
        // the error alone would creep up on the switch in many rejected steps.
        if err.is_finite() {
            let (stepper, z) = (&mut self.work.stepper, &self.work.z[..]);
            let span = (plan.t0, plan.t1);
            if let Some(h) = self.landing.retry_rejected(&mut self.work.det, cx, stepper, z, span, rhs) {
                self.h = h;
            }
        }
        StepOutcome::Rejected
    }

    /// An attempt that passed its error test: its guards at the end and whether it needs its
    /// dense output (for events or samples), built then.
    fn examine<F: Rhs>(&mut self, cx: &Guards<'a, S>, plan: Plan, rhs: &mut F) -> Result<Look, StepOutcome> {
        let (t0, t1) = (plan.t0, plan.t1);
        self.work.det.eval_end(cx, t1, &self.work.stepper);
        let for_events = self.work.det.mark_candidates(cx);
        let sample_due = self.sampler.wanted(&*self.recorder, t1);
        if sample_due || (for_events && self.work.det.crossing_certain(cx)) {
            self.work.stepper.build_interpolant(t0, &self.work.z, rhs);
        } else if for_events {
            // The states' part first: most steps with a candidate guard and no crossing between
            // their ends fire nothing, and only a step cut at an instant reads the sensitivities
            // there (`complete_interpolant`); and of the states, those the walk reads, when the
            // mode's guards read fewer than all (`select_events` completes them if it finds).
            match self.work.det.walk_states(cx) {
                Some(states) => self.work.stepper.build_guard_interpolant(t0, &self.work.z, rhs, states),
                None => self.work.stepper.build_states_interpolant(t0, &self.work.z, rhs),
            }
        }
        Ok(Look { for_events, sample_due })
    }

    /// The events the accepted step ends with: the earliest crossings inside it, or a flow switch
    /// crossed where the step landed just before it, or events on their guard at `t_end`. A
    /// contact found stuck stops the run and a flow switch crossed inside the step retries it
    /// (`Err`).
    fn select_events<F: Rhs>(
        &mut self,
        cx: &Guards<'a, S>,
        plan: Plan,
        look: Look,
        rhs: &mut F,
    ) -> Result<Selection, StepOutcome> {
        let (t0, t1) = (plan.t0, plan.t1);
        let mut selection = if look.for_events {
            self.work.det.scan(cx, self.work.stepper.interpolant(), t1);
            if self.work.det.found_any() {
                // Whatever is done with a finding reads whole states.
                self.work.stepper.complete_states_interpolant(t0, &self.work.z);
            }
            if self.work.det.exhausted && plan.h > GUARD_WALK_FLOOR * t0.abs().max(1.0) {
                // A guard too intricate over this step for the walk's pieces: a shorter step.
                self.work.det.forget_findings();
                self.stats.rejected += 1;
                self.h = 0.25 * plan.h;
                return Err(StepOutcome::Rejected);
            }
            if let Some(pos) = self.work.det.stuck() {
                return Err(StepOutcome::Done(self.stuck_on_guard(cx.events()[pos])));
            }
            let dense = self.work.stepper.interpolant();
            let stray = self.work.det.stray_stage(cx, &self.work.stepper, dense, t0, plan.h);
            if let Some(h) = self.landing.retry(&mut self.work.det, cx, dense, t0, stray) {
                self.h = h;
                self.stats.rejected += 1;
                return Err(StepOutcome::Rejected);
            }
            self.work.det.select(cx, self.work.stepper.interpolant())
        } else {
            Selection::Nothing
        };
        let nothing = matches!(selection, Selection::Nothing) && plan.lands;
        if nothing && self.landing.cross_at_landing(&mut self.work.det, cx, &self.work.breakpoints, t1) {
            if !(look.for_events || look.sample_due) {
                self.work.stepper.build_interpolant(t0, &self.work.z, rhs);
            }
            selection = Selection::Fire(t1);
        }
        // At `t_end`, and at an input knot where the flow jumps: a crossing there to round-off is
        // on it (at a knot, the event meets it, rather than the next step on its other side).
        if matches!(selection, Selection::Nothing)
            && plan.lands
            && (t1 >= self.opts.t_end || plan.on_knot && self.knot_jumps_at(t1))
            && self.end_on_guards()
        {
            if !(look.for_events || look.sample_due) {
                self.work.stepper.build_interpolant(t0, &self.work.z, rhs);
            }
            selection = Selection::Fire(t1);
        }
        Ok(selection)
    }

    /// Nothing fired in the step: the state moves to its end (and across the input knots there).
    fn accept<F: Rhs>(&mut self, plan: Plan, look: Look, h_next: f64, rhs: &mut F) -> StepOutcome {
        let (t0, t1) = (plan.t0, plan.t1);
        // Samples on a knot are taken once it is crossed: the input's value there is the later
        // side's.
        let before_knot = plan.on_knot;
        if look.sample_due {
            self.work.z_start.copy_from_slice(&self.work.z);
            if self.land_samples(t0, t1, before_knot, rhs, (plan, false)) {
                // The step itself again (the same step: samples do not change the run), for
                // its end state.
                self.work.stepper.land(t0, &self.work.z, plan.h, rhs);
            }
            self.sample_step(t1, before_knot, Some((plan, false)));
        }
        let at_start = if self.work.stepper.masked() { self.start_derivative_singularity() } else { None };
        if self.tapes {
            self.tape_x0.copy_from_slice(&self.work.z[..self.n]);
            self.tape_step(plan, plan.h, Cut::End);
        }
        self.work.stepper.accept(&mut self.work.z);
        self.t = t1;
        self.landing.clear();
        if self.work.stepper.masked() {
            match at_start {
                Some(cause) => self.note_new_voids(t0, cause),
                None => self.note_new_voids(t1, VoidCause::NotFinite),
            }
        }
        self.work.det.advance();
        if plan.on_knot {
            self.cross_knots();
            let from = self.sampler.taken();
            self.sampler.take_here(&mut self.work.output_jac, t1, self.mode, &self.work.z[..]);
            self.tape_samples(from, TapeSample::Here);
        }
        self.record(PointKind::Step);
        self.h = h_next;
        StepOutcome::Accepted
    }

    /// Whether an input knot of the current mode where the flow jumps (`pwc`) is at `t`.
    fn knot_jumps_at(&mut self, t: f64) -> bool {
        let info = self.info;
        self.work.breakpoints.knots_at(t, self.mode).iter().any(|&(_, set)| info.knots[set as usize].jumps)
    }

    /// Crosses the input knots of the current mode at the current time, where a step just ended
    /// (reading the inputs on the knots' earlier side): at a `pwc` knot the sensitivities jump
    /// by `(f- - f+) dt_k/dp` (nothing at a `pwl` knot); the stepper restarts on the later side
    /// (its derivative there: the flow, or the sensitivities' rate, changed), and the guards'
    /// speeds with it where the flow jumped. The controller's proposal stands.
    fn cross_knots(&mut self) {
        let (t, mode, n) = (self.t, self.mode, self.n);
        let sets = self.work.breakpoints.knots_at(t, mode);
        self.work.knot_sets.clear();
        self.work.knot_sets.extend_from_slice(sets);
        let x = &self.work.z[..n];
        let crossed = self.work.knots.jump(self.sys, self.p, mode, t, x, &self.work.knot_sets, false);
        self.stats.switches += crossed.jumping;
        if crossed.jumps {
            self.work.knots.apply_new(&mut self.work.z[n..], n);
            self.note_knots_apart(crossed, t);
        }
        if crossed.jumps && self.tapes {
            // Every knot of the instant, of one input or several (the tape's transpose reads
            // their common motion as `Knots::jump` did).
            let jump = &self.work.knots.jump_new;
            self.recorder.tape(&TapeEntry::Knot { sets: &self.work.knot_sets, mode, t, jump });
        }
        if crossed.jumps || self.sens_like {
            let mut rhs = rhs_for(self.sys, self.p, n, mode);
            self.work.stepper.restart(t, &self.work.z, &mut rhs);
        }
        if crossed.jumps {
            let f = &self.work.stepper.start_derivative()[..n];
            self.work.det.eval_start(&self.guards(), t, &self.work.z[..n], f);
        }
    }

    /// Knots of inputs that move apart with a parameter met at `t`: a warning naming them.
    fn note_knots_apart(&mut self, crossed: super::knots::Crossed, t: f64) {
        if !crossed.apart {
            return;
        }
        let names: Vec<&str> = self
            .work
            .knot_sets
            .iter()
            .filter(|&&(_, set)| self.info.knots[set as usize].jumps)
            .map(|&(_, set)| &*self.info.knots[set as usize].name)
            .collect();
        self.warnings.push(SimWarning::KnotsApart { inputs: names.join(", ").into(), time: t });
    }

    /// The guard at `pos` stops being finite at `t` inside the step, before any crossing: the
    /// run stops there.
    fn stop_not_finite(&mut self, pos: usize, t: f64, look: Look) -> StepOutcome {
        if look.sample_due || self.sampler.wanted(&*self.recorder, t) {
            // The run stops on a fault: no gradient, nothing to tape.
            self.sample_step(t, true, None);
        }
        self.work.stepper.interpolant().eval(t, &mut self.work.z);
        self.t = t;
        let event = self.info.events[self.info.modes[self.mode].events[pos]].name.clone();
        let error = SimError::GuardNotFinite { event, t, mode: self.mode, state: self.fault_state() };
        StepOutcome::Done(StopReason::Fault { error })
    }

    /// The step is cut at the instant `t_fire` of the events selected in it: the state there
    /// (the step's end, the step landed on the instant, or the dense output), then the instant
    /// fires.
    fn cut_at_instant<F: Rhs>(
        &mut self,
        t_fire: f64,
        plan: Plan,
        look: Look,
        h_next: f64,
        rhs: &mut F,
    ) -> StepOutcome {
        let (t0, t1) = (plan.t0, plan.t1);
        // A crossing located a few spacings of `t` before an input knot the step ends on, where
        // the flow jumps, is on the knot: the event meets it there (as at `t_end`, rule 8).
        let t_fire = if plan.on_knot && t_fire < t1 && on_breakpoint(t_fire, t1) && self.knot_jumps_at(t1) {
            t1
        } else {
            t_fire
        };
        let at_start = if self.work.stepper.masked() { self.start_derivative_singularity() } else { None };
        if self.tapes {
            self.tape_x0.copy_from_slice(&self.work.z[..self.n]);
        }
        let mut cut = Cut::End;
        let sampling = look.sample_due || self.sampler.wanted(&*self.recorder, t_fire);
        if sampling {
            self.work.z_start.copy_from_slice(&self.work.z);
        }
        let t_fire = if t_fire == t1 {
            // On the step's end: the step's own end state. The dense output reproduces
            // it only to round-off, and a guard found across there by the end values (an
            // event at `t_end`, `x = 0.3 t` reaching 0.3) could be read back on its
            // pre-crossing side and skipped as moved back by an earlier reset.
            self.work.z.copy_from_slice(self.work.stepper.end_state());
            t_fire
        } else {
            match self.land_on_event(t0, t_fire, t1, rhs) {
                Landing::Landed(t_landed) => {
                    cut = Cut::Landed(self.tape_landing.1);
                    t_landed
                }
                Landing::Retry if plan.h > GUARD_WALK_FLOOR * t0.abs().max(1.0) => {
                    // The dense output was too far off where it was read (a stiff phase: its
                    // error times the stiffness is the crossing speed's): the step does not
                    // stand, and a shorter one reads a better dense output (docs/language.md,
                    // rule 3). The controller has learnt from the step; the shorter size
                    // overrides its proposal.
                    self.work.det.forget_findings();
                    self.stats.steps -= 1;
                    self.stats.rejected += 1;
                    self.h = LANDING_RETRY * plan.h;
                    return StepOutcome::Rejected;
                }
                Landing::Dense | Landing::Retry => {
                    self.work.stepper.interpolant().eval(t_fire, &mut self.work.z);
                    cut = Cut::Dense(t_fire);
                    t_fire
                }
            }
        };
        if self.tapes {
            let h = if matches!(cut, Cut::Landed(_)) { self.tape_landing.0 } else { plan.h };
            self.tape_step(plan, h, cut);
        }
        // Samples before the instant, taken now that the step stands.
        if sampling {
            self.land_samples(t0, t_fire, true, rhs, (plan, true));
            self.sample_step(t_fire, true, Some((plan, true)));
        }
        self.t = t_fire;
        self.landing.clear();
        if self.work.stepper.masked() {
            match at_start {
                Some(cause) => self.note_new_voids(t0, cause),
                None => self.note_new_voids(t_fire, VoidCause::NotFinite),
            }
        }
        self.record(PointKind::BeforeEvents);
        self.fire_instant(h_next)
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
    /// the first time found there). Writes that state into `z` and returns `Landed` with the
    /// instant; `Dense` (the caller takes the dense output's state at `t_fire`, as without
    /// landing) when landing is off, when the group holds a touch, an event fired on its guard at
    /// the step's start or a flow switch (their state and sides are the dense output's:
    /// `cross_switch`), or when the landed step fails its error test (it is shorter, so rarely);
    /// `Retry` when the correction is not small against the step: the dense output was off by
    /// more than one Newton step corrects where it was read, and so may be its other findings.
    fn land_on_event<F: Rhs>(&mut self, t0: f64, t_fire: f64, t1: f64, rhs: &mut F) -> Landing {
        if t_fire <= t0 || !self.lands_on_events() {
            return Landing::Dense;
        }
        let evs = &self.info.modes[self.mode].events;
        let plain = |&(ev, c): &(usize, Crossing)| !(c.touch || c.on_guard || self.info.events[ev].implicit);
        if !self.work.det.group.iter().all(plain) {
            return Landing::Dense;
        }
        self.work.z_start.copy_from_slice(&self.work.z);
        let (n, cx) = (self.n, self.guards());
        // Newton's step from the first landing, then secant steps through the landed guard
        // values: in a stiff phase the flow at the landed state carries the state's error times
        // the stiffness into the speed, the guard values do not.
        let (mut t_land, mut dt) = (t_fire, 0.0);
        let mut previous: Option<(f64, f64)> = None;
        let mut crossed = false;
        for landing in 0..LANDINGS {
            let h = t_land - t0;
            let err = self.work.stepper.land(t0, &self.work.z_start, h, rhs);
            // A NaN error (nothing finite) fails too.
            if err.is_nan() || err > 1.0 {
                return Landing::Dense;
            }
            self.work.z.copy_from_slice(self.work.stepper.end_state());
            let f = self.work.stepper.end_derivative();
            // The latest of the group's crossings, so that every guard has crossed.
            let (mut newton, mut g_latest) = (f64::NEG_INFINITY, 0.0);
            crossed = true;
            for gi in 0..self.work.det.group.len() {
                let (ev, c) = self.work.det.group[gi];
                let Some(pos) = evs.iter().position(|&e| e == ev) else { return Landing::Dense };
                let (g, speed) = self.work.det.guard_and_speed(&cx, pos, t_land, &self.work.z[..n], &f[..n]);
                crossed &= c.sigma * g <= 0.0;
                if -g / speed > newton {
                    (newton, g_latest) = (-g / speed, g);
                }
            }
            if !newton.is_finite() {
                return Landing::Dense;
            }
            if landing == 0 && newton.abs() <= LANDING_EXACT * h {
                // The dense output was right to where one Newton step finishes the job (the
                // explicit pairs, and most Rosenbrock landings).
                dt = newton;
                break;
            }
            dt = match previous {
                Some((t_prev, g_prev)) if g_prev != g_latest => {
                    -g_latest * (t_land - t_prev) / (g_latest - g_prev)
                }
                _ => newton,
            };
            let spacing = spacing(t_land);
            if landing > 0 && dt.abs() <= LANDING_RESOLVED * spacing {
                break;
            }
            let next = t_land + dt;
            if !(next > t0 && next <= t1) {
                // The landed guards put the crossing outside the step.
                return Landing::Retry;
            }
            if landing + 1 == LANDINGS {
                break;
            }
            previous = Some((t_land, g_latest));
            t_land = next;
        }
        // Far from where the dense output put it: so may be its other findings; the instant
        // stands when no other guard has crossed by then.
        let far = (t_land - t_fire).abs() > LANDING_CORRECTION * (t_fire - t0);
        if far && self.work.det.another_crossed(&cx, t_land, &self.work.z[..n]) {
            return Landing::Retry;
        }
        let (t_fire, crossed_at_landing) = (t_land, crossed);
        let f = self.work.stepper.end_derivative();
        let end = self.work.stepper.end_state();
        let mut t = t_fire + dt;
        for _ in 0..LANDING_NUDGES {
            let dt = t - t_fire;
            for ((z, &e), &d) in self.work.z.iter_mut().zip(end).zip(f) {
                *z = e + dt * d;
            }
            let mut crossed = true;
            for gi in 0..self.work.det.group.len() {
                let (ev, c) = self.work.det.group[gi];
                let Some(pos) = evs.iter().position(|&e| e == ev) else { return Landing::Dense };
                let g = self.work.det.guard_now(&cx, pos, t, &self.work.z[..n]);
                crossed &= c.sigma * g <= 0.0;
            }
            if crossed {
                if t <= t0 {
                    return Landing::Dense;
                }
                self.tape_landing = (t_fire - t0, dt);
                self.landed_velocity(t0, t_fire, t, rhs);
                return Landing::Landed(t);
            }
            t = t.next_up();
        }
        if crossed_at_landing {
            // The flow's extrapolation did not get across (a stiff flow at the landed state):
            // the landed state is, a few spacings of `t` past the first time across.
            self.work.z.copy_from_slice(self.work.stepper.end_state());
            self.tape_landing = (t_fire - t0, 0.0);
            self.landed_velocity(t0, t_fire, t_fire, rhs);
            return Landing::Landed(t_fire);
        }
        if far {
            // The landed guards never got across, and put the instant far from where the dense
            // output did: its crossing there is the dense output's error (Rodas4 at c = 0.4999
            // fired a crossing the trajectory never makes); a shorter step reads a better one.
            return Landing::Retry;
        }
        Landing::Dense
    }

    /// The velocity of the computed trajectory at the instant landed at `t_land` from
    /// `(t0, z_start)`, for the crossing speed in the event's `dt/dp` (`Jump::set_velocity`, for
    /// the instant `t_instant` a few spacings on, whose state is in `z`), where the flow at the
    /// landed state is not to be trusted with it: in a stiff phase it carries the state's error
    /// times the stiffness (at stiffness 1e6 and rtol 1e-8, the size of a slow crossing's speed:
    /// dt/dc was 0.5% to 13% off), while the trajectory's own velocity does not (its error varies
    /// slowly along it). The test is the flow's growth along the state's error: with `d` the
    /// landed state minus the dense output there (two estimates of one state), the step is stiff
    /// along it when `h |f(x + d) - f(x)|` exceeds a difference's error, `|d|` plus its round-off,
    /// [`STIFF_LANDING`] times (one flow evaluation). Then the velocity is a
    /// central difference of the steps landed `delta` either side; elsewhere the flow, which is
    /// exact where the trajectory is a polynomial of the method's degree and as accurate as a
    /// difference otherwise. Only with sensitivities (nothing else reads the speed that finely);
    /// the flow is kept when a landing fails its error test or `delta` is within a few spacings of
    /// `t`.
    fn landed_velocity<F: Rhs>(&mut self, t0: f64, t_land: f64, t_instant: f64, rhs: &mut F) {
        self.work.jump.clear_velocity();
        let (n, h) = (self.n, t_land - t0);
        let delta = VELOCITY_HALF_WIDTH * h;
        if !self.sens_like || n == 0 || delta <= LANDING_RESOLVED * spacing(t_land) {
            return;
        }
        let (v, probe) = &mut self.work.landed_velocity;
        v.resize(n, 0.0);
        probe.resize(n, 0.0);
        self.work.stepper.interpolant().eval(t_land, v);
        let end = &self.work.stepper.end_state()[..n];
        let mut d_norm = 0.0f64;
        for ((p, &x), &dense) in probe.iter_mut().zip(end).zip(v.iter()) {
            d_norm = d_norm.max((x - dense).abs());
            *p = x + (x - dense);
        }
        if d_norm == 0.0 || !d_norm.is_finite() {
            return;
        }
        self.sys.flow(self.mode, t_land, probe, self.p, v);
        let growth = v
            .iter()
            .zip(&self.work.stepper.end_derivative()[..n])
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        let x_norm = end.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        let difference_error = d_norm + EPS * x_norm / VELOCITY_HALF_WIDTH;
        // NaN-safe: a growth or error that is not a number keeps the flow.
        if (h * growth).partial_cmp(&(STIFF_LANDING * difference_error)) != Some(std::cmp::Ordering::Greater)
        {
            return;
        }
        // A NaN error (nothing finite) fails too.
        let err = self.work.stepper.land(t0, &self.work.z_start, h - delta, rhs);
        if err.is_nan() || err > 1.0 {
            return;
        }
        v.copy_from_slice(&self.work.stepper.end_state()[..n]);
        let err = self.work.stepper.land(t0, &self.work.z_start, h + delta, rhs);
        if err.is_nan() || err > 1.0 {
            return;
        }
        for (v, &x) in v.iter_mut().zip(&self.work.stepper.end_state()[..n]) {
            *v = (x - *v) / (2.0 * delta);
        }
        if v.iter().all(|v| v.is_finite()) {
            self.work.jump.set_velocity(t_instant, self.mode, &self.work.z[..n], v);
        }
    }

    /// Whether event instants inside a step are landed on ([`Self::land_on_event`]).
    fn lands_on_events(&mut self) -> bool {
        match self.opts.land_events {
            Some(land) => land,
            None => self.work.stepper.lands_on_events(&self.work.z),
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
        self.work.fired.clear();
        self.work.before.0.clear();
        self.work.before.0.extend_from_slice(&self.work.z[..n]);
        if on_breakpoint(self.t, self.opts.t_end) {
            // An instant at t_end: the other side of the cusp is the run without it.
            self.before_end = Some((self.work.z.to_vec(), first));
        }
        // On input knots the events are met on the knots' earlier side, and the knots are
        // crossed after them (`knots_after_instant`).
        let (t_instant, switches) = (self.t, self.stats.switches);
        self.left_of_knot = self.knots_at_instant(t_instant);
        let mut rounds = 0;
        let mut estimate;
        loop {
            let round_start = self.work.fired.len();
            if let Some(stop) = self.fire_group(rounds > 0) {
                if self.left_of_knot {
                    self.stop_at_knots(first);
                }
                return StepOutcome::Done(stop);
            }
            if self.work.z[..n].iter().any(|v| !v.is_finite()) {
                return StepOutcome::Done(self.fault_nonfinite());
            }
            if rounds == 0 {
                self.restart_past_switches();
            }
            estimate = self.restart();
            self.work.reset_onto.clear();
            if !self.cascade(round_start) {
                break;
            }
            rounds += 1;
            if rounds > MAX_CASCADE_ROUNDS {
                let ev = self.work.det.group.first().map_or(0, |&(ev, _)| ev);
                return StepOutcome::Done(StopReason::Stuck {
                    time: self.t,
                    event: ev,
                    name: self.info.events[ev].name.clone(),
                    rounds: MAX_CASCADE_ROUNDS,
                });
            }
            self.work.before.0.clear();
            self.work.before.0.extend_from_slice(&self.work.z[..n]);
        }
        if self.left_of_knot {
            // One declared event and nothing else: no cascade, no flow switch.
            let single = rounds == 0 && self.events.len() == first + 1 && self.stats.switches == switches;
            self.knots_after_instant(t_instant, first, single);
            estimate = self.restart();
        }
        self.record(PointKind::AfterEvents);
        let from = self.sampler.taken();
        self.sampler.take_here(&mut self.work.output_jac, self.t, self.mode, &self.work.z[..]);
        self.tape_samples(from, TapeSample::Here);
        for (void, s) in self.work.void.iter_mut().zip(&self.work.z[self.n..]) {
            *void |= s.is_nan();
        }
        if self.events.len() >= self.opts.max_events {
            return StepOutcome::Done(zeno::at_max_events(&self.events, self.t));
        }
        if let Some(stop) = self.zeno.accumulating(&self.events) {
            return StepOutcome::Done(stop);
        }
        if let Some(stop) = self.after_instant() {
            return StepOutcome::Done(stop);
        }
        let growth = if self.mode == mode_before { AFTER_RESET_GROWTH } else { AFTER_SWITCH_GROWTH };
        self.h = self.continue_step(h_next, estimate, growth);
        // The step that found this instant saw further crossings: the next step reaches just past
        // the earliest of them rather than over all of them again (each would be bracketed and
        // scanned only for the earliest to fire).
        if let Some(t_next) =
            self.work.det.next_crossing.take().filter(|&t| t > self.t && self.mode == mode_before)
        {
            // At least a resolvable step: a crossing a few spacings of `t` ahead is then inside it.
            let floor = 16.0 * EPS * self.t.abs();
            self.h = self.h.min((NEXT_CROSSING_REACH * (t_next - self.t)).max(floor));
        }
        StepOutcome::Fired { first, count: self.events.len() - first }
    }

    /// Whether input knots of any mode are at the instant `t` (its events then read the flows on
    /// the knots' earlier side); the flow's jump at those of the current mode, at the state
    /// before the instant, into `Knots::jump_old`.
    fn knots_at_instant(&mut self, t: f64) -> bool {
        let modes = self.info.modes.len();
        if !(0..modes).any(|m| !self.work.breakpoints.knots_at(t, m).is_empty()) {
            return false;
        }
        let sets = self.work.breakpoints.knots_at(t, self.mode);
        self.work.knot_sets.clear();
        self.work.knot_sets.extend_from_slice(sets);
        let x = &self.work.z[..self.n];
        self.work.knots.jump(self.sys, self.p, self.mode, t, x, &self.work.knot_sets, true);
        true
    }

    /// After the events of an instant at `t` on input knots (the run's events `first..`, `single`
    /// when one event fired alone): the knots of the mode the run goes on in are crossed (the
    /// sensitivities jump by `(f- - f+) dt_k/dp` at a `pwc` knot), and where the flow jumps
    /// there, in the mode the events were met in or the one after, the derivatives that moving
    /// the events off the knots would change do not exist: for one event, those that differ
    /// between the two orders of the event and the knots (`Jump::knot_order`); for a group or a
    /// cascade, every derivative with respect to a parameter that moves the instant and the
    /// knots apart, and the event times' where a state event fired. A warning names the first
    /// event when any was found not to exist.
    fn knots_after_instant(&mut self, t: f64, first: usize, single: bool) {
        let (mode, n) = (self.mode, self.n);
        let sets = self.work.breakpoints.knots_at(t, mode);
        self.work.knot_sets.clear();
        self.work.knot_sets.extend_from_slice(sets);
        let x = &self.work.z[..n];
        let crossed = self.work.knots.jump(self.sys, self.p, mode, t, x, &self.work.knot_sets, false);
        self.stats.switches += crossed.jumping;
        if crossed.jumps {
            self.work.knots.apply_new(&mut self.work.z[n..], n);
            self.note_knots_apart(crossed, t);
            if self.tapes {
                let jump = &self.work.knots.jump_new;
                self.recorder.tape(&TapeEntry::Knot { sets: &self.work.knot_sets, mode, t, jump });
            }
        }
        let old = self.work.knots.old;
        let Some(d) = self.instant.filter(|_| self.events.len() > first && (old.jumps || crossed.jumps))
        else {
            return;
        };
        let knots = &self.work.knots;
        let voided = if single {
            let s = &mut self.work.z[n..];
            let voided = self.work.jump.knot_order(
                (&knots.jump_old, &knots.dt_old),
                (&knots.jump_new, &knots.dt_new),
                d,
                s,
            );
            if voided {
                self.events[first].dtime = existing(&self.work.jump.dte);
            }
            voided
        } else {
            self.void_apart(first)
        };
        if self.tapes {
            let e = &self.events[first];
            let x = &self.work.before.0;
            let old_sets = self.work.breakpoints.knots_at(t, e.mode_before);
            let (old, new) =
                ((e.mode_before, old_sets, old.jumps), Some((mode, &self.work.knot_sets[..], crossed.jumps)));
            self.recorder.tape(&TapeEntry::KnotsMet { t, event: e.event, x, old, new });
        }
        if voided {
            let set = old.set.or(crossed.set).unwrap_or(0) as usize;
            let e = &self.events[first];
            self.warnings.push(SimWarning::EventAtKnot {
                event: e.event,
                name: e.name.clone(),
                time: t,
                input: self.info.knots[set].name.clone(),
            });
        }
    }

    /// The events `first..` of an instant on input knots, as a group or a cascade: every
    /// derivative with respect to a parameter that moves the instant (`instant_dte`) and the
    /// knots where the flow jumps apart does not exist, nor does a state event's time derivative
    /// with respect to it. Returns whether any was found so.
    fn void_apart(&mut self, first: usize) -> bool {
        let (n, knots) = (self.n, &self.work.knots);
        let (old_jumps, new_jumps) = (knots.old.jumps, knots.jump_new.iter().any(|&j| j != 0.0));
        let mut voided = false;
        for j in 0..self.m {
            let a = self.work.instant_dte[j];
            let apart = (old_jumps && !same(a, knots.dt_old[j])) || (new_jumps && !same(a, knots.dt_new[j]));
            if !apart {
                continue;
            }
            voided = true;
            self.work.z[n + j * n..n + (j + 1) * n].fill(f64::NAN);
            for e in &mut self.events[first..] {
                if self.info.events[e.event].guard != GuardShape::Time {
                    if let Some(dtime) = &mut e.dtime {
                        dtime[j] = f64::NAN;
                    }
                }
            }
        }
        for e in &mut self.events[first..] {
            if e.dtime.as_ref().is_some_and(|d| d.iter().all(|v| v.is_nan())) {
                e.dtime = None;
            }
        }
        voided
    }

    /// A stop event fired on input knots where the flow jumps, in the mode it was met in: the
    /// final derivatives with respect to a parameter that moves the stop and the knots apart
    /// differ on the two sides (the flow the stop's motion carries the state along is either
    /// side's), and do not exist, nor does the stop's time derivative unless it is a time event's
    /// (the same on both sides).
    fn stop_at_knots(&mut self, first: usize) {
        if !self.work.knots.old.jumps || self.events.len() <= first {
            return;
        }
        let time_event = self.info.events[self.events[first].event].guard == GuardShape::Time;
        let (n, knots) = (self.n, &self.work.knots);
        let mut voided = false;
        for j in 0..self.m {
            let a = self.work.instant_dte.get(j).copied().unwrap_or(f64::NAN);
            if same(a, knots.dt_old[j]) {
                continue;
            }
            voided = true;
            self.work.z[n + j * n..n + (j + 1) * n].fill(f64::NAN);
            if let Some((total, dte)) = &mut self.stop_total {
                total[j * n..(j + 1) * n].fill(f64::NAN);
                if !time_event {
                    dte[j] = f64::NAN;
                }
            }
            if let Some(dtime) = self.events[first].dtime.as_mut().filter(|_| !time_event) {
                dtime[j] = f64::NAN;
            }
        }
        if self.tapes {
            let e = &self.events[first];
            let old = (e.mode_before, self.work.breakpoints.knots_at(self.t, e.mode_before), true);
            let (t, x) = (self.t, &self.work.before.0);
            self.recorder.tape(&TapeEntry::KnotsMet { t, event: e.event, x, old, new: None });
        }
        if voided {
            let set = self.work.knots.old.set.unwrap_or(0) as usize;
            let e = &self.events[first];
            self.warnings.push(SimWarning::EventAtKnot {
                event: e.event,
                name: e.name.clone(),
                time: self.t,
                input: self.info.knots[set].name.clone(),
            });
        }
    }

    /// After a round of events (`before.0` holds the state before it, the detector the guards
    /// after it; the round's events are `fired[round_start..]`): the events whose guard the round moved from strictly its pre-crossing side to
    /// its crossed side, or onto zero with the flow carrying it across, fill the next group (the
    /// next round at this instant). Guards moved onto zero with no clear speed go to
    /// `work.reset_onto`, for the next step to decide. Returns whether there is a next round.
    fn cascade(&mut self, round_start: usize) -> bool {
        let (t, n) = (self.t, self.n);
        let evs = &self.info.modes[self.mode].events;
        let ne = evs.len();
        self.work.det.group.clear();
        // The events that just fired were at their crossing before the round, never strictly on
        // their pre-crossing side: when they are all the mode has, nothing can cascade.
        let fired_now = &self.work.fired[round_start..];
        if evs.iter().all(|ev| fired_now.iter().any(|f| f.0 == *ev)) {
            return false;
        }
        let mut enabled = false;
        self.work.reset_onto_guard.clear();
        let cx = self.guards();
        let (x_before, g_before) = &mut self.work.before;
        g_before.resize(ne, 0.0);
        self.sys.guards(self.mode, t, x_before, self.p, &mut g_before[..ne]);
        for (pos, &ev) in evs.iter().enumerate() {
            let einfo = &self.info.events[ev];
            // A guard the round did not move cannot have been moved across. An event of the
            // round was at its crossing before it: what its reset does to its own guard is
            // rule 6 (`after_instant`), not a cascade, on either side of a `crosses` guard too.
            if einfo.implicit || g_before[pos] == self.work.det.g0[pos] || fired_now.iter().any(|f| f.0 == ev)
            {
                continue;
            }
            let dir = einfo.direction;
            let (noise, speed_noise) = self.work.det.noise0(&cx, pos);
            // Strictly on a pre-crossing side before the round: for `crosses`, either side, the
            // crossed side then being the other one (rule 7 of docs/language.md).
            let before = g_before[pos];
            let either = dir == Direction::Either;
            let pre_crossing = match clear_side(dir, before, noise) {
                Some(crossed) => !crossed || either,
                None => false,
            };
            if !pre_crossing {
                continue;
            }
            let after = self.work.det.g0[pos];
            let sigma = match clear_side(dir, after, noise) {
                Some(true) if !either || after.signum() != before.signum() => before.signum(),
                Some(_) => continue,
                None => match moves_across(dir, self.work.det.dg0[pos], speed_noise)
                    .filter(|&sigma| !either || sigma == before.signum())
                {
                    Some(sigma) => {
                        self.work.reset_onto_guard.push(ev);
                        sigma
                    }
                    None => {
                        if self.work.det.dg0[pos].abs() <= speed_noise {
                            self.work.reset_onto.push(pos);
                        }
                        continue;
                    }
                },
            };
            // Every moved guard joins the round, its condition judged when its turn comes (an
            // earlier event of the round may make it true); the round happens when the first
            // event to fire, which sees the state as the last round left it, has its condition.
            enabled |= self.sys.condition(ev, t, &self.work.z[..n], self.p);
            self.work.det.group.push((ev, Crossing { t, sigma, touch: false, t_pre: t, on_guard: true }));
        }
        if !enabled {
            self.work.det.group.clear();
        }
        enabled
    }

    /// The rules after an instant: a contact that fired and is left on its guard is stuck when
    /// the flow carries it across (or pending when the speed is round-off), a reset that reversed
    /// a guard's speed is a bounce watched for penetration, guards reset onto zero are pending.
    fn after_instant(&mut self) -> Option<StopReason> {
        self.work.det.clear_bounces();
        for &pos in &self.work.reset_onto {
            let (noise, _) = self.work.det.noise0(&self.guards(), pos);
            self.work.det.set_pending(pos, Pending::OnGuard, noise);
        }
        let evs = &self.info.modes[self.mode].events;
        for &(ev, sigma, speed_before, accuracy) in self.work.fired.iter() {
            let Some(pos) = evs.iter().position(|&e| e == ev) else { continue };
            let einfo = &self.info.events[ev];
            // Within round-off, or within what locating the crossing to adjacent floats leaves
            // (the speed before the event times a few spacings of `t`).
            let located = 4.0 * speed_before.abs() * spacing(self.t);
            let (noise, speed_noise) = self.work.det.noise0(&self.guards(), pos);
            let on_guard = self.work.det.g0[pos].abs() <= noise + located;
            // Only a speed the reset left within round-off can be stuck: the first step decides
            // (`Pending::Contact`). A clear speed that keeps the crossing's direction is a
            // pass-through (a gear shift that changes the rate driving its own guard), one that
            // turns around is a bounce. Stopping on the first (round 2's rule) stopped every
            // gear shift, thermostat and dose that changes its own clearance.
            if einfo.contact && on_guard && self.work.det.dg0[pos].abs() <= speed_noise {
                self.work.det.set_pending(pos, Pending::Contact, noise + located);
                continue;
            }
            // Only a reset that turns the guard around on zero bounces in the sense of rule 6: one
            // that puts the guard clearly on its crossed side (`x := -0.85` onto `x <= -0.649`)
            // leaves it there to come back by the flow, as a run starting there does (rule 5), and
            // its way back, however long, is no bounce too small to resolve. On zero is within
            // what the located state is known to: round-off and the guard's accuracy at the
            // tolerances (a landed step's state is off the guard by its own error).
            if self.work.det.g0[pos].abs() <= noise + located + accuracy {
                self.work.det.note_bounce(pos, sigma, speed_before);
            }
        }
        None
    }

    /// A contact stuck on its guard at the current instant.
    fn stuck_on_guard(&self, ev: usize) -> StopReason {
        StopReason::Stuck { time: self.t, event: ev, name: self.info.events[ev].name.clone(), rounds: 0 }
    }

    fn fault_state(&self) -> Vec<f64> {
        self.work.z[..self.n].to_vec()
    }

    /// New start point (beginning, after events): derivative, guards and Hairer's step estimate
    /// for the new state.
    fn restart(&mut self) -> f64 {
        let mut rhs = rhs_for(self.sys, self.p, self.n, self.mode);
        self.work.stepper.restart(self.t, &self.work.z, &mut rhs);
        let n = self.n;
        self.work.det.eval_start(
            &self.guards(),
            self.t,
            &self.work.z[..n],
            &self.work.stepper.start_derivative()[..n],
        );
        self.work.stepper.initial_step(self.t, &self.work.z, self.opts.h_max, &mut rhs)
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
        let group_len = self.work.det.group.len();
        let declared_before = self.work.fired.len();
        for gi in 0..group_len {
            let (ev, crossing): (usize, Crossing) = self.work.det.group[gi];
            let Some(pos) = self.info.modes[self.mode].events.iter().position(|&e| e == ev) else {
                // An earlier event of the group switched to a mode without this event.
                continue;
            };
            let context = self.crossing_context(pos, crossing, self.mode == self.step_mode);
            let cx = self.guards();
            let (x, s) = self.work.z.split_at_mut(n);
            if !(crossing.touch || crossing.on_guard) {
                let g = self.work.det.guard_now(&cx, pos, t, x);
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
                self.cross_switch(ev, pos, crossing, self.work.fired.len() > declared_before || cascade);
                continue;
            }
            let mode_before = self.mode;
            let mode_after = einfo.target_mode.unwrap_or(mode_before);
            let onto_guard = cascade && self.work.reset_onto_guard.contains(&ev);
            if onto_guard {
                // Put on its guard by a reset, to round-off: a parameter change lands the state
                // before the guard (the event fires later, by the flow) or across it (now), with
                // different derivatives on the two sides. None exists where the parameter moves
                // the instant or this guard; where it moves neither, 0.
                let (gx, gp) = &mut self.work.onto_guard_grad;
                // Zeroed as the fresh buffers they replace were.
                gx.fill(0.0);
                gp.fill(0.0);
                self.sys.guard_grad(ev, t, x, self.p, gx, gp);
                self.work.onto_guard_dte.clear();
                for j in 0..self.m {
                    let moved = dot_nonzero(gx, &s[j * n..(j + 1) * n]) + gp[j];
                    let still = moved == 0.0 && self.work.instant_dte.get(j).is_none_or(|&d| d == 0.0);
                    self.work.onto_guard_dte.push(if still { 0.0 } else { f64::NAN });
                }
                self.warnings.push(SimWarning::ResetOntoGuard {
                    event: ev,
                    name: einfo.name.clone(),
                    time: t,
                });
            }
            // An event that takes its own instant is applied where its guard crossed zero, its
            // lateness carried by the flows on both sides (`move_to_crossing`).
            let own_instant = !(self.instant.is_some() && (onto_guard || cascade));
            let late = (own_instant && !self.left_of_knot)
                .then(|| self.move_to_crossing(ev, pos, &context))
                .flatten();
            let (x, s) = self.work.z.split_at_mut(n);
            let given = match self.instant {
                Some(speed) if onto_guard => Some((&self.work.onto_guard_dte[..], speed)),
                Some(speed) if cascade => Some((&self.work.instant_dte[..], speed)),
                _ => None,
            };
            if self.tapes {
                let entry = TapeEntry::Jump {
                    event: ev,
                    t,
                    mode_before,
                    mode_after,
                    x,
                    velocity: self.work.jump.measured_velocity(t, mode_before, x),
                    cascade: given.is_some(),
                    first_of_instant: self.instant.is_none() && !cascade,
                    on_knots: self.left_of_knot,
                };
                self.recorder.tape(&entry);
                if onto_guard && self.instant.is_some() {
                    // Its `dt/dp` is `onto_guard_dte`: the backward pass voids what it reaches.
                    self.recorder.tape(&TapeEntry::OntoGuard);
                }
            }
            let out = self.work.jump.apply(
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
            if let Some(delta) = late.filter(|_| !out.grazing && !einfo.is_stop) {
                self.move_past_crossing(mode_after, delta);
            }
            if self.instant.is_none() && !cascade {
                self.instant = Some(out.denominator);
                self.work.instant_dte.clear();
                self.work.instant_dte.extend_from_slice(&self.work.jump.dte);
            }
            if out.grazing && self.tapes {
                self.recorder.tape(&TapeEntry::Grazed);
            }
            self.note_conditioning(ev, t, out);
            self.events.push(EventRecord {
                index: self.events.len(),
                event: ev,
                name: einfo.name.clone(),
                time: t,
                mode_before,
                mode_after,
                dtime: existing(&self.work.jump.dte),
                grazing: out.grazing,
                denominator: out.denominator,
                margin: out.margin,
                resolution: out.resolution,
            });
            self.stats.events += 1;
            self.work.fired.push((
                ev,
                crossing.sigma,
                out.denominator,
                (out.resolution * out.denominator).abs(),
            ));
            self.mode = mode_after;
            if einfo.is_stop {
                self.stop_total = Some((self.work.jump.total.clone(), self.work.jump.dte.clone()));
                return Some(StopReason::Event { event: ev, name: einfo.name.clone() });
            }
        }
        None
    }

    /// Rule 1 fires an event at the first time `t` on the crossed side of its guard, up to one
    /// spacing of `t` (a landed instant up to 64) after the crossing itself: `delta = g / d` later,
    /// with `g` the guard at `t` and `d` its crossing speed. Applied to the state at `t`, the reset
    /// would start the post-event trajectory `delta` late: at `t = 1e6` a spacing is 1.2e-10, and
    /// over 2,578 events of a state crossing at speed 410 that was 1.2e-4 of phase (12,640
    /// tolerances). So where the lateness moves some state by more than [`LATENESS_RELEVANCE`] of
    /// its tolerance, the state and its sensitivities are first carried back along the flow to
    /// the crossing (`x - delta f`, `S - delta (f_x S + f_p)`), the event is applied there, and
    /// `move_past_crossing` carries the result forward to `t`: the values and derivatives of the
    /// trajectory reset at the crossing, to first order in `delta` (`delta` itself a constant).
    /// Returns `delta` when it moved the state. Nothing moves for a crossing at a step's start
    /// (on its guard), or where the guard says more than a lateness (`delta` beyond
    /// [`LATENESS_SPACINGS`] spacings: the state's own error). Both moves are on the adjoint's
    /// tape (`TapeEntry::Drift`).
    fn move_to_crossing(&mut self, ev: usize, pos: usize, context: &CrossingContext) -> Option<f64> {
        let (n, m, t) = (self.n, self.m, self.t);
        let (t0, d0, t1, d1) = context.step?;
        let cx = self.guards();
        let g = self.work.det.guard_now(&cx, pos, t, &self.work.z[..n]);
        // The speed between the step's ends tells a lateness within the spacings from a guard
        // that says more, before anything is evaluated.
        let rough = if t1 > t0 { d0 + (d1 - d0) * ((t - t0) / (t1 - t0)) } else { d1 };
        let limit = LATENESS_SPACINGS * spacing(t);
        let within = g.abs() <= 2.0 * limit * rough.abs();
        if g == 0.0 || !within {
            return None;
        }
        let (f, ds, gx, gp) = &mut self.work.lateness;
        let (x, sens) = self.work.z.split_at_mut(n);
        let measured = self.work.jump.measured_velocity(t, self.mode, x).map(<[f64]>::to_vec);
        match &measured {
            Some(v) => f.copy_from_slice(v),
            None => self.sys.flow(self.mode, t, x, self.p, f),
        }
        let gt = self.sys.guard_grad(ev, t, x, self.p, gx, gp);
        let delta = g / (dot(gx, f) + gt);
        let (rtol, atol) = (self.opts.rtol, self.opts.atol);
        let relevant = x
            .iter()
            .zip(f.iter())
            .any(|(x, f)| (delta * f).abs() > LATENESS_RELEVANCE * (atol + rtol * x.abs()));
        if !(delta.is_finite() && delta.abs() <= limit && relevant) {
            return None;
        }
        if m > 0 {
            // `gx` is spent: it takes the flow `flow_sens` writes beside `ds`.
            self.sys.flow_sens(self.mode, t, x, sens, self.p, gx, ds);
        }
        if self.tapes {
            self.recorder.tape(&TapeEntry::Drift { dt: -delta, mode: self.mode, t, x });
        }
        for (x, f) in x.iter_mut().zip(f.iter()) {
            *x -= delta * f;
        }
        for (s, d) in sens.iter_mut().zip(ds.iter()) {
            *s -= delta * d;
        }
        if let Some(v) = &measured {
            self.work.jump.set_velocity(t, self.mode, x, v);
        }
        Some(delta)
    }

    /// After `move_to_crossing` and the event at the crossing: the state and its sensitivities
    /// carried `delta` along the new mode's flow, to the instant `t`. Not where that would take a
    /// guard of the new mode off zero: a reset onto a guard stays on it, and what the rules on
    /// resets onto guards see is unchanged.
    fn move_past_crossing(&mut self, mode_after: usize, delta: f64) {
        let (n, m, t) = (self.n, self.m, self.t);
        let (f, ds, moved, _) = &mut self.work.lateness;
        let (x, sens) = self.work.z.split_at_mut(n);
        if m > 0 {
            self.sys.flow_sens(mode_after, t, x, sens, self.p, f, ds);
        } else {
            self.sys.flow(mode_after, t, x, self.p, f);
        }
        moved.resize(n, 0.0);
        for ((m, x), f) in moved.iter_mut().zip(x.iter()).zip(f.iter()) {
            *m = x + delta * f;
        }
        let cx = Guards::new(self.sys, self.info, self.p, mode_after);
        let ne = cx.events().len();
        let (at, at_moved) = &mut self.work.lateness_guards;
        at.resize(ne, 0.0);
        at_moved.resize(ne, 0.0);
        cx.eval(t, x, at);
        cx.eval(t, moved, at_moved);
        // A reset that put the state exactly on a guard leaves it there (rule 7's resets onto
        // guards); a guard near zero at the crossing is decided by the move, as by the flow.
        if at.iter().zip(at_moved.iter()).any(|(a, b)| *a == 0.0 && *b != 0.0) {
            return;
        }
        if self.tapes {
            self.recorder.tape(&TapeEntry::Drift { dt: delta, mode: mode_after, t, x });
        }
        x.copy_from_slice(moved);
        for (s, d) in sens.iter_mut().zip(ds.iter()) {
            *s += delta * d;
        }
    }

    /// Crosses the flow switch `ev` (at position `pos` of the mode's events) located at
    /// `crossing`; the state is already at the group's time. The sensitivities take the jump of
    /// the flow, read on the interpolant at the last time found before the switch and at the
    /// first time strictly past it (on the switch itself an `if` or `sign` may still give the
    /// old branch or neither). When a declared event of the same group has already fired, the
    /// state before the switch is not on the interpolant any more: the gradients are then marked
    /// as not meaningful instead.
    fn cross_switch(&mut self, ev: usize, pos: usize, crossing: Crossing, after_an_event: bool) {
        let (n, t) = (self.n, self.t);
        self.stats.switches += 1;
        // The flow is continuous at a kink: nothing jumps there, whatever else happened at this
        // instant; the run goes on from past it as from past any switch.
        let kink = self.info.events[ev].kink;
        let voids = !kink && (after_an_event || crossing.on_guard);
        if self.tapes && voids {
            self.recorder.tape(&TapeEntry::VoidAll);
        } else if self.tapes && self.left_of_knot && !kink {
            // (A kink on a knot applies nothing: no order between the two to decide.)
            self.recorder.tape(&TapeEntry::Unsupported("a flow switch on an input knot"));
        }
        if voids {
            // The flow before the switch is not known: no sensitivity survives it. A run for the
            // adjoint carries no columns: it warns where forward mode's first void does (once:
            // after it every column is NaN until a reset gives one a value again).
            let warned = || self.warnings.iter().any(|w| matches!(w, SimWarning::SwitchAtEvent { .. }));
            if self.work.z[n..].iter().any(|v| !v.is_nan()) || (self.tapes && !warned()) {
                self.work.z[n..].fill(f64::NAN);
                let name = self.info.events[ev].name.clone();
                self.warnings.push(SimWarning::SwitchAtEvent { name, time: t });
            }
            return;
        }
        let context = self.crossing_context(pos, crossing, true);
        let dense = self.work.stepper.interpolant();
        let cx = self.guards();
        let (x_pre, x_post) = &mut self.work.x_sides;
        dense.eval(crossing.t_pre, x_pre);
        let mut t_post = t;
        let mut gap = 0.0;
        // The dense output holds within its step: the search for the far side reads it at most a
        // step length past the step's end, or 64 spacings of `t` past the crossing for a step
        // shorter than that (a step ending on the crossing finds the far side some ulps on).
        // Unbounded, a step of 2e-15 on the soft ball at wc = 1e5 had its dense output read 6e-5
        // past its end, and DOP853 went on from `y = 7.2e41`.
        let ulp = spacing(t);
        let reach = (dense.t0() + 2.0 * dense.h()).max(t + 64.0 * ulp);
        let mut across = false;
        for _ in 0..SWITCH_SIDE_TRIES {
            dense.eval(t_post, x_post);
            let g = self.work.det.guard_now(&cx, pos, t_post, x_post);
            across = crossing.sigma * g < 0.0;
            if across || t_post >= reach {
                break;
            }
            gap = if gap == 0.0 { t_post.next_up() - t_post } else { 2.0 * gap };
            t_post = (t + gap).min(reach);
        }
        if !across {
            // Not across within what the dense output holds (a step of a few spacings, landed
            // just before the switch, resolves nothing at the scale of its own length): the far
            // side along the flow before the switch, where only the branch matters.
            let f_pre = &mut self.work.switch_flow.0;
            self.sys.flow(self.mode, crossing.t_pre, x_pre, self.p, &mut f_pre[..n]);
            for _ in 0..SWITCH_SIDE_TRIES {
                gap = if gap == 0.0 { t.next_up() - t } else { 2.0 * gap };
                t_post = t + gap;
                for ((xp, x0), f) in x_post.iter_mut().zip(x_pre.iter()).zip(&f_pre[..n]) {
                    *xp = x0 + (t_post - crossing.t_pre) * f;
                }
                if crossing.sigma * self.work.det.guard_now(&cx, pos, t_post, x_post) < 0.0 {
                    break;
                }
            }
        }
        if self.switch_post.is_none_or(|tp| t_post > tp) {
            self.switch_post = Some(t_post);
            self.work.switch_flow.1.copy_from_slice(x_post);
        }
        if kink {
            return;
        }
        let (x, s) = self.work.z.split_at_mut(n);
        let sides = ((crossing.t_pre, &x_pre[..]), (t_post, &x_post[..]));
        if self.tapes {
            let (pre, post) = sides;
            self.recorder.tape(&TapeEntry::Switch { event: ev, t, mode: self.mode, x, pre, post });
        }
        let out = self.work.jump.apply_switch(self.sys, ev, self.mode, t, x, sides, s, self.p, context);
        if self.tapes && self.work.jump.benign {
            self.recorder.tape(&TapeEntry::BenignGraze(self.work.jump.benign_limit()));
        } else if self.tapes && out.grazing {
            self.recorder.tape(&TapeEntry::Grazed);
        }
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
        if !self.work.fired.is_empty() || t_post <= self.t || t_post >= self.opts.t_end {
            return;
        }
        let n = self.n;
        self.work.z[..n].copy_from_slice(&self.work.switch_flow.1[..n]);
        self.t = t_post;
    }

    /// Whether the derivative at the step's start has sensitivities that are not finite where the
    /// sensitivities themselves are (the flow's derivative is singular right there), and how:
    /// infinite, or indeterminate (NaN: `0 / 0`, `inf - inf`) where any is.
    fn start_derivative_singularity(&self) -> Option<VoidCause> {
        let n = self.n;
        let k0 = &self.work.stepper.start_derivative()[n..];
        let singular = k0.iter().zip(&self.work.z[n..]).filter(|(d, s)| !d.is_finite() && s.is_finite());
        singular.map(|(d, _)| d.is_nan()).reduce(|a, b| a || b).map(|indeterminate| {
            if indeterminate {
                VoidCause::Indeterminate
            } else {
                VoidCause::Infinite
            }
        })
    }

    /// Sensitivities that are not finite at a finite state, and not yet known to be missing:
    /// derivatives that do not exist (NaN from here on), with one warning naming the first and
    /// the time `t` from which they are missing.
    fn note_new_voids(&mut self, t: f64, cause: VoidCause) {
        let n = self.n;
        let mut first: Option<usize> = None;
        let mut count = 0;
        for (k, (void, s)) in self.work.void.iter_mut().zip(&mut self.work.z[n..]).enumerate() {
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
                cause,
            });
        }
    }

    /// What a jump needs to judge its crossing: the guard's curvature from the speeds over the
    /// step the crossing was found in (none for a crossing at a step's start, or after a mode
    /// switch in the group), and the run's tolerances.
    fn crossing_context(&self, pos: usize, crossing: Crossing, same_mode: bool) -> CrossingContext {
        let step = if same_mode && !crossing.on_guard { self.work.det.step_speeds(pos) } else { None };
        let flow_jumps = self.info.events[self.info.modes[self.mode].events[pos]].implicit;
        CrossingContext {
            step,
            flow_jumps,
            rtol: self.opts.rtol,
            atol: self.opts.atol,
            graze_tol: self.opts.graze_tol,
            left_of_knot: self.left_of_knot,
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

    /// The samples the recorder and `SimOptions::at` want up to `t_seg_end` (before it when
    /// `before_instant`) from the dense output of the step just attempted.
    /// Where events are landed on (the dense output less accurate than a step end: a Rosenbrock
    /// method, an explicit pair held by stability), the times of `at` due in the step from
    /// `(t0, z_start)` up to `t_seg_end` (before it when `before_instant`) are each taken from the
    /// step retaken to end there (`Stepper::land`), as accurate as a step end; a retaken step
    /// that fails its error test leaves the rest to the dense output ([`Self::sample_step`]).
    /// Returns whether a step was retaken (the stepper's last attempt is then not the step's).
    /// `tape`: the step planned and whether it is already on the adjoint tape (each landed
    /// sample goes there as the end of its retaken step).
    fn land_samples<F: Rhs>(
        &mut self,
        t0: f64,
        t_seg_end: f64,
        before_instant: bool,
        rhs: &mut F,
        tape: (Plan, bool),
    ) -> bool {
        if !self.sampler.due(t_seg_end, before_instant) || !self.lands_on_events() {
            return false;
        }
        let mut landed = false;
        while self.sampler.due(t_seg_end, before_instant) {
            let Some(ts) = self.sampler.next_time().filter(|&ts| ts > t0) else { break };
            let err = self.work.stepper.land(t0, &self.work.z_start, ts - t0, rhs);
            landed = true;
            if err.is_nan() || err > 1.0 {
                break;
            }
            let end = self.work.stepper.end_state();
            let from = self.sampler.taken();
            self.sampler.take_here(&mut self.work.output_jac, ts, self.mode, end);
            if let Some(pair) = self.work.stepper.tape_pair() {
                let (plan, taped) = tape;
                let (ceiling, mode) = (Self::ceiling(plan), self.mode);
                self.tape_samples(from, TapeSample::Landed { pair, t0, h: ts - t0, ceiling, mode, taped });
            }
        }
        landed
    }

    /// The samples due up to `t_seg_end` (before it when `before_instant`) from the dense
    /// output of the step just attempted; `tape`: that step as planned and whether it is
    /// already on the adjoint tape (the samples go there as read off its dense output).
    fn sample_step(&mut self, t_seg_end: f64, before_instant: bool, tape: Option<(Plan, bool)>) {
        let dense = self.work.stepper.interpolant();
        self.sampler.record_dense(self.recorder, &mut self.work.record_buf, dense, self.mode, t_seg_end);
        let from = self.sampler.taken();
        self.sampler.take_dense(&mut self.work.output_jac, dense, self.mode, t_seg_end, before_instant);
        if let (Some((plan, taped)), Some(pair)) = (tape, self.work.stepper.tape_pair()) {
            let (ceiling, mode) = (Self::ceiling(plan), self.mode);
            for row in from..self.sampler.taken() {
                let t = self.sampler.time(row);
                let from = TapeSample::Dense { pair, t0: plan.t0, h: plan.h, ceiling, mode, t, taped };
                if self.tapes {
                    self.recorder.tape(&TapeEntry::Sample { row, from });
                }
            }
        }
    }

    /// The latest time a step planned as `plan` reads the flow at (just before a knot it ends on).
    fn ceiling(plan: Plan) -> f64 {
        if plan.on_knot {
            plan.t1.next_down()
        } else {
            f64::INFINITY
        }
    }

    /// Tells the adjoint tape of the samples of `at` taken from row `from` on, read as `how`.
    fn tape_samples(&mut self, from: usize, how: TapeSample) {
        if !self.tapes {
            return;
        }
        for row in from..self.sampler.taken() {
            self.recorder.tape(&TapeEntry::Sample { row, from: how });
        }
    }

    /// Records the current point as `kind`, if the recorder wants it.
    /// Tells the tape of the step from `tape_x0` planned as `plan` (taken with size `h`) and how
    /// it ended.
    fn tape_step(&mut self, plan: Plan, h: f64, cut: Cut) {
        let Some(pair) = self.work.stepper.tape_pair() else {
            self.recorder.tape(&TapeEntry::Unsupported("a step of a method without a tape form"));
            return;
        };
        let ceiling = if plan.on_knot { plan.t1.next_down() } else { f64::INFINITY };
        let (n, stepper) = (self.n, &self.work.stepper);
        let step = TapeStep {
            pair,
            t0: plan.t0,
            h,
            ceiling,
            mode: self.mode,
            x0: &self.tape_x0,
            f0: &stepper.start_derivative()[..n],
            x1: &stepper.end_state()[..n],
            f1: &stepper.end_derivative()[..n],
        };
        self.recorder.tape(&match cut {
            Cut::End => TapeEntry::Step(step),
            Cut::Landed(dt) => TapeEntry::Landed(step, dt),
            Cut::Dense(t) => TapeEntry::Dense(step, t),
        });
    }

    fn record(&mut self, kind: PointKind) {
        if !(self.recorder.is_active() && self.recorder.wants(kind)) {
            return;
        }
        let n = self.n;
        let outputs = &mut self.work.record_buf.0;
        self.sys.outputs(self.t, &self.work.z[..n], self.p, outputs);
        let (x, s) = self.work.z.split_at(n);
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
        let (e, state) = self.work.stepper.outside_error();
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
        let _ieee = IeeeArithmetic::enter();
        let from = self.sampler.taken();
        self.sampler.take_here(&mut self.work.output_jac, self.t, self.mode, &self.work.z[..]);
        self.tape_samples(from, TapeSample::Here);
        let samples = self.sampler.finish(&self.events);
        let (n, m, k) = (self.n, self.m, self.info.n_outputs());
        let t = self.t;
        let x = &self.work.z[..n];
        let s = &self.work.z[n..];
        let mut outputs = vec![0.0; k];
        self.sys.outputs(t, x, self.p, &mut outputs);
        let (yx, yp, yt) = &mut self.work.output_jac;
        self.sys.output_jac(t, x, self.p, yx, yp, yt);
        let chain =
            |jac: &OutputJac, sens: &[f64], dte: Option<&[f64]>| output_sens((n, m, k), jac, sens, dte);
        let (dstate, doutputs) = (existing(s), existing(&chain(&self.work.output_jac, s, None)));
        let (dstate_total, doutputs_total) = match self.stop_total {
            Some((total, dte)) => {
                let dy = chain(&self.work.output_jac, &total, Some(&dte));
                (existing(&total), existing(&dy))
            }
            None => (None, None),
        };
        let mut stats = self.stats;
        stats.rhs_calls = self.work.stepper.rhs_calls();
        let methods = self.work.stepper.segments(t).unwrap_or_else(|| {
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
                let (yx, yp, yt) = &mut self.work.output_jac;
                self.sys.output_jac(t, xb, self.p, yx, yp, yt);
                let doutputs = existing(&chain(&self.work.output_jac, sb, None));
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
            gradients_of: None,
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
