//! Which parameter vectors a sweep runs: `--vary` specifications, full grids in a fixed order and
//! seeded uniform samples. Pure functions of numbers; knows no model and no simulation.

use rand_chacha::ChaCha8Rng;
use rand_core::{Rng as _, SeedableRng as _};

/// What one `--vary P=...` asks for, before the parameter's name is resolved.
#[derive(Clone, Debug, PartialEq)]
pub enum AxisSpec {
    /// `P=LO:HI:N`: N evenly spaced values from LO to HI, both included.
    Grid { lo: f64, hi: f64, n: usize },
    /// `P=V1,V2,...`: exactly these values, in this order.
    List(Vec<f64>),
    /// `P=LO:HI`: a range to sample from (with `--samples`).
    Range { lo: f64, hi: f64 },
    /// `P` alone: sample from the parameter's declared range (with `--samples`).
    Declared,
}

/// A parsed `--vary` flag.
#[derive(Clone, Debug, PartialEq)]
pub struct VarySpec {
    pub name: String,
    pub axis: AxisSpec,
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum VaryError {
    #[error("`{text}` is not a finite number")]
    NotANumber { text: String },
    #[error("`{text}`: expected P=LO:HI:N, P=LO:HI, P=V1,V2,... or P")]
    Shape { text: String },
    #[error("`{text}`: the number of grid points must be an integer of at least 2")]
    GridCount { text: String },
    #[error("`{text}`: LO must be below HI")]
    EmptyRange { text: String },
}

fn number(text: &str) -> Result<f64, VaryError> {
    text.trim()
        .parse()
        .ok()
        .filter(|v: &f64| v.is_finite())
        .ok_or_else(|| VaryError::NotANumber { text: text.trim().to_string() })
}

/// Parses one `--vary` value: `P=LO:HI:N`, `P=LO:HI`, `P=V1,V2,...` or `P`.
pub fn parse_vary(text: &str) -> Result<VarySpec, VaryError> {
    let shape = || VaryError::Shape { text: text.to_string() };
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
                return Err(VaryError::EmptyRange { text: text.to_string() });
            }
            match parts.get(2) {
                None => AxisSpec::Range { lo, hi },
                Some(n) => match n.trim().parse::<usize>() {
                    Ok(n) if n >= 2 => AxisSpec::Grid { lo, hi, n },
                    _ => return Err(VaryError::GridCount { text: text.to_string() }),
                },
            }
        }
        [list] => AxisSpec::List(list.split(',').map(number).collect::<Result<_, _>>()?),
        _ => return Err(shape()),
    };
    Ok(VarySpec { name, axis })
}

/// `n >= 2` values from `lo` to `hi`; the ends are exactly `lo` and `hi`.
pub fn linspace(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let last = n.saturating_sub(1).max(1);
    (0..n).map(|i| if i == last { hi } else { lo + (hi - lo) * (i as f64 / last as f64) }).collect()
}

/// The full grid over `axes` (parameter index, its values), each point starting from `base`.
/// Order: the first axis varies slowest, the last fastest (nested loops in flag order).
pub fn full_grid(base: &[f64], axes: &[(usize, Vec<f64>)]) -> Vec<Vec<f64>> {
    let mut points = vec![base.to_vec()];
    for (param, values) in axes {
        points = points
            .iter()
            .flat_map(|p| {
                values.iter().map(move |&v| {
                    let mut q = p.clone();
                    q[*param] = v;
                    q
                })
            })
            .collect();
    }
    points
}

/// `n` points, each starting from `base` with every parameter of `ranges` (index, lo, hi) drawn
/// uniformly from `[lo, hi]`.
///
/// The stream is fixed by the algorithm, not by a crate's choices: ChaCha8 keyed by the seed's
/// eight little-endian bytes followed by 24 zero bytes; each value takes the top 53 bits of one
/// `next_u64` as `u` in `[0, 1)` and is `lo + (hi - lo) u`, drawn point by point and within a
/// point in the order of `ranges`. So one seed gives the same points on every machine and
/// every version of hybc that keeps this description.
pub fn uniform_samples(base: &[f64], ranges: &[(usize, f64, f64)], n: usize, seed: u64) -> Vec<Vec<f64>> {
    uniform_samples_from(base, ranges, seed, 0..n)
}

/// Points `indices` (a range of point numbers) of [`uniform_samples`]`(base, ranges, _, seed)`,
/// without drawing the points before them: point `i` starts at word `2 i ranges.len()` of the
/// ChaCha8 stream (each value takes one `next_u64`, two 32-bit words). So a sweep can be sharded
/// by index ranges (a Dask task draws only its own points) and the shards concatenated equal the
/// whole.
pub fn uniform_samples_from(
    base: &[f64],
    ranges: &[(usize, f64, f64)],
    seed: u64,
    indices: std::ops::Range<usize>,
) -> Vec<Vec<f64>> {
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&seed.to_le_bytes());
    let mut rng = ChaCha8Rng::from_seed(key);
    rng.set_word_pos(2 * ranges.len() as u128 * indices.start as u128);
    indices
        .map(|_| {
            let mut p = base.to_vec();
            for &(param, lo, hi) in ranges {
                let u = (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
                // Rounding of lo + (hi - lo) u can pass hi by an ulp; the range is closed.
                p[param] = (lo + (hi - lo) * u).min(hi);
            }
            p
        })
        .collect()
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
        assert!(matches!(parse_vary("e=1:0:3"), Err(VaryError::EmptyRange { .. })));
        assert!(matches!(parse_vary("e=0:1:1"), Err(VaryError::GridCount { .. })));
        assert!(matches!(parse_vary("e=0:1:x"), Err(VaryError::GridCount { .. })));
        assert!(matches!(parse_vary("e=0:nan"), Err(VaryError::NotANumber { .. })));
        assert!(matches!(parse_vary("e=0:1:2:3"), Err(VaryError::Shape { .. })));
        assert!(matches!(parse_vary("=1"), Err(VaryError::Shape { .. })));
        assert!(matches!(parse_vary("e="), Err(VaryError::Shape { .. })));
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
