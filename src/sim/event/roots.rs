//! Stage 5 (sim): root finding in one dimension, for event location: the Illinois variant of
//! regula falsi to adjacent floating-point numbers, the root of a guard's cubic Hermite
//! interpolant as a first estimate, and the extremum of a guard from its speed. Pure arithmetic
//! over closures; knows nothing of models, steps or events.

const EPS: f64 = f64::EPSILON;
/// The smallest positive double (a subnormal): the spacing of doubles below `2^-1022`.
const TINY: f64 = 5e-324;
/// A Newton step on the guard's Hermite cubic at most this long (in the step's unit interval)
/// is the last one [`hermite_root`] takes.
const NEWTON_LAST_STEP: f64 = 1e-9;
/// Relative accuracy (in units of the step) to which [`extremum_time`] locates a guard's
/// extremum: its error of order 1e-9 h changes the guard value there by about 1e-18 of the
/// guard's variation over the step, far below its round-off.
pub(crate) const EXTREMUM_TOL: f64 = 1e-9;

/// Illinois regula falsi on `[a, b]` with `sigma * fa > 0 >= sigma * fb`; returns the final
/// bracket once it is as narrow as the floating-point numbers allow: the largest point found on
/// the pre-crossing side and the smallest point found on the crossed side (the root).
///
/// Near the end the secant keeps landing next to the end it last moved, where the function is
/// round-off, and plain Illinois would then narrow the bracket only by bisection (about 50
/// halvings). So a trial point keeps a distance `push` from both ends, starting at the final
/// resolution and doubling while trial points land on the same side as the end they were pushed
/// away from: once the root is pinned to round-off the bracket closes in a few evaluations, also
/// when the function is noisy there.
///
/// `first`, when inside the bracket, replaces the first secant point: a good estimate (such as
/// [`hermite_root`]) lets the search start next to the root instead of creeping towards it from
/// a far end, as regula falsi does on a convex function.
pub(crate) fn illinois<F: FnMut(f64) -> f64>(
    a: f64,
    fa: f64,
    b: f64,
    fb: f64,
    sigma: f64,
    first: Option<f64>,
    f: F,
) -> (f64, f64) {
    illinois_until(a, fa, b, fb, sigma, first, 0.0, f)
}

/// The time in `(a, b)` where a guard's speed, `sa` at `a` and `sb` at `b` of opposite signs,
/// is zero: [`illinois`], but returning the next secant point as soon as it lies within
/// [`EXTREMUM_TOL`]` (b - a)` of the last trial point. The extremum only has to be known well
/// enough for the guard's value there, whose error is of second order in the time's; pinning
/// it to adjacent floating-point numbers took two evaluations more (three instead of one on a
/// ball's apex, where the speed is linear and the first secant point is the root).
pub(crate) fn extremum_time<F: FnMut(f64) -> f64>(a: f64, sa: f64, b: f64, sb: f64, f: F) -> f64 {
    illinois_until(a, sa, b, sb, sa.signum(), None, EXTREMUM_TOL * (b - a), f).1
}

