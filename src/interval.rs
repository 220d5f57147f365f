//! Interval arithmetic with outward widening: the enclosures that event detection proves
//! crossings with (`expr::enclose` evaluates a guard over a box of states and times, `sim`'s
//! detector asks for them through `HybridSystem::guard_enclosure`). No spans, no IO, no
//! Cranelift, nothing of the model: a leaf module both `expr` and `sim` use.
//!
//! An [`Interval`] `[lo, hi]` encloses every value an operation can take over its arguments'
//! intervals, computed in floating point and then widened: by one unit in the last place (ulp)
//! at each end after an operation IEEE 754 rounds correctly (`+`, `*`, `/`, `sqrt`, `a * a`),
//! and by [`LIBM_ULPS`] after a library function (`sin`, `exp`, `powf`, ...), whose results are
//! within an ulp or two of the exact value on the platforms Rust supports but not correctly
//! rounded. Cranelift and Rust have no directed rounding, so widening after rounding to nearest
//! is what encloses both the exact value and the value the model's kernels compute (the same
//! functions at a point inside the interval).
//!
//! [`Interval::ENTIRE`] means "nothing is known": any operation whose result may be NaN or
//! unbounded over its arguments (a `log` or `sqrt` whose argument interval reaches below zero,
//! a division by an interval holding zero, a `tan` over a pole) gives it, so an enclosure that
//! excludes zero is a proof, and one that does not is only "undecided".

/// Ulps added at each end after a libm function (not correctly rounded; glibc's `sin`, `exp`,
/// `log`, `pow` are within one ulp, with margin for other platforms' libraries).
pub const LIBM_ULPS: u32 = 4;

const PI: f64 = std::f64::consts::PI;
const TAU: f64 = std::f64::consts::TAU;
const HALF_PI: f64 = std::f64::consts::FRAC_PI_2;

/// A closed interval `[lo, hi]` of reals, `lo <= hi`, or [`Interval::ENTIRE`] (which also stands
/// for "may be NaN").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    /// The lower bound (`-inf` when unbounded below).
    pub lo: f64,
    /// The upper bound (`+inf` when unbounded above).
    pub hi: f64,
}

/// `x` moved `k` floating-point numbers down (towards `-inf`).
fn down(mut x: f64, k: u32) -> f64 {
    for _ in 0..k {
        x = x.next_down();
    }
    x
}

/// `x` moved `k` floating-point numbers up (towards `+inf`).
fn up(mut x: f64, k: u32) -> f64 {
    for _ in 0..k {
        x = x.next_up();
    }
    x
}

/// Whether some point `offset + k period` (integer `k`) lies in `[lo, hi]`, judged with a margin
/// for the rounding of the reduction: a point found that is not there only widens the result.
fn holds_point_of(lo: f64, hi: f64, offset: f64, period: f64) -> bool {
    let margin = 16.0 * f64::EPSILON * lo.abs().max(hi.abs()).max(1.0);
    let k = ((lo - margin - offset) / period).ceil();
    offset + k * period <= hi + margin
}

impl Interval {
    /// Every real, and possibly NaN: nothing is known.
    pub const ENTIRE: Interval = Interval { lo: f64::NEG_INFINITY, hi: f64::INFINITY };
    /// The booleans of a comparison that may go either way.
    const EITHER: Interval = Interval { lo: 0.0, hi: 1.0 };

    /// `[lo, hi]`; [`Self::ENTIRE`] when a bound is NaN or the bounds are out of order.
    pub fn new(lo: f64, hi: f64) -> Interval {
        if lo <= hi {
            Interval { lo, hi }
        } else {
            Interval::ENTIRE
        }
    }

    /// The single value `x` (exactly: no widening); [`Self::ENTIRE`] for NaN.
    pub fn point(x: f64) -> Interval {
        Interval::new(x, x)
    }

    /// `[lo, hi]` widened by `k` ulps at each end (a result rounded to nearest `k` times over).
    pub fn widened(lo: f64, hi: f64, k: u32) -> Interval {
        Interval::new(down(lo, k), up(hi, k))
    }

    /// The smallest interval holding both.
    pub fn hull(self, other: Interval) -> Interval {
        Interval::new(self.lo.min(other.lo), self.hi.max(other.hi))
    }

