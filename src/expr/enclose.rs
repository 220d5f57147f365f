//! Stage 3: enclosures of an expression and of its time derivative along a trajectory, over a
//! box of times and states (interval arithmetic, `crate::interval`). Knows no spans, no IO and
//! no Cranelift.
//!
//! An [`Enclosure`] is a guard compiled to straight-line interval code from the same DAG the
//! compiler differentiates and the JIT compiles: evaluating it at `t` in `T`, `x` in `X`, with
//! the states moving at rates in `X'`, gives `(G, G')` with `g(t, x, p)` in `G` and
//! `d/dt g(t, x(t), p) = g_x x' + g_t` in `G'` for every such point (forward-mode
//! differentiation in interval arithmetic). Where a function is only piecewise differentiable
//! (`abs`, `min`, `max`, `pwl` at its knots), `G'` holds the one-sided derivatives, so a `G'`
//! clear of zero still proves the guard monotone; where it may jump (`sign`, a comparison, `if`,
//! `pwc` over a knot), `G'` is `ENTIRE`.
//!
//! The semantics follow `eval::apply_*` operation by operation (`Pow` with exponent 2 is
//! `a * a`), so an enclosure holds both the exact value and the one the kernels compute.

use super::eval::{apply_lookup, Inst, Tape};
use super::node::{BinaryOp, ExprId, Lookup, LookupKind, UnaryOp};
use super::store::ExprStore;
use crate::interval::{Dual, Interval};

/// Straight-line interval code for one expression and its time derivative (see the module
/// documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct Enclosure {
    tape: Tape,
    /// The states the expression reads, ascending.
    states: Vec<u32>,
    /// Whether it reads the time.
    reads_time: bool,
}

impl Enclosure {
    /// The enclosure of `root`.
    pub fn new(store: &ExprStore, root: ExprId) -> Enclosure {
        let tape = Tape::new(store, &[root]);
        let mut states: Vec<u32> = tape
            .insts()
            .iter()
            .filter_map(|inst| match *inst {
                Inst::State(i) => Some(i),
                _ => None,
            })
            .collect();
        states.sort_unstable();
        states.dedup();
        let reads_time = tape.insts().iter().any(|inst| matches!(inst, Inst::Time));
        Enclosure { tape, states, reads_time }
    }

    /// The states the expression reads, ascending: only their entries of `x` and `dx` are read.
    pub fn states(&self) -> &[u32] {
        &self.states
    }

    /// Whether the expression reads the time.
    pub fn reads_time(&self) -> bool {
        self.reads_time
    }

    /// `(G, G')` over `t` in `time`, states in `x` moving at `dx` (indexed by state; only
    /// [`Self::states`] are read), parameters `p` (see the module documentation). `scratch` holds
    /// the intermediate values.
    pub fn eval(
        &self,
        time: Interval,
        x: &[Interval],
        dx: &[Interval],
        p: &[f64],
        scratch: &mut Vec<Dual>,
    ) -> Dual {
        scratch.clear();
        scratch.reserve(self.tape.len());
        for inst in self.tape.insts() {
            let v = match *inst {
                Inst::Const(c) => Dual::constant(c),
                Inst::State(i) => Dual { v: x[i as usize], d: dx[i as usize] },
                Inst::Param(i) => Dual::constant(p[i as usize]),
                Inst::Time => Dual { v: time, d: Interval::point(1.0) },
                Inst::Unary(op, a) => unary(op, scratch[a as usize]),
                Inst::Binary(op, a, b) => binary(op, scratch[a as usize], scratch[b as usize]),
                Inst::Select(c, a, b) => {
                    select(scratch[c as usize], scratch[a as usize], scratch[b as usize])
                }
                Inst::Lookup(l, a) => {
                    let u = &p[l.base as usize..(l.base + l.len) as usize];
                    lookup(l, scratch[a as usize], u)
                }
            };
            scratch.push(v);
        }
        scratch[self.tape.roots()[0] as usize]
    }
}

/// A value that may jump where its argument is undecided: its derivative is zero where the
/// value is decided and unknown where it may jump.
fn stepwise(v: Interval) -> Dual {
    let d = if v.is_point() { Interval::point(0.0) } else { Interval::ENTIRE };
    Dual { v, d }
}

