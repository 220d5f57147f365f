//! Stage 5 (sim): event detection inside one accepted step and root finding on the dense output.
//! Knows the `HybridSystem` guard functions and the interpolant; knows nothing of resets,
//! sensitivities' jumps or the step loop.
//!
//! Detection for every event of the current mode, given guard values `g0`, `g1` and guard speeds
//! `g' = g_x f + g_t` at the step ends:
//! - if `g'` changes sign, the guard has an extremum inside; it is located as the root of the
//!   guard's derivative along the interpolant (`g_x P'(t) + g_t`), so a guard that crosses and
//!   comes back within one step (a short hop) is still seen;
//! - the points `t0 [, t_ext], t1` are scanned in order for the first pair that goes from the
//!   pre-crossing side (strictly: `g > 0` for falling, `g < 0` for rising) to the crossed side
//!   (`g <= 0`, resp. `g >= 0`). Requiring the strict pre-crossing side is what stops an event
//!   from re-firing at the instant it fired (its guard sits at zero, or just past it) and from
//!   firing at the start when the state starts on the guard;
//! - an extremum that stops within round-off of zero on the pre-crossing side counts as touching:
//!   the event is placed at the extremum (the caller will flag it grazing);
//! - the crossing is then located by the Illinois variant of regula falsi (with a bisection
//!   safeguard) to adjacent floating-point numbers, returning the end of the final bracket that
//!   is on the crossed side.

use super::roots::{extremum_time, hermite_root, illinois};
use super::stepper::Interpolant;
use super::system::{Direction, HybridSystem, SystemInfo};

const EPS: f64 = f64::EPSILON;

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
}

pub(crate) struct Detector {
    pub g0: Vec<f64>,
    pub dg0: Vec<f64>,
    pub g1: Vec<f64>,
    pub dg1: Vec<f64>,
    /// Per position in the mode's event list.
    pub found: Vec<Option<Crossing>>,
    gtmp: Vec<f64>,
    gx: Vec<f64>,
    gp: Vec<f64>,
    x: Vec<f64>,
    dx: Vec<f64>,
    /// Events (id and crossing) that fire together at `t_fire`, in declaration order.
    pub group: Vec<(usize, Crossing)>,
    /// Per position: the pre-crossing sign of an event whose reset sent its guard back (a
    /// bounce) while the guard has not yet been strictly on that side again (see
    /// [`Detector::penetrated`]).
    bounced: Vec<Option<f64>>,
    /// Round-off size of `g1` per position.
    noise1: Vec<f64>,
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

impl Detector {
    pub fn new(info: &SystemInfo, nx: usize, m: usize) -> Detector {
        let ne = info.modes.iter().map(|md| md.events.len()).max().unwrap_or(0);
        Detector {
            g0: vec![0.0; ne],
            dg0: vec![0.0; ne],
            g1: vec![0.0; ne],
            dg1: vec![0.0; ne],
            found: vec![None; ne],
            gtmp: vec![0.0; ne],
            gx: vec![0.0; nx],
            gp: vec![0.0; m],
            x: vec![0.0; nx],
            dx: vec![0.0; nx],
            group: Vec::with_capacity(ne),
            bounced: vec![None; ne],
            noise1: vec![0.0; ne],
        }
    }

    /// Guard values and speeds at a step end `(t, x)` with flow `f` into `g0`/`dg0` (`end`
    /// false) or `g1`/`dg1` (`end` true).
    #[allow(clippy::too_many_arguments)]
    pub fn eval_point<S: HybridSystem + ?Sized>(
        &mut self,
        sys: &S,
        info: &SystemInfo,
        mode: usize,
        t: f64,
        x: &[f64],
        f: &[f64],
        p: &[f64],
        end: bool,
    ) {
        let evs = &info.modes[mode].events;
        let ne = evs.len();
        let (g, dg) = if end { (&mut self.g1, &mut self.dg1) } else { (&mut self.g0, &mut self.dg0) };
        sys.guards(mode, t, x, p, &mut g[..ne]);
        for (pos, &ev) in evs.iter().enumerate() {
            let gt = sys.guard_grad(ev, t, x, p, &mut self.gx, &mut self.gp);
            dg[pos] = dot(&self.gx, f) + gt;
            // Only a bounced event's guard is compared with its round-off (`penetrated`).
            if end && self.bounced[pos].is_some() {
                self.noise1[pos] = 16.0 * EPS * (norm(&self.gx) * norm(x) + gt.abs() * t.abs());
            }
        }
    }

