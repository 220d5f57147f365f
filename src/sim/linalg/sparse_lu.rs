//! Stage 5 (sim): the general sparse LU of `linsolve.rs`, for Jacobian patterns that no narrow
//! band fits (a hub state coupled to every other, a 2-D grid).
//!
//! **Symbolic analysis**, once per mode ([`Symbolic::analyse`]): the states are ordered by exact
//! minimum degree on the graph of the symmetrised pattern (`f_x + f_x^T`; `W` always has its
//! diagonal), an explicit elimination on adjacency sets: the node of least degree (the lowest
//! number among equals) is eliminated and its remaining neighbours joined into a clique. The
//! neighbours at elimination are column `k` of `L` and, the structure being symmetric, row `k`
//! of `U`: the static fill pattern of the factors for pivots taken on the diagonal in that order,
//! stored as one compressed-column array (`U` above the diagonal, the diagonal, `L` below). The
//! operation count is `sum_k (c_k^2 + c_k)` for `c_k` entries below the diagonal in column `k`
//! (multiply-adds, as the band's `n kl (kl + ku)` and the dense `n^3 / 3`). The analysis stops
//! and reports that the path does not pay as soon as that count passes a cap the caller gives
//! (the dense or banded count it would have to beat); its own work is about that count times a
//! logarithm, so it stays bounded too. A star (hub) has no fill: its leaves go first, the hub
//! last.
//!
//! **Numeric factorisation**, every attempt ([`Numeric::factor`]): left-looking (column by
//! column, Gilbert-Peierls without the search: the pattern is known) into the precomputed
//! arrays, no allocation. The pivots are the diagonal in the analysis' order (**static
//! pivoting**, no row exchanges), accepted only when `|u_jj| >= PIVOT_THRESHOLD * max_i |a_ij|`
//! over the column's entries on and below the diagonal of the remaining matrix (threshold
//! partial pivoting's test, which bounds every multiplier by `1 / PIVOT_THRESHOLD`); a pivot that
//! fails it, is zero or is not finite makes `factor` return `false`, and the caller factors this
//! attempt with the dense LU instead.

use std::cmp::Reverse;
use std::collections::{BTreeSet, BinaryHeap};

/// A static pivot is accepted when its magnitude is at least this fraction of the largest in its
/// column of the remaining matrix (UMFPACK's default threshold; KLU's is 1e-3): the multipliers
/// stay below 10 in magnitude.
pub(crate) const PIVOT_THRESHOLD: f64 = 0.1;

/// The ordering and the static fill pattern of one Jacobian pattern.
#[derive(Clone, Debug)]
pub(crate) struct Symbolic {
    n: usize,
    /// `perm[i]`: the position of state `i` in the elimination order.
    pub(crate) perm: Vec<usize>,
    /// The factors in the elimination order, compressed by column: column `j`'s rows at
    /// `idx[ptr[j]..ptr[j + 1]]`, ascending (`U`'s, then the diagonal at `diag[j]`, then `L`'s).
    ptr: Vec<usize>,
    idx: Vec<usize>,
    diag: Vec<usize>,
    /// Each pattern entry's slot in the factors' values.
    at: Vec<usize>,
    /// Multiply-adds of one numeric factorisation.
    flops: f64,
}