    /// `[lo - e, hi + e]` (`e >= 0`), widened by an ulp.
    pub fn inflate(self, e: f64) -> Interval {
        Interval::widened(self.lo - e, self.hi + e, 1)
    }

    /// Whether the interval is a single value.
    pub fn is_point(self) -> bool {
        self.lo == self.hi
    }

    /// Whether every value is finite (both bounds are).
    pub fn is_bounded(self) -> bool {
        self.lo.is_finite() && self.hi.is_finite()
    }

    /// Whether `x` lies in the interval.
    pub fn contains(self, x: f64) -> bool {
        self.lo <= x && x <= self.hi
    }

    /// Whether every value is beyond `margin` from zero on one side: the interval proves a sign.
    pub fn clear_of_zero(self, margin: f64) -> bool {
        self.lo > margin || self.hi < -margin
    }

    /// The largest magnitude, `max(|lo|, |hi|)`.
    pub fn mag(self) -> f64 {
        self.lo.abs().max(self.hi.abs())
    }

    /// The smallest magnitude: 0 when the interval holds zero.
    pub fn mig(self) -> f64 {
        if self.lo > 0.0 {
            self.lo
        } else if self.hi < 0.0 {
            -self.hi
        } else {
            0.0
        }
    }

    /// The width `hi - lo`.
    pub fn width(self) -> f64 {
        self.hi - self.lo
    }

    /// `a * c` for a number `c`.
    pub fn scale(self, c: f64) -> Interval {
        self * Interval::point(c)
    }

    /// `a * a`, which is never negative (tighter than `a * a` for an interval holding zero).
    pub fn square(self) -> Interval {
        let (m, n) = (self.mig(), self.mag());
        Interval::widened(m * m, n * n, 1).max(Interval::point(0.0))
    }

    /// A monotone increasing libm function over the interval.
    fn increasing(self, f: fn(f64) -> f64) -> Interval {
        Interval::widened(f(self.lo), f(self.hi), LIBM_ULPS)
    }

    /// A monotone decreasing libm function over the interval.
    fn decreasing(self, f: fn(f64) -> f64) -> Interval {
        Interval::widened(f(self.hi), f(self.lo), LIBM_ULPS)
    }

    /// `sin a`: the ends, and `-1`/`1` where a minimum/maximum of the sine lies inside.
    pub fn sin(self) -> Interval {
        self.periodic(f64::sin, HALF_PI, -HALF_PI)
    }

    /// `cos a`: the ends, and `-1`/`1` where a minimum/maximum of the cosine lies inside.
    pub fn cos(self) -> Interval {
        self.periodic(f64::cos, 0.0, PI)
    }

    /// A sine-like function with maxima at `max_at + 2 k pi` and minima at `min_at + 2 k pi`.
    fn periodic(self, f: fn(f64) -> f64, max_at: f64, min_at: f64) -> Interval {
        if !self.is_bounded() || self.width() >= TAU {
            return Interval { lo: -1.0, hi: 1.0 };
        }
        let (a, b) = (f(self.lo), f(self.hi));
        let mut out = Interval::widened(a.min(b), a.max(b), LIBM_ULPS);
        if holds_point_of(self.lo, self.hi, max_at, TAU) {
            out.hi = 1.0;
        }
        if holds_point_of(self.lo, self.hi, min_at, TAU) {
            out.lo = -1.0;
        }
        out.clamp(-1.0, 1.0)
    }

    /// `tan a`; [`Self::ENTIRE`] over a pole.
    pub fn tan(self) -> Interval {
        if !self.is_bounded() || self.width() >= PI || holds_point_of(self.lo, self.hi, HALF_PI, PI) {
            return Interval::ENTIRE;
        }
        self.increasing(f64::tan)
    }

    /// `asin a`; [`Self::ENTIRE`] where `a` leaves `[-1, 1]`.
    pub fn asin(self) -> Interval {
        if self.lo < -1.0 || self.hi > 1.0 {
            return Interval::ENTIRE;
        }
        self.increasing(f64::asin)
    }

    /// `acos a`; [`Self::ENTIRE`] where `a` leaves `[-1, 1]`.
    pub fn acos(self) -> Interval {
        if self.lo < -1.0 || self.hi > 1.0 {
            return Interval::ENTIRE;
        }
        self.decreasing(f64::acos)
    }

