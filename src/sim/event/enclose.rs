//! Stage 5 (sim), events: enclosures of a guard over pieces of a step, the proof behind
//! detection (docs/language.md, rule 2). Along a step's dense output every state is a polynomial
//! in `s = (t - t0) / h` (`Interpolant::component_form`); over a piece `[a, b]` of the step its
//! Bernstein coefficients bound it and their differences bound its rate (a polynomial lies in
//! the convex hull of its Bernstein coefficients). A guard that reads the states is then enclosed
//! by interval code over those bounds (`HybridSystem::guard_enclosure`); an affine guard is
//! itself a polynomial along the step (`Interpolant::linear_form`), bounded the same way with no
//! overestimation. [`Pieces`] walks a step's pieces in time order, halving those the enclosures
//! do not decide.
//!
//! Knows the `Interpolant` seam and interval arithmetic; nothing of the integrator.

use crate::interval::Interval;
use crate::sim::method::poly::{BINOMIAL, CAP};

const EPS: f64 = f64::EPSILON;
/// Pieces narrower than this fraction of the step (`2^-40`) are not split: the resolution of the
/// walk (docs/language.md, rule 2).
pub(crate) const MIN_WIDTH: f64 = 1.0 / (1u64 << 40) as f64;
/// Splits of one piece's ancestors at most (a bound on the stack; uneven splits go deeper than
/// halvings before reaching [`MIN_WIDTH`]).
pub(crate) const MAX_DEPTH: u8 = 200;
/// Splits at an estimate (uneven) at most this deep; halvings below.
const UNEVEN_DEPTH: u8 = 24;
/// A split at an estimate is kept this fraction of the piece from its ends (`2^-20`), so that
/// every split shrinks both parts ([`Pieces::split_at`]).
const EDGE: f64 = 1.0 / (1u64 << 20) as f64;
/// A split at an estimate keeps this fraction of the piece on either side of it as a part of its
/// own ([`Pieces::split_at`]).
const AROUND: f64 = 1.0 / 256.0;
/// Pieces a guard's walk over one step examines at most; beyond, the step is retried shorter.
/// A walk to one tangency at [`MAX_DEPTH`] takes about 4 per level.
pub(crate) const MAX_PIECES: usize = 2048;

/// `C(i, k) / C(d, k)` for `k <= i <= d < CAP`: the weights that turn power-basis coefficients
/// on the unit interval into Bernstein coefficients, `beta_i = sum_{k <= i} w[d][i][k] r_k`.
const BERNSTEIN: [[[f64; CAP]; CAP]; CAP] = {
    let mut t = [[[0.0; CAP]; CAP]; CAP];
    let mut d = 0;
    while d < CAP {
        let mut i = 0;
        while i <= d {
            let mut k = 0;
            while k <= i {
                t[d][i][k] = BINOMIAL[i][k] / BINOMIAL[d][k];
                k += 1;
            }
            i += 1;
        }
        d += 1;
    }
    t
};

/// A polynomial on a piece of a step in the Bernstein basis, from which its hull and its rate's
/// hull are read ([`poly_hull`]).
pub(crate) struct Bernstein {
    /// The Bernstein coefficients less the value at the piece's start.
    beta: [f64; CAP],
    len: usize,
    /// The value at the piece's start.
    base: f64,
    /// Bounds on the rounding of `base` and of the coefficients' differences from it.
    base_err: f64,
    moving_err: f64,
    /// The piece's start and width (in units of the step).
    a: f64,
    w: f64,
}

