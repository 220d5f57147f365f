//! The Saltelli design: which parameter vector row `r` of a Sobol' analysis runs, computed from
//! `r` alone (so a design streams and shards like a sweep), in SALib's row order, and the priors
//! that map the unit cube onto parameters. Pure functions of numbers; knows no model.

use super::sequence::{Sobol, MAX_DIMS};

/// How one varied parameter is distributed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Prior {
    /// Uniform on `[lo, hi]` (`P=LO:HI`, or `P` for its declared range).
    Uniform {
        /// The lower end.
        lo: f64,
        /// The upper end.
        hi: f64,
    },
    /// `log` uniform on `[log lo, log hi]`, `0 < lo < hi` (`P=loguniform:LO:HI`).
    LogUniform {
        /// The lower end (positive).
        lo: f64,
        /// The upper end.
        hi: f64,
    },
    /// Normal with mean `mu` and standard deviation `sigma > 0` (`P=normal:MU:SIGMA`).
    Normal {
        /// The mean.
        mu: f64,
        /// The standard deviation.
        sigma: f64,
    },
    /// `exp` of a normal with mean `mu` and standard deviation `sigma > 0` (`P=lognormal:MU:SIGMA`,
    /// the parameters of the logarithm, as NumPy's and SALib's `lognorm`).
    LogNormal {
        /// The mean of the logarithm.
        mu: f64,
        /// Its standard deviation.
        sigma: f64,
    },
}

/// A `--vary` prior that does not parse (`hybc sobol`).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PriorError {
    /// Not one of the shapes a prior takes.
    #[error("`{text}`: expected P=LO:HI, P, P=loguniform:LO:HI, P=normal:MU:SIGMA or P=lognormal:MU:SIGMA")]
    Shape {
        /// The text as written.
        text: String,
    },
    /// A number that is not a finite number.
    #[error("`{text}`: `{number}` is not a finite number")]
    NotANumber {
        /// The prior as written.
        text: String,
        /// The number as written.
        number: String,
    },
    /// A range whose lower end is not below its upper end.
    #[error("`{text}`: LO must be below HI")]
    EmptyRange {
        /// The text as written.
        text: String,
    },
    /// A log-uniform range that is not positive.
    #[error("`{text}`: a log-uniform range must be positive")]
    NotPositive {
        /// The text as written.
        text: String,
    },
    /// A standard deviation that is not positive.
    #[error("`{text}`: SIGMA must be positive")]
    BadSigma {
        /// The text as written.
        text: String,
    },
}

/// A parsed `--vary` of `hybc sobol`: the name and its prior, `None` for `P` alone (the declared
/// range, uniform).
pub fn parse_prior(text: &str) -> Result<(String, Option<Prior>), PriorError> {
    let shape = || PriorError::Shape { text: text.to_string() };
    let Some((name, rest)) = text.split_once('=') else {
        let name = text.trim();
        if name.is_empty() || name.contains([':', ',']) {
            return Err(shape());
        }
        return Ok((name.to_string(), None));
    };
    let name = name.trim();
    if name.is_empty() {
        return Err(shape());
    }
    let parts: Vec<&str> = rest.split(':').map(str::trim).collect();
    let num = |s: &str| {
        crate::number::parse_number(s)
            .map_err(|_| PriorError::NotANumber { text: text.to_string(), number: s.to_string() })
    };
    let prior = match parts.as_slice() {
        [lo, hi] => Prior::Uniform { lo: num(lo)?, hi: num(hi)? },
        ["loguniform", lo, hi] => Prior::LogUniform { lo: num(lo)?, hi: num(hi)? },
        ["normal", mu, sigma] => Prior::Normal { mu: num(mu)?, sigma: num(sigma)? },
        ["lognormal", mu, sigma] => Prior::LogNormal { mu: num(mu)?, sigma: num(sigma)? },
        _ => return Err(shape()),
    };
    let text = text.to_string();
    prior.check().map_err(|problem| match problem {
        // `num` refused every number that is not finite.
        PriorProblem::NotFinite | PriorProblem::EmptyRange => PriorError::EmptyRange { text },
        PriorProblem::NotPositive => PriorError::NotPositive { text },
        PriorProblem::BadSigma => PriorError::BadSigma { text },
    })?;
    Ok((name.to_string(), Some(prior)))
}

/// What is wrong with a prior's numbers (see [`Prior::check`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PriorProblem {
    /// A number that is not finite.
    #[error("its numbers must be finite")]
    NotFinite,
    /// A range whose lower end is not below its upper end.
    #[error("the lower bound must be below the upper bound")]
    EmptyRange,
    /// A log-uniform range that is not positive.
    #[error("a log-uniform range must be positive")]
    NotPositive,
    /// A standard deviation that is not positive.
    #[error("the standard deviation must be positive")]
    BadSigma,
}

