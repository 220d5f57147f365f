//! The limited-memory BFGS matrix in compact form (Byrd, Nocedal and Schnabel 1994, as L-BFGS-B
//! uses it): `B = theta I - W M W^T` with `W = [Y, theta S]` (`n x 2k`), the `k <= m` most recent
//! steps `s_i` and gradient changes `y_i` as columns, and the small middle matrix
//! `M = [[-D, L^T], [L, theta S^T S]]^-1` (`D = diag(s_i . y_i)`, `L` the strictly lower part of
//! `S^T Y`). Only `S`, `Y`, their inner products and `M` are kept: `O(m n)` memory, and a product
//! with `B` or a row of `W` costs `O(m)` per variable. Pure arithmetic, no evaluations.

use std::collections::VecDeque;

use nalgebra::{DMatrix, DVector};

/// The `k` most recent correction pairs and the matrices made of them.
pub(super) struct Memory {
    /// The most pairs kept.
    capacity: usize,
    /// Steps `s_i = x_{i+1} - x_i`, oldest first.
    s: VecDeque<Vec<f64>>,
    /// Gradient changes `y_i = g_{i+1} - g_i`, oldest first.
    y: VecDeque<Vec<f64>>,
    /// `s_i . y_j`, row `i`, column `j`.
    sy: VecDeque<VecDeque<f64>>,
    /// `s_i . s_j`.
    ss: VecDeque<VecDeque<f64>>,
    /// The scaling of the identity: `y . y / s . y` of the latest pair (1 before any).
    theta: f64,
    /// `M`, `2k x 2k`.
    middle: DMatrix<f64>,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a * b).sum()
}

impl Memory {
    /// No pairs yet: `B = I`.
    pub fn new(capacity: usize) -> Memory {
        Memory {
            capacity,
            s: VecDeque::new(),
            y: VecDeque::new(),
            sy: VecDeque::new(),
            ss: VecDeque::new(),
            theta: 1.0,
            middle: DMatrix::zeros(0, 0),
        }
    }

    /// Pairs kept.
    pub fn len(&self) -> usize {
        self.s.len()
    }

    /// `theta`.
    pub fn theta(&self) -> f64 {
        self.theta
    }

    /// `M`.
    pub fn middle(&self) -> &DMatrix<f64> {
        &self.middle
    }

    /// Forgets every pair: `B = I` again (after a line search that found no lower point).
    pub fn clear(&mut self) {
        *self = Memory::new(self.capacity);
    }

    /// Adds the pair `(s, y)` when its curvature `s . y` is positive beyond round-off of `y . y`
    /// (else `B` would lose positive definiteness; the pair is skipped, as the published code
    /// skips it); returns whether it was added. The oldest pair goes when `capacity` are kept.
    pub fn push(&mut self, s: Vec<f64>, y: Vec<f64>) -> bool {
        let sy = dot(&s, &y);
        let yy = dot(&y, &y);
        // Written so that a NaN curvature is no curvature.
        let curving = sy > f64::EPSILON * yy;
        if !curving || !yy.is_finite() {
            return false;
        }
        if self.s.len() == self.capacity {
            self.s.pop_front();
            self.y.pop_front();
            self.sy.pop_front();
            self.ss.pop_front();
            for row in self.sy.iter_mut().chain(self.ss.iter_mut()) {
                row.pop_front();
            }
        }
        // The new row and column of S^T Y and S^T S.
        for (i, row) in self.sy.iter_mut().enumerate() {
            row.push_back(dot(&self.s[i], &y));
        }
        for (i, row) in self.ss.iter_mut().enumerate() {
            row.push_back(dot(&self.s[i], &s));
        }
        let mut sy_row: VecDeque<f64> = self.y.iter().map(|yj| dot(&s, yj)).collect();
        sy_row.push_back(sy);
        let mut ss_row: VecDeque<f64> = self.s.iter().map(|sj| dot(&s, sj)).collect();
        ss_row.push_back(dot(&s, &s));
        self.sy.push_back(sy_row);
        self.ss.push_back(ss_row);
        self.s.push_back(s);
        self.y.push_back(y);
        self.theta = yy / sy;
        self.form_middle();
        true
    }

    /// `M = K^-1`, `K = [[-D, L^T], [L, theta S^T S]]`. `K` is nonsingular while every kept pair
    /// has positive curvature (its Schur complement is `theta S^T S + L D^-1 L^T`, positive
    /// definite); should round-off make it singular, the memory is cleared.
    fn form_middle(&mut self) {
        let k = self.len();
        let mut kk = DMatrix::zeros(2 * k, 2 * k);
        for i in 0..k {
            kk[(i, i)] = -self.sy[i][i];
            for j in 0..i {
                // L[i][j] = s_i . y_j for i > j, in the lower left block and its transpose above.
                kk[(k + i, j)] = self.sy[i][j];
                kk[(j, k + i)] = self.sy[i][j];
            }
            for j in 0..k {
                kk[(k + i, k + j)] = self.theta * self.ss[i][j];
            }
        }
        match kk.try_inverse() {
            Some(m) if m.iter().all(|v| v.is_finite()) => self.middle = m,
            _ => self.clear(),
        }
    }

