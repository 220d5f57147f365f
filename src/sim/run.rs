//! Stage 5 (sim): the driver. Integrates `[x, S]` with the chosen Runge-Kutta pair, looks for
//! events after every accepted step, moves to the earliest firing time on the dense output,
//! applies the events, watches for Zeno behaviour and faults, and assembles the result. Generic
//! over `S: HybridSystem + ?Sized` (monomorphised; `&dyn HybridSystem` works too); after setup
//! the step loop allocates nothing unless a trajectory or events are recorded.
//!
//! Knows nothing of Cranelift, expressions or the model's text.

use super::dense::Dense;
use super::events::{Crossing, Detector};
use super::jump::{Jump, JumpOutcome};
use super::options::{Method, SimOptions, TrajectoryRequest};
use super::result::{
    EventRecord, FinalState, SimError, SimResult, SimStats, SimWarning, StopReason, TrajectoryRow,
};
use super::rk::Rk;
use super::system::{HybridSystem, SystemInfo};
use super::tableau::{DOP853, DOPRI5};

const EPS: f64 = f64::EPSILON;
/// Largest ratio of the first step after an event to Hairer's initial estimate at the
/// post-event state, when the event switched the mode (the controller's proposal was learnt on
/// another vector field) and when it did not. Measured (`tests/closed_forms.rs`, thermostat, 30
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

/// Simulates `sys` with parameters `p` (all of them, `n_params` long) from `opts.t_start` to
/// `opts.t_end`. Bad input (parameter length, an inconsistent model shape, invalid options) is an
/// error; runtime faults, Zeno behaviour and stop events end the run with everything computed so
/// far and say why in [`SimResult::stopped_by`].
///
/// Shorthand for [`Simulator::new`] followed by one [`Simulator::run`]; to run one model many
/// times (sweeps, fits, finite differences) keep a `Simulator`, which allocates its scratch
/// buffers once.
pub fn run<S: HybridSystem + ?Sized>(sys: &S, p: &[f64], opts: &SimOptions) -> Result<SimResult, SimError> {
    check_params(sys.info(), p)?;
    Simulator::new(sys, opts)?.run(p)
}

/// A model and options checked once, with the stepper's, interpolant's, detector's and jump's
/// scratch buffers kept between runs: a run then allocates only what its result holds.
/// Runs are independent: the same parameters give bit-for-bit the same result, whatever ran
/// before. One `Simulator` per thread (it is `Send` when the system is `Sync`).
pub struct Simulator<H: SystemRef> {
    sys: H,
    opts: SimOptions,
    work: Workspace,
}

/// What a [`Simulator`] holds its model by: a reference, an `Arc`, a `Box`, anything that
/// dereferences to a [`HybridSystem`]. An owned handle (`Arc<CompiledModel>`) makes an owned
/// simulator that a thread or a Python object can keep.
pub trait SystemRef {
    type System: HybridSystem + ?Sized;
    fn system(&self) -> &Self::System;
}

impl<D: std::ops::Deref> SystemRef for D
where
    D::Target: HybridSystem,
{
    type System = D::Target;
    fn system(&self) -> &D::Target {
        self
    }
}

impl<H: SystemRef> std::fmt::Debug for Simulator<H> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Simulator").field("opts", &self.opts).finish_non_exhaustive()
    }
}

/// Scratch state of the driver, sized by the model and the options.
struct Workspace {
    rk: Rk,
    dense: Dense,
    det: Detector,
    jump: Jump,
    /// The events of the last group that fired: id, pre-crossing sign, crossing speed.
    fired: Vec<(usize, f64, f64)>,
    /// The output Jacobians `y_x`, `y_p`, `y_t` at the final state.
    output_jac: (Vec<f64>, Vec<f64>, Vec<f64>),
    /// The states on either side of a flow switch.
    x_sides: (Vec<f64>, Vec<f64>),
}

