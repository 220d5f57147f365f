//! Stage 5 (sim): event detection inside one accepted step, and the choice of the events that fire
//! next. Knows the `HybridSystem` guard functions, the stepper's interpolant and stage derivatives;
//! knows nothing of resets, sensitivities' jumps or the step loop. The rules it implements are
//! written down in docs/language.md ("When events fire").
//!
//! Per step, every guard of the mode that can cross inside it (every guard but a time event
//! the step does not land on) is searched along the step's dense output by enclosure
//! (`enclose.rs`): the step is walked in time order piece by piece; a piece whose enclosure of
//! the guard is clear of zero (beyond round-off) holds no sign change and no touch; a piece whose
//! enclosure of the guard's time derivative is clear of zero is monotone and holds a sign change
//! exactly when its ends differ in sign; an affine guard's piece is decided first by the signs of
//! its Bernstein coefficients (`enclose::Signs`: one sign, or a single change, which crosses
//! once); any other piece is halved, down to `2^-40` of the step.
//! The ends of the pieces that may hold a sign change become samples, with the extremum inside a
//! piece the walk could not prove monotone. The walk of a guard stops at its first crossing.
//!
//! The samples are scanned in time order for the first pair that goes from the
//! pre-crossing side (strictly: `g > 0` for falling, `g < 0` for rising) to the crossed side
//! (`g <= 0`, resp. `g >= 0`); an extremum that stops within round-off of zero coming from the
//! pre-crossing side is a touch. Only brackets are found per guard; `select` then locates the
//! earliest crossing first (Illinois regula falsi to adjacent floating-point numbers) and the
//! others only when they have crossed by then.
//!
//! Round-off bounds are per component: `16 eps (sum_i |g_x,i x_i| + |g_t t|)` for a guard value
//! and `16 eps (sum_i |g_x,i f_i| + |g_t|)` for its speed, so a large state the guard does not
//! read changes nothing.

use super::enclose::{bernstein, poly_hull, Pieces, Signs};
use super::guards::Guards;
use super::roots::{extremum_time, hermite_root, illinois};
use crate::interval::{Dual, Interval};
use crate::sim::method::poly::{Poly, CAP};
use crate::sim::method::stepper::{Interpolant, Stepper};
use crate::sim::system::{Direction, GuardShape, HybridSystem, SystemInfo};

const EPS: f64 = f64::EPSILON;
/// Up to this many guards in a mode, a step's end is evaluated guard by guard (one gradient each
/// gives the speed and the round-off bounds); above, by the speeds kernel, whatever the number of
/// guards.
const FEW_GUARDS: usize = 4;
/// Samples per step of a nonlinear guard of a system that gives no enclosures.
const UNENCLOSED_SAMPLES: usize = 8;
/// Bisection steps to the boundary where a guard stops being finite (to about 1e-9 of the step).
const NAN_BISECTIONS: usize = 30;
/// A crossing located in the current step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Crossing {
    pub t: f64,
    /// +1 when the guard came from positive values, -1 from negative ones.
    pub sigma: f64,
    /// Located at an extremum that only touches zero within round-off.
    pub touch: bool,
    /// The last time found on the pre-crossing side (next to `t`; `t` itself for a touch): where
    /// a flow switch reads the flow from before its jump.
    pub t_pre: f64,
    /// Fired at the step's start because the state was on the guard there and the flow carried it
    /// to the crossed side (the start of a run, or a reset onto the guard).
    pub on_guard: bool,
}

/// What the scan of one guard found in the current step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Finding {
    Nothing,
    /// A crossing between `a` and `b` (`sigma * g` positive at `a`, not at `b`), with the guard's
    /// values and speeds there (a speed of 0 at an extremum).
    Bracket {
        a: f64,
        ga: f64,
        da: f64,
        b: f64,
        gb: f64,
        db: f64,
        sigma: f64,
    },
    /// Already located (a touch, a crossing at the step's start).
    Located(Crossing),
    /// The guard stops being finite at `t` before crossing zero.
    NotFinite {
        t: f64,
    },
    /// A contact left on its guard by its own reset was carried into the crossed side.
    Stuck,
}

/// A guard within round-off of zero at the start of a step, to be decided by the step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Pending {
    None,
    /// On the guard at the start of the run or after a reset moved it there, with no clear speed:
    /// fires at the step's start if the step carries it to the crossed side.
    OnGuard,
    /// A contact its own reset left on its guard with no clear speed: stuck if the step carries it
    /// to the crossed side.
    Contact,
}

/// A guard value with its time and speed, in a step's scan.
#[derive(Clone, Copy, Debug)]
struct Sample {
    t: f64,
    g: f64,
    dg: f64,
    extremum: bool,
}

pub(crate) struct Detector {
    /// Per position in the current mode's event list: values, speeds and round-off bounds at the
    /// step's start (`0`) and end (`1`).
    pub g0: Vec<f64>,
    pub dg0: Vec<f64>,
    pub noise0: Vec<f64>,
    pub speed_noise0: Vec<f64>,
    pub g1: Vec<f64>,
    pub dg1: Vec<f64>,
    noise1: Vec<f64>,
    speed_noise1: Vec<f64>,
    /// The walk over the current step's pieces (`enclose.rs`).
    pieces: Pieces,
    /// Per event id: the gradient of an affine guard, constant over a run (its `g_x` and `g_t`
    /// read the parameters alone): `g_x`'s nonzero entries at `affine_gx[start..end]` and `g_t`,
    /// valid where the stamp is `run`.
    affine: Vec<(u32, u32, f64, u64)>,
    affine_gx: Vec<(u32, f64)>,
    run: u64,
    /// Per mode: the states its walk reads (`Self::walk_states`), valid where the stamp is
    /// `run`.
    walk_states: Vec<(u64, Option<Vec<u32>>, bool)>,
    /// Per state: `P_i(s) - P_i(0)` of the current interpolant in the power basis
    /// (`Interpolant::component_form`), valid where `poly_stamp` is `stamp`.
    polys: Vec<[f64; CAP]>,
    poly_len: Vec<usize>,
    poly_stamp: Vec<u64>,
    /// Counts the interpolants scanned, so the polynomials of an earlier one are never read.
    stamp: u64,
    /// The interpolant's state at the step's start, `P(0)`.
    x_start: Vec<f64>,
    /// The box of states and rates a piece's enclosure is evaluated over, and its scratch.
    x_box: Vec<Interval>,
    dx_box: Vec<Interval>,
    duals: Vec<Dual>,
    /// Whether a guard's walk over the current step examined its most pieces
    /// ([`super::enclose::MAX_PIECES`]) before ending: the step is then retried shorter.
    pub exhausted: bool,
    pub pending: Vec<Pending>,
    /// Per position: the distance from zero within which a pending guard counts as still on its
    /// guard (its round-off, plus what locating the crossing it fired at to adjacent floats
    /// leaves: [`Detector::set_pending`]).
    pending_margin: Vec<f64>,
    /// Per position: what the current step's scan found.
    pub found: Vec<Finding>,
    /// Events (id and crossing) that fire together at the selected time, in declaration order.
    pub group: Vec<(usize, Crossing)>,
    /// Per position: the pre-crossing sign of an event whose reset sent its guard back (a
    /// bounce) while the guard has not yet been strictly on that side again (see
    /// [`Detector::penetrated`]).
    bounced: Vec<Option<f64>>,
    /// The end of the step `scan` last searched.
    step_end: f64,
    gtmp: Vec<f64>,
    gx: Vec<f64>,
    gp: Vec<f64>,
    x: Vec<f64>,
    dx: Vec<f64>,
    samples: Vec<Sample>,
    located: Vec<(usize, Crossing)>,
    /// Crossings located in the current step whose enabling condition is false before the instant.
    located_off: Vec<(usize, Crossing)>,
    /// The current step's start and end times (equal after a restart, before a step).
    span: (f64, f64),
    /// Time, state and flow at the step's start and end, for round-off bounds asked for later.
    at: [(f64, Vec<f64>, Vec<f64>); 2],
    /// The positions the current step looks at closer (`mark_candidates`), and their first
    /// estimates in `select`.
    candidates: Vec<usize>,
    estimates: Vec<f64>,
    /// Per position: a flow switch's side of zero over the current step (`stray_stage`).
    sides: Vec<f64>,
    /// After `select`: the first estimate of the earliest crossing found in the step beyond the
    /// ones that fire, if any.
    pub next_crossing: Option<f64>,
}