impl Symbolic {
    /// Orders by minimum degree and computes the fill; `None` when the factorisation's count of
    /// multiply-adds would exceed `cap` (it does not pay).
    pub(crate) fn analyse(n: usize, entries: &[(usize, usize)], cap: f64) -> Option<Symbolic> {
        let mut adj: Vec<BTreeSet<usize>> = vec![BTreeSet::new(); n];
        for &(r, c) in entries {
            if r != c {
                adj[r].insert(c);
                adj[c].insert(r);
            }
        }
        // Least degree first, then the lowest number; entries whose degree has changed since
        // are skipped when popped (each change pushes the new one).
        let mut heap: BinaryHeap<Reverse<(usize, usize)>> =
            (0..n).map(|v| Reverse((adj[v].len(), v))).collect();
        let mut done = vec![false; n];
        let mut order = Vec::with_capacity(n);
        let mut cols: Vec<Vec<usize>> = Vec::with_capacity(n);
        let mut flops = 0.0;
        while let Some(Reverse((d, v))) = heap.pop() {
            if done[v] || d != adj[v].len() {
                continue;
            }
            done[v] = true;
            let nb: Vec<usize> = std::mem::take(&mut adj[v]).into_iter().collect();
            let c = nb.len() as f64;
            flops += c * c + c;
            if flops > cap {
                return None;
            }
            for &u in &nb {
                let a = &mut adj[u];
                a.remove(&v);
                a.extend(nb.iter().copied().filter(|&w| w != u));
                heap.push(Reverse((a.len(), u)));
            }
            order.push(v);
            cols.push(nb);
        }
        let mut perm = vec![0; n];
        for (k, &v) in order.iter().enumerate() {
            perm[v] = k;
        }
        // `L`'s column k (rows after k) and, transposed, `U`'s entries above each diagonal.
        let lower: Vec<Vec<usize>> = cols
            .iter()
            .map(|nb| {
                let mut rows: Vec<usize> = nb.iter().map(|&u| perm[u]).collect();
                rows.sort_unstable();
                rows
            })
            .collect();
        let mut upper: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (k, rows) in lower.iter().enumerate() {
            for &i in rows {
                upper[i].push(k);
            }
        }
        let (mut ptr, mut idx, mut diag) = (Vec::with_capacity(n + 1), Vec::new(), Vec::with_capacity(n));
        ptr.push(0);
        for j in 0..n {
            idx.extend_from_slice(&upper[j]);
            diag.push(idx.len());
            idx.push(j);
            idx.extend_from_slice(&lower[j]);
            ptr.push(idx.len());
        }
        let at = entries
            .iter()
            .map(|&(r, c)| {
                let (i, j) = (perm[r], perm[c]);
                let col = &idx[ptr[j]..ptr[j + 1]];
                ptr[j] + col.binary_search(&i).expect("an entry of the pattern is in the factors' pattern")
            })
            .collect();
        Some(Symbolic { n, perm, ptr, idx, diag, at, flops })
    }

    /// Multiply-adds of one numeric factorisation.
    pub(crate) fn flops(&self) -> f64 {
        self.flops
    }

    /// Entries of the factors beyond the pattern and the diagonal.
    #[cfg(test)]
    pub(crate) fn fill(&self) -> usize {
        let mut original = vec![false; self.idx.len()];
        for &slot in self.at.iter().chain(&self.diag) {
            original[slot] = true;
        }
        original.iter().filter(|o| !**o).count()
    }

    /// Numbers stored for the factors.
    #[cfg(test)]
    pub(crate) fn nnz(&self) -> usize {
        self.idx.len()
    }
}

/// The factors' values and the solves' scratch, reused from attempt to attempt.
#[derive(Clone, Debug, Default)]
pub(crate) struct Numeric {
    vals: Vec<f64>,
    /// `1 / u_jj`.
    inv: Vec<f64>,
    /// The column being factored, scattered (zero between columns).
    w: Vec<f64>,
    /// The right-hand sides in the elimination order, row-major.
    work: Vec<f64>,
}

impl Numeric {
    /// Factors `W = I - hg f_x` (`fx`: the pattern's values) with the pivots on the diagonal in
    /// the analysis' order; `false` when a pivot fails the threshold test (module doc), is zero
    /// or is not finite: the factors are then unusable.
    pub(crate) fn factor(&mut self, s: &Symbolic, fx: &[f64], hg: f64) -> bool {
        let n = s.n;
        self.vals.clear();
        self.vals.resize(s.idx.len(), 0.0);
        self.inv.resize(n, 0.0);
        self.w.clear();
        self.w.resize(n, 0.0);
        for (&slot, &v) in s.at.iter().zip(fx) {
            self.vals[slot] -= hg * v;
        }
        for &d in &s.diag {
            self.vals[d] += 1.0;
        }
        let (vals, w) = (&mut self.vals, &mut self.w);
        for j in 0..n {
            let (start, dj, end) = (s.ptr[j], s.diag[j], s.ptr[j + 1]);
            for p in start..end {
                w[s.idx[p]] = vals[p];
            }
            // `U`'s entries of column j in ascending row order: each final when reached.
            for p in start..dj {
                let k = s.idx[p];
                let ukj = w[k];
                if ukj != 0.0 {
                    for q in s.diag[k] + 1..s.ptr[k + 1] {
                        w[s.idx[q]] -= vals[q] * ukj;
                    }
                }
            }
            let pivot = w[j];
            let below = s.idx[dj + 1..end].iter().fold(0.0f64, |m, &i| m.max(w[i].abs()));
            if !(pivot.is_finite()
                && below.is_finite()
                && pivot != 0.0
                && pivot.abs() >= PIVOT_THRESHOLD * below)
            {
                return false;
            }
            let inv = 1.0 / pivot;
            self.inv[j] = inv;
            for (v, &i) in vals[start..end].iter_mut().zip(&s.idx[start..end]) {
                *v = if i > j { w[i] * inv } else { w[i] };
                w[i] = 0.0;
            }
        }
        true
    }