impl<H: SystemRef> Simulator<H> {
    /// Checks the model's shape and the options (an `Err` for an inconsistent shape or an
    /// invalid option) and allocates the scratch buffers.
    pub fn new(sys: H, opts: &SimOptions) -> Result<Self, SimError> {
        let info = sys.system().info();
        validate(info, opts)?;
        let (n, m) = (info.n_states(), info.n_grad());
        let nz = n * (1 + m);
        let tab = if opts.method.resolve(opts.rtol) == Method::Dop853 { &DOP853 } else { &DOPRI5 };
        let n_err = if opts.sens_error_control { nz } else { n };
        let work = Workspace {
            rk: Rk::new(tab, nz, n_err, opts.rtol, opts.atol),
            dense: Dense::new(nz),
            det: Detector::new(info, n, m),
            jump: Jump::new(n, m),
            fired: Vec::new(),
            output_jac: {
                let k = info.n_outputs();
                (vec![0.0; k * n], vec![0.0; k * m], vec![0.0; k])
            },
            x_sides: (vec![0.0; n], vec![0.0; n]),
        };
        Ok(Simulator { sys, opts: opts.clone(), work })
    }

    /// Simulates with parameters `p` (all of them, `n_params` long; an `Err` otherwise).
    pub fn run(&mut self, p: &[f64]) -> Result<SimResult, SimError> {
        let sys = self.sys.system();
        let info = sys.info();
        check_params(info, p)?;
        Ok(Driver::new(sys, info, p, &self.opts, &mut self.work).run())
    }

    pub fn options(&self) -> &SimOptions {
        &self.opts
    }

    /// The model this simulator runs.
    pub fn system(&self) -> &H::System {
        self.sys.system()
    }

    /// The handle the model is held by (for `Simulator<&S>`, the reference itself).
    pub fn handle(&self) -> &H {
        &self.sys
    }
}

fn check_params(info: &SystemInfo, p: &[f64]) -> Result<(), SimError> {
    if p.len() != info.n_params() {
        return Err(SimError::ParamLength { expected: info.n_params(), got: p.len() });
    }
    Ok(())
}

fn validate(info: &SystemInfo, opts: &SimOptions) -> Result<(), SimError> {
    let bad_index = |what, index: usize, count: usize| {
        if index < count {
            Ok(())
        } else {
            Err(SimError::BadIndex { what, index, count })
        }
    };
    bad_index("initial mode", info.initial_mode, info.modes.len())?;
    for mode in &info.modes {
        for &ev in &mode.events {
            bad_index("event", ev, info.events.len())?;
        }
    }
    for ev in &info.events {
        if let Some(target) = ev.target_mode {
            bad_index("target mode", target, info.modes.len())?;
        }
    }
    for &gp in &info.grad_params {
        bad_index("grad parameter", gp, info.n_params())?;
    }
    let checks: [(&'static str, f64, bool); 7] = [
        ("t_start", opts.t_start, opts.t_start.is_finite()),
        ("t_end", opts.t_end, opts.t_end.is_finite() && opts.t_end >= opts.t_start),
        ("rtol", opts.rtol, opts.rtol.is_finite() && opts.rtol > 0.0),
        ("atol", opts.atol, opts.atol.is_finite() && opts.atol >= 0.0),
        ("graze_tol", opts.graze_tol, opts.graze_tol >= 0.0),
        ("zeno_window", opts.zeno_window, opts.zeno_window >= 0.0),
        ("h_max", opts.h_max, opts.h_max > 0.0),
    ];
    for (name, value, ok) in checks {
        if !ok {
            return Err(SimError::InvalidOption { name, value });
        }
    }
    if let TrajectoryRequest::Sample(dt) = opts.trajectory {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(SimError::InvalidOption { name: "trajectory sample interval", value: dt });
        }
    }
    Ok(())
}

/// The flow of `mode` with its sensitivities as one right-hand side over `z = [x, S]`.
fn rhs_for<'a, S: HybridSystem + ?Sized>(
    sys: &'a S,
    p: &'a [f64],
    n: usize,
    mode: usize,
) -> impl FnMut(f64, &[f64], &mut [f64]) + 'a {
    move |t, z, dz| {
        let (x, s) = z.split_at(n);
        let (dx, ds) = dz.split_at_mut(n);
        sys.flow_sens(mode, t, x, s, p, dx, ds);
    }
}