fn unary(op: UnaryOp, a: Dual) -> Dual {
    let one = Interval::point(1.0);
    match op {
        UnaryOp::Neg => Dual { v: -a.v, d: -a.d },
        UnaryOp::Sin => Dual { v: a.v.sin(), d: a.v.cos() * a.d },
        UnaryOp::Cos => Dual { v: a.v.cos(), d: -a.v.sin() * a.d },
        UnaryOp::Tan => {
            let t = a.v.tan();
            Dual { v: t, d: (one + t.square()) * a.d }
        }
        UnaryOp::Asin | UnaryOp::Acos => {
            let root = (one - a.v.square()).sqrt();
            let d = a.d / root;
            if op == UnaryOp::Asin {
                Dual { v: a.v.asin(), d }
            } else {
                Dual { v: a.v.acos(), d: -d }
            }
        }
        UnaryOp::Atan => Dual { v: a.v.atan(), d: a.d / (one + a.v.square()) },
        UnaryOp::Sinh => Dual { v: a.v.sinh(), d: a.v.cosh() * a.d },
        UnaryOp::Cosh => Dual { v: a.v.cosh(), d: a.v.sinh() * a.d },
        UnaryOp::Tanh => {
            let t = a.v.tanh();
            Dual { v: t, d: (one - t.square()) * a.d }
        }
        UnaryOp::Exp => {
            let e = a.v.exp();
            Dual { v: e, d: e * a.d }
        }
        UnaryOp::Log => Dual { v: a.v.ln(), d: a.d / a.v },
        UnaryOp::Sqrt => {
            let s = a.v.sqrt();
            Dual { v: s, d: a.d / s.scale(2.0) }
        }
        UnaryOp::Abs => {
            // |x| is x where x >= 0 and -x where x <= 0; across zero its one-sided derivatives
            // are +-x'.
            let d = if a.v.lo >= 0.0 {
                a.d
            } else if a.v.hi <= 0.0 {
                -a.d
            } else {
                let m = a.d.mag();
                Interval::new(-m, m)
            };
            Dual { v: a.v.abs(), d }
        }
        UnaryOp::Sign => stepwise(a.v.sign()),
        UnaryOp::Not => stepwise(Interval::boolean(a.v.truth().map(|t| !t))),
    }
}

fn binary(op: BinaryOp, a: Dual, b: Dual) -> Dual {
    match op {
        BinaryOp::Add => Dual { v: a.v + b.v, d: a.d + b.d },
        BinaryOp::Mul => Dual { v: a.v * b.v, d: a.d * b.v + a.v * b.d },
        BinaryOp::Div => {
            let q = a.v / b.v;
            Dual { v: q, d: (a.d - q * b.d) / b.v }
        }
        BinaryOp::Pow => pow(a, b),
        BinaryOp::PowLog => pow_log(a, b),
        BinaryOp::Atan2 => {
            // d atan2(y, x) = (x y' - y x') / (x^2 + y^2).
            let num = b.v * a.d - a.v * b.d;
            Dual { v: a.v.atan2(b.v), d: num / (a.v.square() + b.v.square()) }
        }
        BinaryOp::Hypot => {
            let h = a.v.hypot(b.v);
            Dual { v: h, d: (a.v * a.d + b.v * b.d) / h }
        }
        BinaryOp::Min | BinaryOp::Max => {
            let first = if op == BinaryOp::Min { a.v.hi < b.v.lo } else { a.v.lo > b.v.hi };
            let second = if op == BinaryOp::Min { b.v.hi < a.v.lo } else { b.v.lo > a.v.hi };
            let v = if op == BinaryOp::Min { a.v.min(b.v) } else { a.v.max(b.v) };
            // Where either may be the smaller, the derivative is one of theirs.
            let d = if first {
                a.d
            } else if second {
                b.d
            } else {
                a.d.hull(b.d)
            };
            Dual { v, d }
        }
        BinaryOp::Lt => stepwise(a.v.lt(b.v)),
        BinaryOp::Le => stepwise(a.v.le(b.v)),
        BinaryOp::And | BinaryOp::Or => {
            let (x, y) = (a.v.truth(), b.v.truth());
            let truth = if op == BinaryOp::And {
                match (x, y) {
                    (Some(false), _) | (_, Some(false)) => Some(false),
                    (Some(true), Some(true)) => Some(true),
                    _ => None,
                }
            } else {
                match (x, y) {
                    (Some(true), _) | (_, Some(true)) => Some(true),
                    (Some(false), Some(false)) => Some(false),
                    _ => None,
                }
            };
            stepwise(Interval::boolean(truth))
        }
    }
}

