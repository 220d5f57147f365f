//! Stage 5 (sim): small polynomials on the unit interval, held on the stack: the polynomial
//! through samples, its derivative, and all its real roots in `(0, 1)`. The event detector
//! (`event/detect.rs`) uses them for an affine guard along a step's dense output, which is a
//! polynomial of the interpolant's degree. Nothing here allocates: a step may examine thousands
//! of guards.

/// Most coefficients of a [`Poly`]: degree 7, DOP853's dense output.
pub const CAP: usize = 8;

/// A polynomial of degree below [`CAP`] in the power basis: `c[k]` multiplies `s^k`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Poly {
    c: [f64; CAP],
    len: usize,
}

/// The real roots of a [`Poly`] in `(0, 1)`, ascending.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Roots {
    s: [f64; CAP],
    len: usize,
}

impl Roots {
    pub fn as_slice(&self) -> &[f64] {
        &self.s[..self.len]
    }

    fn push(&mut self, s: f64) {
        // A polynomial of degree d has at most d roots, and d < CAP.
        if self.len < CAP {
            self.s[self.len] = s;
            self.len += 1;
        }
    }
}

/// The `k`-th of `count` Chebyshev points of the first kind, mapped onto `[0, 1]` in ascending
/// order: interpolation through them is well conditioned, unlike through equally spaced points.
pub(crate) fn chebyshev_node(k: usize, count: usize) -> f64 {
    let angle = (2 * k + 1) as f64 * std::f64::consts::PI / (2 * count) as f64;
    0.5 - 0.5 * angle.cos()
}

impl Poly {
    /// The polynomial through `(nodes[k], values[k])` (distinct nodes, at most [`CAP`] of them):
    /// Newton's divided differences, expanded into the power basis. For Chebyshev points of
    /// `[0, 1]` its values there are the samples to a few units of their round-off.
    pub fn through(nodes: &[f64], values: &[f64]) -> Poly {
        let n = nodes.len().min(values.len()).min(CAP);
        let mut dd = [0.0; CAP];
        dd[..n].copy_from_slice(&values[..n]);
        for j in 1..n {
            for i in (j..n).rev() {
                dd[i] = (dd[i] - dd[i - 1]) / (nodes[i] - nodes[i - j]);
            }
        }
        // Horner on the Newton form: p = dd[n-1], then p = p (s - x_k) + dd[k], k = n-2 .. 0.
        let mut c = [0.0; CAP];
        let mut len = usize::from(n > 0);
        if n > 0 {
            c[0] = dd[n - 1];
        }
        for k in (0..n.saturating_sub(1)).rev() {
            // Multiply by (s - x_k): the new c[i] is c[i-1] - x_k c[i], from the top down.
            c[len] = 0.0;
            for i in (1..=len).rev() {
                c[i] = c[i - 1] - nodes[k] * c[i];
            }
            c[0] = -nodes[k] * c[0] + dd[k];
            len += 1;
        }
        Poly { c, len }
    }

    /// The polynomial with coefficients `c[..len]` (`len <= CAP`).
    pub fn from_coefficients(c: &[f64; CAP], len: usize) -> Poly {
        Poly { c: *c, len: len.min(CAP) }
    }

    /// Writes the coefficients to `out`; returns how many there are.
    pub fn write_to(&self, out: &mut [f64; CAP]) -> usize {
        *out = self.c;
        self.len
    }

    /// Adds `slope s`.
    pub fn add_linear(&mut self, slope: f64) {
        self.len = self.len.max(2);
        self.c[1] += slope;
    }

    /// The coefficients up to the last one that counts: a leading coefficient below the
    /// round-off of the whole (`eps sum |c_k|`, the error of any evaluation on `[0, 1]`) changes
    /// no value there. An interpolant of degree 7 of a parabola has six such tails of ~1e-17,
    /// whose roots would only be round-off.
    fn coefficients(&self) -> &[f64] {
        let total: f64 = self.c[..self.len].iter().map(|c| c.abs()).sum();
        let mut len = self.len;
        while len > 1 && self.c[len - 1].abs() <= f64::EPSILON * total {
            len -= 1;
        }
        if len == 1 && self.c[0] == 0.0 {
            len = 0;
        }
        &self.c[..len]
    }

    pub fn derivative(&self) -> Poly {
        let mut c = [0.0; CAP];
        let len = self.len.saturating_sub(1);
        for (k, (d, &a)) in c.iter_mut().zip(&self.c[1..]).enumerate().take(len) {
            *d = (k + 1) as f64 * a;
        }
        Poly { c, len }
    }