/// [`illinois`], or when `enough > 0`, stopping at a secant point within `enough` of the last
/// trial point (a secant step that short means the iteration has converged to about that),
/// returned as both ends.
#[allow(clippy::too_many_arguments)]
fn illinois_until<F: FnMut(f64) -> f64>(
    mut a: f64,
    mut fa: f64,
    mut b: f64,
    mut fb: f64,
    sigma: f64,
    first: Option<f64>,
    enough: f64,
    mut f: F,
) -> (f64, f64) {
    let mut side = 0i8;
    let mut width = b - a;
    let mut push = 1.0f64;
    let mut last = f64::NAN;
    for it in 0..200 {
        // Adjacent doubles, subnormal ones too (whose spacing is the smallest double).
        let resolution = (EPS * a.abs().max(b.abs())).max(TINY);
        if b - a <= 2.0 * resolution {
            break;
        }
        // Safeguard: bisect when the secant leaves the bracket, when the bracket is too narrow
        // to keep the push distance from both ends, or every fourth iteration when the bracket
        // has not at least halved, so the iteration count stays bounded.
        let secant = match first {
            Some(c) if it == 0 => c,
            // From the end with the smaller value: near the other end the correction would be
            // the whole bracket and cancel (a root 1e-200 from `a` in a bracket of 1e-3 would
            // come out as `a` itself and be crept towards by pushes).
            _ if fb != fa && fa.abs() < fb.abs() => a - fa * (b - a) / (fb - fa),
            _ if fb != fa => b - fb * (b - a) / (fb - fa),
            _ => f64::NAN,
        };
        if enough > 0.0 && (secant - last).abs() <= enough && secant > a && secant < b {
            return (secant, secant);
        }
        let stalled = it % 4 == 3 && b - a > 0.5 * width;
        if it % 4 == 3 {
            width = b - a;
        }
        // The push is counted in spacings at the trial point's scale, not the bracket's: a root
        // 1e-200 from `a = 0` in a bracket of 1e-3 is resolved to its own spacings, not pushed
        // 1e-19 away and crept back to in 200 iterations.
        let (da, db) = (
            push * (EPS * a.abs().max(secant.abs())).max(TINY),
            push * (EPS * b.abs().max(secant.abs())).max(TINY),
        );
        // Which end the trial point was pushed away from: -1 for `b`, 1 for `a`.
        let mut pushed = 0i8;
        let mut c = if stalled || !(secant >= a && secant <= b) || b - a <= da + db {
            0.5 * (a + b)
        } else if secant - a < da {
            pushed = 1;
            a + da
        } else if b - secant < db {
            pushed = -1;
            b - db
        } else {
            secant
        };
        if !(c > a && c < b) {
            c = 0.5 * (a + b);
            pushed = 0;
            if !(c > a && c < b) {
                break;
            }
        }
        let fc = f(c);
        last = c;
        let crossed = sigma * fc <= 0.0 || fc.is_nan();
        if crossed {
            b = c;
            fb = fc;
            if side == -1 {
                fa *= 0.5;
            }
            side = -1;
        } else {
            a = c;
            fa = fc;
            if side == 1 {
                fb *= 0.5;
            }
            side = 1;
        }
        let same_side = (pushed == -1 && crossed) || (pushed == 1 && !crossed);
        push = if same_side { 2.0 * push } else { 1.0 };
    }
    (a, b)
}

/// The root in `(a, b)` of the cubic Hermite interpolant of a guard with values `ga`, `gb` of
/// opposite signs (or one zero) and time derivatives `da`, `db` at the ends: exact for a guard
/// that is at most cubic along the solution (a ball's height), and a close first estimate for
/// any smooth guard. Pure arithmetic, no model calls: Newton's method on the cubic, safeguarded by
/// bisection of its own sign bracket. `None` when the data are not finite or not bracketing.
pub(crate) fn hermite_root(a: f64, ga: f64, da: f64, b: f64, gb: f64, db: f64) -> Option<f64> {
    let w = b - a;
    let all_finite = [a, ga, da, b, gb, db].iter().all(|v| v.is_finite());
    if !(all_finite && w > 0.0 && ga * gb <= 0.0 && ga != gb) {
        return None;
    }
    // p(s) = c0 + c1 s + c2 s^2 + c3 s^3 on s in [0, 1], from the Hermite basis.
    let (ma, mb) = (w * da, w * db);
    let (c0, c1) = (ga, ma);
    let c2 = 3.0 * (gb - ga) - 2.0 * ma - mb;
    let c3 = 2.0 * (ga - gb) + ma + mb;
    let p = |s: f64| ((c3 * s + c2) * s + c1) * s + c0;
    let dp = |s: f64| (3.0 * c3 * s + 2.0 * c2) * s + c1;
    let mut s = quadratic_start(ga, ma, gb);
    if c3.abs() <= 8.0 * EPS * (ga.abs() + gb.abs() + ma.abs() + mb.abs()) {
        // The cubic term is round-off: the quadratic's root is the cubic's (the ball's case).
        let t = a + s * w;
        return (t > a && t < b).then_some(t);
    }
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    let lo_sign = ga.signum();
    for _ in 0..60 {
        let v = p(s);
        if v == 0.0 {
            break;
        }
        if v.signum() == lo_sign {
            lo = s;
        } else {
            hi = s;
        }
        let d = dp(s);
        let newton = s - v / d;
        if d != 0.0 && (newton - s).abs() <= NEWTON_LAST_STEP && newton > lo && newton < hi {
            // Converged: Newton's error after a step of size delta is about K delta^2 with
            // K = |p''/2p'|, far below round-off here unless the root is nearly double, and the
            // caller polishes the estimate on the true guard anyway. Waiting for a step of 4 EPS
            // instead costs one or two more iterations.
            s = newton;
            break;
        }
        let next = if d != 0.0 && newton > lo && newton < hi { newton } else { 0.5 * (lo + hi) };
        if (next - s).abs() <= 4.0 * EPS {
            s = next;
            break;
        }
        s = next;
    }
    let t = a + s * w;
    (t > a && t < b).then_some(t)
}

