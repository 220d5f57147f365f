//! Sobol' indices from the outputs of a Saltelli design: first order (Saltelli 2010), total
//! (Jansen 1999), second order (Saltelli 2002), and their bootstrap standard errors, the
//! estimators and the centring SALib's `sobol.analyze` uses, so both give the same numbers on the
//! same rows. Pure arithmetic over one output's values; knows no model.

use rand_chacha::ChaCha8Rng;
use rand_core::{Rng as _, SeedableRng as _};

/// The ChaCha8 stream the bootstrap draws from (the scramble uses stream 1).
const BOOTSTRAP_STREAM: u64 = 2;

/// One output's values over a design: `block` rows per base point in SALib's order
/// (`A, AB_1 .. AB_D, [BA_1 .. BA_D], B`), base point after base point. Row `r`'s value is
/// `y[r * stride + offset]`, so several outputs can share one row-major array.
#[derive(Clone, Copy, Debug)]
pub struct Blocks<'a> {
    /// The values, row-major.
    pub y: &'a [f64],
    /// Values per row in `y` (the outputs), and which of them this is.
    pub stride: usize,
    /// Which value of a row is this output's.
    pub offset: usize,
    /// Varied parameters.
    pub d: usize,
    /// Whether the blocks hold the BA rows.
    pub second_order: bool,
}

impl Blocks<'_> {
    fn block(&self) -> usize {
        if self.second_order {
            2 * self.d + 2
        } else {
            self.d + 2
        }
    }

    /// Base points.
    pub fn n(&self) -> usize {
        self.y.len() / self.stride / self.block()
    }

    /// Row `j` of base point `b`'s block.
    pub fn at(&self, b: usize, j: usize) -> f64 {
        self.y[(b * self.block() + j) * self.stride + self.offset]
    }
}

/// Point estimates of the indices.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Indices {
    /// First order, one per varied parameter.
    pub s1: Vec<f64>,
    /// Total, one per varied parameter.
    pub st: Vec<f64>,
    /// Second order `(i, j, S2_ij)` for `i < j`, row by row; empty without second order.
    pub s2: Vec<(usize, usize, f64)>,
    /// The variance the indices divide by: of the A and B rows together (population variance).
    pub variance: f64,
}

/// The indices over the base points `points` (repeats allowed: a bootstrap resample), every
/// value first centred by `centre`.
///
/// With `V` the variance of the A and B values together, per varied parameter `i`:
/// `S1_i = mean(f_B (f_ABi - f_A)) / V`, `ST_i = mean((f_A - f_ABi)^2) / (2 V)`, and for `i < j`
/// `S2_ij = mean(f_BAi f_ABj - f_A f_B) / V - S1_i - S1_j` (SALib's `first_order`, `total_order`,
/// `second_order`). A zero variance (an output that does not vary) gives NaN indices, not a
/// division's infinity passed off as a number.
pub fn indices(blocks: &Blocks<'_>, points: &[u32], centre: f64) -> Indices {
    let d = blocks.d;
    let n = points.len() as f64;
    let (mut sum, mut sum_sq) = (0.0, 0.0);
    let mut first = vec![0.0; d];
    let mut total = vec![0.0; d];
    let pairs = if blocks.second_order { d * (d - 1) / 2 } else { 0 };
    let mut joint = vec![0.0; pairs];
    let mut ab_sum = 0.0;
    for &b in points {
        let at = |j: usize| blocks.at(b as usize, j) - centre;
        let a = at(0);
        let bb = at(blocks.block() - 1);
        sum += a + bb;
        sum_sq += a * a + bb * bb;
        ab_sum += a * bb;
        for i in 0..d {
            let abi = at(1 + i);
            first[i] += bb * (abi - a);
            total[i] += (a - abi) * (a - abi);
        }
        if blocks.second_order {
            let mut k = 0;
            for i in 0..d {
                let bai = at(1 + d + i);
                for j in i + 1..d {
                    joint[k] += bai * at(1 + j);
                    k += 1;
                }
            }
        }
    }
    let mean = sum / (2.0 * n);
    let variance = (sum_sq / (2.0 * n) - mean * mean).max(0.0);
    let scale = if variance > 0.0 { 1.0 / variance } else { f64::NAN };
    let s1: Vec<f64> = first.iter().map(|f| f / n * scale).collect();
    let st = total.iter().map(|t| t / (2.0 * n) * scale).collect();
    let mut s2 = Vec::with_capacity(pairs);
    if blocks.second_order {
        let mut k = 0;
        for i in 0..d {
            for j in i + 1..d {
                s2.push((i, j, (joint[k] - ab_sum) / n * scale - s1[i] - s1[j]));
                k += 1;
            }
        }
    }
    Indices { s1, st, s2, variance }
}