    /// `atan a`.
    pub fn atan(self) -> Interval {
        self.increasing(f64::atan).clamp(-HALF_PI.next_up(), HALF_PI.next_up())
    }

    /// `sinh a`.
    pub fn sinh(self) -> Interval {
        self.increasing(f64::sinh)
    }

    /// `cosh a`: at least 1, its minimum at 0.
    pub fn cosh(self) -> Interval {
        let (m, n) = (self.mig(), self.mag());
        Interval::widened(m.cosh(), n.cosh(), LIBM_ULPS).max(Interval::point(1.0))
    }

    /// `tanh a`.
    pub fn tanh(self) -> Interval {
        self.increasing(f64::tanh).clamp(-1.0, 1.0)
    }

    /// `exp a`, never negative.
    pub fn exp(self) -> Interval {
        self.increasing(f64::exp).max(Interval::point(0.0))
    }

    /// `ln a`; [`Self::ENTIRE`] where `a` reaches zero or below (NaN or `-inf`).
    pub fn ln(self) -> Interval {
        if self.lo.is_nan() || self.lo <= 0.0 {
            return Interval::ENTIRE;
        }
        self.increasing(f64::ln)
    }

    /// `sqrt a` (correctly rounded); [`Self::ENTIRE`] where `a` reaches below zero.
    pub fn sqrt(self) -> Interval {
        if self.lo.is_nan() || self.lo < 0.0 {
            return Interval::ENTIRE;
        }
        Interval::widened(self.lo.sqrt(), self.hi.sqrt(), 1).max(Interval::point(0.0))
    }

    /// `|a|`, exact.
    pub fn abs(self) -> Interval {
        Interval { lo: self.mig(), hi: self.mag() }
    }

    /// `sign a`: -1, 0 or 1 (the hull of those it may take).
    pub fn sign(self) -> Interval {
        let lo = if self.lo < 0.0 {
            -1.0
        } else if self.lo == 0.0 {
            0.0
        } else {
            1.0
        };
        let hi = if self.hi > 0.0 {
            1.0
        } else if self.hi == 0.0 {
            0.0
        } else {
            -1.0
        };
        Interval::new(lo, hi)
    }

    /// The elementwise minimum.
    pub fn min(self, b: Interval) -> Interval {
        Interval::new(self.lo.min(b.lo), self.hi.min(b.hi))
    }

    /// The elementwise maximum.
    pub fn max(self, b: Interval) -> Interval {
        Interval::new(self.lo.max(b.lo), self.hi.max(b.hi))
    }

    /// The interval cut to `[lo, hi]` (the range of the function it encloses).
    fn clamp(self, lo: f64, hi: f64) -> Interval {
        Interval::new(self.lo.max(lo), self.hi.min(hi))
    }

    /// `hypot(a, b)`, increasing in `|a|` and `|b|`.
    pub fn hypot(self, b: Interval) -> Interval {
        Interval::widened(self.mig().hypot(b.mig()), self.mag().hypot(b.mag()), LIBM_ULPS)
    }

    /// `atan2(a, b)` (`a` the ordinate): over a box clear of the origin and of the negative
    /// abscissa (the branch cut), the extremes of the angle are at its corners; else the whole
    /// range `[-pi, pi]`.
    pub fn atan2(self, b: Interval) -> Interval {
        let whole = Interval::widened(-PI, PI, LIBM_ULPS);
        if !(self.is_bounded() && b.is_bounded()) {
            return whole;
        }
        let holds_origin = self.contains(0.0) && b.contains(0.0);
        let on_cut = b.lo < 0.0 && self.contains(0.0);
        if holds_origin || on_cut {
            return whole;
        }
        let corners = [self.lo.atan2(b.lo), self.lo.atan2(b.hi), self.hi.atan2(b.lo), self.hi.atan2(b.hi)];
        let lo = corners.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = corners.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Interval::widened(lo, hi, LIBM_ULPS)
    }

    /// `a ^ b` as `powf` computes it (with `a * a` for an exponent of exactly 2).
    pub fn pow(self, b: Interval) -> Interval {
        if b.is_point() {
            return self.powf(b.lo);
        }
        // A varying exponent: `exp(b ln a)` for a positive base, nothing known otherwise.
        if self.lo.is_nan() || self.lo <= 0.0 {
            return Interval::ENTIRE;
        }
        (b * self.ln()).exp()
    }