/// The polynomial `q` (power basis in `s`, `len` coefficients) on the piece `[a, b]` of
/// `[0, 1]`, in the Bernstein basis of `u` with `s = a + (b - a) u`: the Taylor shift by `a`
/// (repeated synthetic division), the scaling by `w = b - a`, the conversion by the weights of
/// [`BERNSTEIN`]. The rounding: a shifted coefficient `r_k` is computed with an error below
/// `4 len eps m_k`, `m_k` the same computation in magnitudes, and a Bernstein coefficient (weights
/// in `[0, 1]`) adds at most `len eps sum |r_k|`. The value `r_0` at `a` is kept out of the
/// coefficients, so the rate's bound does not grow as the piece shrinks: the errors of `r_k`,
/// `k >= 1`, carry the factor `w^k`.
pub(crate) fn bernstein(q: &[f64; CAP], len: usize, a: f64, b: f64) -> Bernstein {
    let len = len.clamp(1, CAP);
    let d = len - 1;
    let w = b - a;
    let (mut r, mut m) = (*q, [0.0; CAP]);
    for (mk, qk) in m.iter_mut().zip(q).take(len) {
        *mk = qk.abs();
    }
    if a != 0.0 {
        // Taylor shift: r(s + a), one synthetic division per coefficient.
        for i in 0..d {
            for j in (i..d).rev() {
                r[j] += a * r[j + 1];
                m[j] += a.abs() * m[j + 1];
            }
        }
    }
    if w != 1.0 {
        let mut scale = w;
        for k in 1..len {
            r[k] *= scale;
            m[k] *= scale.abs();
            scale *= w;
        }
    }
    let n = len as f64;
    let moving_err: f64 = (1..len).map(|k| 4.0 * n * EPS * m[k] + n * EPS * r[k].abs()).sum();
    let base_err = 4.0 * n * EPS * m[0];
    let weights = &BERNSTEIN[d];
    let mut beta = [0.0; CAP];
    for i in 1..len {
        beta[i] = (1..=i).map(|k| weights[i][k] * r[k]).sum();
    }
    Bernstein { beta, len, base: r[0], base_err, moving_err, a, w }
}

impl Bernstein {
    /// The hull of the polynomial over the piece.
    pub fn value(&self) -> Interval {
        let (lo, hi) = self.beta[..self.len]
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &b| (l.min(b), h.max(b)));
        (Interval::new(lo, hi) + Interval::point(self.base)).inflate(self.base_err + self.moving_err)
    }

    /// The hull of its derivative `dq/ds` over the piece: `d / w` times the hull of the
    /// coefficients' differences.
    pub fn rate(&self, q: &[f64; CAP]) -> Interval {
        let (len, d) = (self.len, self.len - 1);
        if d == 0 {
            return Interval::point(0.0);
        }
        if self.w.is_nan() || self.w <= 0.0 {
            // A piece of no width: the derivative's value there.
            let a = self.a;
            let at: f64 = (1..len).map(|k| k as f64 * q[k] * a.powi(k as i32 - 1)).sum();
            let size: f64 = (1..len).map(|k| k as f64 * (q[k] * a.powi(k as i32 - 1)).abs()).sum();
            return Interval::point(at).inflate(4.0 * len as f64 * EPS * size);
        }
        let (lo, hi) = self.beta[..len]
            .windows(2)
            .map(|p| p[1] - p[0])
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| (l.min(v), h.max(v)));
        Interval::new(lo, hi).inflate(2.0 * self.moving_err).scale(d as f64 / self.w)
    }
}

impl Bernstein {
    /// The signs of the Bernstein coefficients of `offset + q` on the piece ([`Signs`]): each
    /// counted when it is beyond `band` plus the rounding of the conversion (the bound the hull
    /// uses) and of the sum with `offset`.
    pub fn signs(&self, offset: f64, band: f64) -> Signs {
        let len = self.len;
        if len < 2 {
            return Signs::Undecided;
        }
        let start = offset + self.base;
        let size = self.beta[..len].iter().fold(start.abs() + offset.abs(), |m, b| m.max(b.abs()));
        let tol = band + self.base_err + self.moving_err + 4.0 * EPS * size;
        let sign = |c: f64| {
            if c > tol {
                1
            } else if c < -tol {
                -1
            } else {
                0
            }
        };
        let first = sign(start);
        let mut changes = 0u8;
        let mut prev = first;
        for &b in &self.beta[1..len] {
            let s = sign(start + b);
            if s == 0 {
                return Signs::Undecided;
            }
            if prev != 0 && s != prev {
                changes += 1;
                if changes > 1 {
                    return Signs::Undecided;
                }
            }
            prev = s;
        }
        match (first, changes) {
            (0, c) => Signs::FromZero { changes: c },
            (_, 0) => Signs::Clear,
            (_, 1) => Signs::OneChange,
            _ => Signs::Undecided,
        }
    }