/// `a ^ b`: by a constant `c`, `c a^(c - 1) a'`; else `a^b (b' ln a + b a' / a)`.
fn pow(a: Dual, b: Dual) -> Dual {
    let v = a.v.pow(b.v);
    let constant_exponent = b.v.is_point() && b.d == Interval::point(0.0);
    let d = if constant_exponent {
        let c = b.v.lo;
        if c == 0.0 {
            Interval::point(0.0)
        } else if c == 2.0 {
            (a.v * a.d).scale(2.0)
        } else {
            a.v.powf(c - 1.0).scale(c) * a.d
        }
    } else {
        v * (b.d * a.v.ln() + b.v * a.d / a.v)
    };
    Dual { v, d }
}

/// `a^b ln(a)` over a box where `a > 0` as the product it is there; where `a` may be 0 or
/// negative, anything (the limit at 0 and NaN below it are not enclosed: differentiation makes
/// this operation, and a guard, which is not differentiated with respect to parameters before it
/// is enclosed, never holds it).
fn pow_log(a: Dual, b: Dual) -> Dual {
    if a.v.lo > 0.0 {
        let l = Dual { v: a.v.ln(), d: a.d / a.v };
        let p = pow(a, b);
        Dual { v: p.v * l.v, d: p.d * l.v + p.v * l.d }
    } else {
        Dual { v: Interval::ENTIRE, d: Interval::ENTIRE }
    }
}

fn select(c: Dual, a: Dual, b: Dual) -> Dual {
    match c.v.truth() {
        Some(true) => a,
        Some(false) => b,
        // Either branch: the value may jump from one to the other.
        None => Dual { v: a.v.hull(b.v), d: Interval::ENTIRE },
    }
}

/// Knot positions `k` (integers) of a lookup with `lo < k < hi`, clamped to `[0, last]`.
fn knots_inside(lo: f64, hi: f64, last: usize) -> std::ops::RangeInclusive<usize> {
    let first = (lo.floor() + 1.0).max(0.0);
    let end = (hi.ceil() - 1.0).min(last as f64);
    if first.is_nan() || end.is_nan() || first > end {
        #[allow(clippy::reversed_empty_ranges)]
        return 1..=0;
    }
    first as usize..=end as usize
}