impl Prior {
    /// Whether the numbers describe a distribution: finite, `lo < hi` (and `lo > 0` for
    /// log-uniform), `sigma > 0`. Every interface that builds a prior (the CLI's `--vary`, the
    /// Python `problem` dict) refuses one that fails this.
    pub fn check(&self) -> Result<(), PriorProblem> {
        let (a, b) = match *self {
            Prior::Uniform { lo, hi } | Prior::LogUniform { lo, hi } => (lo, hi),
            Prior::Normal { mu, sigma } | Prior::LogNormal { mu, sigma } => (mu, sigma),
        };
        if !(a.is_finite() && b.is_finite()) {
            return Err(PriorProblem::NotFinite);
        }
        match *self {
            Prior::LogUniform { lo, .. } if lo <= 0.0 => Err(PriorProblem::NotPositive),
            Prior::Uniform { lo, hi } | Prior::LogUniform { lo, hi } if lo >= hi => {
                Err(PriorProblem::EmptyRange)
            }
            Prior::Normal { sigma, .. } | Prior::LogNormal { sigma, .. } if sigma <= 0.0 => {
                Err(PriorProblem::BadSigma)
            }
            _ => Ok(()),
        }
    }

    /// The parameter value at quantile `u` in `(0, 1)`.
    pub fn value(&self, u: f64) -> f64 {
        match *self {
            Prior::Uniform { lo, hi } => crate::sweep::lerp(lo, hi, u),
            Prior::LogUniform { lo, hi } => (lo.ln() + (hi.ln() - lo.ln()) * u).exp().clamp(lo, hi),
            Prior::Normal { mu, sigma } => mu + sigma * normal_quantile(u),
            Prior::LogNormal { mu, sigma } => (mu + sigma * normal_quantile(u)).exp(),
        }
    }

    /// The smallest and largest values it can give (for a check against a declared range).
    pub fn support(&self) -> (f64, f64) {
        match *self {
            Prior::Uniform { lo, hi } | Prior::LogUniform { lo, hi } => (lo, hi),
            Prior::Normal { .. } => (f64::NEG_INFINITY, f64::INFINITY),
            Prior::LogNormal { .. } => (0.0, f64::INFINITY),
        }
    }
}

/// The standard normal quantile, Acklam's rational approximation (relative error below 1.2e-9
/// over `(0, 1)`: ample for a prior, whose quantiles only place the design's points).
pub fn normal_quantile(u: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e+01,
        2.209460984245205e+02,
        -2.759285104469687e+02,
        1.38357751867269e+02,
        -3.066479806614716e+01,
        2.506628277459239e+00,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e+01,
        1.615858368580409e+02,
        -1.556989798598866e+02,
        6.680131188771972e+01,
        -1.328068155288572e+01,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-03,
        -3.223964580411365e-01,
        -2.400758277161838e+00,
        -2.549732539343734e+00,
        4.374664141464968e+00,
        2.938163982698783e+00,
    ];
    const D: [f64; 4] =
        [7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00, 3.754408661907416e+00];
    const LOW: f64 = 0.02425;
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if u < LOW {
        tail((-2.0 * u.ln()).sqrt())
    } else if u > 1.0 - LOW {
        -tail((-2.0 * (1.0 - u).ln()).sqrt())
    } else {
        let q = u - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// Too many varied parameters for the embedded direction numbers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{varied} parameters varied; a Sobol' analysis takes 1 to {max} (its design has two coordinates per parameter)")]
pub struct TooManyVaried {
    /// The parameters varied.
    pub varied: usize,
    /// The most a design takes.
    pub max: usize,
}

/// The most parameters a design varies: `2 D` Sobol' dimensions.
pub const MAX_VARIED: usize = MAX_DIMS / 2;

/// Which matrix a row of a base point's block is, in SALib's order:
/// `A, AB_1 .. AB_D, [BA_1 .. BA_D], B`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RowKind {
    /// Matrix A's row.
    A,
    /// A with parameter `i` (0-based, of the varied ones) taken from B.
    AB(usize),
    /// B with parameter `i` taken from A (second order only).
    BA(usize),
    /// Matrix B's row.
    B,
}