    /// Where on the piece (in the step's units) the derivative's control polygon first changes
    /// sign: an estimate of the polynomial's first extremum there (NaN where it keeps its sign),
    /// the point a walk splits a piece at that its rate does not prove monotone. A tiny bounce at
    /// the start of a long step is then cut off in a few splits, where halving took one per
    /// factor two of the step.
    pub fn extremum_estimate(&self) -> f64 {
        let len = self.len;
        if len < 3 {
            return f64::NAN;
        }
        let d1 = (len - 2) as f64;
        let diffs = self.beta[..len].windows(2).map(|p| p[1] - p[0]);
        let mut prev: Option<f64> = None;
        for (i, c) in diffs.enumerate() {
            if let Some(p) = prev {
                if p * c < 0.0 || c == 0.0 {
                    let u = (i as f64 - 1.0 + p / (p - c)) / d1;
                    return self.a + u * self.w;
                }
            }
            prev = Some(c);
        }
        f64::NAN
    }
}

/// The signs of a piece's Bernstein coefficients ([`Bernstein::signs`]), each beyond its rounding
/// and a band about zero. By the variation-diminishing property of the Bernstein basis (a
/// polynomial has at most as many roots inside a piece as its coefficients change sign, and as
/// many modulo 2), they decide a piece without its rate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Signs {
    /// All coefficients clear of the band with one sign: so is the polynomial on the piece.
    Clear,
    /// Both end coefficients (the values at the piece's ends) and all others clear of the band,
    /// changing sign exactly once: the polynomial crosses zero, and each level of the band, exactly
    /// once inside the piece, so it is decided by its ends as a monotone piece is.
    OneChange,
    /// The first coefficient (the value at the piece's start) within the band, all others clear of
    /// it, changing sign `changes` times (0 or 1) among themselves: beyond the band's neighbourhood
    /// of the start the polynomial keeps the sign of the second coefficient (0), or crosses zero
    /// once (1).
    FromZero {
        /// Sign changes among the coefficients after the first.
        changes: u8,
    },
    /// Anything else: a coefficient within the band, or more sign changes.
    Undecided,
}

/// The hull over `s` in `[a, b]` (within `[0, 1]`) of the polynomial `q` (power basis,
/// `len` coefficients) and of its derivative `dq/ds` ([`bernstein`]).
pub(crate) fn poly_hull(q: &[f64; CAP], len: usize, a: f64, b: f64) -> (Interval, Interval) {
    let piece = bernstein(q, len, a, b);
    (piece.value(), piece.rate(q))
}

/// The pieces of a step (in units of the step, `s` in `[0, 1]`) a guard's walk has still to
/// examine, in time order: a stack whose top is the earliest. Reused from step to step.
#[derive(Clone, Debug, Default)]
pub(crate) struct Pieces {
    stack: Vec<(f64, f64, u8)>,
    examined: usize,
}

impl Pieces {
    /// Starts a walk over `[from, to]`.
    pub fn start(&mut self, from: f64, to: f64) {
        self.stack.clear();
        self.examined = 0;
        if from < to {
            self.stack.push((from, to, 0));
        }
    }

    /// The earliest piece left, `(a, b, depth)`; `None` when the walk is over.
    pub fn next(&mut self) -> Option<(f64, f64, u8)> {
        let piece = self.stack.pop()?;
        self.examined += 1;
        Some(piece)
    }

    /// Whether the walk has examined [`MAX_PIECES`] pieces.
    pub fn exhausted(&self) -> bool {
        self.examined >= MAX_PIECES
    }

