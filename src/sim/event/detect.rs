//! Stage 5 (sim): event detection inside one accepted step, and the choice of the events that fire
//! next. Knows the `HybridSystem` guard functions, the stepper's interpolant and stage derivatives;
//! knows nothing of resets, sensitivities' jumps or the step loop. The rules it implements are
//! written down in docs/language.md ("When events fire").
//!
//! Per step, every guard of the mode is sampled: its value and speed `g' = g_x f + g_t` at both
//! ends, and
//! - for a guard affine in the time and the state, its speed at every interior stage of the step
//!   (the stage derivatives are there anyway): each sign change of the speed is an extremum of the
//!   guard, located on the dense output;
//! - for any other guard, its value and speed at two interior points of the dense output, which
//!   also check that the step resolves the guard (`check_resolution`: the step is rejected when
//!   the cubic through the end values and speeds misses them), plus the extrema between samples.
//!
//! The samples and extrema are scanned in time order for the first pair that goes from the
//! pre-crossing side (strictly: `g > 0` for falling, `g < 0` for rising) to the crossed side
//! (`g <= 0`, resp. `g >= 0`); an extremum that stops within round-off of zero coming from the
//! pre-crossing side is a touch. Only brackets are found per guard; `select` then locates the
//! earliest crossing first (Illinois regula falsi to adjacent floating-point numbers) and the
//! others only when they have crossed by then, so a step costs time linear in the number of
//! guards however many are pending in it.
//!
//! Round-off bounds are per component: `16 eps (sum_i |g_x,i x_i| + |g_t t|)` for a guard value
//! and `16 eps (sum_i |g_x,i f_i| + |g_t|)` for its speed, so a large state the guard does not
//! read changes nothing.

use super::guards::Guards;
use super::roots::{extremum_time, hermite_root, illinois};
use crate::sim::method::poly::{self, Poly};
use crate::sim::method::stepper::{Interpolant, Stepper};
use crate::sim::system::{Direction, GuardShape, HybridSystem, SystemInfo};

const EPS: f64 = f64::EPSILON;
/// The two interior sample points of a step, in units of the step, for guards that are not
/// affine: the interior nodes of four-point Gauss-Lobatto, `(5 -/+ sqrt 5) / 10`. Irrational, so
/// a periodic guard cannot hide behind a step that is a rational multiple of its period.
const INTERIOR: [f64; 2] = [0.276_393_202_250_021, 0.723_606_797_749_979];
/// A nonlinear guard is resolved by a step when the cubic through its end values and speeds
/// predicts its interior samples to within this fraction of its variation over the step.
const RESOLUTION: f64 = 0.125;
/// The cubic's largest error over a step against its error at [`INTERIOR`]: `(s (1 - s))^2` peaks
/// at 1/16 and is 0.04 there.
const ERROR_SPREAD: f64 = 1.5625;
/// Up to this many guards in a mode, a step's end is evaluated guard by guard (one gradient each
/// gives the speed and the stage speeds); above, by the speeds kernel, once for the end and once
/// per sampled stage, whatever the number of guards.
const FEW_GUARDS: usize = 4;
/// Bisection steps to the boundary where a guard stops being finite (to about 1e-9 of the step).
const NAN_BISECTIONS: usize = 30;
/// Most samples of a guard that reads only the time in one step it does not resolve
/// ([`Detector::refine_time_guard`]): 1023 halvings at most, a bound on the work of a step.
const MAX_TIME_SAMPLES: usize = 1024;

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
    /// Sign changes of an affine guard's speed over the step's stages and ends.
    speed_changes: Vec<u8>,
    /// The largest magnitude of an affine guard's speed over the step's stages and ends.
    speed_max: Vec<f64>,
    /// Nonlinear guards: values and speeds at the [`INTERIOR`] points of the step.
    interior: [(Vec<f64>, Vec<f64>); 2],
    /// Nonlinear guards the current step does not resolve (`check_resolution`): it was taken
    /// anyway, shorter than the floor of the resolution of `t`.
    unresolved: Vec<bool>,
    pub pending: Vec<Pending>,
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
    /// Sign changes of each guard's speed over the stages of the current step.
    stage_signs: Vec<SignChanges>,
    /// The positions the current step looks at closer (`mark_candidates`), and their first
    /// estimates in `select`.
    candidates: Vec<usize>,
    estimates: Vec<f64>,
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