/// Whether the guard went from its pre-crossing side at `ga` to the crossed side at `gb`;
/// returns the pre-crossing sign.
fn crossing_sign(dir: Direction, ga: f64, gb: f64) -> Option<f64> {
    let falling = ga > 0.0 && gb <= 0.0;
    let rising = ga < 0.0 && gb >= 0.0;
    match dir {
        Direction::Falling if falling => Some(1.0),
        Direction::Rising if rising => Some(-1.0),
        Direction::Either if falling => Some(1.0),
        Direction::Either if rising => Some(-1.0),
        _ => None,
    }
}

/// Whether values of sign `sigma` are on the pre-crossing side for `dir`.
fn allows(dir: Direction, sigma: f64) -> bool {
    match dir {
        Direction::Falling => sigma > 0.0,
        Direction::Rising => sigma < 0.0,
        Direction::Either => true,
    }
}

/// The side of zero a guard value beyond its round-off `noise` is on: `Some(true)` crossed,
/// `Some(false)` pre-crossing, `None` within round-off. For `Either` both sides are both.
pub(crate) fn clear_side(dir: Direction, g: f64, noise: f64) -> Option<bool> {
    // A NaN guard is on no side.
    if g.is_nan() || g.abs() <= noise {
        return None;
    }
    Some(match dir {
        Direction::Falling => g < 0.0,
        Direction::Rising => g > 0.0,
        Direction::Either => true,
    })
}

/// Whether a guard on zero moving at `speed` (beyond `noise`) moves to its crossed side, and
/// from which pre-crossing sign; `None` when the speed is round-off or moves it back.
pub(crate) fn moves_across(dir: Direction, speed: f64, noise: f64) -> Option<f64> {
    if speed.is_nan() || speed.abs() <= noise {
        return None;
    }
    let sigma = -speed.signum();
    allows(dir, sigma).then_some(sigma)
}

/// `16 eps (sum_i |a_i b_i| + |c d|)`: the round-off bound of `a . b + c d` computed in floating
/// point, per component.
fn round_off(a: &[f64], b: &[f64], c: f64, d: f64) -> f64 {
    16.0 * EPS * (a.iter().zip(b).map(|(a, b)| (a * b).abs()).sum::<f64>() + (c * d).abs())
}

impl Detector {
    pub fn new(info: &SystemInfo, nx: usize, m: usize) -> Detector {
        let ne = info.modes.iter().map(|md| md.events.len()).max().unwrap_or(0);
        let per_event = || vec![0.0; ne];
        Detector {
            g0: per_event(),
            dg0: per_event(),
            noise0: per_event(),
            speed_noise0: per_event(),
            g1: per_event(),
            dg1: per_event(),
            noise1: per_event(),
            speed_noise1: per_event(),
            pieces: Pieces::default(),
            affine: vec![(0, 0, 0.0, 0); info.events.len()],
            affine_gx: Vec::new(),
            run: 1,
            walk_states: vec![(0, None, false); info.modes.len()],
            polys: vec![[0.0; CAP]; nx],
            poly_len: vec![0; nx],
            poly_stamp: vec![0; nx],
            stamp: 0,
            x_start: vec![0.0; nx],
            x_box: vec![Interval::point(0.0); nx],
            dx_box: vec![Interval::point(0.0); nx],
            duals: Vec::new(),
            exhausted: false,
            pending: vec![Pending::None; ne],
            pending_margin: vec![0.0; ne],
            found: vec![Finding::Nothing; ne],
            group: Vec::with_capacity(ne),
            bounced: vec![None; ne],
            step_end: f64::NAN,
            gtmp: per_event(),
            gx: vec![0.0; nx],
            gp: vec![0.0; m],
            x: vec![0.0; nx],
            dx: vec![0.0; nx],
            samples: Vec::new(),
            located: Vec::new(),
            located_off: Vec::new(),
            span: (0.0, 0.0),
            at: [(0.0, vec![0.0; nx], vec![0.0; nx]), (0.0, vec![0.0; nx], vec![0.0; nx])],
            candidates: Vec::with_capacity(ne),
            estimates: Vec::with_capacity(ne),
            sides: per_event(),
            next_crossing: None,
        }
    }

    /// Forgets what an earlier run's parameters made constant (the affine guards' gradients).
    pub fn start_run(&mut self) {
        self.run += 1;
        self.affine_gx.clear();
    }

    /// The states the walk over the mode's guards reads of the dense output, when they are fewer
    /// than all and the walk reads nothing else of it: every guard affine or a time event (their
    /// polynomials and speeds read the states of their gradients, a subset of the states they
    /// read) and none a flow switch (whose stray stages are checked on whole states); `None`
    /// otherwise. Once per mode and run.
    pub fn walk_states<S: HybridSystem + ?Sized>(&mut self, cx: &Guards<S>) -> Option<&[u32]> {
        self.mode_facts(cx);
        self.walk_states[cx.mode].1.as_deref()
    }

    /// Whether the mode has a flow switch whose stray stages [`Self::stray_stage`] checks: the
    /// stepper keeps its stages' states then (`Stepper::keep_stage_states`).
    pub fn checks_stages<S: HybridSystem + ?Sized>(&mut self, cx: &Guards<S>) -> bool {
        self.mode_facts(cx);
        self.walk_states[cx.mode].2
    }

    /// [`Self::walk_states`] and [`Self::checks_stages`] of the mode, once per mode and run.
    fn mode_facts<S: HybridSystem + ?Sized>(&mut self, cx: &Guards<S>) {
        let mode = cx.mode;
        if self.walk_states[mode].0 == self.run {
            return;
        }
        let mut states: Vec<u32> = Vec::new();
        let mut lazy = true;
        for &ev in cx.events() {
            let e = &cx.info.events[ev];
            match cx.sys.guard_states(ev) {
                Some(read) if e.guard != GuardShape::Nonlinear && !e.implicit => states.extend(read),
                _ => lazy = false,
            }
        }
        states.sort_unstable();
        states.dedup();
        let lazy = lazy && states.len() < cx.n;
        let switches = cx.events().iter().any(|&ev| Self::is_switch(cx, ev));
        self.walk_states[mode] = (self.run, lazy.then_some(states), switches);
    }

    /// Whether event `ev` is a flow switch whose stages [`Self::stray_stage`] checks.
    fn is_switch<S: HybridSystem + ?Sized>(cx: &Guards<S>, ev: usize) -> bool {
        let e = &cx.info.events[ev];
        e.implicit && e.guard != GuardShape::Time
    }

    /// Whether the last scan found anything (a crossing, a touch, a stuck contact, a guard that
    /// stops being finite): what follows reads whole states of the dense output.
    pub fn found_any(&self) -> bool {
        self.candidates.iter().any(|&pos| !matches!(self.found[pos], Finding::Nothing))
    }

    /// Whether the guard of event `ev` has a gradient constant over the run (affine or a time
    /// event).
    fn is_affine<S: HybridSystem + ?Sized>(cx: &Guards<S>, ev: usize) -> bool {
        cx.info.events[ev].guard != GuardShape::Nonlinear
    }

    /// The constant gradient of the affine guard of event `ev` (`g_x`'s nonzero entries and
    /// `g_t`), from one gradient evaluation per run at any `(t, x)`.
    fn affine_grad<S: HybridSystem + ?Sized>(
        &mut self,
        cx: &Guards<S>,
        ev: usize,
        t: f64,
        x: &[f64],
    ) -> (usize, usize, f64) {
        let (start, end, gt, stamp) = self.affine[ev];
        if stamp == self.run {
            return (start as usize, end as usize, gt);
        }
        let gt = cx.grad(ev, t, x, &mut self.gx, &mut self.gp);
        let start = self.affine_gx.len();
        self.affine_gx
            .extend(self.gx.iter().enumerate().filter(|(_, g)| **g != 0.0).map(|(i, &g)| (i as u32, g)));
        let end = self.affine_gx.len();
        self.affine[ev] = (start as u32, end as u32, gt, self.run);
        (start, end, gt)
    }