    /// Splits `[a, b]` at `m` (NaN, or below `UNEVEN_DEPTH` splits deep: its middle), kept
    /// [`EDGE`] of the piece from its ends (so that every split shrinks both parts): both parts are examined, the
    /// earlier first. Returns `false` (nothing split) when the piece is narrower than
    /// [`MIN_WIDTH`], at [`MAX_DEPTH`], or the walk is exhausted.
    ///
    /// At an estimate (an extremum's), the piece is cut in three instead, the middle part
    /// [`AROUND`] of the piece on either side of it (at most half the distance to the nearer
    /// end): the extremum inside a part short enough for
    /// its value to be clear of zero, the outer parts monotone, where cutting at the estimate
    /// itself left the extremum at an end of both parts, neither monotone, each split again
    /// (a ball's step over its apex took four pieces more).
    pub fn split_at(&mut self, a: f64, b: f64, m: f64, depth: u8) -> bool {
        let w = b - a;
        // Uneven splits only for the first levels, so that halvings reach `MIN_WIDTH` well
        // within `MAX_DEPTH` whatever the estimates.
        let uneven = !m.is_nan() && depth < UNEVEN_DEPTH;
        let m = if uneven { m.clamp(a + w * EDGE, b - w * EDGE) } else { 0.5 * (a + b) };
        if w <= MIN_WIDTH || depth >= MAX_DEPTH || self.exhausted() || !(m > a && m < b) {
            return false;
        }
        // The part around the estimate: AROUND of the piece, or half the distance to the nearer
        // end where that is shorter (an extremum near a piece's end, a tiny bounce at a long
        // step's start, is then cut out in one split, not after a split at the clamp).
        let around = (AROUND * w).min(0.5 * (m - a)).min(0.5 * (b - m));
        let (lo, hi) = (m - around, m + around);
        if uneven && lo > a && hi < b {
            self.stack.push((hi, b, depth + 1));
            self.stack.push((lo, hi, depth + 1));
            self.stack.push((a, lo, depth + 1));
        } else {
            self.stack.push((m, b, depth + 1));
            self.stack.push((a, m, depth + 1));
        }
        true
    }

    /// Splits `[a, b]` in two at `m` (its middle when `m` is NaN), kept [`EDGE`] of the piece from
    /// its ends, the earlier part examined first; `false` (nothing split) as [`Self::split_at`].
    /// For a piece whose decision needs only the cut at `m` (a guard leaving zero at the piece's
    /// start, then crossing it once: cut at its extremum, each part is decided by its signs).
    pub fn split_in_two(&mut self, a: f64, b: f64, m: f64, depth: u8) -> bool {
        let w = b - a;
        let m = if m.is_nan() { 0.5 * (a + b) } else { m.clamp(a + w * EDGE, b - w * EDGE) };
        if w <= MIN_WIDTH || depth >= MAX_DEPTH || self.exhausted() || !(m > a && m < b) {
            return false;
        }
        self.stack.push((m, b, depth + 1));
        self.stack.push((a, m, depth + 1));
        true
    }

