//! Gradient check: the finite-difference step of one parameter and the points it is evaluated at.
//! Knows parameter values and ranges only; no runs, no results.

use serde::Serialize;

/// Which finite difference approximates a derivative.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Difference {
    /// `(Q(p + h) - Q(p - h)) / 2h`.
    Central,
    /// `(-3 Q(p) + 4 Q(p + h) - Q(p + 2h)) / 2h`: the parameter sits at (or within `h` of) the
    /// lower end of its declared range.
    Forward,
    /// `(3 Q(p) - 4 Q(p - h) + Q(p - 2h)) / 2h`: at the upper end.
    Backward,
}

impl Difference {
    /// Short name for the table.
    pub fn name(self) -> &'static str {
        match self {
            Difference::Central => "central",
            Difference::Forward => "forward",
            Difference::Backward => "backward",
        }
    }

    /// The three points in ascending order, as multiples of `h` from `p`, and the weights that
    /// make the derivative `sum w_i Q(p + o_i h) / h`. All three are second order (error
    /// `~h^2 Q'''`).
    fn offsets_and_weights(self) -> ([f64; 3], [f64; 3]) {
        match self {
            Difference::Central => ([-1.0, 0.0, 1.0], [-0.5, 0.0, 0.5]),
            Difference::Forward => ([0.0, 1.0, 2.0], [-1.5, 2.0, -0.5]),
            Difference::Backward => ([-2.0, -1.0, 0.0], [0.5, -2.0, 1.5]),
        }
    }

    /// Labels of the three points, for messages.
    pub fn point_names(self) -> [&'static str; 3] {
        match self {
            Difference::Central => ["p - h", "p", "p + h"],
            Difference::Forward => ["p", "p + h", "p + 2h"],
            Difference::Backward => ["p - 2h", "p - h", "p"],
        }
    }
}

/// The step of one parameter and the three points of its difference (one of them `p` itself).
#[derive(Clone, Debug, PartialEq)]
pub struct Stencil {
    /// Central, or one-sided at a bound.
    pub difference: Difference,
    /// The step `h`.
    pub step: f64,
    /// Parameter values at the three points, ascending.
    pub points: [f64; 3],
    /// Weights of the three values (already divided by `h`).
    pub weights: [f64; 3],
    /// Which of the points is `p`.
    pub nominal: usize,
    /// The parameter's own scale: `|p|`, or the width of its range (or 1) for `p = 0`. The step
    /// is `rel_step` times it; a tolerance-sized error that moves with `p` moves on this scale.
    pub scale: f64,
    /// Something the user should know about the step (`p = 0` with no range, `p` outside its
    /// range).
    pub note: Option<String>,
}

/// The stencil for parameter value `p` with declared range `range`: step `h = rel_step |p|`, or
/// `rel_step (hi - lo)` for `p = 0` with a range, or `rel_step` itself for `p = 0` without one;
/// at most a quarter of the range, so that one of the three differences fits inside it. Central
/// when `p +/- h` stays inside the range, else one-sided away from the bound. `Err` with the
/// reason when the parameter cannot be varied (a range of one point, a step lost in round-off).
pub fn stencil(p: f64, range: Option<(f64, f64)>, rel_step: f64) -> Result<Stencil, String> {
    let mut note = None;
    let scale = match range {
        _ if p != 0.0 => p.abs(),
        Some((lo, hi)) => hi - lo,
        None => {
            note = Some(format!(
                "p = 0 with no declared range: the step is {rel_step:.0e} in the parameter's own units \
                 (declare `in [lo, hi]` to scale it)"
            ));
            1.0
        }
    };
    let mut h = rel_step * scale;
    if let Some((lo, hi)) = range {
        if hi <= lo {
            return Err(format!("its declared range [{lo}, {hi}] leaves no room to vary it"));
        }
        h = h.min((hi - lo) / 4.0);
    }
    // The step actually taken: p + h rounded, so that both points are exact.
    let h = (p + h) - p;
    if !(h > 0.0 && h.is_finite()) {
        return Err(format!("a step {:.0e} of |p| is lost in round-off at p = {p}", rel_step));
    }
    let fits = |d: Difference| {
        let (offsets, _) = d.offsets_and_weights();
        range.is_none_or(|(lo, hi)| offsets.iter().all(|o| (lo..=hi).contains(&(p + o * h))))
    };
    let difference =
        match [Difference::Central, Difference::Forward, Difference::Backward].into_iter().find(|&d| fits(d))
        {
            Some(d) => d,
            None => {
                note = Some(format!("p = {p} is outside its declared range: central differences across it"));
                Difference::Central
            }
        };
    let (offsets, weights) = difference.offsets_and_weights();
    Ok(Stencil {
        difference,
        step: h,
        points: offsets.map(|o| p + o * h),
        weights: weights.map(|w| w / h),
        nominal: offsets.iter().position(|&o| o == 0.0).expect("every stencil holds p"),
        scale,
        note,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_follow_the_parameter_and_stay_inside_its_range() {
        let s = stencil(1e-6, None, 1e-5).unwrap();
        assert_eq!(s.difference, Difference::Central);
        // 1e-5 |p|, moved by the rounding of p + h: at most half an ulp of p.
        assert!((s.step - 1e-11).abs() <= 0.5 * f64::EPSILON * 1e-6);
        assert!(s.note.is_none());
        // p = 0 with a range: scaled by the range; at its lower end: forward.
        let s = stencil(0.0, Some((0.0, 5.0)), 1e-5).unwrap();
        assert_eq!((s.difference, s.step, s.nominal), (Difference::Forward, 5e-5, 0));
        assert_eq!(s.points, [0.0, 5e-5, 1e-4]);
        // p = 0 without one: the step is rel_step itself, said in a note.
        let s = stencil(0.0, None, 1e-5).unwrap();
        assert_eq!((s.difference, s.step), (Difference::Central, 1e-5));
        assert!(s.note.unwrap().contains("no declared range"));
        // At the upper end: backward, the weights of the second-order formula.
        let s = stencil(1.0, Some((0.0, 1.0)), 1e-5).unwrap();
        assert_eq!((s.difference, s.nominal), (Difference::Backward, 2));
        let h = s.step;
        assert_eq!(s.weights, [0.5 / h, -2.0 / h, 1.5 / h]);
        // A range narrower than 4 steps shrinks the step.
        let s = stencil(1.0, Some((0.999_999_9, 1.000_000_1)), 1e-5).unwrap();
        assert!(s.step <= 0.5e-7 + 1e-16, "{s:?}");
        assert!(stencil(1.0, Some((1.0, 1.0)), 1e-5).is_err());
    }

    #[test]
    fn the_differences_are_exact_for_quadratics() {
        // Q = 3 + 2 p + 5 p^2: every second-order formula gives Q' = 2 + 10 p exactly (up to
        // round-off), at p well inside the range and at both ends.
        for (p, range) in [(0.3, None), (0.0, Some((0.0, 1.0))), (1.0, Some((0.0, 1.0)))] {
            let s = stencil(p, range, 1e-3).unwrap();
            let q = |x: f64| 3.0 + 2.0 * x + 5.0 * x * x;
            let d: f64 = s.points.iter().zip(s.weights).map(|(&x, w)| w * q(x)).sum();
            assert!((d - (2.0 + 10.0 * p)).abs() < 1e-9, "{p}: {d}");
        }
    }
}