    /// `a ^ c` for a number `c`.
    pub fn powf(self, c: f64) -> Interval {
        if c == 2.0 {
            return self.square();
        }
        if c == 0.0 {
            return Interval::point(1.0);
        }
        if c.is_nan() || !self.is_bounded() {
            return Interval::ENTIRE;
        }
        let integer = c.fract() == 0.0 && c.abs() < 9.0e15;
        if integer {
            let even = (c / 2.0).fract() == 0.0;
            if c < 0.0 && self.contains(0.0) {
                return Interval::ENTIRE;
            }
            return match (even, c > 0.0) {
                // |a|^c: increasing in |a| for c > 0, decreasing for c < 0.
                (true, true) => Interval::widened(self.mig().powf(c), self.mag().powf(c), LIBM_ULPS),
                (true, false) => Interval::widened(self.mag().powf(c), self.mig().powf(c), LIBM_ULPS),
                // Odd: increasing for c > 0; for c < 0 decreasing on each side of zero, which the
                // interval does not hold.
                (false, true) => Interval::widened(self.lo.powf(c), self.hi.powf(c), LIBM_ULPS),
                (false, false) => Interval::widened(self.hi.powf(c), self.lo.powf(c), LIBM_ULPS),
            };
        }
        // A fractional power of a negative number is NaN; of zero with c < 0, infinite.
        if self.lo < 0.0 || (c < 0.0 && self.lo == 0.0) {
            return Interval::ENTIRE;
        }
        if c > 0.0 {
            Interval::widened(self.lo.powf(c), self.hi.powf(c), LIBM_ULPS).max(Interval::point(0.0))
        } else {
            Interval::widened(self.hi.powf(c), self.lo.powf(c), LIBM_ULPS)
        }
    }

    /// Whether the value is certainly true (nonzero, as `Select` and the logic operators read
    /// it), certainly false (exactly zero) or undecided.
    pub fn truth(self) -> Option<bool> {
        if self.is_point() && self.lo == 0.0 {
            Some(false)
        } else if self.lo > 0.0 || self.hi < 0.0 {
            Some(true)
        } else {
            None
        }
    }

    /// The boolean interval of a decided or undecided truth value.
    pub fn boolean(truth: Option<bool>) -> Interval {
        match truth {
            Some(true) => Interval::point(1.0),
            Some(false) => Interval::point(0.0),
            None => Interval::EITHER,
        }
    }

    /// `a < b` as 0/1.
    pub fn lt(self, b: Interval) -> Interval {
        if self.hi < b.lo {
            Interval::point(1.0)
        } else if self.lo >= b.hi && self.is_bounded() && b.is_bounded() {
            Interval::point(0.0)
        } else {
            Interval::EITHER
        }
    }

    /// `a <= b` as 0/1.
    pub fn le(self, b: Interval) -> Interval {
        if self.hi <= b.lo && self.is_bounded() && b.is_bounded() {
            Interval::point(1.0)
        } else if self.lo > b.hi {
            Interval::point(0.0)
        } else {
            Interval::EITHER
        }
    }
}

impl std::ops::Neg for Interval {
    type Output = Interval;
    /// `-a`, exact.
    fn neg(self) -> Interval {
        Interval { lo: -self.hi, hi: -self.lo }
    }
}

impl std::ops::Add for Interval {
    type Output = Interval;
    /// `a + b`.
    fn add(self, b: Interval) -> Interval {
        Interval::widened(self.lo + b.lo, self.hi + b.hi, 1)
    }
}

impl std::ops::Sub for Interval {
    type Output = Interval;
    /// `a - b`.
    fn sub(self, b: Interval) -> Interval {
        self + -b
    }
}

impl std::ops::Mul for Interval {
    type Output = Interval;
    /// `a * b`: the extremes are among the four products of the ends. A product `0 * inf` (an
    /// unbounded argument) gives [`Interval::ENTIRE`].
    fn mul(self, b: Interval) -> Interval {
        let zero = |a: Interval| a.is_point() && a.lo == 0.0;
        if (zero(self) && b.is_bounded()) || (zero(b) && self.is_bounded()) {
            return Interval::point(0.0);
        }
        let p = [self.lo * b.lo, self.lo * b.hi, self.hi * b.lo, self.hi * b.hi];
        if p.iter().any(|v| v.is_nan()) {
            return Interval::ENTIRE;
        }
        let lo = p.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = p.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Interval::widened(lo, hi, 1)
    }
}