    /// Ends the walk.
    pub fn stop(&mut self) {
        self.stack.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn eval(q: &[f64], s: f64) -> f64 {
        q.iter().rev().fold(0.0, |acc, c| acc * s + c)
    }

    #[test]
    fn polynomial_hulls_enclose_values_and_rates_on_every_piece() {
        // (s - 0.3)(s - 0.6)(s + 1)^2 (s - 2) expanded, degree 5, and a degree-7 wiggle.
        let quintic = [0.36, 0.54, -1.48, -0.84, 0.1, 1.0];
        let septic = [0.0, 1.0, -8.0, 20.0, -15.0, -3.0, 7.0, -1.5];
        for q in [&quintic[..], &septic[..]] {
            let mut c = [0.0; CAP];
            c[..q.len()].copy_from_slice(q);
            let dq: Vec<f64> = (1..q.len()).map(|k| k as f64 * q[k]).collect();
            for (a, b) in [(0.0, 1.0), (0.2, 0.35), (0.5, 0.5 + 1e-9), (0.9, 1.0), (0.0, 0.01)] {
                let (v, r) = poly_hull(&c, q.len(), a, b);
                for k in 0..=64 {
                    let s = a + (b - a) * k as f64 / 64.0;
                    assert!(v.contains(eval(q, s)), "{q:?} [{a}, {b}] at {s}: {v:?}");
                    assert!(r.contains(eval(&dq, s)), "{q:?} [{a}, {b}] rate at {s}: {r:?}");
                }
                // Tight on a narrow piece: within a few times the variation there.
                if b - a < 0.02 {
                    let spread = (eval(q, b) - eval(q, a)).abs();
                    assert!(v.width() <= 4.0 * spread + 1e-12, "{v:?} vs {spread}");
                }
            }
        }
    }

    #[test]
    fn a_polynomial_clear_of_zero_is_proved_so_on_the_whole_step() {
        // 1 + s - 3 s^2 / 2 stays above 0.5 on [0, 1]: its Bernstein coefficients 1, 1.5, 0.5.
        let mut c = [0.0; CAP];
        c[..3].copy_from_slice(&[1.0, 1.0, -1.5]);
        let (v, r) = poly_hull(&c, 3, 0.0, 1.0);
        assert!(v.clear_of_zero(0.4));
        // Its rate goes from 1 to -2: not monotone on the step, monotone on [0.5, 1].
        assert!(!r.clear_of_zero(0.0));
        assert!(poly_hull(&c, 3, 0.5, 1.0).1.clear_of_zero(0.0));
    }

    /// The signs of the coefficients claim a number of roots on a piece: check every claim on
    /// thousands of random polynomials (degrees 2 to 7, roots inside the step and out) against
    /// the sign changes of dense samples of the polynomial itself.
    #[test]
    fn coefficient_signs_never_claim_fewer_roots_than_the_polynomial_has() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut uniform = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut claims = [0usize; 4];
        for _ in 0..4000 {
            // A product of linear factors with roots in [-0.5, 1.5] times a scale: the roots
            // where the signs must see them.
            let degree = 2 + (uniform() * 6.0) as usize;
            let mut c = [0.0; CAP];
            c[0] = 1.0;
            for k in 0..degree {
                let root = -0.5 + 2.0 * uniform();
                for j in (0..=k + 1).rev() {
                    c[j] = if j > 0 { c[j - 1] } else { 0.0 } - root * c[j];
                }
            }
            let scale = 10f64.powf(6.0 * uniform() - 3.0) * if uniform() < 0.5 { -1.0 } else { 1.0 };
            c.iter_mut().for_each(|v| *v *= scale);
            // The guard less its start value, as the walk hands it over: the offset is `q(0)`.
            let offset = c[0];
            let mut q = c;
            q[0] = 0.0;
            let a = 0.8 * uniform();
            let b = a + (1.0 - a) * uniform().max(1e-3);
            let piece = bernstein(&q, degree + 1, a, b);
            let values: Vec<f64> =
                (0..=2000).map(|k| eval(&c[..=degree], a + (b - a) * k as f64 / 2000.0)).collect();
            let changes = values.windows(2).filter(|w| w[0] * w[1] < 0.0).count();
            match piece.signs(offset, 0.0) {
                Signs::Clear => {
                    claims[0] += 1;
                    assert_eq!(changes, 0, "{c:?} on [{a}, {b}]");
                }
                Signs::OneChange => {
                    claims[1] += 1;
                    assert_eq!(changes, 1, "{c:?} on [{a}, {b}]");
                }
                Signs::FromZero { changes: n } => {
                    claims[2] += 1;
                    // Beyond the start, at most `n` changes (within round-off of the start the
                    // sign is the band's).
                    let beyond = values[1..].windows(2).filter(|w| w[0] * w[1] < 0.0).count();
                    assert!(beyond <= n as usize, "{c:?} on [{a}, {b}]: {beyond} > {n}");
                }
                Signs::Undecided => claims[3] += 1,
            }
        }
        // Each kind of claim is exercised.
        assert!(claims[0] > 100 && claims[1] > 100 && claims[3] > 100, "{claims:?}");
    }