    /// The value at `s` (Horner).
    pub fn eval(&self, s: f64) -> f64 {
        self.c[..self.len].iter().rev().fold(0.0, |acc, &c| acc * s + c)
    }

    /// The real roots in `(0, 1)`, ascending. Between consecutive roots of the derivative (found
    /// the same way) the polynomial is monotone, so each sign change there is one root, bisected
    /// to adjacent floating-point numbers. A root of even multiplicity (a touch) is a root of the
    /// derivative instead; a root at a root of the derivative where the value is exactly zero is
    /// kept.
    pub fn roots_01(&self) -> Roots {
        let mut out = Roots::default();
        let a = self.coefficients();
        if !may_vanish_01(a) {
            return out;
        }
        match a.len() {
            0 | 1 => return out,
            2 => {
                let s = -a[0] / a[1];
                if s > 0.0 && s < 1.0 {
                    out.push(s);
                }
                return out;
            }
            _ => {}
        }
        let slope = self.derivative();
        let turning = slope.roots_01();
        let mut points = [0.0; CAP + 1];
        points[1..=turning.len].copy_from_slice(turning.as_slice());
        points[turning.len + 1] = 1.0;
        for w in points[..turning.len + 2].windows(2) {
            let (lo, hi) = (w[0], w[1]);
            let (flo, fhi) = (self.eval(lo), self.eval(hi));
            if flo == 0.0 {
                if lo > 0.0 {
                    out.push(lo);
                }
                continue;
            }
            if fhi == 0.0 || flo.signum() == fhi.signum() {
                continue;
            }
            out.push(self.root_in(&slope, lo, hi, flo));
        }
        out
    }
}

impl Poly {
    /// The root in `(lo, hi)`, where the polynomial is monotone and changes sign (`flo` its value
    /// at `lo`): Newton's method from the middle, kept inside the shrinking bracket and halving it
    /// where a Newton step would leave it, until the iterate stops moving or the bracket holds
    /// adjacent doubles. A handful of iterations where bisection alone took some fifty.
    fn root_in(&self, slope: &Poly, mut lo: f64, mut hi: f64, flo: f64) -> f64 {
        let mut x = 0.5 * (lo + hi);
        // Each pass at least halves the bracket or moves by Newton; 1100 halvings span any two
        // doubles, so the count only guards against a pathological cycle.
        for _ in 0..1100 {
            let fx = self.eval(x);
            if fx == 0.0 {
                return x;
            }
            if fx.signum() == flo.signum() {
                lo = x;
            } else {
                hi = x;
            }
            let mid = 0.5 * (lo + hi);
            if !(mid > lo && mid < hi) {
                break;
            }
            let newton = x - fx / slope.eval(x);
            let next = if newton > lo && newton < hi { newton } else { mid };
            if next == x {
                break;
            }
            x = next;
        }
        x
    }
}

/// Pascal's triangle up to `CAP - 1`, as doubles (exact: the largest is C(7, 3) = 35).
const BINOMIAL: [[f64; CAP]; CAP] = {
    let mut t = [[0.0; CAP]; CAP];
    let mut i = 0;
    while i < CAP {
        t[i][0] = 1.0;
        let mut k = 1;
        while k <= i {
            t[i][k] = t[i - 1][k - 1] + if k < i { t[i - 1][k] } else { 0.0 };
            k += 1;
        }
        i += 1;
    }
    t
};

