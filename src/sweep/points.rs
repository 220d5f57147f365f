//! Which parameter vectors a sweep runs: `--vary` specifications, full grids in a fixed order and
//! seeded uniform samples. Pure functions of numbers; knows no model and no simulation.

use rand_chacha::ChaCha8Rng;
use rand_core::{Rng as _, SeedableRng as _};

/// What one `--vary P=...` asks for, before the parameter's name is resolved.
#[derive(Clone, Debug, PartialEq)]
pub enum AxisSpec {
    /// `P=LO:HI:N`: N evenly spaced values from LO to HI, both included.
    Grid {
        /// The first value.
        lo: f64,
        /// The last value.
        hi: f64,
        /// How many.
        n: usize,
    },
    /// `P=V1,V2,...`: exactly these values, in this order.
    List(Vec<f64>),
    /// `P=LO:HI`: a range to sample from (with `--samples`).
    Range {
        /// The lower end.
        lo: f64,
        /// The upper end.
        hi: f64,
    },
    /// `P` alone: sample from the parameter's declared range (with `--samples`).
    Declared,
}

/// A parsed `--vary` flag.
#[derive(Clone, Debug, PartialEq)]
pub struct VarySpec {
    /// The parameter's name, as written.
    pub name: String,
    /// What it asks for.
    pub axis: AxisSpec,
}

/// A `--vary` text that does not parse (`hybc sweep`).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum VarySpecError {
    /// A number that is not a finite number.
    #[error("`{text}` is not a finite number")]
    NotANumber {
        /// The number as written.
        text: String,
    },
    /// A decimal a double cannot hold (`1e-400` would round to 0).
    #[error(transparent)]
    Unrepresentable(crate::number::NumberError),
    /// Not one of the shapes a `--vary` takes.
    #[error("`{text}`: expected P=LO:HI:N, P=LO:HI, P=V1,V2,... or P")]
    Shape {
        /// The text as written.
        text: String,
    },
    /// A grid count that is not a whole number from 2.
    #[error("`{text}`: the number of grid points must be an integer of at least 2")]
    GridCount {
        /// The text as written.
        text: String,
    },
    /// A range whose lower end is not below its upper end.
    #[error("`{text}`: LO must be below HI")]
    EmptyRange {
        /// The text as written.
        text: String,
    },
}

fn number(text: &str) -> Result<f64, VarySpecError> {
    use crate::number::NumberError;
    crate::number::parse_number(text.trim()).map_err(|e| match e {
        NumberError::TooSmall { .. } => VarySpecError::Unrepresentable(e),
        _ => VarySpecError::NotANumber { text: text.trim().to_string() },
    })
}

/// Parses one `--vary` value: `P=LO:HI:N`, `P=LO:HI`, `P=V1,V2,...` or `P`.
pub fn parse_vary(text: &str) -> Result<VarySpec, VarySpecError> {
    let shape = || VarySpecError::Shape { text: text.to_string() };
    let Some((name, values)) = text.split_once('=') else {
        let name = text.trim();
        if name.is_empty() || name.contains([':', ',']) {
            return Err(shape());
        }
        return Ok(VarySpec { name: name.to_string(), axis: AxisSpec::Declared });
    };
    let name = name.trim().to_string();
    if name.is_empty() || values.trim().is_empty() {
        return Err(shape());
    }
    let parts: Vec<&str> = values.split(':').collect();
    let axis = match parts.as_slice() {
        [lo, hi] | [lo, hi, _] => {
            let (lo, hi) = (number(lo)?, number(hi)?);
            if lo >= hi {
                return Err(VarySpecError::EmptyRange { text: text.to_string() });
            }
            match parts.get(2) {
                None => AxisSpec::Range { lo, hi },
                Some(n) => match n.trim().parse::<usize>() {
                    Ok(n) if n >= 2 => AxisSpec::Grid { lo, hi, n },
                    _ => return Err(VarySpecError::GridCount { text: text.to_string() }),
                },
            }
        }
        [list] => AxisSpec::List(list.split(',').map(number).collect::<Result<_, _>>()?),
        _ => return Err(shape()),
    };
    Ok(VarySpec { name, axis })
}