/// The mean of every value of the base points `points` (all rows of their blocks): the centre
/// SALib subtracts (it standardises the whole output vector first). Centring leaves the indices'
/// expectations alone and removes the mean's share of their sampling noise.
pub fn centre(blocks: &Blocks<'_>, points: &[u32]) -> f64 {
    let m = blocks.block();
    let total: f64 = points.iter().map(|&b| (0..m).map(|j| blocks.at(b as usize, j)).sum::<f64>()).sum();
    total / (points.len() * m) as f64
}

/// Bootstrap standard errors of [`indices`]: `resamples` times, as many base points as `points`
/// are drawn from them with replacement, and the indices recomputed (with the same centre); the
/// error is the standard deviation of those estimates (divisor `resamples - 1`). NaN with fewer
/// than two resamples.
///
/// Draws: ChaCha8 keyed by the seed's eight little-endian bytes then zeros, stream 2; a draw of
/// one of `n` base points is the high 64 bits of `next_u64() * n` (a bias below `n / 2^64`).
pub fn bootstrap(blocks: &Blocks<'_>, points: &[u32], centre: f64, resamples: usize, seed: u64) -> Indices {
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&seed.to_le_bytes());
    let mut rng = ChaCha8Rng::from_seed(key);
    rng.set_stream(BOOTSTRAP_STREAM);
    let n = points.len();
    let mut counts = vec![0u32; n];
    let mut sample = Vec::with_capacity(n);
    let mut sum = Indices::default();
    let mut sum_sq = Indices::default();
    for _ in 0..resamples {
        counts.fill(0);
        for _ in 0..n {
            counts[((rng.next_u64() as u128 * n as u128) >> 64) as usize] += 1;
        }
        // The drawn points in ascending order (each as often as drawn): the same multiset, read
        // in memory order rather than at random (a random walk over the values cost more than
        // the runs of a small model).
        sample.clear();
        for (&point, &count) in points.iter().zip(&counts) {
            sample.extend(std::iter::repeat_n(point, count as usize));
        }
        let est = indices(blocks, &sample, centre);
        accumulate(&mut sum, &mut sum_sq, &est);
    }
    let r = resamples as f64;
    let sd = |s: f64, q: f64| {
        if resamples < 2 {
            f64::NAN
        } else {
            ((q - s * s / r) / (r - 1.0)).max(0.0).sqrt()
        }
    };
    Indices {
        s1: sum.s1.iter().zip(&sum_sq.s1).map(|(s, q)| sd(*s, *q)).collect(),
        st: sum.st.iter().zip(&sum_sq.st).map(|(s, q)| sd(*s, *q)).collect(),
        s2: sum.s2.iter().zip(&sum_sq.s2).map(|(s, q)| (s.0, s.1, sd(s.2, q.2))).collect(),
        variance: sd(sum.variance, sum_sq.variance),
    }
}