    /// An affine guard's speed `g_x f + g_t` and the round-off bounds of its value at `(t, x)`
    /// and of its speed, from its constant gradient.
    fn affine_speed_noise<S: HybridSystem + ?Sized>(
        &mut self,
        cx: &Guards<S>,
        ev: usize,
        t: f64,
        x: &[f64],
        f: &[f64],
    ) -> (f64, f64, f64) {
        let (start, end, gt) = self.affine_grad(cx, ev, t, x);
        let entries = &self.affine_gx[start..end];
        let speed = entries.iter().map(|&(i, g)| g * f[i as usize]).sum::<f64>() + gt;
        let value_terms: f64 = entries.iter().map(|&(i, g)| (g * x[i as usize]).abs()).sum();
        let speed_terms: f64 = entries.iter().map(|&(i, g)| (g * f[i as usize]).abs()).sum();
        (speed, 16.0 * EPS * (value_terms + (gt * t).abs()), 16.0 * EPS * (speed_terms + gt.abs()))
    }

    /// Guard values and speeds at a step's start `(t, x)` with flow `f` (after a restart), into
    /// `g0`, `dg0`; their round-off bounds are computed when asked for (`noise0`).
    pub fn eval_start<S: HybridSystem + ?Sized>(&mut self, cx: &Guards<S>, t: f64, x: &[f64], f: &[f64]) {
        let (sys, mode, p) = (cx.sys, cx.mode, cx.p);
        let evs = cx.events();
        let ne = evs.len();
        self.span = (t, t);
        cx.eval(t, x, &mut self.g0);
        self.at[0].0 = t;
        self.at[0].1.copy_from_slice(x);
        self.at[0].2.copy_from_slice(f);
        if ne <= FEW_GUARDS {
            // Guard by guard, the round-off bounds at once (see `eval_end_each`).
            for (pos, &ev) in evs.iter().enumerate() {
                if Self::is_affine(cx, ev) {
                    (self.dg0[pos], self.noise0[pos], self.speed_noise0[pos]) =
                        self.affine_speed_noise(cx, ev, t, x, f);
                    continue;
                }
                let gt = sys.guard_grad(ev, t, x, p, &mut self.gx, &mut self.gp);
                self.dg0[pos] = dot(&self.gx, f) + gt;
                self.noise0[pos] = round_off(&self.gx, x, gt, t);
                self.speed_noise0[pos] = round_off(&self.gx, f, gt, 1.0);
            }
            return;
        }
        sys.guard_speeds(mode, t, x, f, p, &mut self.dg0[..ne]);
        self.noise0[..ne].fill(f64::NAN);
        self.speed_noise0[..ne].fill(f64::NAN);
    }

    /// The round-off bounds of the value and the speed of the guard at `pos` at the step's start
    /// (`16 eps (sum_i |g_x,i x_i| + |g_t t|)` and `16 eps (sum_i |g_x,i f_i| + |g_t|)`), computed
    /// on first use.
    pub fn noise0<S: HybridSystem + ?Sized>(&mut self, cx: &Guards<S>, pos: usize) -> (f64, f64) {
        self.noise_at(cx, 0, pos)
    }

    /// The round-off bounds at the step's start (`end` 0) or end (1), computed on first use.
    fn noise_at<S: HybridSystem + ?Sized>(&mut self, cx: &Guards<S>, end: usize, pos: usize) -> (f64, f64) {
        let noise = if end == 0 { &self.noise0 } else { &self.noise1 };
        if noise[pos].is_nan() {
            let ev = cx.events()[pos];
            let at = std::mem::take(&mut self.at[end]);
            let (t, x, f) = (at.0, &at.1, &at.2);
            let (value, speed) = if Self::is_affine(cx, ev) {
                let (_, value, speed) = self.affine_speed_noise(cx, ev, t, x, f);
                (value, speed)
            } else {
                let gt = cx.grad(ev, t, x, &mut self.gx, &mut self.gp);
                (round_off(&self.gx, x, gt, t), round_off(&self.gx, f, gt, 1.0))
            };
            self.at[end] = at;
            let (noise, speed_noise) = match end {
                0 => (&mut self.noise0, &mut self.speed_noise0),
                _ => (&mut self.noise1, &mut self.speed_noise1),
            };
            (noise[pos], speed_noise[pos]) = (value, speed);
        }
        let (noise, speed_noise) = match end {
            0 => (&self.noise0, &self.speed_noise0),
            _ => (&self.noise1, &self.speed_noise1),
        };
        (noise[pos], speed_noise[pos])
    }

    /// At the end of a step that ends the run with nothing selected: the events whose guard is
    /// within round-off of zero there (or within what locating to adjacent floats leaves), not
    /// yet across, with the flow moving it across. Their crossing is at the end to round-off, so
    /// they fire there, whatever side of zero round-off put them on: an event at `t_end` fires.
    /// Fills `group` (conditions are judged by the group) and says whether there is any.
    pub fn on_guard_at_end<S: HybridSystem + ?Sized>(&mut self, cx: &Guards<S>) -> bool {
        self.group.clear();
        let t = self.span.1;
        for (pos, &ev) in cx.events().iter().enumerate() {
            let einfo = &cx.info.events[ev];
            let (g, speed) = (self.g1[pos], self.dg1[pos]);
            // On zero or across already (the scan found it), or moving away: nothing to decide.
            if einfo.implicit || !g.is_finite() || g * speed >= 0.0 {
                continue;
            }
            let (_, speed_noise) = self.noise_at(cx, 1, pos);
            let noise = self.carried_round_off(cx, ev);
            let located = 4.0 * speed.abs() * crate::sim::spacing(t);
            if g.abs() > noise + located {
                continue;
            }
            // Rule 1 still holds: at the step's start the guard was strictly on the side it is
            // leaving, beyond round-off (not on zero after an event that just fired on it).
            let (noise0, _) = self.noise0(cx, pos);
            let g0 = self.g0[pos];
            if !(g0 * g > 0.0 && g0.abs() > noise0) {
                continue;
            }
            if let Some(sigma) = moves_across(einfo.direction, speed, speed_noise) {
                self.group.push((ev, Crossing { t, sigma, touch: false, t_pre: t, on_guard: true }));
            }
        }
        !self.group.is_empty()
    }

    /// The round-off a guard's value at the step's end carries from the step:
    /// `16 eps (sum_i |g_x,i| max(|x_i(t0)|, |x_i(t1)|) + |g_t t1|)`. A state at the end is its
    /// value at the start plus the step's increment, rounded at the scale of the larger: a ball
    /// dropped from 1 m (Rodas5P, five steps) reaches the floor at `t_end = sqrt(2 / g)` with
    /// `y = 1.3e-15`, six spacings of its drop height, where `16 eps |y|` is nothing.
    fn carried_round_off<S: HybridSystem + ?Sized>(&mut self, cx: &Guards<S>, ev: usize) -> f64 {
        let (t, x1) = (self.at[1].0, &self.at[1].1);
        let gt = cx.grad(ev, t, x1, &mut self.gx, &mut self.gp);
        let x0 = &self.at[0].1;
        let terms: f64 =
            self.gx.iter().zip(x0.iter().zip(x1)).map(|(g, (a, b))| g.abs() * a.abs().max(b.abs())).sum();
        16.0 * EPS * (terms + (gt * t).abs())
    }

    /// Guard values and speeds at the end of the stepper's last attempt, which ends at `t`, with
    /// the round-off bounds of the guards whose closeness to zero this step judges (the others
    /// are computed when asked for).
    pub fn eval_end<S: HybridSystem + ?Sized, St: Stepper>(&mut self, cx: &Guards<S>, t: f64, stepper: &St) {
        let (sys, info, mode, p, n) = (cx.sys, cx.info, cx.mode, cx.p, cx.n);
        let (x, f) = (&stepper.end_state()[..n], &stepper.end_derivative()[..n]);
        let evs = cx.events();
        let ne = evs.len();
        self.span.1 = t;
        cx.eval(t, x, &mut self.g1);
        self.at[1].0 = t;
        self.at[1].1.copy_from_slice(x);
        self.at[1].2.copy_from_slice(f);
        if ne <= FEW_GUARDS {
            self.eval_end_each(cx, t, stepper);
            return;
        }
        sys.guard_speeds(mode, t, x, f, p, &mut self.dg1[..ne]);
        for (pos, &ev) in evs.iter().enumerate() {
            let shape = info.events[ev].guard;
            if shape == GuardShape::Nonlinear
                || self.pending[pos] != Pending::None
                || self.bounced[pos].is_some()
            {
                let gt = sys.guard_grad(ev, t, x, p, &mut self.gx, &mut self.gp);
                self.noise1[pos] = round_off(&self.gx, x, gt, t);
                self.speed_noise1[pos] = round_off(&self.gx, f, gt, 1.0);
            } else {
                self.noise1[pos] = f64::NAN;
                self.speed_noise1[pos] = f64::NAN;
            }
        }
    }