    #[test]
    fn a_guard_leaving_zero_is_told_from_one_that_returns() {
        // s (1 - s) on [0, 1]: leaves zero and comes back to it at the end; the end coefficient
        // is zero, so nothing is claimed. s (1.2 - s): leaves, never returns on [0, 1].
        // s (0.8 - s): leaves and crosses once.
        let cases = [(1.0, None), (1.2, Some(0u8)), (0.8, Some(1u8))];
        for (r, claim) in cases {
            let mut c = [0.0; CAP];
            c[..3].copy_from_slice(&[0.0, r, -1.0]);
            let signs = bernstein(&c, 3, 0.0, 1.0).signs(0.0, 1e-12);
            match claim {
                Some(n) => assert_eq!(signs, Signs::FromZero { changes: n }, "r = {r}"),
                None => assert_eq!(signs, Signs::Undecided, "r = {r}"),
            }
        }
        // Cut at the extremum, the piece that crosses gives two decided parts.
        let mut c = [0.0; CAP];
        c[..3].copy_from_slice(&[0.0, 0.8, -1.0]);
        let piece = bernstein(&c, 3, 0.0, 1.0);
        let m = piece.extremum_estimate();
        assert!((m - 0.4).abs() < 1e-12, "{m}");
        assert_eq!(bernstein(&c, 3, 0.0, m).signs(0.0, 1e-12), Signs::FromZero { changes: 0 });
        assert_eq!(bernstein(&c, 3, m, 1.0).signs(0.0, 1e-12), Signs::OneChange);
    }

    #[test]
    fn pieces_come_in_time_order_and_stop_at_the_depth_limit() {
        let mut p = Pieces::default();
        p.start(0.0, 1.0);
        let (a, b, d) = p.next().unwrap();
        assert!(p.split_at(a, b, f64::NAN, d));
        let (a, b, d) = p.next().unwrap();
        assert_eq!((a, b), (0.0, 0.5));
        assert!(p.split_at(a, b, f64::NAN, d));
        let order: Vec<(f64, f64)> = std::iter::from_fn(|| p.next().map(|(a, b, _)| (a, b))).collect();
        assert_eq!(order, [(0.0, 0.25), (0.25, 0.5), (0.5, 1.0)]);
        assert!(!p.split_at(0.0, 1.0, f64::NAN, MAX_DEPTH));
        assert!(!p.split_at(0.5, 0.5 + MIN_WIDTH, f64::NAN, 3));
        // An uneven split at a point near an end keeps EDGE on that side, the part around it
        // half the distance to the end on either side.
        p.start(0.0, 1.0);
        let (a, b, d) = p.next().unwrap();
        assert!(p.split_at(a, b, 1e-9, d));
        let order: Vec<(f64, f64)> = std::iter::from_fn(|| p.next().map(|(a, b, _)| (a, b))).collect();
        assert_eq!(order, [(0.0, 0.5 * EDGE), (0.5 * EDGE, 1.5 * EDGE), (1.5 * EDGE, 1.0)]);
        // Near an end but farther than EDGE: cut out at the estimate, in three.
        p.start(0.0, 1.0);
        let (a, b, d) = p.next().unwrap();
        assert!(p.split_at(a, b, 1e-4, d));
        let order: Vec<(f64, f64)> = std::iter::from_fn(|| p.next().map(|(a, b, _)| (a, b))).collect();
        let (lo, hi) = (1e-4 - 0.5e-4, 1e-4 + 0.5e-4);
        assert_eq!(order, [(0.0, lo), (lo, hi), (hi, 1.0)]);
        // At an estimate inside: three parts in time order, the middle one around it, covering
        // the piece.
        p.start(0.0, 1.0);
        let (a, b, d) = p.next().unwrap();
        assert!(p.split_at(a, b, 0.5, d));
        let order: Vec<(f64, f64)> = std::iter::from_fn(|| p.next().map(|(a, b, _)| (a, b))).collect();
        assert_eq!(order, [(0.0, 0.5 - AROUND), (0.5 - AROUND, 0.5 + AROUND), (0.5 + AROUND, 1.0)]);
    }
}