/// The value a fraction `s` in `[0, 1]` of the way from `lo` to `hi` (`lo < hi`), inside
/// `[lo, hi]` and finite for any finite ends, nondecreasing in `s`.
///
/// `lo + (hi - lo) s` where `hi - lo` is finite (so the values of ordinary ranges are the ones
/// hybc always printed); where it overflows (`-1e308..1e308`), half the width is stepped twice,
/// `lo + w s + w s` with `w = hi / 2 - lo / 2`: every operation is finite and rounding is
/// monotone in each operand, so the values still never decrease.
pub fn lerp(lo: f64, hi: f64, s: f64) -> f64 {
    let width = hi - lo;
    let v = if width.is_finite() {
        lo + width * s
    } else {
        let half = (hi * 0.5 - lo * 0.5) * s;
        lo + half + half
    };
    // Rounding can pass an end by an ulp; the range is closed.
    v.clamp(lo, hi)
}

/// The `i`-th of `n >= 2` evenly spaced values from `lo` to `hi`; index 0 is `lo` and `n - 1`
/// exactly `hi`.
pub fn even_value(lo: f64, hi: f64, i: usize, n: usize) -> f64 {
    let last = n.saturating_sub(1).max(1);
    if i >= last {
        hi
    } else {
        lerp(lo, hi, i as f64 / last as f64)
    }
}

/// `n >= 2` values from `lo` to `hi`; the ends are exactly `lo` and `hi`.
pub fn linspace(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n).map(|i| even_value(lo, hi, i, n)).collect()
}

/// One axis of a grid: its values, computed from the index rather than stored (an axis of
/// 10^7 evenly spaced values takes no memory).
#[derive(Clone, Debug, PartialEq)]
pub enum Axis {
    /// `n >= 2` evenly spaced values from `lo` to `hi`, both included.
    Even {
        /// The first value.
        lo: f64,
        /// The last value.
        hi: f64,
        /// How many.
        n: usize,
    },
    /// Exactly these values, in this order.
    List(Vec<f64>),
}

impl Axis {
    /// The number of values.
    pub fn len(&self) -> usize {
        match self {
            Axis::Even { n, .. } => *n,
            Axis::List(values) => values.len(),
        }
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The `i`-th value (`i < len`).
    pub fn value(&self, i: usize) -> f64 {
        match self {
            Axis::Even { lo, hi, n } => even_value(*lo, *hi, i, *n),
            Axis::List(values) => values[i],
        }
    }
}

/// The full grid over some axes, each point starting from a base vector. Point `i` is computed
/// alone, from `i` written in mixed radix (the last axis is the lowest digit), so a sweep never
/// holds its points and a shard can start anywhere.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid {
    base: Vec<f64>,
    axes: Vec<(usize, Axis)>,
    len: usize,
}

/// Too many points to count in a `usize`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("the number of points does not fit in 64 bits")]
pub struct TooManyPoints;

impl Grid {
    /// The grid over `axes` (parameter index, values) from `base`. Order: the first axis varies
    /// slowest, the last fastest (nested loops in flag order).
    pub fn new(base: Vec<f64>, axes: Vec<(usize, Axis)>) -> Result<Grid, TooManyPoints> {
        let len =
            axes.iter().try_fold(1usize, |acc, (_, a)| acc.checked_mul(a.len())).ok_or(TooManyPoints)?;
        Ok(Grid { base, axes, len })
    }

    /// Writes point `i < len` into `out` (as long as the base).
    pub fn fill(&self, mut i: usize, out: &mut [f64]) {
        out.copy_from_slice(&self.base);
        for (param, axis) in self.axes.iter().rev() {
            let n = axis.len();
            out[*param] = axis.value(i % n);
            i /= n;
        }
    }
}

/// `n` points drawn uniformly from ranges with a seed. Point `i` is computed alone: its values are
/// the `i * R`-th to `(i + 1) * R - 1`-th 64-bit outputs of the stream (`R` ranges), found by
/// seeking the counter-based generator, so they are the values a sequential draw gives.
///
/// The stream is fixed by the algorithm, not by a crate's choices: ChaCha8 keyed by the seed's
/// eight little-endian bytes followed by 24 zero bytes, stream 0; each value takes the top 53 bits
/// of one `next_u64` as `u` in `[0, 1)` and is [`lerp`]`(lo, hi, u)`, drawn point by point and
/// within a point in the order of `ranges`. So one seed gives the same points on every machine and
/// every version of hybc that keeps this description.
#[derive(Clone, Debug)]
pub struct Draws {
    base: Vec<f64>,
    ranges: Vec<(usize, f64, f64)>,
    n: usize,
    /// The ChaCha8 key (the generator is built per point: a key copy and a block, nothing to
    /// share between threads).
    key: [u8; 32],
}