/// Whether the polynomial `a` (power basis) may vanish on `[0, 1]`: false when its Bernstein
/// coefficients there all have one strict sign, since the polynomial lies in their convex hull.
/// `O(d^2)`, so most guards (a speed that keeps its sign over the step) need no root isolation.
fn may_vanish_01(a: &[f64]) -> bool {
    let d = match a.len() {
        0 => return true,
        len => len - 1,
    };
    // b_i = sum_{k <= i} C(i, k) / C(d, k) a_k.
    let binom = &BINOMIAL;
    let mut sign = 0.0;
    for i in 0..=d {
        let b: f64 = (0..=i).map(|k| binom[i][k] / binom[d][k] * a[k]).sum();
        if !(b != 0.0) || (sign != 0.0 && b.signum() != sign) {
            return true;
        }
        sign = b.signum();
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    fn samples(f: impl Fn(f64) -> f64, count: usize) -> Poly {
        let nodes: Vec<f64> = (0..count).map(|k| chebyshev_node(k, count)).collect();
        let values: Vec<f64> = nodes.iter().map(|&s| f(s)).collect();
        Poly::through(&nodes, &values)
    }

    #[test]
    fn a_polynomial_through_its_samples_is_itself() {
        // (s - 0.1)(s - 0.35)(s - 0.8) s^2 + 1, degree 5, from six Chebyshev points.
        let f = |s: f64| (s - 0.1) * (s - 0.35) * (s - 0.8) * s * s + 1.0;
        let a = samples(f, 6);
        for s in [0.0, 0.2, 0.5, 0.77, 1.0] {
            assert!((a.eval(s) - f(s)).abs() < 1e-13, "{s}");
        }
        // Its derivative, against the product rule's closed form at one point.
        let df = |s: f64| {
            let (a, b, c) = (s - 0.1, s - 0.35, s - 0.8);
            (b * c + a * c + a * b) * s * s + 2.0 * a * b * c * s
        };
        assert!((a.derivative().eval(0.6) - df(0.6)).abs() < 1e-12);
    }

    #[test]
    fn roots_in_the_unit_interval_are_all_found_and_no_others() {
        // Four roots in (0, 1), two close together, and two outside it: degree 6 from 7 points.
        let roots = [0.1, 0.11, 0.5, 0.93];
        let f = |s: f64| roots.iter().fold(1.0, |acc, r| acc * (s - r)) * (s + 1.0) * (s - 2.0);
        let found = samples(f, 7).roots_01();
        assert_eq!(found.as_slice().len(), 4, "{found:?}");
        for (f, r) in found.as_slice().iter().zip(roots) {
            assert!((f - r).abs() < 1e-12, "{f} vs {r}");
        }
        // s^2 + 1 has none; a degree-7 polynomial with seven roots in (0, 1) has all seven.
        assert!(samples(|s| s * s + 1.0, 3).roots_01().as_slice().is_empty());
        let seven: Vec<f64> = (1..=7).map(|k| k as f64 / 8.0).collect();
        let found = samples(|s| seven.iter().fold(1.0, |acc, r| acc * (s - r)), 8).roots_01();
        assert_eq!(found.as_slice().len(), 7, "{found:?}");
        for (f, r) in found.as_slice().iter().zip(&seven) {
            assert!((f - r).abs() < 1e-12, "{f} vs {r}");
        }
    }

    #[test]
    fn bernstein_signs_rule_out_roots_only_where_there_are_none() {
        // 1 + s - 3 s^2 (roots outside [0, 1]? 1 + 1 - 3 = -1 at s = 1: one root inside).
        assert!(may_vanish_01(&[1.0, 1.0, -3.0]));
        // (s - 0.5)^2 + 0.3 > 0 on [0, 1], though its power coefficients change sign; the test is
        // conservative: (s - 0.5)^2 + 0.01 > 0 too, but its middle Bernstein coefficient is not.
        assert!(!may_vanish_01(&[0.55, -1.0, 1.0]));
        assert!(may_vanish_01(&[0.26, -1.0, 1.0]));
        // A constant, a zero and a NaN.
        assert!(!may_vanish_01(&[2.0]));
        assert!(may_vanish_01(&[0.0]));
        assert!(may_vanish_01(&[f64::NAN, 1.0]));
    }

    #[test]
    fn a_near_touch_has_two_roots_or_none_and_its_turning_point_either_way() {
        // (s - 0.4)^2 (s + 1) -/+ 1e-6: the cubic dips 1e-6 below zero near 0.4 (two roots, 1e-6 /
        // sqrt(1.4) apart from 0.4 to first order) or stays 1e-6 above it (none); its derivative's
        // root in (0, 1) is 0.4 exactly either way.
        let dip = |e: f64| samples(move |s| (s - 0.4) * (s - 0.4) * (s + 1.0) + e, 4);
        let below = dip(-1e-6).roots_01();
        assert_eq!(below.as_slice().len(), 2, "{below:?}");
        let half_width = (1e-6f64 / 1.4).sqrt();
        for (r, sign) in below.as_slice().iter().zip([-1.0, 1.0]) {
            assert!((r - (0.4 + sign * half_width)).abs() < 1e-6, "{r}");
        }
        assert!(dip(1e-6).roots_01().as_slice().is_empty());
        let turning = dip(1e-6).derivative().roots_01();
        assert_eq!(turning.as_slice().len(), 1);
        assert!((turning.as_slice()[0] - 0.4).abs() < 1e-12);
    }
}