impl std::ops::Div for Interval {
    type Output = Interval;
    /// `a / b`; [`Interval::ENTIRE`] when `b` holds zero.
    fn div(self, b: Interval) -> Interval {
        if b.lo <= 0.0 && b.hi >= 0.0 {
            return Interval::ENTIRE;
        }
        let q = [self.lo / b.lo, self.lo / b.hi, self.hi / b.lo, self.hi / b.hi];
        if q.iter().any(|v| v.is_nan()) {
            return Interval::ENTIRE;
        }
        let lo = q.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = q.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Interval::widened(lo, hi, 1)
    }
}

/// A value and its time derivative as intervals: forward-mode differentiation in interval
/// arithmetic (`expr::enclose`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dual {
    /// The enclosure of the value.
    pub v: Interval,
    /// The enclosure of its time derivative.
    pub d: Interval,
}

impl Dual {
    /// A constant: the value `c`, derivative 0.
    pub fn constant(c: f64) -> Dual {
        Dual { v: Interval::point(c), d: Interval::point(0.0) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Points spread over an interval, ends included.
    fn points(a: Interval) -> impl Iterator<Item = f64> {
        (0..=16).map(move |k| {
            let s = k as f64 / 16.0;
            (a.lo + s * (a.hi - a.lo)).clamp(a.lo, a.hi)
        })
    }

    fn encloses(out: Interval, v: f64) -> bool {
        out == Interval::ENTIRE || out.contains(v)
    }

    fn arg() -> impl Strategy<Value = Interval> {
        (-50.0f64..50.0, 0.0f64..20.0).prop_map(|(lo, w)| Interval::new(lo, lo + w))
    }

    fn small_arg() -> impl Strategy<Value = Interval> {
        (-3.0f64..3.0, 0.0f64..2.0).prop_map(|(lo, w)| Interval::new(lo, lo + w))
    }

    type Unary = (&'static str, fn(Interval) -> Interval, fn(f64) -> f64);
    const UNARY: [Unary; 14] = [
        ("neg", |a| -a, |x| -x),
        ("sin", Interval::sin, f64::sin),
        ("cos", Interval::cos, f64::cos),
        ("tan", Interval::tan, f64::tan),
        ("asin", Interval::asin, f64::asin),
        ("acos", Interval::acos, f64::acos),
        ("atan", Interval::atan, f64::atan),
        ("sinh", Interval::sinh, f64::sinh),
        ("cosh", Interval::cosh, f64::cosh),
        ("tanh", Interval::tanh, f64::tanh),
        ("exp", Interval::exp, f64::exp),
        ("ln", Interval::ln, f64::ln),
        ("sqrt", Interval::sqrt, f64::sqrt),
        ("abs", Interval::abs, f64::abs),
    ];

    proptest! {
        /// Every operation's enclosure holds the operation's value at every point tried inside
        /// its arguments (or is ENTIRE where a value may be NaN).
        #[test]
        fn unary_enclosures_hold_their_values(a in arg(), b in small_arg()) {
            for (name, f, point) in UNARY {
                for x in [a, b] {
                    let out = f(x);
                    for v in points(x) {
                        prop_assert!(encloses(out, point(v)), "{name} {x:?} at {v}: {out:?} vs {}", point(v));
                    }
                }
            }
        }

        #[test]
        fn binary_enclosures_hold_their_values(a in arg(), b in arg(), c in small_arg()) {
            type Binary = (&'static str, fn(Interval, Interval) -> Interval, fn(f64, f64) -> f64);
            let ops: [Binary; 8] = [
                ("add", |a, b| a + b, |x, y| x + y),
                ("mul", |a, b| a * b, |x, y| x * y),
                ("div", |a, b| a / b, |x, y| x / y),
                ("min", Interval::min, f64::min),
                ("max", Interval::max, f64::max),
                ("hypot", Interval::hypot, f64::hypot),
                ("atan2", Interval::atan2, f64::atan2),
                ("pow", Interval::pow, f64::powf),
            ];
            for (name, f, point) in ops {
                for (x, y) in [(a, b), (c, a), (c, c)] {
                    let out = f(x, y);
                    for u in points(x) {
                        for v in points(y) {
                            prop_assert!(encloses(out, point(u, v)), "{name} {x:?} {y:?} at {u}, {v}: {out:?}");
                        }
                    }
                }
            }
        }

        #[test]
        fn powers_by_numbers_hold_their_values(a in small_arg(), k in -4i32..6, frac in 0.05f64..3.0) {
            for c in [k as f64, frac, -frac, 2.0] {
                let out = a.powf(c);
                for v in points(a) {
                    let want = if c == 2.0 { v * v } else { v.powf(c) };
                    prop_assert!(encloses(out, want), "{a:?}^{c} at {v}: {out:?} vs {want}");
                }
            }
        }
    }

    #[test]
    fn periodic_functions_reach_their_extremes_only_where_the_interval_holds_them() {
        // [1, 2] holds pi/2 (sin's maximum) and no minimum of the sine.
        let s = Interval::new(1.0, 2.0).sin();
        assert_eq!(s.hi, 1.0);
        assert!(s.lo > 0.84 && s.lo <= 1f64.sin().min(2f64.sin()));
        // [0.1, 0.2] holds no extremum: the ends, barely widened.
        let s = Interval::new(0.1, 0.2).sin();
        assert!(s.lo <= 0.1f64.sin() && s.lo > 0.0998 && s.hi >= 0.2f64.sin() && s.hi < 0.1988);
        // Far out (1e6 rad) the reduction is judged with margin: the ends still bound it.
        let far = Interval::new(1e6, 1e6 + 0.01);
        let s = far.sin();
        for v in points(far) {
            assert!(s.contains(v.sin()));
        }
        assert!(s.width() < 0.02);
        // cos over [3, 3.3] holds pi: -1.
        assert_eq!(Interval::new(3.0, 3.3).cos().lo, -1.0);
        // tan over a pole knows nothing.
        assert_eq!(Interval::new(1.5, 1.6).tan(), Interval::ENTIRE);
    }

    #[test]
    fn domains_left_give_nothing_and_zeros_are_exact() {
        assert_eq!(Interval::new(-0.1, 1.0).sqrt(), Interval::ENTIRE);
        assert_eq!(Interval::new(0.0, 1.0).ln(), Interval::ENTIRE);
        assert_eq!(Interval::new(1.0, 2.0) / Interval::new(-1.0, 1.0), Interval::ENTIRE);
        assert_eq!(Interval::point(0.0) * Interval::new(-3.0, 5.0), Interval::point(0.0));
        assert_eq!(Interval::ENTIRE * Interval::point(0.0), Interval::ENTIRE);
        assert_eq!(Interval::new(f64::NAN, 1.0), Interval::ENTIRE);
        // Widening moves each end by exact ulps, also through zero and subnormals.
        let w = Interval::widened(0.0, 0.0, 1);
        assert_eq!((w.lo, w.hi), (-f64::from_bits(1), f64::from_bits(1)));
        let tiny = Interval::point(-1e-200) + Interval::point(1e-200);
        assert!(tiny.contains(0.0) && tiny.width() < 1e-300);
    }

    #[test]
    fn comparisons_and_truth_are_decided_only_when_the_intervals_say_so() {
        let (a, b) = (Interval::new(0.0, 1.0), Interval::new(2.0, 3.0));
        assert_eq!(a.lt(b), Interval::point(1.0));
        assert_eq!(b.lt(a), Interval::point(0.0));
        assert_eq!(a.lt(Interval::new(0.5, 4.0)), Interval::EITHER);
        assert_eq!(Interval::new(1.0, 1.0).le(Interval::point(1.0)), Interval::point(1.0));
        assert_eq!(Interval::point(0.0).truth(), Some(false));
        assert_eq!(Interval::new(0.5, 1.0).truth(), Some(true));
        assert_eq!(Interval::new(0.0, 1.0).truth(), None);
        assert_eq!(Interval::new(-2.0, 3.0).sign(), Interval::new(-1.0, 1.0));
    }
}