    /// [`Self::eval_end`] for a mode with few guards, guard by guard: one gradient evaluation per
    /// guard gives its speed and its round-off bounds, cheaper there than the speeds kernel.
    fn eval_end_each<S: HybridSystem + ?Sized, St: Stepper>(&mut self, cx: &Guards<S>, t: f64, stepper: &St) {
        let n = cx.n;
        let (x, f) = (&stepper.end_state()[..n], &stepper.end_derivative()[..n]);
        for (pos, &ev) in cx.events().iter().enumerate() {
            if Self::is_affine(cx, ev) {
                (self.dg1[pos], self.noise1[pos], self.speed_noise1[pos]) =
                    self.affine_speed_noise(cx, ev, t, x, f);
                continue;
            }
            let gt = cx.grad(ev, t, x, &mut self.gx, &mut self.gp);
            self.dg1[pos] = dot(&self.gx, f) + gt;
            self.noise1[pos] = round_off(&self.gx, x, gt, t);
            self.speed_noise1[pos] = round_off(&self.gx, f, gt, 1.0);
        }
    }

    /// Forgets every bounce and pending decision (at the start of a run and after every instant).
    pub fn clear_bounces(&mut self) {
        self.bounced.fill(None);
        self.pending.fill(Pending::None);
        self.pending_margin.fill(0.0);
    }

    /// The guard at `pos` is on zero to within `margin` at the step's start with no clear speed:
    /// the first sample beyond `margin` (and beyond round-off) decides it (`kind`).
    pub fn set_pending(&mut self, pos: usize, kind: Pending, margin: f64) {
        self.pending[pos] = kind;
        self.pending_margin[pos] = margin;
    }

    /// The distance from zero a guard must pass to leave its guard, judged at `pos`: its
    /// round-off at the step's ends, or for a pending guard its margin if larger.
    fn on_guard_margin<S: HybridSystem + ?Sized>(&mut self, cx: &Guards<S>, pos: usize) -> f64 {
        let noise = self.noise_at(cx, 0, pos).0.max(self.noise_at(cx, 1, pos).0);
        if self.pending[pos] != Pending::None {
            noise.max(self.pending_margin[pos])
        } else {
            noise
        }
    }

    /// Records that the event at `pos` (in the current mode) just fired from the side of sign
    /// `sigma` and its reset turned the guard speed around from `speed_before`, when the guard
    /// is not yet strictly back on that side (`g0`, `dg0` hold the post-event values). The caller
    /// calls it only for a guard the reset left on zero (within its round-off).
    pub fn note_bounce(&mut self, pos: usize, sigma: f64, speed_before: f64) {
        let reversed = self.dg0[pos] * speed_before < 0.0;
        if reversed && sigma * self.g0[pos] <= 0.0 {
            self.bounced[pos] = Some(sigma);
        }
    }

    /// After an accepted step without a firing: the position of a bounced event whose guard
    /// went deeper into the crossed side than round-off without ever getting strictly back. The
    /// reset meant to send the state back, but the bounce was too small to resolve: in exact
    /// arithmetic the event would fire again and again (Zeno), in floating point the state
    /// would fall through the guard. Otherwise forgets the bounces that are back on their side.
    pub fn penetrated(&mut self) -> Option<usize> {
        for (pos, b) in self.bounced.iter_mut().enumerate() {
            if let Some(sigma) = *b {
                if sigma * self.g1[pos] < -self.noise1[pos] {
                    return Some(pos);
                }
                if sigma * self.g1[pos] > 0.0 {
                    *b = None;
                }
            }
        }
        None
    }

    /// The current step's ends with the speeds of the guard at `pos` there, `(t0, g'0, t1, g'1)`,
    /// when the step has a width (not after a restart).
    pub fn step_speeds(&self, pos: usize) -> Option<(f64, f64, f64, f64)> {
        let (t0, t1) = self.span;
        (t1 > t0).then(|| (t0, self.dg0[pos], t1, self.dg1[pos]))
    }

    /// After a step without events the end values become the next step's start values.
    pub fn advance(&mut self) {
        self.span.0 = self.span.1;
        std::mem::swap(&mut self.g0, &mut self.g1);
        std::mem::swap(&mut self.dg0, &mut self.dg1);
        std::mem::swap(&mut self.noise0, &mut self.noise1);
        std::mem::swap(&mut self.speed_noise0, &mut self.speed_noise1);
        self.at.swap(0, 1);
        // A guard decided by this step is no longer pending.
        for (pos, pending) in self.pending.iter_mut().enumerate() {
            if *pending != Pending::None
                && self.g0[pos].abs() > self.noise0[pos].max(self.pending_margin[pos])
            {
                *pending = Pending::None;
            }
        }
    }

    /// Marks the guards the step searches (`candidates`): every guard but a time event, which
    /// the steps land on (its times are breakpoints), and which is searched only when the step
    /// carries it across, it is pending or not finite. Returns whether there is any (then the
    /// step needs its dense output for the events).
    pub fn mark_candidates<S: HybridSystem + ?Sized>(&mut self, cx: &Guards<S>) -> bool {
        self.candidates.clear();
        for (pos, &ev) in cx.events().iter().enumerate() {
            let einfo = &cx.info.events[ev];
            let (g0, g1) = (self.g0[pos], self.g1[pos]);
            let look = einfo.guard != GuardShape::Time
                || !g1.is_finite()
                || self.pending[pos] != Pending::None
                || crossing_sign(einfo.direction, g0, g1).is_some();
            if look {
                self.candidates.push(pos);
            }
        }
        !self.candidates.is_empty()
    }

    /// Whether a candidate guard (`mark_candidates`) is across in its direction between the
    /// step's ends: a crossing inside the step is then certain, not merely possible.
    pub fn crossing_certain<S: HybridSystem + ?Sized>(&self, cx: &Guards<S>) -> bool {
        self.candidates.iter().any(|&pos| {
            let ev = cx.events()[pos];
            crossing_sign(cx.info.events[ev].direction, self.g0[pos], self.g1[pos]).is_some()
        })
    }

    /// The guard of event `ev` (at `pos` in `mode`) and its speed `g_x f + g_t` at an explicit
    /// state `x` with flow `f`.
    pub fn guard_and_speed<S: HybridSystem + ?Sized>(
        &mut self,
        cx: &Guards<S>,
        pos: usize,
        t: f64,
        x: &[f64],
        f: &[f64],
    ) -> (f64, f64) {
        let g = self.guard_now(cx, pos, t, x);
        let gt = cx.grad(cx.events()[pos], t, x, &mut self.gx, &mut self.gp);
        (g, dot(&self.gx, f) + gt)
    }

    /// Whether a guard of the mode outside the selected group has crossed (by its direction)
    /// between the step's start and the state `x` at `t`: an instant landed far from where the
    /// dense output put it stands only when no other event's crossing came before it.
    pub fn another_crossed<S: HybridSystem + ?Sized>(&mut self, cx: &Guards<S>, t: f64, x: &[f64]) -> bool {
        cx.eval(t, x, &mut self.gtmp);
        cx.events().iter().enumerate().any(|(pos, &ev)| {
            !self.group.iter().any(|&(e, _)| e == ev)
                && crossing_sign(cx.info.events[ev].direction, self.g0[pos], self.gtmp[pos]).is_some()
        })
    }

    /// One guard of the mode at an explicit state.
    pub fn guard_now<S: HybridSystem + ?Sized>(
        &mut self,
        cx: &Guards<S>,
        pos: usize,
        t: f64,
        x: &[f64],
    ) -> f64 {
        cx.eval(t, x, &mut self.gtmp);
        self.gtmp[pos]
    }