/// The Saltelli design over `D` varied parameters and `N` base points: `N (D + 2)` rows, or
/// `N (2 D + 2)` with second-order indices, base point `b`'s block of rows consecutive. Base point
/// `b` is point `b` of a scrambled Sobol' sequence in `2 D` dimensions: its first `D` coordinates
/// are A's row, the last `D` B's (as SALib's `sobol.sample`).
#[derive(Clone, Debug)]
pub struct Design {
    base: Vec<f64>,
    varied: Vec<(usize, Prior)>,
    n: usize,
    second_order: bool,
    sobol: Sobol,
}

impl Design {
    /// The design from `base` (every parameter's value), the varied parameters (index, prior) in
    /// order, `n` base points, the scramble's `seed`.
    pub fn new(
        base: Vec<f64>,
        varied: Vec<(usize, Prior)>,
        n: usize,
        second_order: bool,
        seed: u64,
    ) -> Result<Design, TooManyVaried> {
        let d = varied.len();
        if d == 0 || d > MAX_VARIED {
            return Err(TooManyVaried { varied: d, max: MAX_VARIED });
        }
        Ok(Design { base, varied, n, second_order, sobol: Sobol::scrambled(2 * d, seed) })
    }

    /// Varied parameters.
    pub fn d(&self) -> usize {
        self.varied.len()
    }

    /// Base points.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Whether the design has the BA rows of second-order indices.
    pub fn second_order(&self) -> bool {
        self.second_order
    }

    /// The varied parameters (index, prior), in the design's order.
    pub fn varied(&self) -> &[(usize, Prior)] {
        &self.varied
    }

    /// Rows per base point: `D + 2`, or `2 D + 2` with second order.
    pub fn block(&self) -> usize {
        if self.second_order {
            2 * self.d() + 2
        } else {
            self.d() + 2
        }
    }

    /// All rows, `N` blocks (`None` past `usize`).
    pub fn rows(&self) -> Option<usize> {
        self.n.checked_mul(self.block())
    }

    /// Values per point (the model's parameters).
    pub fn width(&self) -> usize {
        self.base.len()
    }

    /// What row `j` of a block is.
    pub fn kind(&self, j: usize) -> RowKind {
        let d = self.d();
        match j {
            0 => RowKind::A,
            j if j <= d => RowKind::AB(j - 1),
            j if j + 1 < self.block() => RowKind::BA(j - 1 - d),
            _ => RowKind::B,
        }
    }

    /// The unit-cube coordinates of row `r`'s varied parameters (`D` values).
    pub fn unit_row(&self, r: usize, out: &mut [f64]) {
        let d = self.d();
        let mut u = [0.0; MAX_DIMS];
        self.sobol.point((r / self.block()) as u64, &mut u[..2 * d]);
        let (a, b) = u[..2 * d].split_at(d);
        let (from, other, swapped) = match self.kind(r % self.block()) {
            RowKind::A => (a, a, None),
            RowKind::B => (b, b, None),
            RowKind::AB(i) => (a, b, Some(i)),
            RowKind::BA(i) => (b, a, Some(i)),
        };
        out[..d].copy_from_slice(from);
        if let Some(i) = swapped {
            out[i] = other[i];
        }
    }