    /// Solves `W y = b` in place for `cols` right-hand sides stored one after another (`n`
    /// each), with the factors of the last successful [`Self::factor`].
    pub(crate) fn solve(&mut self, s: &Symbolic, b: &mut [f64], cols: usize) {
        let n = s.n;
        let mut work = std::mem::take(&mut self.work);
        work.resize(n * cols, 0.0);
        for (c, col) in b.chunks_exact(n).take(cols).enumerate() {
            for (&v, &at) in col.iter().zip(&s.perm) {
                work[at * cols + c] = v;
            }
        }
        // Rows of up to 16 columns as fixed-size arrays (the row operations unrolled).
        macro_rules! fixed {
            ($($c:literal)*) => {
                match cols {
                    $($c => self.substitute_rows::<$c>(s, work.as_chunks_mut::<$c>().0),)*
                    _ => self.substitute_any(s, &mut work, cols),
                }
            };
        }
        fixed!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16);
        for (c, col) in b.chunks_exact_mut(n).take(cols).enumerate() {
            for (v, &at) in col.iter_mut().zip(&s.perm) {
                *v = work[at * cols + c];
            }
        }
        self.work = work;
    }

    /// Solves `W^T y = b` in place for one right-hand side (`n`), with the factors of the last
    /// successful [`Self::factor`]: `U^T` forward (column `j` of `U` is row `j` of `U^T`, stored
    /// contiguous), then `L^T` backward, in the elimination order.
    pub(crate) fn solve_transposed(&mut self, s: &Symbolic, b: &mut [f64]) {
        let n = s.n;
        let mut work = std::mem::take(&mut self.work);
        work.resize(n, 0.0);
        for (&v, &at) in b.iter().zip(&s.perm) {
            work[at] = v;
        }
        for j in 0..n {
            let dot: f64 = (s.ptr[j]..s.diag[j]).map(|q| self.vals[q] * work[s.idx[q]]).sum();
            work[j] = (work[j] - dot) * self.inv[j];
        }
        for j in (0..n).rev() {
            let dot: f64 = (s.diag[j] + 1..s.ptr[j + 1]).map(|q| self.vals[q] * work[s.idx[q]]).sum();
            work[j] -= dot;
        }
        for (v, &at) in b.iter_mut().zip(&s.perm) {
            *v = work[at];
        }
        self.work = work;
    }

    /// The substitutions of [`Self::solve`] on rows of `C` columns (the operations of
    /// [`Self::substitute_any`], in its order).
    fn substitute_rows<const C: usize>(&self, s: &Symbolic, x: &mut [[f64; C]]) {
        for j in 0..s.n {
            let xj = x[j];
            for q in s.diag[j] + 1..s.ptr[j + 1] {
                let (i, l) = (s.idx[q], self.vals[q]);
                if l != 0.0 {
                    for (x, y) in x[i].iter_mut().zip(&xj) {
                        *x -= l * y;
                    }
                }
            }
        }
        for j in (0..s.n).rev() {
            let mut xj = x[j];
            for v in xj.iter_mut() {
                *v *= self.inv[j];
            }
            x[j] = xj;
            for q in s.ptr[j]..s.diag[j] {
                let (i, u) = (s.idx[q], self.vals[q]);
                if u != 0.0 {
                    for (x, y) in x[i].iter_mut().zip(&xj) {
                        *x -= u * y;
                    }
                }
            }
        }
    }

    /// The substitutions of [`Self::solve`] on `work`, row-major with `cols` columns.
    fn substitute_any(&self, s: &Symbolic, work: &mut [f64], cols: usize) {
        let n = s.n;
        // `L y = b`, unit diagonal, column by column.
        for j in 0..n {
            let (head, tail) = work.split_at_mut((j + 1) * cols);
            let xj = &head[j * cols..];
            for q in s.diag[j] + 1..s.ptr[j + 1] {
                let (i, l) = (s.idx[q], self.vals[q]);
                if l != 0.0 {
                    let xi = &mut tail[(i - j - 1) * cols..(i - j) * cols];
                    for (x, y) in xi.iter_mut().zip(xj) {
                        *x -= l * y;
                    }
                }
            }
        }
        // `U x = y`, column by column from the last.
        for j in (0..n).rev() {
            let (head, tail) = work.split_at_mut(j * cols);
            let xj = &mut tail[..cols];
            for x in xj.iter_mut() {
                *x *= self.inv[j];
            }
            for q in s.ptr[j]..s.diag[j] {
                let (i, u) = (s.idx[q], self.vals[q]);
                if u != 0.0 {
                    for (x, y) in head[i * cols..(i + 1) * cols].iter_mut().zip(&*xj) {
                        *x -= u * y;
                    }
                }
            }
        }
    }
}