    /// Every guard of the mode at `t` on the interpolant, into `gtmp`.
    fn guards_on_dense<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        t: f64,
        dense: &I,
    ) {
        dense.eval(t, &mut self.x);
        cx.eval(t, &self.x, &mut self.gtmp);
    }

    fn guard_on_dense<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        pos: usize,
        t: f64,
        dense: &I,
    ) -> f64 {
        self.guards_on_dense(cx, t, dense);
        self.gtmp[pos]
    }

    /// Guard speed along the interpolant, `g_x P'(t) + g_t`.
    fn speed_on_dense<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        ev: usize,
        t: f64,
        dense: &I,
    ) -> f64 {
        dense.eval_deriv(t, &mut self.dx);
        let (start, end, gt, stamp) = self.affine[ev];
        if stamp == self.run && Self::is_affine(cx, ev) {
            // The run's constant gradient: no kernel call.
            let entries = &self.affine_gx[start as usize..end as usize];
            return entries.iter().map(|&(i, g)| g * self.dx[i as usize]).sum::<f64>() + gt;
        }
        dense.eval(t, &mut self.x);
        let gt = cx.grad(ev, t, &self.x, &mut self.gx, &mut self.gp);
        dot(&self.gx, &self.dx) + gt
    }

    /// The round-off bound of the guard value at `(t, self.x)`: called right after
    /// [`Self::guard_on_dense`] at `t`, whose interpolated state is still in `self.x`.
    fn noise_at_x<S: HybridSystem + ?Sized>(&mut self, cx: &Guards<S>, ev: usize, t: f64) -> f64 {
        let gt = cx.grad(ev, t, &self.x, &mut self.gx, &mut self.gp);
        round_off(&self.gx, &self.x, gt, t)
    }

    /// Scans every guard of `mode` over the step of `dense` (the stepper's last attempt) into
    /// `found`. The step ends at `t1` exactly (a breakpoint it landed on; `t0 + h` may round
    /// elsewhere).
    pub fn scan<S: HybridSystem + ?Sized, I: Interpolant>(&mut self, cx: &Guards<S>, dense: &I, t1: f64) {
        self.step_end = t1;
        self.exhausted = false;
        self.stamp += 1;
        dense.eval(dense.t0(), &mut self.x_start);
        for c in 0..self.candidates.len() {
            let pos = self.candidates[c];
            let dir = cx.info.events[cx.events()[pos]].direction;
            self.build_samples(cx, dense, pos, None);
            self.found[pos] = self.scan_samples(cx, dir, pos, dense);
        }
    }

    /// The samples of the guard at `pos` along the step from `from` (the step's start when
    /// `None`) to its first crossing or its end, in time order, for `scan_samples`: the walk of
    /// the module documentation. Between two consecutive samples the guard either keeps a strict
    /// sign (the pieces between were proved clear of zero) or is monotone, or the samples are
    /// the ends of a piece too short to halve with its extremum between them.
    fn build_samples<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        dense: &I,
        pos: usize,
        from: Option<Sample>,
    ) {
        let (t0, h) = (dense.t0(), dense.h());
        let ev = cx.events()[pos];
        let shape = cx.info.events[ev].guard;
        let start = from.unwrap_or(Sample { t: t0, g: self.g0[pos], dg: self.dg0[pos], extremum: false });
        self.samples.clear();
        self.samples.push(start);
        let margin = self.on_guard_margin(cx, pos);
        // An affine guard (a time event too) is a polynomial along the step:
        // `g0 + g_x (P(s) - P(0)) + g_t h s`, bounded piece by piece without overestimation.
        let mut guard_poly = ([0.0; CAP], 0);
        if shape != GuardShape::Nonlinear {
            let x_start = std::mem::take(&mut self.x_start);
            let (first, last, gt) = self.affine_grad(cx, ev, t0, &x_start);
            self.x_start = x_start;
            // Most steps pass far from the guard: one bound of the whole step settles them (not
            // worth computing when the ends already differ in sign or one is on zero).
            let ends_apart = self.g0[pos] * self.g1[pos] > 0.0;
            let hull = if ends_apart {
                dense.affine_motion_hull(&self.affine_gx[first..last], gt * h)
            } else {
                None
            };
            if let Some((lo, hi)) = hull {
                let whole = Interval::new(lo, hi) + Interval::point(self.g0[pos]);
                if whole.clear_of_zero(margin) {
                    self.close_samples(pos);
                    return;
                }
            }
            let poly = self.affine_poly(dense, first, last, gt * h);
            guard_poly.1 = poly.write_to(&mut guard_poly.0);
        }
        let s_from = if h > 0.0 { ((start.t - t0) / h).clamp(0.0, 1.0) } else { 1.0 };
        if shape == GuardShape::Nonlinear {
            let whole = self.enclose_piece(cx, ev, dense, s_from, 1.0);
            if whole.v == Interval::ENTIRE && whole.d == Interval::ENTIRE {
                self.sample_without_enclosures(cx, pos, dense, s_from);
                return;
            }
        }
        self.pieces.start(s_from, 1.0);
        while let Some((a, b, depth)) = self.pieces.next() {
            // Halving, unless an affine guard's extremum gives a better place (a nonlinear guard's
            // pieces split three ways around their middle left the running cost of
            // `tests/it/detection.rs` 2% off: not understood yet, so they halve).
            let mut split = f64::NAN;
            let e = if shape == GuardShape::Nonlinear {
                self.enclose_piece(cx, ev, dense, a, b)
            } else {
                let piece = bernstein(&guard_poly.0, guard_poly.1, a, b);
                // The coefficients' signs decide most pieces without the hull or the rate: a
                // single sign change is decided by the ends, as a monotone piece is; at the walk's
                // start, a guard on zero that leaves it and never returns holds nothing to sample,
                // and one that leaves and crosses once is cut at its extremum into two such pieces
                // (a ball's whole flight, from one bounce to the next, in one step).
                let at_start = a == s_from && self.samples.len() == 1;
                match piece.signs(self.g0[pos], margin) {
                    Signs::Clear => continue,
                    Signs::FromZero { changes: 0 } if at_start => continue,
                    Signs::OneChange => {
                        if self.sample_piece(cx, pos, dense, (a, b), true, margin) {
                            self.pieces.stop();
                        }
                        continue;
                    }
                    Signs::FromZero { changes: 1 }
                        if at_start && self.pieces.split_in_two(a, b, piece.extremum_estimate(), depth) =>
                    {
                        continue
                    }
                    _ => {}
                }
                // Else the hull, and the rate where the hull does not decide; split where the
                // rate's control polygon changes sign.
                let v = piece.value() + Interval::point(self.g0[pos]);
                if v.clear_of_zero(margin) {
                    continue;
                }
                split = piece.extremum_estimate();
                Dual { v, d: piece.rate(&guard_poly.0) / Interval::point(h) }
            };
            if e.v.clear_of_zero(margin) {
                continue;
            }
            let monotone = e.d.clear_of_zero(0.0);
            // Within round-off of zero all along: no sign change beyond round-off to prove;
            // its ends decide (a guard resting on zero, pending).
            let on_zero = e.v.lo >= -margin && e.v.hi <= margin;
            if !(monotone || on_zero) && self.pieces.split_at(a, b, split, depth) {
                continue;
            }
            if !(monotone || on_zero) && self.pieces.exhausted() {
                self.exhausted = true;
                self.pieces.stop();
            }
            if self.sample_piece(cx, pos, dense, (a, b), monotone, margin) {
                self.pieces.stop();
            }
        }
        self.close_samples(pos);
    }

    /// Ends the samples of the guard at `pos` at the step's end, unless they reached it.
    fn close_samples(&mut self, pos: usize) {
        let t1 = self.step_end;
        if self.samples.last().is_some_and(|last| last.t < t1) {
            self.samples.push(Sample { t: t1, g: self.g1[pos], dg: self.dg1[pos], extremum: false });
        }
    }

    /// A nonlinear guard of a system that gives no enclosures (`HybridSystem::guard_enclosure`'s
    /// default, a hand-written system): samples at [`UNENCLOSED_SAMPLES`] evenly spaced points of
    /// the step from `s_from` and the extrema between samples whose speeds differ in sign. No
    /// guarantee: a sign change between samples that hides behind no extremum is missed.
    fn sample_without_enclosures<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        pos: usize,
        dense: &I,
        s_from: f64,
    ) {
        let (t0, h, t1) = (dense.t0(), dense.h(), self.step_end);
        let ev = cx.events()[pos];
        for k in 1..UNENCLOSED_SAMPLES {
            let t = t0 + (s_from + (1.0 - s_from) * k as f64 / UNENCLOSED_SAMPLES as f64) * h;
            if t > self.samples.last().map_or(t0, |s| s.t) && t < t1 {
                let g = self.guard_on_dense(cx, pos, t, dense);
                let dg = self.speed_on_dense(cx, ev, t, dense);
                self.samples.push(Sample { t, g, dg, extremum: false });
            }
        }
        if self.samples.last().is_some_and(|last| last.t < t1) {
            self.samples.push(Sample { t: t1, g: self.g1[pos], dg: self.dg1[pos], extremum: false });
        }
        let count = self.samples.len();
        for k in 0..count - 1 {
            let (a, b) = (self.samples[k], self.samples[k + 1]);
            if a.dg * b.dg < 0.0 {
                let te = extremum_time(a.t, a.dg, b.t, b.dg, |t| self.speed_on_dense(cx, ev, t, dense));
                if te > a.t && te < b.t {
                    let ge = self.guard_on_dense(cx, pos, te, dense);
                    self.samples.push(Sample { t: te, g: ge, dg: 0.0, extremum: true });
                }
            }
        }
        self.samples.sort_by(|a, b| a.t.total_cmp(&b.t));
    }

    /// `g_x (P(s) - P(0)) + slope s` along the step of `dense` for the gradient entries
    /// `affine_gx[first..last]`: combined component by component when they are few against the
    /// states (each component's polynomial is read alone), else by `Interpolant::linear_form`.
    fn affine_poly<I: Interpolant>(&mut self, dense: &I, first: usize, last: usize, slope: f64) -> Poly {
        let entries = &self.affine_gx[first..last];
        let mut coef = [0.0; CAP];
        let mut len = 1;
        if 8 * entries.len() < self.gx.len() {
            let mut part = [0.0; CAP];
            for &(i, g) in entries {
                let k = dense.component_form(i as usize, &mut part);
                for (c, p) in coef.iter_mut().zip(&part[..k]) {
                    *c += g * p;
                }
                len = len.max(k);
            }
        } else {
            self.gx.fill(0.0);
            for &(i, g) in entries {
                self.gx[i as usize] = g;
            }
            len = dense.linear_form(&self.gx, &mut coef);
        }
        let mut poly = Poly::from_coefficients(&coef, len);
        poly.add_linear(slope);
        poly
    }

    /// The enclosure of event `ev`'s nonlinear guard and its time derivative over the piece
    /// `[a, b]` of the step (in units of the step): its states bounded by their polynomials'
    /// Bernstein coefficients (computed once per interpolant), the times by the piece.
    fn enclose_piece<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        ev: usize,
        dense: &I,
        a: f64,
        b: f64,
    ) -> Dual {
        let (t0, h) = (dense.t0(), dense.h());
        let mut bound = |i: usize| {
            if self.poly_stamp[i] != self.stamp {
                self.poly_len[i] = dense.component_form(i, &mut self.polys[i]);
                self.poly_stamp[i] = self.stamp;
            }
            let (v, r) = poly_hull(&self.polys[i], self.poly_len[i], a, b);
            self.x_box[i] = v + Interval::point(self.x_start[i]);
            self.dx_box[i] = r / Interval::point(h);
        };
        match cx.sys.guard_states(ev) {
            Some(states) => states.iter().for_each(|&i| bound(i as usize)),
            None => (0..cx.n).for_each(bound),
        }
        // The step's end is `t1` exactly, which `t0 + h` may round either side of.
        let ta = t0 + a * h;
        let tb = if b >= 1.0 { (t0 + h).max(self.step_end) } else { t0 + b * h };
        let time = Interval::widened(ta.min(tb), ta.max(tb), 1);
        cx.sys.guard_enclosure(ev, time, &self.x_box, &self.dx_box, cx.p, &mut self.duals)
    }

    /// Adds the samples of a piece `[a, b]` the walk could not prove clear of zero: its start
    /// (unless the last sample is there), its end, and between them the extremum of a piece not
    /// proved monotone where the speeds at its ends differ in sign (a touch, or two crossings
    /// closer than the piece). Returns whether the walk can stop: the guard crossed (not from a
    /// start on zero, which a bounce or a pending decision leaves), touched zero or stopped
    /// being finite.
    #[allow(clippy::too_many_arguments)]
    fn sample_piece<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        pos: usize,
        dense: &I,
        (a, b): (f64, f64),
        monotone: bool,
        margin: f64,
    ) -> bool {
        let (t0, h, t1) = (dense.t0(), dense.h(), self.step_end);
        let ev = cx.events()[pos];
        let dir = cx.info.events[ev].direction;
        let time_of = |s: f64| if s >= 1.0 { t1 } else { t0 + s * h };
        let (ta, tb) = (time_of(a), time_of(b));
        let first_new = self.samples.len();
        if self.samples.last().is_some_and(|last| last.t < ta) {
            let g = self.guard_on_dense(cx, pos, ta, dense);
            let dg = self.speed_on_dense(cx, ev, ta, dense);
            self.samples.push(Sample { t: ta, g, dg, extremum: false });
        }
        let mut end = if tb >= t1 {
            Sample { t: t1, g: self.g1[pos], dg: self.dg1[pos], extremum: false }
        } else {
            let g = self.guard_on_dense(cx, pos, tb, dense);
            Sample { t: tb, g, dg: self.speed_on_dense(cx, ev, tb, dense), extremum: false }
        };
        let Some(&prev) = self.samples.last() else { return true };
        if end.t <= prev.t {
            return false;
        }
        if !monotone && prev.g.is_finite() && end.g.is_finite() {
            if prev.dg * end.dg < 0.0 {
                let te =
                    extremum_time(prev.t, prev.dg, end.t, end.dg, |t| self.speed_on_dense(cx, ev, t, dense));
                if te > prev.t && te < end.t {
                    let ge = self.guard_on_dense(cx, pos, te, dense);
                    self.samples.push(Sample { t: te, g: ge, dg: 0.0, extremum: true });
                }
            } else if end.t < t1 && end.g.abs() <= margin {
                // An extremum on the piece's end itself.
                end.extremum = true;
            }
        }
        self.samples.push(end);
        for k in first_new.saturating_sub(1)..self.samples.len() - 1 {
            let (x, y) = (self.samples[k], self.samples[k + 1]);
            let crossed = crossing_sign(dir, x.g, y.g).is_some() && !(k == 0 && x.g.abs() <= margin);
            if !y.g.is_finite() || crossed || (y.extremum && y.g.abs() <= margin) {
                return true;
            }
        }
        false
    }

    /// The next crossing of the guard at `pos` in the step after `after` (a crossing located
    /// there whose enabling condition was false): the step's samples of that guard beyond
    /// `after`, from the guard's value there. A step can hold several crossings of one guard
    /// (a polynomial flow integrated exactly in one long step); the first being disabled does
    /// not end the search (docs/language.md, `if C`).
    fn crossing_after<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        pos: usize,
        dense: &I,
        after: f64,
    ) -> Option<Crossing> {
        if after >= self.step_end {
            return None;
        }
        let ev = cx.events()[pos];
        let dir = cx.info.events[ev].direction;
        let g = self.guard_on_dense(cx, pos, after, dense);
        let dg = self.speed_on_dense(cx, ev, after, dense);
        self.build_samples(cx, dense, pos, Some(Sample { t: after, g, dg, extremum: false }));
        // The start rules (a guard pending on zero, a bounce leaving zero) are the step start's,
        // not this point's.
        let (pending, bounced) = (self.pending[pos], self.bounced[pos]);
        self.pending[pos] = Pending::None;
        self.bounced[pos] = None;
        let finding =
            if self.samples.len() < 2 { Finding::Nothing } else { self.scan_samples(cx, dir, pos, dense) };
        self.pending[pos] = pending;
        self.bounced[pos] = bounced;
        let crossing = match finding {
            Finding::Bracket { .. } => {
                self.found[pos] = finding;
                let c = self.locate(cx, pos, dense);
                self.found[pos] = Finding::Nothing;
                c
            }
            Finding::Located(c) => c,
            Finding::Nothing | Finding::Stuck | Finding::NotFinite { .. } => return None,
        };
        (crossing.t > after).then_some(crossing)
    }

    /// The first crossing, touch, pending decision or non-finite guard in the samples of one
    /// guard, in time order.
    fn scan_samples<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        dir: Direction,
        pos: usize,
        dense: &I,
    ) -> Finding {
        let ev = cx.events()[pos];
        if self.pending[pos] != Pending::None {
            // The first sample beyond round-off decides a guard that started on zero.
            let margin = self.on_guard_margin(cx, pos);
            let decided = self.samples[1..].iter().find_map(|s| clear_side(dir, s.g, margin));
            match (decided, self.pending[pos]) {
                (Some(true), Pending::OnGuard) => {
                    let t0 = self.samples[0].t;
                    let sigma = -self.samples[1..].iter().find(|s| s.g != 0.0).map_or(1.0, |s| s.g.signum());
                    return Finding::Located(Crossing {
                        t: t0,
                        sigma,
                        touch: false,
                        t_pre: t0,
                        on_guard: true,
                    });
                }
                (Some(true), Pending::Contact) => return Finding::Stuck,
                (Some(false), _) => self.pending[pos] = Pending::None,
                _ => {}
            }
        }
        for k in 0..self.samples.len() - 1 {
            let (a, b) = (self.samples[k], self.samples[k + 1]);
            if b.g.is_nan() || b.g.is_infinite() {
                return self.before_not_finite(cx, dir, pos, (a, b), dense);
            }
            if let Some(sigma) = crossing_sign(dir, a.g, b.g) {
                // A `crosses` guard that bounced (its reset turned it around on zero) leaves
                // round-off of zero back towards the side it came from: that is the bounce, not a
                // crossing. (A directional guard never counts the way back as a crossing.)
                let returning = k == 0
                    && self.bounced[pos] == Some(-sigma)
                    && a.g.abs()
                        <= self.noise0[pos].max(self.noise1[pos])
                            + 4.0 * a.dg.abs() * crate::sim::spacing(a.t);
                if !returning {
                    return Finding::Bracket { a: a.t, ga: a.g, da: a.dg, b: b.t, gb: b.g, db: b.dg, sigma };
                }
            }
            // Moving towards zero and stopping within round-off of it: a touch.
            if b.extremum && allows(dir, a.g.signum()) && a.g != 0.0 && a.dg * a.g < 0.0 {
                self.guard_on_dense(cx, pos, b.t, dense);
                if b.g.abs() <= self.noise_at_x(cx, ev, b.t) {
                    let c =
                        Crossing { t: b.t, sigma: a.g.signum(), touch: true, t_pre: b.t, on_guard: false };
                    return Finding::Located(c);
                }
            }
        }
        Finding::Nothing
    }

    /// The guard is finite at `a` and not at `b`: the crossing before the boundary, if any,
    /// else where the guard stops being finite.
    fn before_not_finite<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        dir: Direction,
        pos: usize,
        (a, b): (Sample, Sample),
        dense: &I,
    ) -> Finding {
        let (mut lo, mut glo, mut hi) = (a.t, a.g, b.t);
        for _ in 0..NAN_BISECTIONS {
            let mid = 0.5 * (lo + hi);
            if !(mid > lo && mid < hi) {
                break;
            }
            let g = self.guard_on_dense(cx, pos, mid, dense);
            if let Some(sigma) = crossing_sign(dir, a.g, g) {
                return Finding::Bracket { a: a.t, ga: a.g, da: a.dg, b: mid, gb: g, db: f64::NAN, sigma };
            }
            if g.is_finite() {
                (lo, glo) = (mid, g);
            } else {
                hi = mid;
            }
        }
        let _ = glo;
        Finding::NotFinite { t: hi }
    }

    /// Chooses the events that fire next from what the scan found: the earliest crossing whose
    /// condition holds on the interpolated state there, with every other crossing at the same time
    /// to the resolution of `t` (four floating-point spacings), whether its condition holds there
    /// or not (`fire_group` judges each when its turn comes, after the events before it). The earliest by its first estimate
    /// (the Hermite root of its bracket) is located first, the others only if they have crossed by
    /// then. Fills `group` (declaration order) and returns the firing time, the latest of the
    /// group's times so that every guard in it has crossed, or the earliest non-finite guard
    /// (position and time) when it comes first. Leaves `found` empty again.
    pub fn select<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        dense: &I,
    ) -> Selection {
        let (sys, info, p, evs) = (cx.sys, cx.info, cx.p, cx.events());
        self.located.clear();
        self.located_off.clear();
        self.group.clear();
        self.next_crossing = None;
        // The common case, one candidate: nothing to order.
        if let [pos] = self.candidates[..] {
            let finding = std::mem::replace(&mut self.found[pos], Finding::Nothing);
            return match finding {
                Finding::Bracket { .. } | Finding::Located(_) => {
                    self.found[pos] = finding;
                    let mut crossing = self.locate(cx, pos, dense);
                    self.found[pos] = Finding::Nothing;
                    let ev = evs[pos];
                    loop {
                        let holds = !info.events[ev].has_condition || {
                            dense.eval(crossing.t, &mut self.x);
                            sys.condition(ev, crossing.t, &self.x, p)
                        };
                        if holds {
                            self.group.push((ev, crossing));
                            return Selection::Fire(crossing.t);
                        }
                        match self.crossing_after(cx, pos, dense, crossing.t) {
                            Some(next) => crossing = next,
                            None => return Selection::Nothing,
                        }
                    }
                }
                Finding::NotFinite { t } => Selection::NotFinite { pos, t },
                Finding::Nothing | Finding::Stuck => Selection::Nothing,
            };
        }
        let mut not_finite: Option<(usize, f64)> = None;
        // Each candidate's first estimate, once.
        self.estimates.clear();
        for &pos in &self.candidates {
            let estimate = match self.found[pos] {
                Finding::Bracket { a, ga, da, b, gb, db, .. } => {
                    // A guard on zero at the bracket's end (a breakpoint landed on) is the root.
                    if gb == 0.0 {
                        b
                    } else {
                        hermite_root(a, ga, da, b, gb, db).unwrap_or(0.5 * (a + b))
                    }
                }
                Finding::Located(c) => c.t,
                Finding::NotFinite { t } => {
                    if not_finite.is_none_or(|(_, tn)| t < tn) {
                        not_finite = Some((pos, t));
                    }
                    f64::NAN
                }
                Finding::Nothing | Finding::Stuck => f64::NAN,
            };
            self.estimates.push(estimate);
        }
        loop {
            let best = (0..self.candidates.len())
                .filter(|&c| !self.estimates[c].is_nan())
                .min_by(|&a, &b| self.estimates[a].total_cmp(&self.estimates[b]));
            let Some(best) = best else { break };
            self.estimates[best] = f64::NAN;
            let pos = self.candidates[best];
            let crossing = self.locate(cx, pos, dense);
            let ev = evs[pos];
            let holds = !info.events[ev].has_condition || {
                dense.eval(crossing.t, &mut self.x);
                sys.condition(ev, crossing.t, &self.x, p)
            };
            if !holds {
                // Not the instant's first event; it may still join a group whose earlier events
                // make its condition true (judged when its turn comes in `fire_group`). Its next
                // crossing in the step is a candidate of its own.
                self.located_off.push((pos, crossing));
                if let Some(next) = self.crossing_after(cx, pos, dense, crossing.t) {
                    self.found[pos] = Finding::Located(next);
                    self.estimates[best] = next.t;
                }
                continue;
            }
            self.located.push((pos, crossing));
            let resolution = 4.0 * (crossing.t.abs().next_up() - crossing.t.abs());
            // Every bracket left that has crossed by this time is located too (it may be
            // earlier, its estimate notwithstanding); the others cross later and wait.
            let others = (0..self.candidates.len()).any(|c| {
                !self.estimates[c].is_nan()
                    && matches!(self.found[self.candidates[c]], Finding::Bracket { .. })
            });
            if others {
                self.guards_on_dense(cx, crossing.t, dense);
            }
            for c in 0..self.candidates.len() {
                if self.estimates[c].is_nan() {
                    continue;
                }
                let other = self.candidates[c];
                match self.found[other] {
                    Finding::Bracket { a, ga, da, sigma, .. }
                        if a < crossing.t && sigma * self.gtmp[other] <= 0.0 =>
                    {
                        let gb = self.gtmp[other];
                        self.found[other] =
                            Finding::Bracket { a, ga, da, b: crossing.t, gb, db: f64::NAN, sigma };
                    }
                    // A bracket that ends by this time (to the resolution of a group) has crossed
                    // by then, whatever its guard does after (a dip below zero and back): it is
                    // located in its turn.
                    Finding::Bracket { b, .. } if b <= crossing.t + resolution => {}
                    Finding::Located(c) if c.t <= crossing.t => {}
                    _ => {
                        // It crosses later: remembered as the next crossing's estimate.
                        let later = self.estimates[c];
                        self.next_crossing = Some(self.next_crossing.map_or(later, |t: f64| t.min(later)));
                        self.estimates[c] = f64::NAN;
                    }
                }
            }
        }
        for &pos in &self.candidates {
            self.found[pos] = Finding::Nothing;
        }
        let Some(t_min) = self.located.iter().map(|(_, c)| c.t).reduce(f64::min) else {
            return match not_finite {
                Some((pos, t)) => Selection::NotFinite { pos, t },
                None => Selection::Nothing,
            };
        };
        if let Some((pos, t)) = not_finite {
            if t <= t_min {
                return Selection::NotFinite { pos, t };
            }
        }
        let resolution = 4.0 * (t_min.next_up() - t_min);
        let mut t_fire = t_min;
        // Crossings whose condition is false before the instant join its group too: an event
        // before them in the group may make it true.
        self.located.extend(self.located_off.drain(..).filter(|(_, c)| c.t >= t_min - resolution));
        self.located.sort_by_key(|&(pos, _)| pos);
        for &(pos, c) in &self.located {
            if c.t <= t_min + resolution {
                self.group.push((evs[pos], c));
                t_fire = t_fire.max(c.t);
            }
        }
        Selection::Fire(t_fire)
    }

    /// Locates the crossing of the guard at `pos` found by the scan.
    fn locate<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        pos: usize,
        dense: &I,
    ) -> Crossing {
        match self.found[pos] {
            Finding::Located(c) => c,
            Finding::Bracket { a, ga, da, b, gb, db, sigma } => {
                let first = hermite_root(a, ga, da, b, gb, db);
                let (t_pre, t) =
                    illinois(a, ga, b, gb, sigma, first, |t| self.guard_on_dense(cx, pos, t, dense));
                Crossing { t, sigma, touch: false, t_pre, on_guard: false }
            }
            Finding::Nothing | Finding::NotFinite { .. } | Finding::Stuck => {
                unreachable!("only brackets and located crossings are selected")
            }
        }
    }

    /// The earliest flow switch (implicit event) the scan found crossing in the step, located on
    /// `dense` (its position and crossing; the located crossings are kept for `select`).
    pub fn earliest_switch<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        dense: &I,
    ) -> Option<(usize, Crossing)> {
        let (info, evs) = (cx.info, cx.events());
        let mut earliest: Option<(usize, Crossing)> = None;
        for c in 0..self.candidates.len() {
            let pos = self.candidates[c];
            if !info.events[evs[pos]].implicit
                || !matches!(self.found[pos], Finding::Bracket { .. } | Finding::Located(_))
            {
                continue;
            }
            let crossing = self.locate(cx, pos, dense);
            self.found[pos] = Finding::Located(crossing);
            if earliest.is_none_or(|(_, c)| crossing.t_pre < c.t_pre) {
                earliest = Some((pos, crossing));
            }
        }
        earliest
    }

    /// The earliest stage of the last attempt (from `t0`, of length `h`) at which a flow switch
    /// of the mode was not strictly on the side of zero the step started on: the stage may have
    /// evaluated the flow's other branch, and its error is in the whole step's polynomial. (The
    /// dense output may show no crossing: a stage's state is not the dense output's, and a step
    /// that lands on a switch puts its last stages on it.) Returns the switch's position, its
    /// starting side and the time to land before instead: the stage's time less twice what the
    /// stage's guard value strays from the dense output's there, over the guard's speed.
    pub fn stray_stage<S: HybridSystem + ?Sized, St: Stepper, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        stepper: &St,
        dense: &I,
        t0: f64,
        h: f64,
    ) -> Option<(usize, f64, f64)> {
        let evs = cx.events();
        let is_switch = |ev: usize| Self::is_switch(cx, ev);
        if !evs.iter().any(|&ev| is_switch(ev)) {
            return None;
        }
        // Each switch's side over the step: its start's, or its end's when the start is on it, or
        // (both ends on switches) the middle's on the dense output.
        for (pos, &ev) in evs.iter().enumerate() {
            let side = if !is_switch(ev) || self.crosses_at_start(cx, pos) {
                0.0
            } else if self.g0[pos].abs() > self.noise_at(cx, 0, pos).0 {
                self.g0[pos].signum()
            } else if self.g1[pos].abs() > self.noise_at(cx, 1, pos).0 {
                self.g1[pos].signum()
            } else {
                let g = self.guard_on_dense(cx, pos, t0 + 0.5 * h, dense);
                if g.is_finite() && g != 0.0 {
                    g.signum()
                } else {
                    0.0
                }
            };
            self.sides[pos] = side;
        }
        let mut first: Option<(f64, usize, f64)> = None;
        let (sides, values) = (&self.sides, &mut self.gtmp);
        stepper.visit_stage_states(|c, y| {
            let t = t0 + c * h;
            if first.is_some_and(|(tf, _, _)| tf <= t) {
                return;
            }
            cx.eval(t, y, values);
            for (pos, &side) in sides.iter().enumerate() {
                if side != 0.0 && side * values[pos] <= 0.0 || values[pos].is_nan() {
                    first = Some((t, pos, values[pos]));
                    break;
                }
            }
        });
        let (t, pos, g_stage) = first?;
        let ev = evs[pos];
        let g_dense = self.guard_on_dense(cx, pos, t, dense);
        let speed = self.speed_on_dense(cx, ev, t, dense).abs();
        let noise = self.noise_at(cx, 0, pos).0.max(self.noise_at(cx, 1, pos).0);
        let spacing = t.abs().next_up() - t.abs();
        let margin = 2.0 * ((g_stage - g_dense).abs() + noise) / speed + 16.0 * spacing;
        let land = if margin.is_finite() && t - margin > t0 { t - margin } else { t0 + 0.5 * (t - t0) };
        Some((pos, self.sides[pos], land))
    }

    /// Whether the guard at `pos` is on zero to round-off at the step's start and the scan found
    /// it crossing in the step: it crosses at the start (rule 5), where no retry can land before.
    pub fn crosses_at_start<S: HybridSystem + ?Sized>(&mut self, cx: &Guards<S>, pos: usize) -> bool {
        matches!(self.found[pos], Finding::Bracket { .. } | Finding::Located(_))
            && self.g0[pos].abs() <= self.noise_at(cx, 0, pos).0
    }

    /// Drops what the scan found (the step is retried).
    pub fn forget_findings(&mut self) {
        for &pos in &self.candidates {
            self.found[pos] = Finding::Nothing;
        }
    }

    /// The position of a contact found stuck by the scan, if any.
    pub fn stuck(&self) -> Option<usize> {
        self.candidates.iter().copied().find(|&pos| self.found[pos] == Finding::Stuck)
    }
}