struct Driver<'a, S: HybridSystem + ?Sized> {
    sys: &'a S,
    info: &'a SystemInfo,
    p: &'a [f64],
    opts: &'a SimOptions,
    n: usize,
    m: usize,
    mode: usize,
    rk: &'a mut Rk,
    dense: &'a mut Dense,
    det: &'a mut Detector,
    jump: &'a mut Jump,
    events: Vec<EventRecord>,
    warnings: Vec<SimWarning>,
    /// False once a grazing event has made the sensitivities meaningless.
    sens_valid: bool,
    stats: SimStats,
    trajectory: Option<Vec<TrajectoryRow>>,
    next_sample: usize,
    /// Total derivative of the final state and `dt/dp` of a stop event.
    stop_total: Option<(Vec<f64>, Vec<f64>)>,
    fired: &'a mut Vec<(usize, f64, f64)>,
    output_jac: &'a mut (Vec<f64>, Vec<f64>, Vec<f64>),
    x_sides: &'a mut (Vec<f64>, Vec<f64>),
}

impl<'a, S: HybridSystem + ?Sized> Driver<'a, S> {
    fn new(
        sys: &'a S,
        info: &'a SystemInfo,
        p: &'a [f64],
        opts: &'a SimOptions,
        work: &'a mut Workspace,
    ) -> Self {
        let (n, m) = (info.n_states(), info.n_grad());
        let Workspace { rk, dense, det, jump, fired, output_jac, x_sides } = work;
        rk.reset(opts.t_start);
        sys.initial_state(p, &mut rk.y[..n]);
        sys.initial_sens(p, &mut rk.y[n..]);
        Driver {
            sys,
            info,
            p,
            opts,
            n,
            m,
            mode: info.initial_mode,
            rk,
            dense,
            det,
            jump,
            events: Vec::new(),
            warnings: Vec::new(),
            sens_valid: true,
            stats: SimStats::default(),
            trajectory: match opts.trajectory {
                TrajectoryRequest::None => None,
                _ => Some(Vec::new()),
            },
            next_sample: 0,
            stop_total: None,
            fired,
            output_jac,
            x_sides,
        }
    }

    fn fault_state(&self) -> Vec<f64> {
        self.rk.y[..self.n].to_vec()
    }

    /// New start point (beginning, after events): derivative, guards and Hairer's step estimate
    /// for the new state.
    fn restart(&mut self) -> f64 {
        let mut rhs = rhs_for(self.sys, self.p, self.n, self.mode);
        self.rk.restart(&mut rhs);
        let n = self.n;
        self.det.eval_point(
            self.sys,
            self.info,
            self.mode,
            self.rk.t,
            &self.rk.y[..n],
            &self.rk.k[..n],
            self.p,
            false,
        );
        self.rk.initial_step(self.opts.h_max, &mut rhs)
    }

    fn run(mut self) -> SimResult {
        let stop = self.integrate();
        self.finish(stop)
    }

