//! Stage 5 (sim): small polynomials on the unit interval, held on the stack: the polynomial
//! through samples, in the power basis. An affine guard along a step's dense output is one
//! (`Interpolant::linear_form`), which the event detector bounds piece by piece
//! (`event/enclose.rs`). Nothing here allocates: a step may examine thousands of guards.

/// Most coefficients of a [`Poly`]: degree 7, DOP853's dense output.
pub const CAP: usize = 8;

/// A polynomial of degree below [`CAP`] in the power basis: `c[k]` multiplies `s^k`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Poly {
    c: [f64; CAP],
    len: usize,
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

    /// The value at `s` (Horner), for tests.
    #[cfg(test)]
    pub fn eval(&self, s: f64) -> f64 {
        self.c[..self.len].iter().rev().fold(0.0, |acc, &c| acc * s + c)
    }

    /// Adds `slope s`.
    pub fn add_linear(&mut self, slope: f64) {
        self.len = self.len.max(2);
        self.c[1] += slope;
    }
}

/// Pascal's triangle up to `CAP - 1`, as doubles (exact: the largest is C(7, 3) = 35).
pub(crate) const BINOMIAL: [[f64; CAP]; CAP] = {
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
        let mut b = a;
        b.add_linear(2.0);
        assert!((b.eval(0.3) - f(0.3) - 0.6).abs() < 1e-13);
    }
}