fn accumulate(sum: &mut Indices, sum_sq: &mut Indices, est: &Indices) {
    if sum.s1.is_empty() {
        *sum = Indices { s1: vec![0.0; est.s1.len()], st: vec![0.0; est.st.len()], ..est.clone() };
        sum.s2.iter_mut().for_each(|s| s.2 = 0.0);
        sum.variance = 0.0;
        *sum_sq = sum.clone();
    }
    let add = |acc: &mut [f64], acc_sq: &mut [f64], v: &[f64]| {
        for ((a, q), v) in acc.iter_mut().zip(acc_sq.iter_mut()).zip(v) {
            *a += v;
            *q += v * v;
        }
    };
    add(&mut sum.s1, &mut sum_sq.s1, &est.s1);
    add(&mut sum.st, &mut sum_sq.st, &est.st);
    for ((a, q), v) in sum.s2.iter_mut().zip(sum_sq.s2.iter_mut()).zip(&est.s2) {
        a.2 += v.2;
        q.2 += v.2 * v.2;
    }
    sum.variance += est.variance;
    sum_sq.variance += est.variance * est.variance;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A design's values written by hand: the additive `f = x1 + 2 x2` on the points of a
    /// 2-parameter block, where every estimator is exact algebra.
    #[test]
    fn an_additive_function_gives_its_variance_shares() {
        // f(x1, x2) = x1 + 2 x2 at A = (a1, a2), B = (b1, b2): AB_1 = (b1, a2), AB_2 = (a1, b2).
        let bases = [((0.1, 0.7), (0.9, 0.2)), ((0.4, 0.3), (0.6, 0.8)), ((0.8, 0.5), (0.2, 0.1))];
        let f = |x1: f64, x2: f64| x1 + 2.0 * x2;
        let mut y = Vec::new();
        for ((a1, a2), (b1, b2)) in bases {
            y.extend([f(a1, a2), f(b1, a2), f(a1, b2), f(b1, b2)]);
        }
        let blocks = Blocks { y: &y, stride: 1, offset: 0, d: 2, second_order: false };
        let all = [0, 1, 2];
        let c = centre(&blocks, &all);
        let est = indices(&blocks, &all, c);
        // By hand: ST_i = mean((f_A - f_ABi)^2) / (2 V) = c_i^2 mean((a_i - b_i)^2) / (2 V).
        let ab: Vec<f64> = bases.iter().flat_map(|((a1, a2), (b1, b2))| [f(*a1, *a2), f(*b1, *b2)]).collect();
        let m = ab.iter().sum::<f64>() / 6.0;
        let v = ab.iter().map(|x| (x - m).powi(2)).sum::<f64>() / 6.0;
        assert!((est.variance - v).abs() < 1e-15);
        let st1 = bases.iter().map(|((a1, _), (b1, _))| (a1 - b1).powi(2)).sum::<f64>() / 3.0 / (2.0 * v);
        let st2 =
            4.0 * bases.iter().map(|((_, a2), (_, b2))| (a2 - b2).powi(2)).sum::<f64>() / 3.0 / (2.0 * v);
        assert!((est.st[0] - st1).abs() < 1e-14 && (est.st[1] - st2).abs() < 1e-14, "{est:?}");
        // S1_1 = mean((f_B - c) (f_AB1 - f_A)) / V with f_AB1 - f_A = b1 - a1.
        let s1 = bases.iter().map(|((a1, _), (b1, b2))| (f(*b1, *b2) - c) * (b1 - a1)).sum::<f64>() / 3.0 / v;
        assert!((est.s1[0] - s1).abs() < 1e-14);
    }

    #[test]
    fn a_constant_output_has_no_indices() {
        let y = vec![2.0; 12];
        let blocks = Blocks { y: &y, stride: 1, offset: 0, d: 2, second_order: false };
        let est = indices(&blocks, &[0, 1, 2], 2.0);
        assert_eq!(est.variance, 0.0);
        assert!(est.s1.iter().chain(&est.st).all(|v| v.is_nan()));
    }

    #[test]
    fn second_order_lists_each_pair_once() {
        let d = 3;
        let y: Vec<f64> = (0..5 * (2 * d + 2)).map(|k| ((k * 7919) % 101) as f64).collect();
        let blocks = Blocks { y: &y, stride: 1, offset: 0, d, second_order: true };
        let all: Vec<u32> = (0..5).collect();
        let est = indices(&blocks, &all, centre(&blocks, &all));
        let pairs: Vec<(usize, usize)> = est.s2.iter().map(|s| (s.0, s.1)).collect();
        assert_eq!(pairs, [(0, 1), (0, 2), (1, 2)]);
        let se = bootstrap(&blocks, &all, 0.0, 50, 1);
        assert_eq!(se.s2.len(), 3);
        assert!(se.s1.iter().all(|s| s.is_finite() && *s > 0.0));
    }
}