    fn integrate(&mut self) -> StopReason {
        let t_end = self.opts.t_end;
        if self.rk.y.iter().any(|v| !v.is_finite()) {
            return self.fault_nonfinite();
        }
        let mut h = self.restart();
        // A reused detector may remember bounces of an earlier run.
        self.det.clear_bounces();
        self.push_step_row();
        if let TrajectoryRequest::Sample(_) = self.opts.trajectory {
            self.push_row(self.rk.t, &self.rk.y.clone());
            self.next_sample = 1;
        }
        let mut attempts = 0usize;
        let mut nonfinite_rejects = 0usize;
        loop {
            if self.rk.t >= t_end {
                return StopReason::TEnd;
            }
            if attempts >= self.opts.max_steps {
                return StopReason::Fault {
                    error: SimError::TooManySteps {
                        t: self.rk.t,
                        max_steps: self.opts.max_steps,
                        mode: self.mode,
                        state: self.fault_state(),
                    },
                };
            }
            let t0 = self.rk.t;
            let mut h_try = h.min(self.opts.h_max);
            let hit_end = t0 + 1.01 * h_try >= t_end;
            if hit_end {
                h_try = t_end - t0;
            }
            let h_resolvable = h_try > 8.0 * EPS * t0.abs() && h_try > 0.0;
            if !h_resolvable {
                return StopReason::Fault {
                    error: SimError::StepTooSmall {
                        t: t0,
                        h: h_try,
                        mode: self.mode,
                        state: self.fault_state(),
                    },
                };
            }
            attempts += 1;
            let mut rhs = rhs_for(self.sys, self.p, self.n, self.mode);
            let err = self.rk.attempt(h_try, &mut rhs);
            let accepted = err <= 1.0;
            if !accepted {
                self.stats.rejected += 1;
                if err.is_finite() {
                    nonfinite_rejects = 0;
                } else {
                    nonfinite_rejects += 1;
                    if nonfinite_rejects > MAX_NONFINITE_REJECTS {
                        return self.fault_nonfinite();
                    }
                }
                h = self.rk.shrink(err);
                continue;
            }
            nonfinite_rejects = 0;
            let h_next = self.rk.grow(err);
            self.stats.steps += 1;
            let t1 = if hit_end { t_end } else { t0 + h_try };
            let n = self.n;
            self.det.eval_point(
                self.sys,
                self.info,
                self.mode,
                t1,
                &self.rk.y_new[..n],
                &self.rk.f_new()[..n],
                self.p,
                true,
            );
            let may_cross = self.det.may_cross(self.info, self.mode);
            let sample_due = self.sample_due(t1);
            if may_cross || sample_due {
                self.dense.build(self.rk, &mut rhs);
            }
            let fire = if may_cross {
                self.det.locate(self.sys, self.info, self.mode, self.dense, self.p);
                self.det.select(self.sys, self.info, self.mode, self.dense, self.p)
            } else {
                None
            };
            match fire {
                None if self.det.penetrated().is_some() => {
                    // Stop where the last bounce left the state (the step is not taken).
                    return self.zeno_stop();
                }
                None => {
                    if sample_due {
                        self.push_samples(t1);
                    }
                    self.rk.accept();
                    self.rk.t = t1;
                    self.det.advance();
                    self.push_step_row();
                    h = h_next;
                }
                Some(t_fire) => {
                    let mode_before = self.mode;
                    if sample_due || self.sample_due(t_fire) {
                        self.push_samples(t_fire);
                    }
                    self.dense.eval(t_fire, &mut self.rk.y);
                    self.rk.t = t_fire;
                    self.push_step_row();
                    if let Some(stop) = self.fire_group() {
                        return stop;
                    }
                    self.push_step_row();
                    if let Some(stop) = self.check_zeno() {
                        return stop;
                    }
                    if self.rk.y.iter().any(|v| !v.is_finite()) {
                        return self.fault_nonfinite();
                    }
                    let estimate = self.restart();
                    self.note_bounces();
                    let growth =
                        if self.mode == mode_before { AFTER_RESET_GROWTH } else { AFTER_SWITCH_GROWTH };
                    h = self.continue_step(h_next, estimate, growth);
                }
            }
        }
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
            error: SimError::NonFinite { t: self.rk.t, mode: self.mode, state: self.fault_state() },
        }
    }

    /// Fires the selected events at the current point in declaration order, each seeing the
    /// state the previous one left. Returns a stop reason for a stop event.
    fn fire_group(&mut self) -> Option<StopReason> {
        let (n, t) = (self.n, self.rk.t);
        let group_len = self.det.group.len();
        self.fired.clear();
        for gi in 0..group_len {
            let (ev, crossing): (usize, Crossing) = self.det.group[gi];
            let Some(pos) = self.info.modes[self.mode].events.iter().position(|&e| e == ev) else {
                // An earlier event of the group switched to a mode without this event.
                continue;
            };
            let (x, s) = self.rk.y.split_at_mut(n);
            if !crossing.touch {
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
                self.cross_switch(ev, pos, crossing);
                continue;
            }
            let mode_before = self.mode;
            let mode_after = einfo.target_mode.unwrap_or(mode_before);
            let out = self.jump.apply(
                self.sys,
                ev,
                mode_before,
                mode_after,
                t,
                x,
                s,
                self.p,
                self.opts.graze_tol,
                einfo.is_stop,
            );
            if out.grazing {
                self.note_grazing(ev, t, out);
            }
            self.events.push(EventRecord {
                index: self.events.len(),
                event: ev,
                name: einfo.name.clone(),
                time: t,
                mode_before,
                mode_after,
                dtime: self.sens_valid.then(|| self.jump.dte.clone()),
                grazing: out.grazing,
                denominator: out.denominator,
            });
            self.stats.events += 1;
            self.fired.push((ev, crossing.sigma, out.denominator));
            self.mode = mode_after;
            if einfo.is_stop {
                if self.sens_valid {
                    self.stop_total = Some((self.jump.total.clone(), self.jump.dte.clone()));
                }
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
    fn cross_switch(&mut self, ev: usize, pos: usize, crossing: Crossing) {
        let (n, t) = (self.n, self.rk.t);
        self.stats.switches += 1;
        if !self.fired.is_empty() {
            if self.sens_valid {
                self.sens_valid = false;
                let name = self.info.events[ev].name.clone();
                self.warnings.push(SimWarning::SwitchAtEvent { name, time: t });
            }
            return;
        }
        let (x_pre, x_post) = &mut *self.x_sides;
        self.dense.eval(crossing.t_pre, x_pre);
        let mut t_post = t;
        let mut gap = 0.0;
        for _ in 0..SWITCH_SIDE_TRIES {
            self.dense.eval(t_post, x_post);
            let g = self.det.guard_now(self.sys, self.mode, pos, t_post, x_post, self.p);
            if crossing.sigma * g < 0.0 {
                break;
            }
            gap = if gap == 0.0 { t_post.next_up() - t_post } else { 2.0 * gap };
            t_post = t + gap;
        }
        let (x, s) = self.rk.y.split_at_mut(n);
        let sides = ((crossing.t_pre, &x_pre[..]), (t_post, &x_post[..]));
        let out =
            self.jump.apply_switch(self.sys, ev, self.mode, t, x, sides, s, self.p, self.opts.graze_tol);
        if out.grazing {
            self.note_grazing(ev, t, out);
        }
    }

    /// A grazing crossing of event `ev` at `t`: no gradient from here on, and a warning.
    fn note_grazing(&mut self, ev: usize, t: f64, out: JumpOutcome) {
        self.sens_valid = false;
        self.warnings.push(SimWarning::Grazing {
            event: ev,
            name: self.info.events[ev].name.clone(),
            time: t,
            denominator: out.denominator,
            scale: out.scale,
        });
    }

    /// Marks the events of the group just fired that bounced: their reset turned the guard
    /// speed around (`g0`, `dg0` are the post-event values after `restart`).
    fn note_bounces(&mut self) {
        self.det.clear_bounces();
        let events = &self.info.modes[self.mode].events;
        for &(ev, sigma, speed_before) in self.fired.iter() {
            if let Some(pos) = events.iter().position(|&e| e == ev) {
                self.det.note_bounce(pos, sigma, speed_before);
            }
        }
    }

    /// Zeno behaviour at the last event: the accumulation point is estimated from the last
    /// inter-event intervals.
    fn zeno_stop(&self) -> StopReason {
        match self.events.last() {
            Some(last) => StopReason::Zeno {
                time: last.time,
                event: last.event,
                count: self.events.len(),
                accumulation: self.accumulation(),
            },
            None => StopReason::TEnd,
        }
    }

    /// Zeno: `max_events` in total, or `zeno_events` events inside the window.
    fn check_zeno(&self) -> Option<StopReason> {
        let count = self.events.len();
        let last = self.events.last()?;
        let span = (self.opts.t_end - self.opts.t_start).abs().max(1.0);
        let window = self.opts.zeno_window * span;
        let in_window = self.events.iter().rev().take_while(|e| e.time >= last.time - window).count();
        let too_many = count >= self.opts.max_events;
        let crowded = self.opts.zeno_events > 0 && in_window >= self.opts.zeno_events;
        if !(too_many || crowded) {
            return None;
        }
        Some(self.zeno_stop())
    }

    /// Geometric extrapolation of the last two inter-event intervals: with ratio
    /// `r = d2 / d1 < 1` the remaining intervals sum to `d2 r / (1 - r)`.
    fn accumulation(&self) -> Option<f64> {
        let k = self.events.len();
        if k < 3 {
            return None;
        }
        let (ta, tb, tc) = (self.events[k - 3].time, self.events[k - 2].time, self.events[k - 1].time);
        let (d1, d2) = (tb - ta, tc - tb);
        if d1 <= 0.0 || d2 <= 0.0 {
            return Some(tc);
        }
        let r = d2 / d1;
        (r < 1.0).then(|| tc + d2 * r / (1.0 - r))
    }

    fn sample_due(&self, t_seg_end: f64) -> bool {
        match self.opts.trajectory {
            TrajectoryRequest::Sample(dt) => self.opts.t_start + self.next_sample as f64 * dt <= t_seg_end,
            _ => false,
        }
    }

    /// Sample rows in `(t0, t_seg_end]` from the dense output of the current step.
    fn push_samples(&mut self, t_seg_end: f64) {
        let TrajectoryRequest::Sample(dt) = self.opts.trajectory else {
            return;
        };
        let mut z = vec![0.0; self.rk.nz];
        loop {
            let ts = self.opts.t_start + self.next_sample as f64 * dt;
            if ts > t_seg_end {
                break;
            }
            self.dense.eval(ts, &mut z);
            self.push_row(ts, &z);
            self.next_sample += 1;
        }
    }

    fn push_step_row(&mut self) {
        if self.opts.trajectory == TrajectoryRequest::Steps {
            let z = self.rk.y.clone();
            self.push_row(self.rk.t, &z);
        }
    }

    fn push_row(&mut self, t: f64, z: &[f64]) {
        let n = self.n;
        let mut outputs = vec![0.0; self.info.n_outputs()];
        self.sys.outputs(t, &z[..n], self.p, &mut outputs);
        if let Some(rows) = self.trajectory.as_mut() {
            rows.push(TrajectoryRow { t, mode: self.mode, x: z[..n].to_vec(), s: z[n..].to_vec(), outputs });
        }
    }

    fn finish(mut self, stopped_by: StopReason) -> SimResult {
        let (n, m, k) = (self.n, self.m, self.info.n_outputs());
        let t = self.rk.t;
        let x = &self.rk.y[..n];
        let s = &self.rk.y[n..];
        let mut outputs = vec![0.0; k];
        self.sys.outputs(t, x, self.p, &mut outputs);
        let (yx, yp, yt) = &mut *self.output_jac;
        self.sys.output_jac(t, x, self.p, yx, yp, yt);
        // y_x S_j + y_p_j (+ y_t dt_j for totals), column per parameter.
        let chain = |sens: &[f64], dte: Option<&[f64]>| {
            let mut out = vec![0.0; k * m];
            for j in 0..m {
                for i in 0..k {
                    let row = &yx[i * n..(i + 1) * n];
                    let mut v = yp[j * k + i];
                    v += row.iter().zip(&sens[j * n..(j + 1) * n]).map(|(a, b)| a * b).sum::<f64>();
                    if let Some(d) = dte {
                        v += yt[i] * d[j];
                    }
                    out[j * k + i] = v;
                }
            }
            out
        };
        let (dstate, doutputs) =
            if self.sens_valid { (Some(s.to_vec()), Some(chain(s, None))) } else { (None, None) };
        let (dstate_total, doutputs_total) = match self.stop_total.take() {
            Some((total, dte)) => {
                let dy = chain(&total, Some(&dte));
                (Some(total), Some(dy))
            }
            None => (None, None),
        };
        self.stats.rhs_calls = self.rk.rhs_calls;
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
            warnings: self.warnings,
            stats: self.stats,
            trajectory: self.trajectory,
        }
    }
}