/// What [`Detector::select`] chose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Selection {
    Nothing,
    /// The events in `group` fire at this time.
    Fire(f64),
    /// The guard at this position stops being finite at `t`, before any crossing.
    NotFinite {
        pos: usize,
        t: f64,
    },
}

pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crossing_signs_follow_direction() {
        assert_eq!(crossing_sign(Direction::Falling, 1.0, 0.0), Some(1.0));
        assert_eq!(crossing_sign(Direction::Falling, 0.0, -1.0), None);
        assert_eq!(crossing_sign(Direction::Rising, -1.0, 0.0), Some(-1.0));
        assert_eq!(crossing_sign(Direction::Rising, 1.0, -1.0), None);
        assert_eq!(crossing_sign(Direction::Either, 1.0, -1.0), Some(1.0));
        assert_eq!(crossing_sign(Direction::Either, -1.0, 2.0), Some(-1.0));
    }

    #[test]
    fn round_off_is_per_component() {
        // An unrelated state of 1e10 the guard does not read (g_x = 0 there) adds nothing.
        assert_eq!(round_off(&[1.0, 0.0], &[1e-6, 1e10], 0.0, 0.0), 16.0 * EPS * 1e-6);
    }

    #[test]
    fn a_guard_on_zero_moves_across_only_with_a_clear_speed_towards_its_crossed_side() {
        assert_eq!(moves_across(Direction::Rising, 1.0, 1e-15), Some(-1.0));
        assert_eq!(moves_across(Direction::Rising, -1.0, 1e-15), None);
        assert_eq!(moves_across(Direction::Falling, -1e-20, 1e-15), None);
        assert_eq!(moves_across(Direction::Either, 2.0, 0.0), Some(-1.0));
    }
}