    /// Writes row `r < rows()` into `out` (`width` long): the base with the varied parameters at
    /// their priors' quantiles of the row's coordinates.
    pub fn fill(&self, r: usize, out: &mut [f64]) {
        out.copy_from_slice(&self.base);
        let mut u = [0.0; MAX_VARIED];
        self.unit_row(r, &mut u);
        for ((param, prior), u) in self.varied.iter().zip(u) {
            out[*param] = prior.value(u);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_quantiles_match_tabulated_values() {
        for (u, z) in [
            (0.975, 1.959963984540054),
            (0.5, 0.0),
            (0.8413447460685429, 1.0),
            (0.001, -3.090232306167813),
            (1e-12, -7.034483825301131),
            (0.02, -2.053748910631823),
        ] {
            let got = normal_quantile(u);
            assert!((got - z).abs() <= 2e-9 * z.abs().max(1.0), "{u}: {got} vs {z}");
            // 1 - u is exact for these u, not for 1e-12.
            if u >= 1e-3 {
                assert!((normal_quantile(1.0 - u) + z).abs() <= 2e-9 * z.abs().max(1.0) + 1e-15);
            }
        }
    }

    #[test]
    fn priors_parse_and_refuse_clearly() {
        assert_eq!(parse_prior("e=0.6:0.9"), Ok(("e".into(), Some(Prior::Uniform { lo: 0.6, hi: 0.9 }))));
        assert_eq!(parse_prior(" e "), Ok(("e".into(), None)));
        assert_eq!(
            parse_prior("k=loguniform:1e-3:10"),
            Ok(("k".into(), Some(Prior::LogUniform { lo: 1e-3, hi: 10.0 })))
        );
        assert_eq!(
            parse_prior("k=normal:1:0.5"),
            Ok(("k".into(), Some(Prior::Normal { mu: 1.0, sigma: 0.5 })))
        );
        assert_eq!(
            parse_prior("k=lognormal:0:1"),
            Ok(("k".into(), Some(Prior::LogNormal { mu: 0.0, sigma: 1.0 })))
        );
        assert!(matches!(parse_prior("k=1:0"), Err(PriorError::EmptyRange { .. })));
        assert!(matches!(parse_prior("k=loguniform:0:1"), Err(PriorError::NotPositive { .. })));
        assert!(matches!(parse_prior("k=normal:0:0"), Err(PriorError::BadSigma { .. })));
        assert!(matches!(parse_prior("k=normal:0:x"), Err(PriorError::NotANumber { .. })));
        assert!(matches!(parse_prior("k=0:1:5"), Err(PriorError::Shape { .. })));
        assert!(matches!(parse_prior("k=cauchy:0:1"), Err(PriorError::Shape { .. })));
        assert!(matches!(parse_prior("=1:2"), Err(PriorError::Shape { .. })));
    }

    #[test]
    fn a_prior_built_from_numbers_is_checked_as_a_parsed_one() {
        assert_eq!(Prior::Uniform { lo: 0.0, hi: 1.0 }.check(), Ok(()));
        assert_eq!(Prior::Uniform { lo: 1.0, hi: 1.0 }.check(), Err(PriorProblem::EmptyRange));
        assert_eq!(Prior::Uniform { lo: 0.0, hi: f64::INFINITY }.check(), Err(PriorProblem::NotFinite));
        assert_eq!(Prior::LogUniform { lo: 0.0, hi: 1.0 }.check(), Err(PriorProblem::NotPositive));
        assert_eq!(Prior::LogUniform { lo: 2.0, hi: 1.0 }.check(), Err(PriorProblem::EmptyRange));
        assert_eq!(Prior::Normal { mu: f64::NAN, sigma: 1.0 }.check(), Err(PriorProblem::NotFinite));
        assert_eq!(Prior::LogNormal { mu: 0.0, sigma: -1.0 }.check(), Err(PriorProblem::BadSigma));
        assert_eq!(Prior::Normal { mu: -3.0, sigma: 0.5 }.check(), Ok(()));
    }

    #[test]
    fn blocks_follow_salib_order_and_swap_one_column() {
        let varied = vec![(0, Prior::Uniform { lo: 0.0, hi: 1.0 }), (2, Prior::Uniform { lo: 0.0, hi: 1.0 })];
        let design = Design::new(vec![0.0, 5.0, 0.0], varied, 8, true, 3).expect("two varied");
        assert_eq!(design.block(), 6);
        assert_eq!(design.rows(), Some(48));
        let kinds: Vec<RowKind> = (0..6).map(|j| design.kind(j)).collect();
        use RowKind::*;
        assert_eq!(kinds, [A, AB(0), AB(1), BA(0), BA(1), B]);
        let row = |r: usize| {
            let mut p = vec![0.0; 3];
            design.fill(r, &mut p);
            p
        };
        for b in [0, 5] {
            let at = |j: usize| row(6 * b + j);
            let (a, bb) = (at(0), at(5));
            assert_eq!(a[1], 5.0);
            assert_eq!(at(1), vec![bb[0], 5.0, a[2]]);
            assert_eq!(at(2), vec![a[0], 5.0, bb[2]]);
            assert_eq!(at(3), vec![a[0], 5.0, bb[2]]);
            assert_eq!(at(4), vec![bb[0], 5.0, a[2]]);
        }
        assert_ne!(row(0), row(6), "base points differ");
        let first_only = Design::new(vec![0.0; 3], design.varied().to_vec(), 8, false, 3).expect("two");
        assert_eq!(first_only.block(), 4);
        assert_eq!(first_only.kind(3), B);
        assert_eq!(Design::new(vec![0.0], vec![], 1, false, 0).unwrap_err().varied, 0);
    }

    #[test]
    fn priors_map_quantiles_into_their_support() {
        let lu = Prior::LogUniform { lo: 1e-3, hi: 10.0 };
        assert!((lu.value(0.25) - 1e-2).abs() < 1e-15);
        let ln = Prior::LogNormal { mu: 0.0, sigma: 1.0 };
        assert!((ln.value(0.5) - 1.0).abs() < 1e-15);
        let n = Prior::Normal { mu: 2.0, sigma: 3.0 };
        assert!((n.value(0.975) - (2.0 + 3.0 * 1.959963984540054)).abs() < 1e-8);
    }
}
