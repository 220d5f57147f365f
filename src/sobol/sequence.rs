//! The scrambled Sobol' sequence: Joe and Kuo's direction numbers, linear matrix scrambling and a
//! digital shift (the scrambling SciPy's `qmc.Sobol` applies), seeded. Point `i` is computed from
//! `i` alone, so a shard of a design can start anywhere. Pure functions of numbers.
//!
//! Why not a crate: `sobol` 1.0.2 (Joe-Kuo numbers) generates only sequentially and does not
//! scramble, and pulls in a gzip decoder for its tables; `sobol_burley` is `f32` with at most 2^16
//! points. What is needed is small: 64 direction numbers per dimension, XORed.

use rand_chacha::ChaCha8Rng;
use rand_core::{Rng as _, SeedableRng as _};

use super::joe_kuo::JOE_KUO;

/// Bits of every coordinate: points are 64-bit binary fractions, read as `f64` from their top 53.
const BITS: usize = 64;

/// The dimensions the embedded table covers (dimension 1 plus Joe and Kuo's rows).
pub const MAX_DIMS: usize = JOE_KUO.len() + 1;

/// The ChaCha8 stream the scrambling draws from (a sweep's `--samples` use stream 0, the
/// bootstrap stream 2), so one seed gives unrelated numbers to each.
const SCRAMBLE_STREAM: u64 = 1;

/// A scrambled Sobol' sequence in `dims` dimensions.
#[derive(Clone, Debug)]
pub struct Sobol {
    /// Per dimension the `BITS` scrambled direction numbers, `v[k]` for bit `k` of the index's
    /// Gray code (bit 0 the lowest).
    directions: Vec<[u64; BITS]>,
    /// Per dimension the digital shift XORed onto every point (0 unscrambled).
    shifts: Vec<u64>,
}

/// The unscrambled direction numbers of dimension `dim` (0-based): `V_k = m_k 2^(64 - k)` with
/// the `m_k` from the table and Bratley and Fox's recurrence beyond it.
fn directions(dim: usize) -> [u64; BITS] {
    let mut m = [0u64; BITS + 1];
    if dim == 0 {
        m[1..].fill(1);
    } else {
        let (s, a, init) = JOE_KUO[dim - 1];
        let s = s as usize;
        m[1..=s].copy_from_slice(init);
        for k in s + 1..=BITS {
            // m_k = 2 a_1 m_(k-1) ^ 4 a_2 m_(k-2) ^ ... ^ 2^(s-1) a_(s-1) m_(k-s+1) ^ 2^s m_(k-s) ^ m_(k-s);
            // m_k < 2^k, so m_64 still fits in 64 bits (the shifts drop nothing that matters:
            // 2^s m_(k-s) < 2^k).
            let mut value = m[k - s] ^ (m[k - s] << s);
            for i in 1..s {
                if (a >> (s - 1 - i)) & 1 == 1 {
                    value ^= m[k - i] << i;
                }
            }
            m[k] = value;
        }
    }
    let mut v = [0u64; BITS];
    for k in 1..=BITS {
        v[k - 1] = m[k] << (BITS - k);
    }
    v
}

impl Sobol {
    /// The unscrambled sequence (its first point is the origin).
    ///
    /// # Panics
    /// When `dims` exceeds [`MAX_DIMS`] (callers check it first).
    pub fn plain(dims: usize) -> Sobol {
        assert!(dims <= MAX_DIMS, "{dims} Sobol' dimensions, the table has {MAX_DIMS}");
        Sobol { directions: (0..dims).map(directions).collect(), shifts: vec![0; dims] }
    }

    /// The sequence scrambled by `seed`: for each dimension a random lower triangular binary
    /// matrix with unit diagonal multiplies every direction number (linear matrix scrambling:
    /// the digital net stays a net, with random digits), then a random shift is XORed on.
    ///
    /// The random bits are ChaCha8 keyed by the seed's eight little-endian bytes followed by 24
    /// zero bytes, stream 1; per dimension in order, 64 words for the matrix rows (row `r`, the
    /// output bit `r` counted from the top, keeps the top `r` bits of its word below the diagonal)
    /// and one word for the shift.
    pub fn scrambled(dims: usize, seed: u64) -> Sobol {
        let mut plain = Sobol::plain(dims);
        let mut key = [0u8; 32];
        key[..8].copy_from_slice(&seed.to_le_bytes());
        let mut rng = ChaCha8Rng::from_seed(key);
        rng.set_stream(SCRAMBLE_STREAM);
        for (v, shift) in plain.directions.iter_mut().zip(&mut plain.shifts) {
            let mut rows = [0u64; BITS];
            for (r, row) in rows.iter_mut().enumerate() {
                let diagonal = 1u64 << (BITS - 1 - r);
                // The bits above the diagonal's (more significant: earlier columns) are random.
                let below = if r == 0 { 0 } else { !((diagonal << 1).wrapping_sub(1)) };
                *row = (rng.next_u64() & below) | diagonal;
            }
            for d in v.iter_mut() {
                let mut out = 0u64;
                for (r, row) in rows.iter().enumerate() {
                    out |= u64::from((row & *d).count_ones() & 1) << (BITS - 1 - r);
                }
                *d = out;
            }
            *shift = rng.next_u64();
        }
        plain
    }