    /// Forgets every bounce (at the start of a run and after every event group).
    pub fn clear_bounces(&mut self) {
        self.bounced.fill(None);
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

    /// After a step without events the end values become the next step's start values.
    pub fn advance(&mut self) {
        std::mem::swap(&mut self.g0, &mut self.g1);
        std::mem::swap(&mut self.dg0, &mut self.dg1);
    }

    /// Whether any event of the mode may cross in the step (then the dense output is needed).
    pub fn may_cross(&self, info: &SystemInfo, mode: usize) -> bool {
        info.modes[mode].events.iter().enumerate().any(|(pos, &ev)| {
            let dir = info.events[ev].direction;
            let (g0, g1) = (self.g0[pos], self.g1[pos]);
            crossing_sign(dir, g0, g1).is_some()
                || extremum_may_cross(dir, g0, g1, self.dg0[pos], self.dg1[pos])
        })
    }

    /// One guard of `mode` at an explicit state.
    pub fn guard_now<S: HybridSystem + ?Sized>(
        &mut self,
        sys: &S,
        mode: usize,
        pos: usize,
        t: f64,
        x: &[f64],
        p: &[f64],
    ) -> f64 {
        let ne = sys.info().modes[mode].events.len();
        sys.guards(mode, t, x, p, &mut self.gtmp[..ne]);
        self.gtmp[pos]
    }

    #[allow(clippy::too_many_arguments)]
    fn guard_on_dense<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        sys: &S,
        mode: usize,
        ne: usize,
        pos: usize,
        t: f64,
        dense: &I,
        p: &[f64],
    ) -> f64 {
        dense.eval(t, &mut self.x);
        sys.guards(mode, t, &self.x, p, &mut self.gtmp[..ne]);
        self.gtmp[pos]
    }

    /// Guard speed along the interpolant, `g_x P'(t) + g_t`.
    fn speed_on_dense<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        sys: &S,
        ev: usize,
        t: f64,
        dense: &I,
        p: &[f64],
    ) -> f64 {
        dense.eval(t, &mut self.x);
        dense.eval_deriv(t, &mut self.dx);
        let gt = sys.guard_grad(ev, t, &self.x, p, &mut self.gx, &mut self.gp);
        dot(&self.gx, &self.dx) + gt
    }

    /// The round-off size of the guard value at `(t, self.x)`: called right after
    /// [`Self::guard_on_dense`] at `t`, whose interpolated state is still in `self.x`.
    fn noise_at_x<S: HybridSystem + ?Sized>(&mut self, sys: &S, ev: usize, t: f64, p: &[f64]) -> f64 {
        let gt = sys.guard_grad(ev, t, &self.x, p, &mut self.gx, &mut self.gp);
        16.0 * EPS * (norm(&self.gx) * norm(&self.x) + gt.abs() * t.abs())
    }