impl Draws {
    /// `n` points from `base`, the parameters `ranges` (index, lo, hi) drawn with `seed`.
    pub fn new(base: Vec<f64>, ranges: Vec<(usize, f64, f64)>, n: usize, seed: u64) -> Draws {
        let mut key = [0u8; 32];
        key[..8].copy_from_slice(&seed.to_le_bytes());
        Draws { base, ranges, n, key }
    }

    /// Writes point `i < n` into `out` (as long as the base).
    pub fn fill(&self, i: usize, out: &mut [f64]) {
        out.copy_from_slice(&self.base);
        let mut rng = ChaCha8Rng::from_seed(self.key);
        // Two 32-bit words per value; a u64 read at an even word offset is the one a sequential
        // draw gives there.
        rng.set_word_pos(2 * i as u128 * self.ranges.len() as u128);
        for &(param, lo, hi) in &self.ranges {
            let u = (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
            out[param] = lerp(lo, hi, u);
        }
    }
}

/// The points of a sweep, each computed from its index.
#[derive(Clone, Debug)]
pub enum Points {
    /// A full grid over axes (`hybc sweep --vary P=LO:HI:N`, `P=V1,V2`).
    Grid(Grid),
    /// Seeded uniform draws (`hybc sweep --samples N`, Python's `hybc.Samples`).
    Draws(Draws),
    /// Explicit parameter vectors (Python's points), every one as long as the model's
    /// parameters.
    Rows(Vec<Vec<f64>>),
}

impl Points {
    /// The number of points.
    pub fn len(&self) -> usize {
        match self {
            Points::Grid(g) => g.len,
            Points::Draws(s) => s.n,
            Points::Rows(rows) => rows.len(),
        }
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// How many values a point has (the model's parameters).
    pub fn width(&self) -> usize {
        match self {
            Points::Grid(g) => g.base.len(),
            Points::Draws(s) => s.base.len(),
            Points::Rows(rows) => rows.first().map_or(0, Vec::len),
        }
    }

    /// Writes point `i < len` into `out` (`width` long).
    pub fn fill(&self, i: usize, out: &mut [f64]) {
        match self {
            Points::Grid(g) => g.fill(i, out),
            Points::Draws(s) => s.fill(i, out),
            Points::Rows(rows) => out.copy_from_slice(&rows[i]),
        }
    }

    /// Point `i < len`.
    pub fn point(&self, i: usize) -> Vec<f64> {
        let mut p = vec![0.0; self.width()];
        self.fill(i, &mut p);
        p
    }

    /// Every point, in order (for sweeps small enough to hold).
    pub fn to_vec(&self) -> Vec<Vec<f64>> {
        match self {
            Points::Rows(rows) => rows.clone(),
            _ => (0..self.len()).map(|i| self.point(i)).collect(),
        }
    }
}

/// The full grid over `axes` (parameter index, its values), each point starting from `base`.
/// Order: the first axis varies slowest, the last fastest (nested loops in flag order).
///
/// # Panics
/// When the number of points overflows a `usize` (it could not be held anyway).
pub fn full_grid(base: &[f64], axes: &[(usize, Vec<f64>)]) -> Vec<Vec<f64>> {
    let axes = axes.iter().map(|(p, v)| (*p, Axis::List(v.clone()))).collect();
    Points::Grid(Grid::new(base.to_vec(), axes).expect("a grid small enough to hold")).to_vec()
}

/// `n` points, each starting from `base` with every parameter of `ranges` (index, lo, hi) drawn
/// uniformly from `[lo, hi]`: [`Draws`], collected.
pub fn uniform_samples(base: &[f64], ranges: &[(usize, f64, f64)], n: usize, seed: u64) -> Vec<Vec<f64>> {
    Points::Draws(Draws::new(base.to_vec(), ranges.to_vec(), n, seed)).to_vec()
}

/// Points `indices` (a range of point numbers) of [`uniform_samples`]`(base, ranges, _, seed)`,
/// without drawing the points before them (each [`Draws`] point is computed from its index),
/// so a sweep can be sharded by index ranges (a Dask task draws only its own points) and the
/// shards concatenated equal the whole.
pub fn uniform_samples_from(
    base: &[f64],
    ranges: &[(usize, f64, f64)],
    seed: u64,
    indices: std::ops::Range<usize>,
) -> Vec<Vec<f64>> {
    let points = Points::Draws(Draws::new(base.to_vec(), ranges.to_vec(), indices.end, seed));
    indices.map(|i| points.point(i)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_shape() {
        let grid = parse_vary("e=0.1:0.9:5").expect("grid");
        assert_eq!(grid, VarySpec { name: "e".into(), axis: AxisSpec::Grid { lo: 0.1, hi: 0.9, n: 5 } });
        assert_eq!(parse_vary("h0=1, 2,3").expect("list").axis, AxisSpec::List(vec![1.0, 2.0, 3.0]));
        assert_eq!(parse_vary("g=9:10").expect("range").axis, AxisSpec::Range { lo: 9.0, hi: 10.0 });
        assert_eq!(parse_vary(" e ").expect("declared").axis, AxisSpec::Declared);
        assert!(matches!(parse_vary("e=1:0:3"), Err(VarySpecError::EmptyRange { .. })));
        assert!(matches!(parse_vary("e=0:1:1"), Err(VarySpecError::GridCount { .. })));
        assert!(matches!(parse_vary("e=0:1:x"), Err(VarySpecError::GridCount { .. })));
        assert!(matches!(parse_vary("e=0:nan"), Err(VarySpecError::NotANumber { .. })));
        assert!(matches!(parse_vary("e=0:1:2:3"), Err(VarySpecError::Shape { .. })));
        assert!(matches!(parse_vary("=1"), Err(VarySpecError::Shape { .. })));
        assert!(matches!(parse_vary("e="), Err(VarySpecError::Shape { .. })));
    }

    #[test]
    fn linspace_hits_both_ends_exactly() {
        let v = linspace(0.1, 0.7, 7);
        assert_eq!(v.len(), 7);
        assert_eq!((v[0], v[6]), (0.1, 0.7));
        for w in v.windows(2) {
            approx::assert_relative_eq!(w[1] - w[0], 0.1, max_relative = 1e-12);
        }
    }

    #[test]
    fn huge_ranges_stay_finite_in_range_and_monotone() {
        for (lo, hi) in [(-1e308, 1e308), (-f64::MAX, f64::MAX), (-f64::MAX, 0.0), (1.0, f64::MAX)] {
            for n in [2, 3, 5, 1000] {
                let v = linspace(lo, hi, n);
                assert_eq!((v[0], v[n - 1]), (lo, hi), "{lo}..{hi} n {n}");
                assert!(v.iter().all(|x| x.is_finite() && (lo..=hi).contains(x)), "{v:?}");
                assert!(v.windows(2).all(|w| w[0] < w[1]), "{lo}..{hi} n {n}: {v:?}");
            }
        }
        // The middle of a symmetric range is exactly 0; the quarter points are half the ends.
        let v = linspace(-1e308, 1e308, 5);
        assert_eq!(v[2], 0.0);
        approx::assert_relative_eq!(v[1], -5e307, max_relative = 1e-15);
        approx::assert_relative_eq!(v[3], 5e307, max_relative = 1e-15);
    }

    #[test]
    fn lerp_is_nondecreasing_and_closed_over_many_fractions() {
        for (lo, hi) in [(-1.7e308, 1.7e308), (0.1, 0.7), (-3.0, -2.9999999999999996)] {
            let mut last = lo;
            for k in 0..=10_000 {
                let v = lerp(lo, hi, k as f64 / 10_000.0);
                assert!(v >= last && v <= hi && v.is_finite(), "{lo}..{hi} at {k}: {v} after {last}");
                last = v;
            }
            assert_eq!(last, hi);
        }
    }

    /// The draw as hybc 0.x made it: one sequential ChaCha8 stream, `lo + (hi - lo) u`.
    fn sequential_samples(ranges: &[(usize, f64, f64)], n: usize, seed: u64) -> Vec<Vec<f64>> {
        let mut key = [0u8; 32];
        key[..8].copy_from_slice(&seed.to_le_bytes());
        let mut rng = ChaCha8Rng::from_seed(key);
        (0..n)
            .map(|_| {
                let mut p = vec![0.0; 3];
                for &(param, lo, hi) in ranges {
                    let u = (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
                    p[param] = (lo + (hi - lo) * u).min(hi);
                }
                p
            })
            .collect()
    }

    #[test]
    fn indexed_samples_are_the_sequential_stream() {
        // Odd and even numbers of ranges, across ChaCha's 64-word buffer boundaries.
        for ranges in [vec![(1, 0.5, 0.9)], vec![(0, 9.0, 10.0), (1, 0.5, 0.9), (2, 0.1, 3.0)]] {
            let indexed = uniform_samples(&[0.0; 3], &ranges, 300, 42);
            assert_eq!(indexed, sequential_samples(&ranges, 300, 42));
            let points = Points::Draws(Draws::new(vec![0.0; 3], ranges.clone(), 300, 42));
            for i in [299, 0, 150, 31, 32, 33] {
                assert_eq!(points.point(i), indexed[i], "point {i} alone");
            }
        }
    }

    #[test]
    fn samples_over_the_whole_double_range_spread_over_it() {
        let samples = uniform_samples(&[0.0], &[(0, -1.7e308, 1.7e308)], 1000, 7);
        let values: Vec<f64> = samples.iter().map(|p| p[0]).collect();
        assert!(values.iter().all(|v| v.is_finite() && v.abs() <= 1.7e308));
        // Uniform: about half on each side, and the mean of |v| near half the end (1000 draws:
        // the standard error of the fraction is 0.016, of the mean 0.009 of the end).
        let positive = values.iter().filter(|v| **v > 0.0).count();
        assert!((400..=600).contains(&positive), "{positive} positive of 1000");
        let mean_abs = values.iter().map(|v| v.abs() / 1.7e308).sum::<f64>() / 1000.0;
        assert!((mean_abs - 0.5).abs() < 0.05, "{mean_abs}");
    }

    #[test]
    fn a_grid_point_is_its_index_in_mixed_radix() {
        let axes = vec![(0, Axis::Even { lo: 0.0, hi: 1.0, n: 3 }), (2, Axis::List(vec![7.0, 8.0]))];
        let grid = Points::Grid(Grid::new(vec![0.0, 5.0, 0.0], axes).expect("small"));
        assert_eq!(grid.len(), 6);
        assert_eq!(grid.point(3), vec![0.5, 5.0, 8.0]);
        assert_eq!(grid.point(4), vec![1.0, 5.0, 7.0]);
        let huge = vec![(0, Axis::Even { lo: 0.0, hi: 1.0, n: 1 << 40 }); 2];
        assert_eq!(Grid::new(vec![0.0], huge), Err(TooManyPoints));
    }

    #[test]
    fn sample_shards_concatenate_to_the_whole() {
        let ranges = [(0, 0.0, 1.0), (2, -5.0, 5.0), (1, 10.0, 20.0)];
        let base = [0.5, 15.0, 0.0, 7.0];
        let whole = uniform_samples(&base, &ranges, 1000, 42);
        // Shard bounds at odd and even points, across the generator's 64-word buffer.
        let mut joined = Vec::new();
        for bounds in [0..1, 1..10, 10..11, 11..333, 333..334, 334..1000] {
            joined.extend(uniform_samples_from(&base, &ranges, 42, bounds));
        }
        assert_eq!(joined, whole);
        assert_eq!(
            uniform_samples_from(&base, &ranges[..1], 7, 5..6)[0],
            uniform_samples(&base, &ranges[..1], 6, 7)[5]
        );
    }

    #[test]
    fn grid_varies_the_last_axis_fastest() {
        let g = full_grid(&[0.0, 5.0, 0.0], &[(0, vec![1.0, 2.0]), (2, vec![3.0, 4.0, 6.0])]);
        let expect: Vec<Vec<f64>> = [(1., 3.), (1., 4.), (1., 6.), (2., 3.), (2., 4.), (2., 6.)]
            .iter()
            .map(|&(a, c)| vec![a, 5.0, c])
            .collect();
        assert_eq!(g, expect);
    }
}