    /// The number of dimensions.
    pub fn dims(&self) -> usize {
        self.directions.len()
    }

    /// The 64-bit integer coordinates of point `i` (Gray-code order, as Antonov and Saleev and
    /// SciPy generate them: point `i` XORs the direction numbers of the bits of `i ^ (i >> 1)`).
    pub fn integers(&self, i: u64, out: &mut [u64]) {
        let gray = i ^ (i >> 1);
        for ((v, shift), x) in self.directions.iter().zip(&self.shifts).zip(out.iter_mut()) {
            let mut acc = *shift;
            let mut bits = gray;
            while bits != 0 {
                acc ^= v[bits.trailing_zeros() as usize];
                bits &= bits - 1;
            }
            *x = acc;
        }
    }

    /// Point `i` in the open unit cube: coordinate `(top 53 bits + 1/2) / 2^53`, the centre of
    /// its cell, never 0 or 1 (so an unbounded prior's quantile stays finite).
    pub fn point(&self, i: u64, out: &mut [f64]) {
        let mut ints = [0u64; MAX_DIMS];
        let ints = &mut ints[..self.dims()];
        self.integers(i, ints);
        for (x, u) in ints.iter().zip(out.iter_mut()) {
            *u = ((x >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_points_are_the_published_ones() {
        // The unscrambled sequence's first points in dimensions 1-3 (as in Joe and Kuo's and
        // SciPy's `Sobol(d=3, scramble=False)`): 0, 1/2, then 3/4 1/4 1/4, 1/4 3/4 3/4, ...
        let s = Sobol::plain(3);
        let expect = [
            [0.0, 0.0, 0.0],
            [0.5, 0.5, 0.5],
            [0.75, 0.25, 0.25],
            [0.25, 0.75, 0.75],
            [0.375, 0.375, 0.625],
            [0.875, 0.875, 0.125],
            [0.625, 0.125, 0.875],
            [0.125, 0.625, 0.375],
        ];
        let mut x = [0u64; 3];
        for (i, row) in expect.iter().enumerate() {
            s.integers(i as u64, &mut x);
            let got: Vec<f64> = x.iter().map(|v| *v as f64 / 2f64.powi(64)).collect();
            assert_eq!(got, row.to_vec(), "point {i}");
        }
    }

    /// The first 2^m points of a Sobol' sequence hit each of the 2^m intervals `[k, k + 1) / 2^m`
    /// of every coordinate exactly once, and each of the 2^m cells of the 2^a x 2^(m-a) grids
    /// of the first two dimensions exactly once (they form a (0, m, 2)-net); linear scrambling and
    /// a shift keep both.
    #[test]
    fn every_dimension_is_stratified_plain_and_scrambled() {
        let m = 10;
        for s in [Sobol::plain(MAX_DIMS), Sobol::scrambled(MAX_DIMS, 7)] {
            let mut seen = vec![vec![0u32; 1 << m]; MAX_DIMS];
            let mut x = vec![0u64; MAX_DIMS];
            let mut pair = vec![vec![0u32; 1 << m]; m + 1];
            for i in 0..1u64 << m {
                s.integers(i, &mut x);
                for (d, v) in x.iter().enumerate() {
                    seen[d][(v >> (64 - m)) as usize] += 1;
                }
                for (a, cells) in pair.iter_mut().enumerate() {
                    let hi = if a == 0 { 0 } else { x[0] >> (64 - a) };
                    let lo = if a == m { 0 } else { x[1] >> (64 - (m - a)) };
                    cells[((hi << (m - a)) | lo) as usize] += 1;
                }
            }
            for (d, counts) in seen.iter().enumerate() {
                assert!(counts.iter().all(|c| *c == 1), "dimension {d}");
            }
            for (a, cells) in pair.iter().enumerate() {
                assert!(cells.iter().all(|c| *c == 1), "2^{a} x 2^{} cells", m - a);
            }
        }
    }

    #[test]
    fn a_seed_fixes_the_scramble_and_another_changes_it() {
        let (a, b, c) = (Sobol::scrambled(4, 1), Sobol::scrambled(4, 1), Sobol::scrambled(4, 2));
        let (mut x, mut y, mut z) = ([0.0; 4], [0.0; 4], [0.0; 4]);
        a.point(5, &mut x);
        b.point(5, &mut y);
        c.point(5, &mut z);
        assert_eq!(x, y);
        assert_ne!(x, z);
        assert!(x.iter().all(|u| *u > 0.0 && *u < 1.0));
    }
}