/// Whether an extremum of the guard inside the step (its speed goes from `dg0` to `dg1` with a
/// sign change) can hide a crossing that the step ends do not show. With one extremum in the
/// step, a falling crossing hides behind a minimum only when the guard starts positive, and
/// behind a maximum only when it starts and ends on the crossed side (`g <= 0`); rising is the
/// mirror image. Skipping the others spares the dense output and a root search at every apex of
/// a bouncing ball.
fn extremum_may_cross(dir: Direction, g0: f64, g1: f64, dg0: f64, dg1: f64) -> bool {
    let minimum = dg0 < 0.0 && dg1 > 0.0;
    let maximum = dg0 > 0.0 && dg1 < 0.0;
    match dir {
        Direction::Falling => (minimum && g0 > 0.0) || (maximum && g0 <= 0.0 && g1 <= 0.0),
        Direction::Rising => (maximum && g0 < 0.0) || (minimum && g0 >= 0.0 && g1 >= 0.0),
        Direction::Either => minimum || maximum,
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

/// Counts the sign changes of a sequence pushed value by value, zeros (and NaN) skipped.
#[derive(Clone, Copy, Debug, Default)]
struct SignChanges {
    last: f64,
    changes: u8,
    /// The largest magnitude pushed.
    max_abs: f64,
}

impl SignChanges {
    fn new(first: f64) -> SignChanges {
        let mut counter = SignChanges { last: 0.0, changes: 0, max_abs: 0.0 };
        counter.push(first);
        counter
    }

    fn push(&mut self, v: f64) {
        self.max_abs = self.max_abs.max(v.abs());
        if v != 0.0 && !v.is_nan() {
            if self.last != 0.0 && v.signum() != self.last.signum() {
                self.changes = self.changes.saturating_add(1);
            }
            self.last = v;
        }
    }
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
            speed_changes: vec![0; ne],
            interior: [(per_event(), per_event()), (per_event(), per_event())],
            unresolved: vec![false; ne],
            pending: vec![Pending::None; ne],
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
            stage_signs: vec![SignChanges::default(); ne],
            speed_max: vec![0.0; ne],
            candidates: Vec::with_capacity(ne),
            estimates: Vec::with_capacity(ne),
            next_crossing: None,
        }
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
        let (noise, speed_noise) = match end {
            0 => (&mut self.noise0, &mut self.speed_noise0),
            _ => (&mut self.noise1, &mut self.speed_noise1),
        };
        if noise[pos].is_nan() {
            let ev = cx.events()[pos];
            let (t, x, f) = (self.at[end].0, &self.at[end].1, &self.at[end].2);
            let gt = cx.grad(ev, t, x, &mut self.gx, &mut self.gp);
            noise[pos] = round_off(&self.gx, x, gt, t);
            speed_noise[pos] = round_off(&self.gx, f, gt, 1.0);
        }
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
            let located = 4.0 * speed.abs() * (t.abs().next_up() - t.abs());
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
    /// the round-off bounds of the guards whose closeness to zero this step judges; for affine
    /// guards also the sign changes of their speed over the step's stages.
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
        let mut any_affine = false;
        for (pos, &ev) in evs.iter().enumerate() {
            let shape = info.events[ev].guard;
            any_affine |= shape == GuardShape::Affine;
            // The round-off bounds matter only where a guard's closeness to zero is judged.
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
            self.speed_changes[pos] = 0;
        }
        if !any_affine {
            return;
        }
        // Affine guards: `g_x` and `g_t` are constants, so their speed at a stage is the speeds
        // kernel at the stage's derivative (the state it is given does not matter to them).
        for pos in 0..ne {
            self.stage_signs[pos] = SignChanges::new(self.dg0[pos]);
        }
        let (signs, speeds) = (&mut self.stage_signs, &mut self.gtmp);
        stepper.visit_interior(|_, k| {
            sys.guard_speeds(mode, t, x, &k[..n], p, &mut speeds[..ne]);
            for (sign, &speed) in signs.iter_mut().zip(&speeds[..ne]) {
                sign.push(speed);
            }
        });
        for (pos, &ev) in evs.iter().enumerate() {
            if info.events[ev].guard == GuardShape::Affine {
                let mut counter = self.stage_signs[pos];
                counter.push(self.dg1[pos]);
                self.speed_changes[pos] = counter.changes;
                self.speed_max[pos] = counter.max_abs;
            }
        }
    }

    /// [`Self::eval_end`] for a mode with few guards, guard by guard: one gradient evaluation per
    /// guard gives its speed, its round-off bounds and (affine) its speeds at the stages as dot
    /// products, cheaper there than the speeds kernel called once per stage.
    fn eval_end_each<S: HybridSystem + ?Sized, St: Stepper>(&mut self, cx: &Guards<S>, t: f64, stepper: &St) {
        let n = cx.n;
        let (x, f) = (&stepper.end_state()[..n], &stepper.end_derivative()[..n]);
        for (pos, &ev) in cx.events().iter().enumerate() {
            let gt = cx.grad(ev, t, x, &mut self.gx, &mut self.gp);
            let speed = dot(&self.gx, f) + gt;
            self.dg1[pos] = speed;
            let shape = cx.info.events[ev].guard;
            if shape == GuardShape::Nonlinear
                || self.pending[pos] != Pending::None
                || self.bounced[pos].is_some()
            {
                self.noise1[pos] = round_off(&self.gx, x, gt, t);
                self.speed_noise1[pos] = round_off(&self.gx, f, gt, 1.0);
            } else {
                self.noise1[pos] = f64::NAN;
                self.speed_noise1[pos] = f64::NAN;
            }
            (self.speed_changes[pos], self.speed_max[pos]) = if shape == GuardShape::Affine {
                let mut counter = SignChanges::new(self.dg0[pos]);
                let gx = &self.gx;
                stepper.visit_interior(|_, k| {
                    counter.push(gx.iter().zip(k).fold(gt, |acc, (a, b)| acc + a * b))
                });
                counter.push(speed);
                (counter.changes, counter.max_abs)
            } else {
                (0, 0.0)
            };
        }
    }

    /// Forgets every bounce and pending decision (at the start of a run and after every instant).
    pub fn clear_bounces(&mut self) {
        self.bounced.fill(None);
        self.pending.fill(Pending::None);
    }

    /// Records that the event at `pos` (in the current mode) just fired from the side of sign
    /// `sigma` and its reset turned the guard speed around from `speed_before`, when the guard
    /// is not yet strictly back on that side (`g0`, `dg0` hold the post-event values).
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
            if *pending != Pending::None && self.g0[pos].abs() > self.noise0[pos] {
                *pending = Pending::None;
            }
        }
    }

    /// Marks the guards whose step needs a closer look (`candidates`): a guard that changes sign,
    /// may hide a crossing behind an extremum, is not affine, is pending or is not finite. Returns
    /// whether there is any (then the step needs its dense output for the events).
    pub fn mark_candidates<S: HybridSystem + ?Sized>(&mut self, cx: &Guards<S>) -> bool {
        self.candidates.clear();
        for (pos, &ev) in cx.events().iter().enumerate() {
            let einfo = &cx.info.events[ev];
            let (g0, g1) = (self.g0[pos], self.g1[pos]);
            let look = einfo.guard == GuardShape::Nonlinear
                || !g1.is_finite()
                || self.pending[pos] != Pending::None
                || self.speed_changes[pos] >= 2
                || crossing_sign(einfo.direction, g0, g1).is_some()
                || (einfo.guard == GuardShape::Affine && self.may_come_near(pos))
                || extremum_may_cross(einfo.direction, g0, g1, self.dg0[pos], self.dg1[pos]);
            if look {
                self.candidates.push(pos);
            }
        }
        !self.candidates.is_empty()
    }

    /// How well the step `[t0, t0 + h]` of `dense` resolves the guards of the mode that are not
    /// affine (see the module documentation), sampling them at the interior points for the scan:
    /// whether all are resolved, and the factor the step size may change by for the least
    /// resolved one (the guards take part in step-size control).
    pub fn check_resolution<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        dense: &I,
    ) -> GuardControl {
        let (sys, info, mode, p) = (cx.sys, cx.info, cx.mode, cx.p);
        let mut control = GuardControl { resolved: true, factor: f64::INFINITY };
        let evs = cx.events();
        if !evs.iter().any(|&ev| info.events[ev].guard == GuardShape::Nonlinear) {
            return control;
        }
        let ne = evs.len();
        let (t0, h) = (dense.t0(), dense.h());
        for (k, &s) in INTERIOR.iter().enumerate() {
            let t = t0 + s * h;
            dense.eval(t, &mut self.x);
            sys.guards(mode, t, &self.x, p, &mut self.interior[k].0[..ne]);
            dense.eval_deriv(t, &mut self.dx);
            for (pos, &ev) in evs.iter().enumerate() {
                if info.events[ev].guard == GuardShape::Nonlinear {
                    let gt = sys.guard_grad(ev, t, &self.x, p, &mut self.gx, &mut self.gp);
                    self.interior[k].1[pos] = dot(&self.gx, &self.dx) + gt;
                }
            }
        }
        for (pos, &ev) in evs.iter().enumerate() {
            if info.events[ev].guard != GuardShape::Nonlinear {
                continue;
            }
            let (g0, g1) = (self.g0[pos], self.g1[pos]);
            let (m0, m1) = (h * self.dg0[pos], h * self.dg1[pos]);
            let inner = [self.interior[0].0[pos], self.interior[1].0[pos]];
            self.unresolved[pos] = false;
            if !(g0.is_finite() && g1.is_finite() && m0.is_finite() && m1.is_finite())
                || inner.iter().any(|g| !g.is_finite())
            {
                // Left to the scan, which finds where the guard stops being finite.
                continue;
            }
            let cubic = |s: f64| {
                let (c2, c3) = (3.0 * (g1 - g0) - 2.0 * m0 - m1, 2.0 * (g0 - g1) + m0 + m1);
                ((c3 * s + c2) * s + m0) * s + g0
            };
            let slope = |s: f64| {
                let (c2, c3) = (3.0 * (g1 - g0) - 2.0 * m0 - m1, 2.0 * (g0 - g1) + m0 + m1);
                (3.0 * c3 * s + 2.0 * c2) * s + m0
            };
            let speeds = [h * self.interior[0].1[pos], h * self.interior[1].1[pos]];
            // Values and speeds at the interior points: a guard oscillating within the step can
            // match the cubic's values at two points by chance (a chirp lost 10 of 31 crossings
            // that way), hardly its values and speeds at both. A speed miss of `d` (per unit of
            // `s`) is a value miss of about `d / 4` over the step.
            let miss = INTERIOR
                .iter()
                .zip(inner.iter().zip(speeds))
                .map(|(&s, (g, m))| (g - cubic(s)).abs().max(0.25 * (m - slope(s)).abs()))
                .fold(0.0, f64::max);
            let variation = inner
                .iter()
                .chain([&g1])
                .map(|g| (g - g0).abs())
                .chain(speeds.iter().map(|m| m.abs()))
                .fold(m0.abs().max(m1.abs()), f64::max);
            let allowed = RESOLUTION * variation + self.noise0[pos].max(self.noise1[pos]);
            let miss = ERROR_SPREAD * miss;
            if miss > allowed {
                control.resolved = false;
                self.unresolved[pos] = true;
            }
            // The miss shrinks like h^4 and the variation like h once the step resolves the
            // guard's shape: the cube root of their ratio; far from that, a quarter.
            let factor = if miss > 4.0 * allowed { 0.25 } else { 0.9 * (allowed / miss).cbrt() };
            control.factor = control.factor.min(factor);
        }
        control
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
        dense.eval(t, &mut self.x);
        dense.eval_deriv(t, &mut self.dx);
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
        for c in 0..self.candidates.len() {
            let pos = self.candidates[c];
            let dir = cx.info.events[cx.events()[pos]].direction;
            self.build_samples(cx, dense, pos);
            self.found[pos] = self.scan_samples(cx, dir, pos, dense);
        }
    }

    /// The samples of the guard at `pos` along the step, in time order, for `scan_samples`: its
    /// ends, and what its shape needs between them so that each piece holds at most one sign
    /// change.
    fn build_samples<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        dense: &I,
        pos: usize,
    ) {
        let (info, evs) = (cx.info, cx.events());
        let (t0, t1) = (dense.t0(), self.step_end);
        {
            let ev = evs[pos];
            let einfo = &info.events[ev];
            let dir = einfo.direction;
            let (g0, g1, dg0, dg1) = (self.g0[pos], self.g1[pos], self.dg0[pos], self.dg1[pos]);
            self.samples.clear();
            self.samples.push(Sample { t: t0, g: g0, dg: dg0, extremum: false });
            match einfo.guard {
                GuardShape::Nonlinear => {
                    for (k, &s) in INTERIOR.iter().enumerate() {
                        let (g, dg) = (self.interior[k].0[pos], self.interior[k].1[pos]);
                        self.samples.push(Sample { t: t0 + s * dense.h(), g, dg, extremum: false });
                    }
                    self.samples.push(Sample { t: t1, g: g1, dg: dg1, extremum: false });
                    if self.unresolved[pos] && einfo.time_only {
                        self.refine_time_guard(cx, pos, dense);
                    }
                    self.add_extrema_between_samples(cx, pos, dense);
                }
                GuardShape::Affine if self.speed_changes[pos] >= 2 || self.may_come_near(pos) => {
                    // Along the dense output an affine guard is a polynomial of the interpolant's
                    // degree, known exactly from that many samples plus one: its extrema in the
                    // step (the roots of its derivative) split the step into monotone pieces,
                    // each with at most one crossing. The stage speeds alone are those of the
                    // stages' own low-order states, not samples of the solution: they showed
                    // sign changes where there were none and missed two that were there (a
                    // state polynomial in `t`, integrated exactly in long steps).
                    self.extrema_on_dense(cx, pos, self.x.len(), dense);
                    self.samples.push(Sample { t: t1, g: g1, dg: dg1, extremum: false });
                    self.samples.sort_by(|a, b| a.t.total_cmp(&b.t));
                }
                _ => {
                    // At most one extremum, where the end speeds differ: searched only when it
                    // can hide a crossing.
                    if extremum_may_cross(dir, g0, g1, dg0, dg1) {
                        let te = extremum_time(t0, dg0, t1, dg1, |t| self.speed_on_dense(cx, ev, t, dense));
                        if te > t0 && te < t1 {
                            let ge = self.guard_on_dense(cx, pos, te, dense);
                            self.samples.push(Sample { t: te, g: ge, dg: 0.0, extremum: true });
                        }
                    }
                    self.samples.push(Sample { t: t1, g: g1, dg: dg1, extremum: false });
                }
            }
        }
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
        self.build_samples(cx, dense, pos);
        let g = self.guard_on_dense(cx, pos, after, dense);
        let dg = self.speed_on_dense(cx, ev, after, dense);
        self.samples.retain(|s| s.t > after);
        self.samples.insert(0, Sample { t: after, g, dg, extremum: false });
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

    /// A guard that reads only the time, in a step that does not resolve it (taken anyway, being
    /// shorter than the floor `1e-9 max(|t|, 1)`, long late in time: 1e-3 at `t = 1e6`): its
    /// samples in time order are refined where they do not resolve it, since it is known exactly
    /// at any time (the dense output's state is not read). Each piece between samples is halved
    /// until the cubic through its ends' values and speeds predicts the value and speed at its
    /// midpoint to within [`RESOLUTION`] of its variation, as `check_resolution` asks of a step,
    /// up to [`MAX_TIME_SAMPLES`]. A chirp at `t0 = 1e6` had two crossings `2e-4` apart inside
    /// one such step of `6e-4`, between samples that did not show them.
    fn refine_time_guard<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        pos: usize,
        dense: &I,
    ) {
        let ev = cx.events()[pos];
        let noise = self.noise0[pos].max(self.noise1[pos]);
        let mut k = 0;
        while k + 1 < self.samples.len() && self.samples.len() < MAX_TIME_SAMPLES {
            let (a, b) = (self.samples[k], self.samples[k + 1]);
            let w = b.t - a.t;
            let mid = a.t + 0.5 * w;
            // The Hermite cubic of the piece at its midpoint: value and speed.
            let predicted = 0.5 * (a.g + b.g) + 0.125 * w * (a.dg - b.dg);
            let predicted_speed = 1.5 * (b.g - a.g) / w - 0.25 * (a.dg + b.dg);
            if !(mid > a.t && mid < b.t && predicted.is_finite() && predicted_speed.is_finite()) {
                k += 1;
                continue;
            }
            let g = self.guard_on_dense(cx, pos, mid, dense);
            let dg = self.speed_on_dense(cx, ev, mid, dense);
            self.samples.insert(k + 1, Sample { t: mid, g, dg, extremum: false });
            if !(g.is_finite() && dg.is_finite()) {
                // Left to the scan, which finds where the guard stops being finite.
                return;
            }
            let miss = (g - predicted).abs().max(0.25 * w * (dg - predicted_speed).abs());
            let variation =
                [(b.g - a.g).abs(), (g - a.g).abs(), w * a.dg.abs(), w * b.dg.abs(), w * dg.abs()]
                    .into_iter()
                    .fold(0.0, f64::max);
            if miss <= RESOLUTION * variation + noise {
                // Resolved: both halves stand.
                k += 2;
            }
        }
    }

    /// For a nonlinear guard: the extrema between consecutive samples whose speeds differ in sign.
    fn add_extrema_between_samples<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        pos: usize,
        dense: &I,
    ) {
        let ev = cx.events()[pos];
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
            let decided = self.samples[1..]
                .iter()
                .find_map(|s| clear_side(dir, s.g, self.noise0[pos].max(self.noise1[pos])));
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
                            + 4.0 * a.dg.abs() * (a.t.abs().next_up() - a.t.abs());
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
                    hermite_root(a, ga, da, b, gb, db).unwrap_or(0.5 * (a + b))
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

    /// Whether an affine guard, at the step's ends no farther from zero than twice what it moves
    /// over the step (the step times the largest speed at the ends and stages, or its change),
    /// may reach zero inside it: then its dense polynomial is examined exactly. Farther away, a
    /// crossing would need an excursion of more than twice what the speeds show.
    fn may_come_near(&self, pos: usize) -> bool {
        let (g0, g1) = (self.g0[pos], self.g1[pos]);
        let h = self.span.1 - self.span.0;
        let speed = self.speed_max[pos].max(self.dg0[pos].abs()).max(self.dg1[pos].abs());
        let reach = (h * speed).max((g1 - g0).abs());
        g0.abs().min(g1.abs()) <= 2.0 * reach
    }

    /// Adds the extrema of the affine guard at `pos` (event `ev`) inside the step to `samples`.
    /// Along the dense output the guard is `g0 + g_x (P(s) - P(0)) + g_t h s` with constant `g_x`
    /// and `g_t`: a polynomial of the interpolant's degree, which the interpolant gives in the
    /// power basis (`Interpolant::linear_form`). Each guard costs one gradient call and that
    /// combination: a mode with 10,000 guards evaluates none of the others. The roots of its
    /// derivative in the step (`Poly::roots_01`) are its extrema, where the guard is evaluated on
    /// the dense output itself.
    fn extrema_on_dense<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        cx: &Guards<S>,
        pos: usize,
        n: usize,
        dense: &I,
    ) {
        let ev = cx.events()[pos];
        let (t0, h) = (dense.t0(), dense.h());
        // The start of the step on the interpolant, once: the gradient's argument (constant for
        // an affine guard) and the base of every extremum's value below.
        dense.eval(t0, &mut self.dx[..n]);
        let gt = cx.grad(ev, t0, &self.dx, &mut self.gx, &mut self.gp);
        let mut coef = [0.0; poly::CAP];
        let len = dense.linear_form(&self.gx, &mut coef);
        let mut guard = Poly::from_coefficients(&coef, len);
        guard.add_linear(gt * h);
        let speed = guard.derivative();
        let start = self.g0[pos];
        for &s in speed.roots_01().as_slice() {
            let te = t0 + s * h;
            if te > t0 && te < t0 + h {
                // The value from the dense output itself, not from the power basis: that sums
                // terms of the guard's size over the whole step, and a bounce a billionth of a
                // long step wide has its apex far below their round-off.
                dense.eval(te, &mut self.x[..n]);
                let moved: f64 =
                    self.gx.iter().zip(self.x.iter().zip(&self.dx)).map(|(g, (x, b))| g * (x - b)).sum();
                let g = start + moved + gt * (te - t0);
                if g.is_finite() {
                    self.samples.push(Sample { t: te, g, dg: speed.eval(s) / h, extremum: true });
                }
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

/// How a step resolves the nonlinear guards: [`Detector::check_resolution`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct GuardControl {
    pub resolved: bool,
    /// The factor the step size may change by (infinite when no guard limits it).
    pub factor: f64,
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
    fn only_extrema_that_can_hide_a_crossing_are_searched() {
        use Direction::*;
        // The apex of a falling ball above a floor (maximum, starts positive): nothing to find.
        assert!(!extremum_may_cross(Falling, 1.0, 0.5, 2.0, -1.0));
        // A dip towards the floor (minimum, starts positive): may touch or cross.
        assert!(extremum_may_cross(Falling, 1.0, 0.5, -2.0, 1.0));
        // Starting on the crossed side, rising above zero and falling back: a hidden crossing.
        assert!(extremum_may_cross(Falling, -0.1, -0.2, 2.0, -1.0));
        assert!(!extremum_may_cross(Falling, -0.1, 0.2, 2.0, -1.0));
        // Mirror images for rising guards, and no sign change means no extremum.
        assert!(extremum_may_cross(Rising, -1.0, -0.5, 2.0, -1.0));
        assert!(!extremum_may_cross(Rising, -1.0, -0.5, -2.0, 1.0));
        assert!(extremum_may_cross(Rising, 0.1, 0.2, -2.0, 1.0));
        assert!(extremum_may_cross(Either, 1.0, 0.5, 2.0, -1.0));
        assert!(!extremum_may_cross(Either, 1.0, 0.5, 2.0, 1.0));
    }

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
    fn sign_changes_skip_zeros_and_count_each_change() {
        let count = |values: &[f64]| {
            let mut counter = SignChanges::new(values[0]);
            values[1..].iter().for_each(|&v| counter.push(v));
            counter.changes
        };
        assert_eq!(count(&[0.0, -1.0, -2.0]), 0);
        assert_eq!(count(&[1.0, 0.0, -1.0, 2.0]), 2);
        assert_eq!(count(&[1.0, f64::NAN, 1.0]), 0);
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