    /// Locates the first crossing of every event of `mode` in the step `[t0, t1]` described by
    /// `dense`, into `found`.
    pub fn locate<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        sys: &S,
        info: &SystemInfo,
        mode: usize,
        dense: &I,
        p: &[f64],
    ) {
        let evs = &info.modes[mode].events;
        let ne = evs.len();
        let (t0, t1) = (dense.t0(), dense.t0() + dense.h());
        for (pos, &ev) in evs.iter().enumerate() {
            self.found[pos] = None;
            let dir = info.events[ev].direction;
            let (g0, g1) = (self.g0[pos], self.g1[pos]);
            // The extremum, when the guard speed changes sign and a crossing could hide there.
            let mut ext = None;
            if extremum_may_cross(dir, g0, g1, self.dg0[pos], self.dg1[pos]) {
                let te = extremum_time(t0, self.dg0[pos], t1, self.dg1[pos], |t| {
                    self.speed_on_dense(sys, ev, t, dense, p)
                });
                if te > t0 && te < t1 {
                    let ge = self.guard_on_dense(sys, mode, ne, pos, te, dense, p);
                    ext = Some((te, ge));
                }
            }
            // Brackets carry the guard speeds at their ends for the Hermite first estimate
            // (zero at an extremum).
            let (dg0, dg1) = (self.dg0[pos], self.dg1[pos]);
            let mut bracket = None;
            match ext {
                Some((te, ge)) => {
                    if let Some(sigma) = crossing_sign(dir, g0, ge) {
                        bracket = Some((t0, g0, dg0, te, ge, 0.0, sigma));
                    } else if allows(dir, g0.signum())
                        && g0 != 0.0
                        && self.dg0[pos] * g0 < 0.0
                        && ge.abs() <= self.noise_at_x(sys, ev, te, p)
                    {
                        // Moving towards zero and stopping within round-off of it: a touch.
                        self.found[pos] =
                            Some(Crossing { t: te, sigma: g0.signum(), touch: true, t_pre: te });
                        continue;
                    } else if let Some(sigma) = crossing_sign(dir, ge, g1) {
                        bracket = Some((te, ge, 0.0, t1, g1, dg1, sigma));
                    }
                }
                None => {
                    if let Some(sigma) = crossing_sign(dir, g0, g1) {
                        bracket = Some((t0, g0, dg0, t1, g1, dg1, sigma));
                    }
                }
            }
            if let Some((a, ga, da, b, gb, db, sigma)) = bracket {
                let first = hermite_root(a, ga, da, b, gb, db);
                let (t_pre, t) = illinois(a, ga, b, gb, sigma, first, |t| {
                    self.guard_on_dense(sys, mode, ne, pos, t, dense, p)
                });
                self.found[pos] = Some(Crossing { t, sigma, touch: false, t_pre });
            }
        }
    }

    /// Chooses the events that fire next: the earliest located crossing whose condition holds on
    /// the interpolated state there, together with every other such crossing within a few
    /// round-offs of it. Fills `group` (declaration order) and returns the firing time, the
    /// latest of the group's times so that every guard in it has crossed.
    pub fn select<S: HybridSystem + ?Sized, I: Interpolant>(
        &mut self,
        sys: &S,
        info: &SystemInfo,
        mode: usize,
        dense: &I,
        p: &[f64],
    ) -> Option<f64> {
        let evs = &info.modes[mode].events;
        let mut t_min = f64::INFINITY;
        for (pos, &ev) in evs.iter().enumerate() {
            if let Some(c) = self.found[pos] {
                let holds = !info.events[ev].has_condition || {
                    dense.eval(c.t, &mut self.x);
                    sys.condition(ev, c.t, &self.x, p)
                };
                if holds {
                    t_min = t_min.min(c.t);
                } else {
                    self.found[pos] = None;
                }
            }
        }
        if !t_min.is_finite() {
            return None;
        }
        let tol = 64.0 * EPS * (t_min.abs() + dense.h().abs());
        self.group.clear();
        let mut t_fire = t_min;
        for (pos, &ev) in evs.iter().enumerate() {
            if let Some(c) = self.found[pos] {
                if c.t <= t_min + tol {
                    self.group.push((ev, c));
                    t_fire = t_fire.max(c.t);
                } else {
                    self.found[pos] = None;
                }
            }
        }
        Some(t_fire)
    }
}

pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

pub(crate) fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
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
}