/// A lookup over a knot-position interval: the values at its ends and at every knot inside for
/// `pwl` (piecewise linear), with the slopes of the segments it overlaps times the position's
/// rate; the hull of the segments' values for `pwc` and `pwl`'s slope (piecewise constant).
fn lookup(l: Lookup, pos: Dual, u: &[f64]) -> Dual {
    let len = u.len();
    let hull_of = |values: &mut dyn Iterator<Item = f64>| {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for v in values {
            lo = lo.min(v);
            hi = hi.max(v);
        }
        Interval::new(lo, hi)
    };
    if !pos.v.is_bounded() {
        let all = match l.kind {
            LookupKind::Pwl | LookupKind::Pwc => hull_of(&mut u.iter().copied()),
            LookupKind::PwlSlope => hull_of(&mut u.windows(2).map(|w| w[1] - w[0]).chain([0.0])),
        };
        return Dual { v: all.inflate(4.0 * f64::EPSILON * all.mag()), d: Interval::ENTIRE };
    }
    let (lo, hi) = (pos.v.lo, pos.v.hi);
    match l.kind {
        LookupKind::Pwl if len >= 2 => {
            let (a, b) = (apply_lookup(l.kind, lo, u), apply_lookup(l.kind, hi, u));
            let inner = knots_inside(lo, hi, len - 1).map(|k| u[k]);
            let v = hull_of(&mut [a, b].into_iter().chain(inner));
            // The interpolation rounds three times at the scale of its knots' values.
            let v = v.inflate(4.0 * f64::EPSILON * v.mag());
            // Segments overlapped (`floor(lo) .. floor(hi)` within `[0, len - 2]`), and 0 where
            // the position is outside the knots (held values).
            let first = lo.floor().clamp(0.0, (len - 2) as f64) as usize;
            let last = hi.floor().clamp(0.0, (len - 2) as f64) as usize;
            let outside = lo < 0.0 || hi > (len - 1) as f64;
            let slopes = hull_of(&mut (first..=last).map(|k| u[k + 1] - u[k]).chain(outside.then_some(0.0)));
            let slopes = slopes.inflate(2.0 * f64::EPSILON * slopes.mag());
            Dual { v, d: slopes * pos.d }
        }
        _ => {
            let (first, last) = (lo.floor(), hi.floor());
            let segment = |k: f64| k.clamp(0.0, (len.max(1) - 1) as f64) as usize;
            let v = match l.kind {
                LookupKind::PwlSlope if len >= 2 => {
                    let inside = (segment(first)..=segment(last).min(len - 2)).map(|k| u[k + 1] - u[k]);
                    let outside = lo < 0.0 || hi >= (len - 1) as f64;
                    hull_of(&mut inside.chain(outside.then_some(0.0)))
                }
                LookupKind::PwlSlope => Interval::point(0.0),
                // A one-element `pwl` is its element; `pwc` is its segment's value.
                _ => hull_of(&mut (segment(first)..=segment(last)).map(|k| u[k])),
            };
            // One segment: a constant; more: it jumps at the knots between.
            let v = v.inflate(2.0 * f64::EPSILON * v.mag());
            let d = if segment(first) == segment(last) { Interval::point(0.0) } else { Interval::ENTIRE };
            Dual { v, d }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::eval::eval_one;
    use proptest::prelude::*;

    /// A store with `g = sin(3 x0) * x1 + exp(-t) - abs(x0 - 0.5) / (2 + x1^2) + min(x0, x1)^2`.
    fn guard() -> (ExprStore, ExprId) {
        let mut s = ExprStore::new();
        let (x0, x1, t) = (s.state(0), s.state(1), s.time());
        let c = |s: &mut ExprStore, v: f64| s.constant(v);
        let three = c(&mut s, 3.0);
        let a = s.mul(three, x0);
        let sin = s.unary(UnaryOp::Sin, a);
        let term1 = s.mul(sin, x1);
        let nt = s.neg(t);
        let term2 = s.unary(UnaryOp::Exp, nt);
        let half = c(&mut s, 0.5);
        let nh = s.neg(half);
        let shifted = s.add(x0, nh);
        let ab = s.unary(UnaryOp::Abs, shifted);
        let two = c(&mut s, 2.0);
        let sq = s.binary(BinaryOp::Pow, x1, two);
        let den = s.add(two, sq);
        let q = s.div(ab, den);
        let nq = s.neg(q);
        let mn = s.binary(BinaryOp::Min, x0, x1);
        let mn2 = s.binary(BinaryOp::Pow, mn, two);
        let sum1 = s.add(term1, term2);
        let sum2 = s.add(sum1, nq);
        let g = s.add(sum2, mn2);
        (s, g)
    }

    proptest! {
        /// Along a trajectory inside the box (states affine in time with rates inside the rate
        /// box), the guard's values lie in `G` and its central differences in time lie in `G'`
        /// (up to the difference's own error).
        #[test]
        fn enclosures_hold_the_values_and_rates_of_trajectories_inside_the_box(
            x0 in -2.0f64..2.0, x1 in -2.0f64..2.0, r0 in -3.0f64..3.0, r1 in -3.0f64..3.0,
            t0 in 0.0f64..5.0, w in 1e-4f64..0.3,
        ) {
            let (store, g) = guard();
            let enc = Enclosure::new(&store, g);
            prop_assert_eq!(enc.states(), &[0, 1]);
            let path = |t: f64| [x0 + r0 * (t - t0), x1 + r1 * (t - t0)];
            let (a, b) = (path(t0), path(t0 + w));
            // The path's own rounding may put an interior point an ulp outside its ends' hull.
            let hull = |i: usize| Interval::widened(a[i].min(b[i]), a[i].max(b[i]), 2);
            let x = [hull(0), hull(1)];
            let dx = [Interval::point(r0), Interval::point(r1)];
            let out = enc.eval(Interval::new(t0, t0 + w), &x, &dx, &[], &mut Vec::new());
            for k in 0..=20 {
                let t = t0 + w * k as f64 / 20.0;
                let v = eval_one(&store, g, t, &path(t), &[]);
                prop_assert!(out.v.contains(v), "{v} outside {:?}", out.v);
                let h = 1e-7;
                if t - h >= t0 && t + h <= t0 + w {
                    let fd = (eval_one(&store, g, t + h, &path(t + h), &[]) - eval_one(&store, g, t - h, &path(t - h), &[])) / (2.0 * h);
                    prop_assert!(out.d.inflate(1e-5 * (1.0 + fd.abs())).contains(fd), "{fd} outside {:?}", out.d);
                }
            }
        }
    }

    #[test]
    fn a_derivative_clear_of_zero_is_found_on_a_narrow_box_and_jumps_are_unknown() {
        let mut s = ExprStore::new();
        let x = s.state(0);
        let sin = s.unary(UnaryOp::Sin, x);
        let enc = Enclosure::new(&s, sin);
        // sin(x) moving at 1 over x in [0.1, 0.2]: increasing, values in [sin 0.1, sin 0.2].
        let out = enc.eval(
            Interval::point(0.0),
            &[Interval::new(0.1, 0.2)],
            &[Interval::point(1.0)],
            &[],
            &mut Vec::new(),
        );
        assert!(out.d.clear_of_zero(0.0) && out.d.lo > 0.97 && out.d.hi < 1.0);
        assert!(out.v.lo <= 0.1f64.sin() && out.v.hi >= 0.2f64.sin() && out.v.width() < 0.11);
        // sign(x) over an interval holding zero may jump.
        let sg = s.unary(UnaryOp::Sign, x);
        let out = Enclosure::new(&s, sg).eval(
            Interval::point(0.0),
            &[Interval::new(-0.1, 0.2)],
            &[Interval::point(1.0)],
            &[],
            &mut Vec::new(),
        );
        assert_eq!(out.d, Interval::ENTIRE);
        assert_eq!(out.v, Interval::new(-1.0, 1.0));
    }

    #[test]
    fn lookups_enclose_their_knots_and_slopes() {
        // pwl over u = [0, 2, 1, 5] at positions [0.5, 2.5]: values 1 (at 0.5), 2, 1 (knots), 3
        // (at 2.5); slopes 2, -1, 4.
        let u = [0.0, 2.0, 1.0, 5.0];
        let l = Lookup { kind: LookupKind::Pwl, base: 0, len: 4 };
        let out = lookup(l, Dual { v: Interval::new(0.5, 2.5), d: Interval::point(1.0) }, &u);
        assert!(out.v.contains(1.0) && out.v.contains(3.0) && out.v.lo > 0.99 && out.v.hi < 3.01);
        assert!(out.d.contains(-1.0) && out.d.contains(4.0) && out.d.lo > -1.01 && out.d.hi < 4.01);
        // pwc within one segment is constant; over a knot it may jump.
        let c = Lookup { kind: LookupKind::Pwc, base: 0, len: 4 };
        let one = lookup(c, Dual { v: Interval::new(1.2, 1.8), d: Interval::point(1.0) }, &u);
        assert!(one.v.contains(2.0) && one.v.width() < 1e-14 && one.d == Interval::point(0.0));
        let two = lookup(c, Dual { v: Interval::new(1.2, 2.8), d: Interval::point(1.0) }, &u);
        assert!(two.v.contains(1.0) && two.v.contains(2.0) && two.d == Interval::ENTIRE);
    }
}