    /// Row `i` of `W`: `(y_1[i] .. y_k[i], theta s_1[i] .. theta s_k[i])`.
    pub fn w_row(&self, i: usize) -> DVector<f64> {
        let k = self.len();
        DVector::from_fn(2 * k, |r, _| if r < k { self.y[r][i] } else { self.theta * self.s[r - k][i] })
    }

    /// `W^T v` over the variables `indices` only (`v` indexed like `x`).
    pub fn w_t_over(&self, indices: &[usize], v: &[f64]) -> DVector<f64> {
        let k = self.len();
        DVector::from_fn(2 * k, |r, _| {
            let sum: f64 = if r < k {
                indices.iter().map(|&i| self.y[r][i] * v[i]).sum()
            } else {
                indices.iter().map(|&i| self.s[r - k][i] * v[i]).sum()
            };
            if r < k {
                sum
            } else {
                self.theta * sum
            }
        })
    }

    /// `W^T Z Z^T W = sum_{i in indices} w_i w_i^T`, `2k x 2k`.
    pub fn w_t_w_over(&self, indices: &[usize]) -> DMatrix<f64> {
        let k = self.len();
        let column = |r: usize| -> (&[f64], f64) {
            if r < k {
                (&self.y[r], 1.0)
            } else {
                (&self.s[r - k], self.theta)
            }
        };
        let mut out = DMatrix::zeros(2 * k, 2 * k);
        for a in 0..2 * k {
            let (ca, fa) = column(a);
            for b in 0..=a {
                let (cb, fb) = column(b);
                let sum: f64 = indices.iter().map(|&i| ca[i] * cb[i]).sum();
                out[(a, b)] = fa * fb * sum;
                out[(b, a)] = out[(a, b)];
            }
        }
        out
    }

    /// `B v` for a full vector `v`: `theta v - W M W^T v` (used by the tests to check the compact
    /// form against the BFGS recursion).
    #[cfg(test)]
    pub fn times(&self, v: &[f64]) -> Vec<f64> {
        let all: Vec<usize> = (0..v.len()).collect();
        let mwv = &self.middle * self.w_t_over(&all, v);
        (0..v.len()).map(|i| self.theta * v[i] - self.w_row(i).dot(&mwv)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The BFGS recursion from `B_0 = theta I` over the pairs, as a dense matrix.
    fn bfgs(theta: f64, pairs: &[(Vec<f64>, Vec<f64>)], n: usize) -> DMatrix<f64> {
        let mut b = DMatrix::<f64>::identity(n, n) * theta;
        for (s, y) in pairs {
            let s = DVector::from_column_slice(s);
            let y = DVector::from_column_slice(y);
            let bs = &b * &s;
            b = &b - &bs * bs.transpose() / s.dot(&bs) + &y * y.transpose() / s.dot(&y);
        }
        b
    }

    fn pairs() -> Vec<(Vec<f64>, Vec<f64>)> {
        // y = A s for a fixed SPD A: every pair has positive curvature.
        let a = [[4.0, 1.0, 0.0, 0.5], [1.0, 3.0, 0.2, 0.0], [0.0, 0.2, 2.0, 0.3], [0.5, 0.0, 0.3, 1.0]];
        let steps =
            [[1.0, 0.0, 0.5, -0.2], [0.3, -1.0, 0.1, 0.4], [-0.2, 0.5, 1.0, 0.0], [0.1, 0.1, -0.3, 1.0]];
        steps
            .iter()
            .map(|s| {
                let y = (0..4).map(|i| (0..4).map(|j| a[i][j] * s[j]).sum()).collect();
                (s.to_vec(), y)
            })
            .collect()
    }

    #[test]
    fn the_compact_form_is_the_bfgs_matrix_of_the_latest_pairs() {
        let all = pairs();
        // Capacity 3 over 4 pairs: the first is dropped; theta is the latest pair's.
        let mut memory = Memory::new(3);
        for (s, y) in &all {
            assert!(memory.push(s.clone(), y.clone()));
        }
        assert_eq!(memory.len(), 3);
        let (s, y) = &all[3];
        let theta = dot(y, y) / dot(s, y);
        assert_eq!(memory.theta(), theta);
        let dense = bfgs(theta, &all[1..], 4);
        for v in [[1.0, 0.0, 0.0, 0.0], [0.3, -0.7, 1.1, 0.2]] {
            let compact = memory.times(&v);
            let expected = &dense * DVector::from_column_slice(&v);
            for i in 0..4 {
                approx::assert_relative_eq!(compact[i], expected[i], max_relative = 1e-12, epsilon = 1e-12);
            }
        }
    }

    #[test]
    fn a_pair_without_positive_curvature_is_skipped() {
        let mut memory = Memory::new(5);
        assert!(!memory.push(vec![1.0, 0.0], vec![-1.0, 0.0]));
        assert!(!memory.push(vec![1.0, 0.0], vec![0.0, 1.0]));
        assert_eq!((memory.len(), memory.theta()), (0, 1.0));
        assert!(memory.push(vec![1.0, 0.0], vec![2.0, 0.0]));
        assert_eq!((memory.len(), memory.theta()), (1, 2.0));
    }
}
