//! The coefficients of `row_tableau`: derived from the published ones, and satisfying the order
//! conditions in f64 to a few ulps.

// The order conditions read as the index sums of Hairer and Wanner's table.
#![allow(clippy::needless_range_loop)]

use super::published::{Published, RODAS4_PUBLISHED, RODAS5P_PUBLISHED};
use super::*;

const METHODS: [(&RowTableau, &Published); 2] =
    [(&RODAS4, &RODAS4_PUBLISHED), (&RODAS5P, &RODAS5P_PUBLISHED)];

/// Lower-triangular `s x s` with the given strictly lower rows and `diag` on the diagonal.
fn lower(rows: &[&[f64]], s: usize, diag: f64) -> Vec<Vec<f64>> {
    (0..s)
        .map(|i| {
            (0..s)
                .map(|j| {
                    if j < i {
                        rows[i][j]
                    } else if j == i {
                        diag
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect()
}

#[test]
fn rows_have_their_shapes() {
    for (tab, _) in METHODS {
        let s = tab.stages;
        assert_eq!((tab.alpha.len(), tab.gam.len(), tab.c.len(), tab.d.len()), (s, s, s, s));
        assert_eq!((tab.b.len(), tab.e.len()), (s, s));
        for i in 0..s {
            assert_eq!((tab.alpha[i].len(), tab.gam[i].len()), (i, i), "{} row {i}", tab.name);
        }
        for row in tab.dense {
            assert_eq!(row.len(), s);
        }
        assert_eq!(tab.d[0], tab.gamma);
        assert_eq!(tab.c[s - 1], 1.0);
    }
}

/// `Gamma = (diag(1/gamma) - C)^-1`, `alpha = a Gamma`, `H_original = H Gamma`, recomputed in
/// f64 from the published decimals: they agree with the stored coefficients to 3e-13 (the
/// repair moved none by more than 1.2e-13; the rest is this f64 recomputation's round-off on
/// coefficients of size 165).
#[test]
fn the_coefficients_are_the_published_ones_in_the_original_form() {
    for (tab, p) in METHODS {
        let s = tab.stages;
        assert_eq!(tab.gamma, p.gamma);
        let mut gm = vec![vec![0.0; s]; s];
        for j in 0..s {
            gm[j][j] = p.gamma;
            for i in j + 1..s {
                gm[i][j] = p.gamma * (j..i).map(|k| p.cm[i][k] * gm[k][j]).sum::<f64>();
            }
        }
        let close = |got: f64, want: f64, what: &str| {
            assert!(
                (got - want).abs() <= 3e-13 * want.abs().max(1.0),
                "{} {what}: {got} vs {want}",
                tab.name
            );
        };
        for i in 0..s {
            for j in 0..i {
                close(tab.gam[i][j], gm[i][j], "Gamma");
                let alpha: f64 = (0..i).map(|k| p.a[i][k] * gm[k][j]).sum();
                close(tab.alpha[i][j], alpha, "alpha");
            }
            // Stiffly accurate: b and e are the last rows of alpha + Gamma and of Gamma.
            let last_alpha = if i < s - 1 { tab.alpha[s - 1][i] } else { 0.0 };
            close(tab.e[i], gm[s - 1][i], "e");
            close(tab.b[i], last_alpha + gm[s - 1][i], "b");
        }
        for (row, prow) in tab.dense.iter().zip(p.dense) {
            for j in 0..s {
                close(row[j], (0..s).map(|k| prow[k] * gm[k][j]).sum(), "H");
            }
        }
    }
}

/// The conditions a clock needs hold in f64: the sums the stepper forms (left to right, as
/// `rosenbrock::combine`) are exactly the stage times, one for the weights, zero for the error
/// weights and for every dense-output row; the time-derivative weights are the row sums of
/// `Gamma` to 2 ulps.
#[test]
fn the_linear_conditions_hold_in_f64() {
    let sum = |v: &[f64]| v.iter().fold(0.0, |acc, x| acc + x);
    for (tab, _) in METHODS {
        for i in 1..tab.stages {
            assert_eq!(sum(tab.alpha[i]), tab.c[i], "{} c_{i}", tab.name);
            let d = tab.gamma + sum(tab.gam[i]);
            assert!((d - tab.d[i]).abs() <= 2.0 * f64::EPSILON, "{} d_{i}: {d} vs {}", tab.name, tab.d[i]);
        }
        assert_eq!(sum(tab.b), 1.0, "{}", tab.name);
        assert_eq!(sum(tab.e), 0.0, "{}", tab.name);
        for row in tab.dense {
            assert_eq!(sum(row), 0.0, "{}", tab.name);
        }
    }
}

/// The order conditions of Hairer & Wanner's Table IV.7.1 up to order 4 (the autonomous ones;
/// with `c` and `d` the row sums, the non-autonomous ones follow) for the solution and, up to
/// the embedded order, for the embedded solution `b^ = alpha_s`: each residual is at most
/// 8 ulps of the sum of its terms' magnitudes (f64 evaluation; in exact arithmetic the residuals
/// are below 9e-16).
#[test]
fn the_order_conditions_hold_to_a_few_ulps() {
    for (tab, _) in METHODS {
        let (s, g) = (tab.stages, tab.gamma);
        let al = lower(tab.alpha, s, 0.0);
        let gm = lower(tab.gam, s, 0.0);
        let be: Vec<Vec<f64>> = (0..s).map(|i| (0..s).map(|j| al[i][j] + gm[i][j]).collect()).collect();
        let a: Vec<f64> = al.iter().map(|r| r.iter().sum()).collect();
        let bp: Vec<f64> = be.iter().map(|r| r.iter().sum()).collect();
        let bhat: Vec<f64> = (0..s).map(|j| al[s - 1][j]).collect();
        for (which, w, order) in [("b", tab.b.to_vec(), tab.order), ("b^", bhat, tab.embedded)] {
            // (order, value, magnitude, right-hand side) of each condition.
            let mut conds: Vec<(usize, f64, f64, f64)> = Vec::new();
            let mut add = |p: usize, terms: &mut dyn Iterator<Item = f64>, rhs: f64| {
                let (mut v, mut m) = (0.0, 0.0);
                for t in terms {
                    v += t;
                    m += t.abs();
                }
                conds.push((p, v, m, rhs));
            };
            let r = 0..s;
            add(1, &mut r.clone().map(|j| w[j]), 1.0);
            add(2, &mut r.clone().map(|j| w[j] * bp[j]), 0.5 - g);
            add(3, &mut r.clone().map(|j| w[j] * a[j] * a[j]), 1.0 / 3.0);
            add(
                3,
                &mut r
                    .clone()
                    .flat_map(|j| r.clone().map(move |k| (j, k)))
                    .map(|(j, k)| w[j] * be[j][k] * bp[k]),
                1.0 / 6.0 - g + g * g,
            );
            add(4, &mut r.clone().map(|j| w[j] * a[j].powi(3)), 0.25);
            add(
                4,
                &mut r
                    .clone()
                    .flat_map(|j| r.clone().map(move |k| (j, k)))
                    .map(|(j, k)| w[j] * a[j] * al[j][k] * bp[k]),
                1.0 / 8.0 - g / 3.0,
            );
            add(
                4,
                &mut r
                    .clone()
                    .flat_map(|j| r.clone().map(move |k| (j, k)))
                    .map(|(j, k)| w[j] * be[j][k] * a[k] * a[k]),
                1.0 / 12.0 - g / 3.0,
            );
            add(
                4,
                &mut r
                    .clone()
                    .flat_map(|j| r.clone().flat_map(move |k| (0..s).map(move |l| (j, k, l))))
                    .map(|(j, k, l)| w[j] * be[j][k] * be[k][l] * bp[l]),
                1.0 / 24.0 - g / 2.0 + 1.5 * g * g - g * g * g,
            );
            for (n, &(p, v, m, rhs)) in conds.iter().enumerate() {
                if p <= order {
                    let tol = 8.0 * f64::EPSILON * m.max(1.0);
                    assert!(
                        (v - rhs).abs() <= tol,
                        "{} {which} condition {n} (order {p}): {:e} > {tol:e}",
                        tab.name,
                        v - rhs
                    );
                }
            }
        }
    }
}