/// Newton's start for [`hermite_root`] on `s` in `[0, 1]`: the root of the quadratic
/// `q(s) = ga + ma s + (gb - ga - ma) s^2` through both ends with the start slope `ma`. It differs
/// from the Hermite cubic by `c3 s^2 (s - 1)`, so for a guard at most quadratic along the solution
/// (a ball's height, by far the commonest contact) it is the root itself and [`hermite_root`]
/// needs no Newton iteration at all; from the secant point it took four to six (on the bouncing
/// ball, where the crossing sits late in a step that starts at the apex). `ga`, `gb` bracket a root, so `q` has
/// exactly one in `[0, 1]`; the secant point stands in when round-off puts it outside.
fn quadratic_start(ga: f64, ma: f64, gb: f64) -> f64 {
    let (a, b, c) = (gb - ga - ma, ma, ga);
    let candidates = if a == 0.0 {
        [-c / b, f64::NAN]
    } else {
        // The cancellation-free pair of roots, `q / a` and `c / q`.
        let root = (b * b - 4.0 * a * c).max(0.0).sqrt();
        let q = -0.5 * (b + root.copysign(b));
        [q / a, c / q]
    };
    candidates.into_iter().find(|s| (0.0..=1.0).contains(s)).unwrap_or_else(|| ga / (ga - gb))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn illinois_finds_root_to_adjacent_floats() {
        // cos has a root at pi/2, falling.
        let (t_pre, t) = illinois(1.0, 1f64.cos(), 2.0, 2f64.cos(), 1.0, None, f64::cos);
        assert!((t - std::f64::consts::FRAC_PI_2).abs() <= 4.0 * EPS * 2.0, "{t}");
        assert!(t.cos() <= 0.0);
        // The bracket's other end (where a flow switch reads the old flow) is strictly before.
        assert!(t_pre.cos() > 0.0 && t - t_pre <= 4.0 * EPS * 2.0, "{t_pre} {t}");
    }

    #[test]
    fn illinois_returns_crossed_side_for_rising() {
        let f = |t: f64| t * t * t - 0.3;
        let (_, t) = illinois(0.0, f(0.0), 1.0, f(1.0), -1.0, None, f);
        assert!(f(t) >= 0.0);
        assert!((t - 0.3f64.cbrt()).abs() < 1e-15, "{t}");
    }

    #[test]
    fn illinois_handles_exact_zero_at_right_end() {
        // Root exactly at 0.5, bracket end exactly on it: must still narrow to 0.5.
        let f = |t: f64| 0.5 - t;
        let (_, t) = illinois(0.0, 0.5, 1.0, -0.5, 1.0, None, f);
        assert_eq!(t, 0.5);
    }

    #[test]
    fn illinois_closes_the_bracket_in_few_evaluations() {
        // A linear function is found by the first secant; closing the bracket around it must not
        // fall back to some 50 bisections.
        let mut calls = 0;
        let (_, t) = illinois(1.349, 1.11, 1.782, -3.13, 1.0, None, |t| {
            calls += 1;
            (1.462_936_596_793_766 - t) * 7.3
        });
        assert!((t - 1.462_936_596_793_766).abs() <= 4.0 * EPS * 1.5, "{t}");
        assert!(calls <= 8, "{calls} evaluations");
        // Round-off noise of a few hundred ulps around the root: still few evaluations.
        let mut calls = 0;
        let noisy = |t: f64| {
            let wobble = ((t.to_bits() % 7) as f64 - 3.0) * 1e-14;
            (0.75 - t) + wobble
        };
        let (_, t) = illinois(0.0, noisy(0.0), 1.0, noisy(1.0), 1.0, None, |t| {
            calls += 1;
            noisy(t)
        });
        assert!(noisy(t) <= 0.0 && (t - 0.75).abs() < 1e-13, "{t}");
        assert!(calls <= 30, "{calls} evaluations");
    }

    #[test]
    fn hermite_root_is_exact_for_a_falling_ball_and_close_for_a_smooth_guard() {
        // y(t) = 1 - 4.905 t^2 on [0.2, 0.9]: the cubic Hermite reproduces the parabola.
        let (y, dy) = (|t: f64| 1.0 - 4.905 * t * t, |t: f64| -9.81 * t);
        let first = hermite_root(0.2, y(0.2), dy(0.2), 0.9, y(0.9), dy(0.9)).expect("a root");
        let exact = (1.0f64 / 4.905).sqrt();
        assert!((first - exact).abs() <= 4.0 * EPS, "{first} vs {exact}");
        // From the apex (zero speed at the start), as after every bounce.
        let from_apex = hermite_root(0.0, y(0.0), dy(0.0), 0.9, y(0.9), dy(0.9)).expect("a root");
        assert!((from_apex - exact).abs() <= 4.0 * EPS, "{from_apex} vs {exact}");
        // A cubic guard (c3 != 0): Newton from the quadratic start still reaches the cubic's root.
        let cubic = |t: f64| t * t * t - 0.3;
        let t = hermite_root(0.0, cubic(0.0), 0.0, 1.0, cubic(1.0), 3.0).expect("a root");
        assert!((t - 0.3f64.cbrt()).abs() <= 4.0 * EPS, "{t}");
        // A first estimate on the root closes the bracket in a few evaluations (about ten
        // without it, see the evaluation counts above).
        let mut calls = 0;
        let (_, t) = illinois(0.2, y(0.2), 0.9, y(0.9), 1.0, Some(first), |t| {
            calls += 1;
            y(t)
        });
        assert!((t - exact).abs() <= 4.0 * EPS && y(t) <= 0.0, "{t}");
        assert!(calls <= 4, "{calls} evaluations");
        // cos on [1, 2]: the Hermite estimate is within the cubic's error, ~1e-3 here.
        let t = hermite_root(1.0, 1f64.cos(), -1f64.sin(), 2.0, 2f64.cos(), -2f64.sin()).expect("a root");
        assert!((t - std::f64::consts::FRAC_PI_2).abs() < 1e-2, "{t}");
        assert_eq!(hermite_root(0.0, 1.0, 0.0, 1.0, 2.0, 0.0), None, "no sign change");
        assert_eq!(hermite_root(0.0, f64::NAN, 0.0, 1.0, -1.0, 0.0), None);
    }

    #[test]
    fn extremum_time_takes_one_evaluation_for_a_linear_speed_and_is_close_for_others() {
        // A ball's height speed 3.5 - 9.81 t: the first secant point is the apex.
        let mut calls = 0;
        let apex = 3.5 / 9.81;
        let t = extremum_time(0.1, 3.5 - 0.981, 0.9, 3.5 - 8.829, |t| {
            calls += 1;
            3.5 - 9.81 * t
        });
        assert!((t - apex).abs() <= 4.0 * EPS, "{t} vs {apex}");
        assert_eq!(calls, 1);
        // A curved speed (-sin, extremum of cos at pi): within the tolerance of the step.
        let t = extremum_time(2.5, -2.5f64.sin(), 3.9, -3.9f64.sin(), |t| -t.sin());
        assert!((t - std::f64::consts::PI).abs() <= EXTREMUM_TOL * 1.4, "{t}");
    }
}

#[cfg(test)]
mod tiny_roots {
    /// A root 1e-200 from the bracket's start, and one subnormal: resolved to their own spacings
    /// in a few evaluations, a subnormal one in some more (the push was counted at the bracket's scale, 1e-19, and 200
    /// evaluations left the bracket at [8e-205, 1.7e-198]).
    #[test]
    fn a_root_tiny_against_its_bracket_is_found_to_its_own_spacings() {
        for root in [1e-200, 1e-300, 5e-310, 1e-12] {
            let mut n = 0;
            let (pre, t) = super::illinois(0.0, -root, 1e-3, 1e-3 - root, -1.0, None, |t| {
                n += 1;
                t - root
            });
            let spacing = (4.0 * f64::EPSILON * root).max(1e-323);
            assert!(t >= root && t - root <= spacing, "{root}: {t}");
            assert!(pre < root && root - pre <= spacing, "{root}: {pre}");
            // Subnormal values carry fewer digits: the secant is rougher there.
            let most = if root < f64::MIN_POSITIVE { 40 } else { 12 };
            assert!(n <= most, "{root}: {n} evaluations");
        }
    }
}
