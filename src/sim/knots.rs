//! Stage 5 (sim): input knots (`pwl`, `pwc` read by a mode's flows), the times where a flow kinks
//! or jumps that are known when a run starts. Their times are computed once from the parameters
//! and queued per mode as breakpoints (`breakpoints.rs`); a step ends exactly on the next one
//! (the integrator reads the flow on the knot's earlier side at the step's end, `ModeRhs`'s
//! ceiling), and the next step starts on its later side. At a `pwc` knot the sensitivities jump
//! by `(f- - f+) dt_k/dp`, the flow's jump times the knot's motion `dt_k/dp = -s_p / s_t` (`s`
//! the knot position); a `pwl` knot only kinks and nothing jumps. So a knot costs what a step
//! end costs: no guard is evaluated for it, no crossing located, no step rejected.
//!
//! Knows the `HybridSystem` functions and the breakpoints; knows nothing of steppers or events.

use super::breakpoints::Breakpoints;
use super::event::jump::same;
use super::system::HybridSystem;

const EPS: f64 = f64::EPSILON;

/// The first floating-point time at which a knot at position `k` is on its later side, for a
/// knot position `s(t)` (monotone in `t`) rising or falling: `s(t) >= k` when it rises, `s(t) < k`
/// when it falls (a window with `t1 < t0`, whose knots the run meets from above: at `s = k`
/// exactly the input still reads the segment the run comes from, as the value computes it).
/// Searched from `estimate` outwards by doubling distances, then by bisection, so that the step
/// ending just before it and the value agree on the side of the knot to the last bit. `None`
/// when no finite time is on the later side after one that is not.
pub(crate) fn first_time_past(s: impl Fn(f64) -> f64, k: f64, rising: bool, estimate: f64) -> Option<f64> {
    let later = |t: f64| if rising { s(t) >= k } else { s(t) < k };
    if !estimate.is_finite() {
        return None;
    }
    // Zero only where subnormals flush (a run holds IEEE arithmetic, `fp_mode.rs`; the search
    // is bounded whatever the mode all the same).
    let spacing = |t: f64| (t.abs().next_up() - t.abs()).max(f64::MIN_POSITIVE);
    // A bracket `lo` (earlier side) < `hi` (later side): the doubling reaches an infinite time
    // within SEARCH_STEPS from any start, as the bisection resolves any finite bracket.
    let (mut lo, mut hi) = if later(estimate) {
        let mut gap = spacing(estimate);
        let mut bracket = None;
        for _ in 0..SEARCH_STEPS {
            let lo = estimate - gap;
            if !lo.is_finite() {
                return None;
            }
            if !later(lo) {
                bracket = Some((lo, estimate));
                break;
            }
            gap *= 2.0;
        }
        bracket?
    } else {
        let mut gap = spacing(estimate);
        let mut bracket = None;
        for _ in 0..SEARCH_STEPS {
            let hi = estimate + gap;
            if !hi.is_finite() {
                return None;
            }
            if later(hi) {
                bracket = Some((estimate, hi));
                break;
            }
            gap *= 2.0;
        }
        bracket?
    };
    for _ in 0..SEARCH_STEPS {
        if lo.next_up() >= hi {
            break;
        }
        let mid = lo + 0.5 * (hi - lo);
        let mid = if mid <= lo || mid >= hi { lo.next_up() } else { mid };
        if later(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    Some(hi)
}

/// The motion `dt_k/dp` (into `dt`, m; `sp` scratch of m) of the knots of jumping inputs of
/// `mode` among `sets`, met at `t`: their common motion, NaN for a parameter that moves them
/// apart (`Crossed::apart`). What the forward sensitivities and the adjoint's transpose of a
/// knot both read (`Knots::jump`, `adjoint::backward::knot_backward`). `Crossed::jumps` is left
/// for the caller, which knows the flow's jump.
pub(crate) fn motion<S: HybridSystem + ?Sized>(
    sys: &S,
    p: &[f64],
    mode: usize,
    t: f64,
    sets: &[(f64, u32)],
    sp: &mut [f64],
    dt: &mut [f64],
) -> Crossed {
    let info = sys.info();
    dt.fill(0.0);
    let mut crossed = Crossed::default();
    let mut first = true;
    for &(_, set) in sets {
        if !info.knots.get(set as usize).is_some_and(|k| k.jumps && k.mode == mode) {
            continue;
        }
        crossed.jumping += 1;
        crossed.set.get_or_insert(set);
        let rate = sys.knot_position_grad(set as usize, t, p, sp);
        for (d, &sp) in dt.iter_mut().zip(sp.iter()) {
            // `dt_k/dp = -s_p / s_t`; a parameter that does not move the position does not
            // move the knot.
            let here = if sp == 0.0 { 0.0 } else { -sp / rate };
            if first {
                *d = here;
            } else if !same(*d, here) {
                *d = f64::NAN;
                crossed.apart = true;
            }
        }
        first = false;
    }
    crossed
}

/// More than the doublings from the least spacing to overflow (about 2,100), and than the
/// halvings from the widest finite bracket to adjacent floats.
const SEARCH_STEPS: usize = 4096;

/// What the knots of a run need: scratch for their jumps, and the knot sets that cannot be
/// timed.
#[derive(Clone, Debug)]
pub(crate) struct Knots {
    /// Per mode: a knot set of it whose position is not finite (a window with `t1 = t0`): the
    /// run stops with an error when it is in that mode.
    pub broken: Vec<Option<u32>>,
    /// The derivatives of a knot position (m).
    sp: Vec<f64>,
    /// The flow on the earlier and the later side of the knots of one instant (n).
    f_pre: Vec<f64>,
    f_post: Vec<f64>,
    /// The flow's jump at the knots of one instant, `f- - f+`, in the mode the knots were met in
    /// (`old`, before the events of an instant there) and in the mode the run goes on in (`new`).
    pub jump_old: Vec<f64>,
    pub jump_new: Vec<f64>,
    /// The knots' motion `dt_k/dp` (m), NaN where knots of one instant move apart.
    pub dt_old: Vec<f64>,
    pub dt_new: Vec<f64>,
    /// What the knots of the current instant were in the mode they were met in (`jump_old`).
    pub old: Crossed,
}

/// What crossing the knots of one instant in one mode found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Crossed {
    /// The knots of jumping inputs (`pwc`) among them.
    pub jumping: usize,
    /// Whether the flow jumps there (beyond round-off).
    pub jumps: bool,
    /// Whether knots of inputs that move apart with a parameter meet there (their jumps cannot be
    /// told apart: the derivatives with respect to that parameter do not exist).
    pub apart: bool,
    /// The first jumping knot set among them.
    pub set: Option<u32>,
}

impl Knots {
    pub fn new(n: usize, m: usize, modes: usize) -> Knots {
        Knots {
            broken: vec![None; modes],
            sp: vec![0.0; m],
            f_pre: vec![0.0; n],
            f_post: vec![0.0; n],
            jump_old: vec![0.0; n],
            jump_new: vec![0.0; n],
            dt_old: vec![0.0; m],
            dt_new: vec![0.0; m],
            old: Crossed::default(),
        }
    }

    /// Queues every knot of `sys` in `(t_start, t_end]` as a breakpoint of its mode, at the
    /// first floating-point time where it is on its later side ([`first_time_past`]); notes the
    /// knot sets whose position is not finite. The position is affine in `t`, `s(t) = s(0) + s_t
    /// t`: the estimate of knot `k`'s time is `(k - s(0)) / s_t`, within a few spacings of `t` of
    /// the time searched, so each knot costs a few evaluations of its position.
    pub fn queue<S: HybridSystem + ?Sized>(
        &mut self,
        sys: &S,
        p: &[f64],
        (t_start, t_end): (f64, f64),
        breakpoints: &mut Breakpoints,
    ) {
        self.broken.fill(None);
        for (set, knots) in sys.info().knots.iter().enumerate() {
            let rate = sys.knot_position_grad(set, 0.0, p, &mut self.sp);
            let at_zero = sys.knot_position(set, 0.0, p);
            if !(rate.is_finite() && at_zero.is_finite()) {
                if let Some(slot) = self.broken.get_mut(knots.mode) {
                    slot.get_or_insert(set as u32);
                }
                continue;
            }
            if rate == 0.0 {
                // A position that does not move (an infinite window): no knot is ever met.
                continue;
            }
            let position = |t: f64| sys.knot_position(set, t, p);
            for k in knots.knots.clone() {
                let k = f64::from(k);
                let estimate = (k - at_zero) / rate;
                // Only the knots near the run's span are searched exactly.
                let reach = 1e-6 * (estimate.abs() + t_start.abs() + t_end.abs());
                if !(estimate > t_start - reach && estimate <= t_end + reach) {
                    continue;
                }
                match first_time_past(position, k, rate > 0.0, estimate) {
                    Some(t) if t > t_start && t <= t_end => breakpoints.add_knot(knots.mode, t, set as u32),
                    _ => {}
                }
            }
        }
    }

    /// The flow's jump `f- - f+` at the knots `sets` of `mode` met at `t`, with the state `x`
    /// (into `jump_new`, or `jump_old` when `old`), and their motion `dt_k/dp` (into `dt_new` /
    /// `dt_old`): `f-` read just before `t` (the knots' earlier side), `f+` at `t`. A component
    /// whose jump is round-off of the flows is no jump. Nothing jumps at a `pwl` knot.
    #[allow(clippy::too_many_arguments)]
    pub fn jump<S: HybridSystem + ?Sized>(
        &mut self,
        sys: &S,
        p: &[f64],
        mode: usize,
        t: f64,
        x: &[f64],
        sets: &[(f64, u32)],
        old: bool,
    ) -> Crossed {
        let (jump, dt) =
            if old { (&mut self.jump_old, &mut self.dt_old) } else { (&mut self.jump_new, &mut self.dt_new) };
        jump.fill(0.0);
        let mut crossed = motion(sys, p, mode, t, sets, &mut self.sp, dt);
        if crossed.jumping == 0 {
            crossed.apart = false;
            if old {
                self.old = crossed;
            }
            return crossed;
        }
        sys.flow(mode, t.next_down(), x, p, &mut self.f_pre);
        sys.flow(mode, t, x, p, &mut self.f_post);
        for ((j, &a), &b) in jump.iter_mut().zip(&self.f_pre).zip(&self.f_post) {
            let d = a - b;
            *j = if d.abs() <= 16.0 * EPS * (a.abs() + b.abs()) { 0.0 } else { d };
        }
        crossed.jumps = jump.iter().any(|&j| j != 0.0);
        crossed.apart &= crossed.jumps;
        if old {
            self.old = crossed;
        }
        crossed
    }

    /// `S += (f- - f+) dt_k/dp` (`jump_new`, `dt_new`) over the sensitivities `s` of `n` states,
    /// column per parameter: a column whose knots move apart (NaN) gets NaN where the flow jumps.
    pub fn apply_new(&self, s: &mut [f64], n: usize) {
        for (j, &dt) in self.dt_new.iter().enumerate() {
            if dt == 0.0 {
                continue;
            }
            for (s, &jump) in s[j * n..(j + 1) * n].iter_mut().zip(&self.jump_new) {
                if jump != 0.0 {
                    *s += jump * dt;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_time_past_a_knot_is_where_the_position_has_reached_it() {
        // s = (t - 0.1) * 4 / 0.8 reaches 1 at t = 0.3, where it rounds to 0.9999999999999999:
        // the time is a few spacings on.
        let s = |t: f64| (t - 0.1) * 4.0 / 0.8;
        let t = first_time_past(s, 1.0, true, 0.3).expect("a time");
        assert!(s(t) >= 1.0 && s(t.next_down()) < 1.0, "{t}: {} {}", s(t), s(t.next_down()));
        // From a far estimate too.
        assert_eq!(first_time_past(s, 1.0, true, 0.7), Some(t));
        assert_eq!(first_time_past(s, 1.0, true, -3.0), Some(t));
        // A falling position: the later side is strictly below the knot.
        let f = |t: f64| (t - 2.0) * 3.0 / -1.0;
        let t = first_time_past(f, 1.0, false, 5.0 / 3.0).expect("a time");
        assert!(f(t) < 1.0 && f(t.next_down()) >= 1.0, "{t}");
        // A position that never reaches the knot at a finite time.
        assert_eq!(first_time_past(|_| 0.0, 1.0, true, 1.0), None);
        assert_eq!(first_time_past(s, 1.0, true, f64::NAN), None);
    }
}
