//! Stage 5 (sim): the linear solves of a Rosenbrock step, `W = I / (h gamma) - f_x`, factored
//! once per attempt and solved for the state block and every sensitivity column.
//!
//! Three factorisations. **Dense** (nalgebra's LU with partial pivoting, `n^3 / 3`): for the tens
//! of states of contact and kinetics models, and for any model whose Jacobian pattern is
//! unknown. The two structured ones use the pattern a compiled model gives (the structurally
//! nonzero entries of `f_x` per mode, `HybridSystem::jac_pattern`): the kernel computes only
//! those entries (`fx` holds their values, never an `n x n` matrix), and each mode's pattern is
//! analysed once (cached by the mode's key).
//!
//! **Banded**: the *symbolic analysis* orders the states by reverse Cuthill-McKee and measures
//! the band (`kl` below, `ku` above the diagonal) of the permuted `f_x`; every attempt fills the
//! band and factors it with partial pivoting inside the band (LAPACK's `gbtf2`: `n kl (kl + ku)`
//! operations, `n (2 kl + ku + 1)` numbers). A chain is tridiagonal (`kl = ku = 1`): linear in
//! `n`, in time and memory. As robust as the dense LU.
//!
//! **Sparse** (`sparse_lu.rs`), for patterns no narrow band fits (a hub coupled to every state:
//! an arrowhead, whose band is the whole matrix; a 2-D grid of `k x k` cells, band `k`, band
//! cost `n^2`): the analysis orders the states by exact minimum degree on the symmetrised
//! pattern and computes the static fill pattern of `L` and `U` (a hub then has no fill: it is
//! eliminated last); every attempt factors into that pattern with the pivots on the diagonal in
//! that order (static pivoting, no row exchanges, no allocation), each pivot accepted only when
//! `|u_jj| >= 0.1 max |a_ij|` over its column of the remaining matrix
//! (`sparse_lu::PIVOT_THRESHOLD`). When a pivot fails, that attempt is factored by the dense LU
//! instead (counted in `LinSolve::sparse_fallbacks`): a failed static pivot costs time, never a
//! wrong solve. `W = I - h gamma f_x` has the identity on its diagonal, so for small steps and
//! for diffusive (diagonally dominant) Jacobians the static pivots pass.
//!
//! Choice (`LinearSolver::Auto`, per mode, from [`SPARSE_MIN_STATES`] states): the least of the
//! factorisations' multiply-adds, dense `n^3 / 3`, banded `n kl (kl + ku)` and sparse
//! `sum_k (c_k^2 + c_k)` (`c_k` entries below the diagonal in column `k` of `L`) times
//! [`SPARSE_COST`], measured where the paths' run times tie (docs/performance.md). A chain
//! keeps the band (equal counts; the band's solves run in registers), hubs and grids take the
//! sparse LU. Why not faer's sparse LU: about 50 crates and minutes of cold build
//! (docs/design.md); the hand-written one is some 300 lines.

use nalgebra::{DMatrix, DMatrixViewMut};

use super::sparse_lu::{Numeric, Symbolic};

/// Which factorisation a Rosenbrock stepper uses (`SimOptions::linear_solver`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LinearSolver {
    /// From [`SPARSE_MIN_STATES`] states on, when the model gives its Jacobian's pattern, the
    /// cheapest of the dense, the banded and the sparse LU by their operation counts (the
    /// sparse one weighted by [`SPARSE_COST`]); dense otherwise.
    #[default]
    Auto,
    /// Always the dense LU.
    Dense,
    /// The banded LU whenever the model gives the pattern and the band costs fewer operations
    /// than the dense LU (tests and measurements).
    Banded,
    /// The sparse LU (minimum-degree order, static pivots) whenever the model gives the pattern
    /// and the fill stays below the dense LU's cost (tests and measurements).
    Sparse,
}

impl LinearSolver {
    /// The factorisation this choice uses for a mode of `n` states whose `f_x` has the
    /// structural nonzeros `pattern` (`HybridSystem::jac_pattern`): `Dense`, `Banded` or
    /// `Sparse` (the analysis a stepper makes once per mode).
    pub fn resolve(self, n: usize, pattern: &[(u32, u32)]) -> LinearSolver {
        let mut lin = LinSolve::new(n);
        lin.select(self, Some((0, pattern)));
        match lin.current {
            Path::Dense => LinearSolver::Dense,
            Path::Band(_) => LinearSolver::Banded,
            Path::Sparse(_) => LinearSolver::Sparse,
        }
    }
}

/// The multiply-adds of one factorisation of `W` for a pattern, by path (measurements).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FactorCosts {
    /// `n^3 / 3`.
    pub dense: f64,
    /// `n kl (kl + ku)` after reverse Cuthill-McKee; `None` when above the dense count.
    pub banded: Option<f64>,
    /// The minimum-degree order's count (before the [`SPARSE_COST`] weight); `None` when above
    /// the dense count.
    pub sparse: Option<f64>,
}

impl FactorCosts {
    /// The counts for a mode of `n` states whose `f_x` has the structural nonzeros `pattern`.
    pub fn of(n: usize, pattern: &[(u32, u32)]) -> FactorCosts {
        let dense = dense_cost(n);
        let banded = Structure::analyse(n, pattern).map(|s| band_cost(n, s.band()));
        let sparse = SparseStructure::analyse(n, pattern, dense).map(|s| s.sym.flops());
        FactorCosts { dense, banded, sparse }
    }
}

/// `Auto` takes the sparse LU when its multiply-adds times this factor are fewer than the
/// band's and the dense LU's: the price of its indirect addressing against the band's
/// contiguous columns and the dense LU's kernels. Measured on whole Rodas5P runs with 10
/// gradients (`benches/measure/sparse_hub.rs`, docs/performance.md), where the paths tie: the sparse
/// and the banded LU on the W5 chain (counts equal: within 4% either way at 10, 100 and 1000
/// states), a 3-state hub (ratio 1.5: within 3% either way) and a 3 x 3 grid (ratio 2.9: the
/// sparse LU 3-5% faster, 6% at 4 x 4, 10% at 5 x 5); the sparse and the dense LU on a 2 x 2
/// grid (ratio 1.5: within 1%), a 3-state hub (2.25: within 2%) and a 4-state hub (3.6: the
/// sparse LU 5% faster).
pub const SPARSE_COST: f64 = 2.0;

/// From this many states `Auto` uses a structured factorisation, banded or sparse (when the
/// model gives its Jacobian's pattern and it costs fewer operations than the dense LU). Measured
/// for the band on the diffusion
/// chain of workload W5 (Rodas5P, 10 gradients, `benches/measure/w5_chain.rs`, docs/performance.md):
/// a run with the band takes the time of the dense one at 2 states (0.188 ms both), 0.93 of it at
/// 3, 0.54 at 10, 0.40 at 30 and 0.008 at 1000; the switch is where the band becomes narrower
/// than the matrix, not a size. The dense LU stays for one and two states, where there is no
/// band to find (nor, at 2 states, a sparse LU to gain: a 2 x 2 grid's four states tie).
pub const SPARSE_MIN_STATES: usize = 3;

/// A pattern's entries grouped by row, for the products `f_x x` and the row sums of every
/// structured path.
#[derive(Clone, Debug)]
pub(crate) struct Rows {
    /// Each pattern entry's `(row, column)` as the model numbers the states.
    entries: Vec<(usize, usize)>,
    /// The entries' positions in the pattern grouped by row (in pattern order within a row),
    /// row `r` at `row_start[r]..row_start[r + 1]`: row sums and products without a scratch
    /// row or scattered updates.
    by_row: Vec<usize>,
    row_start: Vec<usize>,
    /// The column of each entry of `by_row`.
    row_col: Vec<usize>,
    /// When the pattern fills a band of the model's own numbering exactly (every position from
    /// `kl0` below to `ku0` above the diagonal an entry, once: a chain), `(kl0, ku0)` and each
    /// entry's slot in diagonal storage (`diagonal * n + row`); the product `f_x x` then runs
    /// along contiguous diagonals. With a hole in the band a zero slot would multiply an
    /// entry of `x` the pattern does not read (a NaN there must not spread), so then no.
    diagonals: Option<(usize, usize, Vec<usize>)>,
}

impl Rows {
    fn new(n: usize, entries: Vec<(usize, usize)>) -> Rows {
        let mut row_start = vec![0usize; n + 1];
        for &(r, _) in &entries {
            row_start[r + 1] += 1;
        }
        for r in 0..n {
            row_start[r + 1] += row_start[r];
        }
        let mut next = row_start.clone();
        let mut by_row = vec![0usize; entries.len()];
        for (k, &(r, _)) in entries.iter().enumerate() {
            by_row[next[r]] = k;
            next[r] += 1;
        }
        let diagonals = full_band(n, &entries, band_of(entries.iter().copied()));
        let row_col = by_row.iter().map(|&k| entries[k].1).collect();
        Rows { entries, by_row, row_start, row_col, diagonals }
    }
}

/// The symbolic analysis of one pattern for the banded path: the ordering and the band.
#[derive(Clone, Debug)]
pub(crate) struct Structure {
    /// `perm[i]`: the position of state `i` in the banded order.
    perm: Vec<usize>,
    /// `perm` is the identity: a single right-hand side is solved in place.
    identity: bool,
    /// Each pattern entry's `(row, column)` in the banded order.
    at: Vec<(usize, usize)>,
    rows: Rows,
    kl: usize,
    ku: usize,
}

impl Structure {
    /// Orders the states by reverse Cuthill-McKee on the symmetrised pattern and measures the
    /// band; `None` when the banded factorisation would cost more than the dense one.
    pub(crate) fn analyse(n: usize, entries: &[(u32, u32)]) -> Option<Structure> {
        let entries: Vec<(usize, usize)> = entries.iter().map(|&(r, c)| (r as usize, c as usize)).collect();
        let natural = band_of(entries.iter().copied());
        let ordered = rcm(n, &entries);
        let reordered = band_of(entries.iter().map(|&(r, c)| (ordered[r], ordered[c])));
        // The model's own numbering when it is as narrow (a chain written in order): the
        // solves' permutation is then the identity, read in order.
        let (perm, (kl, ku)) = if band_cost(n, natural) <= band_cost(n, reordered) {
            ((0..n).collect(), natural)
        } else {
            (ordered, reordered)
        };
        let at: Vec<(usize, usize)> = entries.iter().map(|&(r, c)| (perm[r], perm[c])).collect();
        let identity = perm.iter().enumerate().all(|(i, &p)| i == p);
        (band_cost(n, (kl, ku)) < dense_cost(n)).then(|| Structure {
            perm,
            identity,
            at,
            rows: Rows::new(n, entries),
            kl,
            ku,
        })
    }

    /// `(kl, ku)`: the band below and above the diagonal.
    pub(crate) fn band(&self) -> (usize, usize) {
        (self.kl, self.ku)
    }
}

/// Multiply-adds of the banded factorisation: `n kl (kl + ku)` (pivoting widens the upper band
/// to `kl + ku`).
fn band_cost(n: usize, (kl, ku): (usize, usize)) -> f64 {
    n as f64 * kl as f64 * (kl + ku) as f64
}

/// Multiply-adds of the dense LU: `n^3 / 3`.
fn dense_cost(n: usize) -> f64 {
    (n as f64).powi(3) / 3.0
}

/// The symbolic analysis of one pattern for the sparse path: the minimum-degree order and the
/// factors' fill pattern (`sparse_lu`).
#[derive(Clone, Debug)]
pub(crate) struct SparseStructure {
    sym: Symbolic,
    rows: Rows,
}

impl SparseStructure {
    /// `None` when the factorisation would cost more than `cap` multiply-adds.
    fn analyse(n: usize, entries: &[(u32, u32)], cap: f64) -> Option<SparseStructure> {
        let entries: Vec<(usize, usize)> = entries.iter().map(|&(r, c)| (r as usize, c as usize)).collect();
        let sym = Symbolic::analyse(n, &entries, cap)?;
        Some(SparseStructure { sym, rows: Rows::new(n, entries) })
    }
}

/// The analyses of one mode's pattern, each made when first wanted (`None` inside: that path
/// does not pay), and `Auto`'s choice.
#[derive(Clone, Debug, Default)]
struct Mode {
    band: Option<Option<Structure>>,
    sparse: Option<Option<SparseStructure>>,
    auto: Option<LinearSolver>,
}

impl Mode {
    fn band(&mut self, n: usize, entries: &[(u32, u32)]) -> bool {
        self.band.get_or_insert_with(|| Structure::analyse(n, entries)).is_some()
    }

    /// The sparse analysis, stopped at `cap` multiply-adds.
    fn sparse(&mut self, n: usize, entries: &[(u32, u32)], cap: f64) -> bool {
        self.sparse.get_or_insert_with(|| SparseStructure::analyse(n, entries, cap)).is_some()
    }

    /// `Auto`'s choice: the least of the dense count, the band's and the sparse count times
    /// [`SPARSE_COST`] (the sparse analysis stopped where it can no longer win).
    fn auto(&mut self, n: usize, entries: &[(u32, u32)]) -> LinearSolver {
        if let Some(choice) = self.auto {
            return choice;
        }
        let dense = dense_cost(n);
        let band = if self.band(n, entries) {
            self.band.as_ref().and_then(|b| b.as_ref()).map(|s| band_cost(n, s.band()))
        } else {
            None
        };
        let best = band.unwrap_or(f64::INFINITY).min(dense);
        let choice = if self.sparse(n, entries, best / SPARSE_COST) {
            LinearSolver::Sparse
        } else if band.is_some() {
            LinearSolver::Banded
        } else {
            LinearSolver::Dense
        };
        self.auto = Some(choice);
        choice
    }
}

/// `(kl, ku)`: the band below and above the diagonal that `entries` span.
fn band_of(entries: impl Iterator<Item = (usize, usize)>) -> (usize, usize) {
    entries.fold((0, 0), |(kl, ku), (r, c)| (kl.max(r.saturating_sub(c)), ku.max(c.saturating_sub(r))))
}

/// Each entry's slot `(c - r + kl) * n + r` in diagonal storage when the entries fill the band
/// `(kl, ku)` exactly, every position once; `None` otherwise (or when the band's storage would
/// be large against the pattern).
fn full_band(
    n: usize,
    entries: &[(usize, usize)],
    (kl, ku): (usize, usize),
) -> Option<(usize, usize, Vec<usize>)> {
    let width = kl + ku + 1;
    // Positions in the band: `n` per diagonal less the ends it loses.
    let positions = width * n - (kl * (kl + 1) + ku * (ku + 1)) / 2;
    if n == 0 || width > n || entries.len() != positions {
        return None;
    }
    let mut seen = vec![false; width * n];
    let mut slots = Vec::with_capacity(entries.len());
    for &(r, c) in entries {
        let slot = (c + kl - r) * n + r;
        if std::mem::replace(&mut seen[slot], true) {
            return None;
        }
        slots.push(slot);
    }
    Some((kl, ku, slots))
}

/// Reverse Cuthill-McKee: breadth-first from a node of least degree in each connected
/// component, neighbours by increasing degree, the order reversed. Returns `perm[i]`, the new
/// position of node `i`.
fn rcm(n: usize, entries: &[(usize, usize)]) -> Vec<usize> {
    let mut adj: Vec<Vec<usize>> = vec![Vec::new(); n];
    for &(r, c) in entries {
        if r != c && r < n && c < n {
            adj[r].push(c);
            adj[c].push(r);
        }
    }
    for a in &mut adj {
        a.sort_unstable();
        a.dedup();
    }
    let degree: Vec<usize> = adj.iter().map(Vec::len).collect();
    let mut by_degree: Vec<usize> = (0..n).collect();
    by_degree.sort_by_key(|&i| (degree[i], i));
    let mut order = Vec::with_capacity(n);
    let mut seen = vec![false; n];
    let mut queue = std::collections::VecDeque::new();
    for &start in &by_degree {
        if seen[start] {
            continue;
        }
        seen[start] = true;
        queue.push_back(start);
        while let Some(v) = queue.pop_front() {
            order.push(v);
            let mut next: Vec<usize> = adj[v].iter().copied().filter(|&w| !seen[w]).collect();
            next.sort_by_key(|&w| (degree[w], w));
            for w in next {
                seen[w] = true;
                queue.push_back(w);
            }
        }
    }
    let mut perm = vec![0; n];
    for (pos, &v) in order.iter().rev().enumerate() {
        perm[v] = pos;
    }
    perm
}

/// A banded matrix factored in place with partial pivoting (LAPACK's `gbtf2` layout): column
/// `j` holds rows `j - (kl + ku) ..= j + kl` at `ab[j * ld + (i + kl + ku - j)]`, the upper part
/// widened by `kl` for the fill that row exchanges bring.
#[derive(Clone, Debug, Default)]
struct Band {
    n: usize,
    kl: usize,
    /// `kl + ku`: the upper band after pivoting.
    ku2: usize,
    ld: usize,
    ab: Vec<f64>,
    piv: Vec<usize>,
    /// `1 / u_jj`, the pivots' reciprocals (the solves multiply by them).
    inv: Vec<f64>,
    /// The right-hand sides in the banded order, row-major.
    work: Vec<f64>,
}

impl Band {
    fn shape(&mut self, n: usize, kl: usize, ku: usize) {
        self.n = n;
        self.kl = kl;
        self.ku2 = kl + ku;
        self.ld = 2 * kl + ku + 1;
        self.ab.clear();
        self.ab.resize(n * self.ld, 0.0);
        self.piv.resize(n, 0);
        self.inv.resize(n, 0.0);
    }

    #[inline(always)]
    fn idx(&self, i: usize, j: usize) -> usize {
        debug_assert!(i + self.ku2 >= j && i <= j + self.kl);
        j * self.ld + (i + self.ku2 - j)
    }

    /// LU with partial pivoting; `false` when a pivot is zero or not finite.
    fn factor(&mut self) -> bool {
        let (n, kl, ku2) = (self.n, self.kl, self.ku2);
        for j in 0..n {
            let last = (j + kl).min(n - 1);
            let (mut p, mut best) = (j, self.ab[self.idx(j, j)].abs());
            for i in j + 1..=last {
                let v = self.ab[self.idx(i, j)].abs();
                if v > best {
                    (p, best) = (i, v);
                }
            }
            self.piv[j] = p;
            if best == 0.0 || !best.is_finite() {
                return false;
            }
            let right = (j + ku2).min(n - 1);
            if p != j {
                for c in j..=right {
                    let (a, b) = (self.idx(j, c), self.idx(p, c));
                    self.ab.swap(a, b);
                }
            }
            let inv = 1.0 / self.ab[self.idx(j, j)];
            self.inv[j] = inv;
            for i in j + 1..=last {
                let k = self.idx(i, j);
                self.ab[k] *= inv;
            }
            for c in j + 1..=right {
                let u = self.ab[self.idx(j, c)];
                if u != 0.0 {
                    for i in j + 1..=last {
                        let l = self.ab[self.idx(i, j)];
                        let k = self.idx(i, c);
                        self.ab[k] -= l * u;
                    }
                }
            }
        }
        true
    }

    /// Solves in place for `cols` right-hand sides in the banded order, stored row-major
    /// (`b[i * cols + c]`): every row operation acts on all the columns at once, so the
    /// substitutions' dependency chains run side by side instead of one column after another.
    /// Rows of up to 16 columns are fixed-size arrays (the row operations unrolled).
    fn solve(&self, b: &mut [f64], cols: usize) {
        macro_rules! fixed {
            ($($c:literal)*) => {
                match cols {
                    $($c => self.solve_rows::<$c>(b.as_chunks_mut::<$c>().0),)*
                    _ => self.solve_any(b, cols),
                }
            };
        }
        fixed!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16)
    }

    /// [`Self::solve`] for rows of `C` columns. The row that the next step needs first (row
    /// `j + 1` going down, `j - 1` going up) is carried in registers instead of being stored
    /// and loaded again: that store and load were on the substitution's dependency chain, which
    /// bounds the solve's speed. The operations and their order are those of
    /// [`Self::solve_any`].
    fn solve_rows<const C: usize>(&self, b: &mut [[f64; C]]) {
        let (n, kl, ku2, ld) = (self.n, self.kl, self.ku2, self.ld);
        if n == 0 {
            return;
        }
        let sub = |row: &mut [f64; C], m: f64, by: &[f64; C]| {
            if m != 0.0 {
                for (x, y) in row.iter_mut().zip(by) {
                    *x -= m * y;
                }
            }
        };
        // Row j with every earlier column's update applied.
        let mut cur = b[0];
        for j in 0..n {
            let p = self.piv[j];
            if p != j {
                std::mem::swap(&mut cur, &mut b[p]);
            }
            let last = (j + kl).min(n - 1);
            // Column j's multipliers are contiguous in `ab`.
            let l = &self.ab[j * ld + ku2 + 1..j * ld + ku2 + 1 + (last - j)];
            let mut next = if j + 1 < n { b[j + 1] } else { cur };
            if let Some((&l1, rest)) = l.split_first() {
                sub(&mut next, l1, &cur);
                for (bi, &l) in b[j + 2..=last].iter_mut().zip(rest) {
                    sub(bi, l, &cur);
                }
            }
            b[j] = cur;
            cur = next;
        }
        // Row j with every later row's update applied.
        let mut cur = b[n - 1];
        for j in (0..n).rev() {
            for x in cur.iter_mut() {
                *x *= self.inv[j];
            }
            b[j] = cur;
            let first = j.saturating_sub(ku2);
            let u = &self.ab[j * ld + ku2 - (j - first)..j * ld + ku2];
            if let Some((&u1, rest)) = u.split_last() {
                let mut next = b[j - 1];
                sub(&mut next, u1, &cur);
                for (bi, &u) in b[first..j - 1].iter_mut().zip(rest) {
                    sub(bi, u, &cur);
                }
                cur = next;
            } else if j > 0 {
                // No band above the diagonal: the next row has no update.
                cur = b[j - 1];
            }
        }
    }

    /// Solves `W^T x = b` in place for one right-hand side in the banded order, with the
    /// factors of [`Self::factor`] (LAPACK's `dgbtrs` transposed): `W^{-1}` is
    /// `U^{-1} M_{n-1} .. M_0` with `M_j` row `j`'s exchange then its multipliers, so its
    /// transpose is `U^{-T}` first, then each `M_j^T` from the last: the multipliers of column `j`
    /// gathered into row `j`, then the exchange.
    fn solve_transposed(&self, b: &mut [f64]) {
        let (n, kl, ku2) = (self.n, self.kl, self.ku2);
        // `U^T z = b`: row `j` of `U^T` is column `j` of `U`, contiguous in `ab`.
        for j in 0..n {
            let first = j.saturating_sub(ku2);
            let u = &self.ab[self.idx(first, j)..self.idx(j, j)];
            let dot: f64 = u.iter().zip(&b[first..j]).map(|(u, z)| u * z).sum();
            b[j] = (b[j] - dot) * self.inv[j];
        }
        for j in (0..n).rev() {
            let last = (j + kl).min(n - 1);
            if last > j {
                let l = &self.ab[self.idx(j + 1, j)..=self.idx(last, j)];
                let dot: f64 = l.iter().zip(&b[j + 1..=last]).map(|(l, y)| l * y).sum();
                b[j] -= dot;
            }
            let p = self.piv[j];
            if p != j {
                b.swap(j, p);
            }
        }
    }

    /// [`Self::solve`] for rows of any width.
    fn solve_any(&self, b: &mut [f64], cols: usize) {
        let (n, kl, ku2) = (self.n, self.kl, self.ku2);
        let row = |i: usize| i * cols..(i + 1) * cols;
        for j in 0..n {
            let p = self.piv[j];
            if p != j {
                let (head, tail) = b.split_at_mut(p * cols);
                head[row(j)].swap_with_slice(&mut tail[..cols]);
            }
            let last = (j + kl).min(n - 1);
            if last > j {
                let (head, tail) = b.split_at_mut((j + 1) * cols);
                let bj = &head[row(j)];
                // Column j's multipliers are contiguous in `ab`.
                let l = &self.ab[self.idx(j + 1, j)..=self.idx(last, j)];
                for (bi, &l) in tail.chunks_exact_mut(cols).zip(l) {
                    if l != 0.0 {
                        for (x, y) in bi.iter_mut().zip(bj) {
                            *x -= l * y;
                        }
                    }
                }
            }
        }
        for j in (0..n).rev() {
            let first = j.saturating_sub(ku2);
            let (head, tail) = b.split_at_mut(j * cols);
            let bj = &mut tail[..cols];
            for x in bj.iter_mut() {
                *x *= self.inv[j];
            }
            let u = &self.ab[self.idx(first, j)..self.idx(j, j)];
            for (bi, &u) in head[first * cols..].chunks_exact_mut(cols).zip(u) {
                if u != 0.0 {
                    for (x, y) in bi.iter_mut().zip(&*bj) {
                        *x -= u * y;
                    }
                }
            }
        }
    }
}

/// Which factorisation a mode's `W` is factored with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
enum Path {
    #[default]
    Dense,
    /// The banded LU of mode `key`'s analysis.
    Band(usize),
    /// The sparse LU of mode `key`'s analysis.
    Sparse(usize),
}

/// The factorisation of `W` for one stepper: the Jacobian's values, the cached symbolic
/// analyses (one per mode, by the key the right-hand side gives) and the factors.
#[derive(Default)]
pub(crate) struct LinSolve {
    n: usize,
    /// `f_x`: row-major `n x n` for the dense path, the pattern's values for the structured ones.
    pub(crate) fx: Vec<f64>,
    /// The analyses of each mode's pattern once made.
    modes: Vec<Mode>,
    /// The path `fx` follows.
    current: Path,
    band: Band,
    sparse: Numeric,
    /// On the sparse path, this attempt's static pivots failed: `lu` holds the dense factors.
    sparse_in_dense: bool,
    /// Attempts on the sparse path factored densely because a static pivot failed (tests).
    pub(crate) sparse_fallbacks: usize,
    /// `f_x` in diagonal storage (`Rows::diagonals`), or else its values in the order of
    /// `Rows::by_row`, filled by [`Self::factor`] for the products.
    diag: Vec<f64>,
    fx_rows: Vec<f64>,
    lu: Option<nalgebra::LU<f64, nalgebra::Dyn, nalgebra::Dyn>>,
}

impl LinSolve {
    pub(crate) fn new(n: usize) -> LinSolve {
        LinSolve { n, ..LinSolve::default() }
    }

    /// Chooses the factorisation for the Jacobian about to be evaluated: banded or sparse when
    /// `pattern` (mode `key`'s entries) is given, `choice` allows it and it pays (the analysis
    /// made once per mode); sizes `fx` for it. Returns whether the Jacobian is wanted as the
    /// pattern's values.
    pub(crate) fn select(&mut self, choice: LinearSolver, pattern: Option<(usize, &[(u32, u32)])>) -> bool {
        let n = self.n;
        let path = match (choice, pattern) {
            (LinearSolver::Dense, _) | (_, None) => Path::Dense,
            (LinearSolver::Auto, Some(_)) if n < SPARSE_MIN_STATES => Path::Dense,
            (_, Some((key, entries))) => {
                if self.modes.len() <= key {
                    self.modes.resize_with(key + 1, Mode::default);
                }
                let mode = &mut self.modes[key];
                let choice = match choice {
                    LinearSolver::Auto => mode.auto(n, entries),
                    c => c,
                };
                match choice {
                    LinearSolver::Banded if mode.band(n, entries) => Path::Band(key),
                    // Forced: up to the dense count (at least 10^6, for small tests).
                    LinearSolver::Sparse if mode.sparse(n, entries, dense_cost(n).max(1e6)) => {
                        Path::Sparse(key)
                    }
                    _ => Path::Dense,
                }
            }
        };
        match path {
            Path::Band(key) => {
                let Some(Some(s)) = &self.modes[key].band else { unreachable!("analysed above") };
                let (nnz, (kl, ku)) = (s.rows.entries.len(), s.band());
                if self.current != path || self.band.n != n {
                    self.band.shape(n, kl, ku);
                }
                self.fx.resize(nnz, 0.0);
            }
            Path::Sparse(key) => {
                let Some(Some(s)) = &self.modes[key].sparse else { unreachable!("analysed above") };
                self.fx.resize(s.rows.entries.len(), 0.0);
            }
            Path::Dense => self.fx.resize(n * n, 0.0),
        }
        self.current = path;
        path != Path::Dense
    }

    /// The pattern `fx` follows, `None` on the dense path.
    fn rows(&self) -> Option<&Rows> {
        match self.current {
            Path::Dense => None,
            Path::Band(key) => self.modes.get(key)?.band.as_ref()?.as_ref().map(|s| &s.rows),
            Path::Sparse(key) => self.modes.get(key)?.sparse.as_ref()?.as_ref().map(|s| &s.rows),
        }
    }

    /// `y += a f_x x` for every block of `n` of `x` and `y` (the state and each sensitivity
    /// column), from the values in `fx` (dense or the pattern's; on a structured path as of the
    /// last [`Self::factor`], which the stepper calls first). Each `y_r` gets its row's terms
    /// in the pattern's order, or by column on a full band.
    pub(crate) fn mul_add(&self, a: f64, x: &[f64], y: &mut [f64]) {
        let n = self.n;
        if n == 0 {
            return;
        }
        let rows = self.rows();
        for (yc, xc) in y.chunks_exact_mut(n).zip(x.chunks_exact(n)) {
            match rows {
                Some(Rows { diagonals: Some((kl, ku, _)), .. }) => {
                    // Diagonal by diagonal, contiguous: `y_r += a f_(r, r + d) x_(r + d)`.
                    for (k, diag) in self.diag.chunks_exact(n).take(kl + ku + 1).enumerate() {
                        let (rows, x0) = if k < *kl { (kl - k..n, 0) } else { (0..n - (k - kl), k - kl) };
                        let xs = &xc[x0..];
                        for ((y, v), x) in yc[rows.clone()].iter_mut().zip(&diag[rows]).zip(xs) {
                            *y += a * v * x;
                        }
                    }
                }
                Some(s) => {
                    // `fx_rows`: the values in `by_row`'s order, contiguous.
                    for (r, yr) in yc.iter_mut().enumerate() {
                        let range = s.row_start[r]..s.row_start[r + 1];
                        // In a register (the same sums in the same order).
                        let mut acc = *yr;
                        for (&v, &col) in self.fx_rows[range.clone()].iter().zip(&s.row_col[range]) {
                            acc += a * v * xc[col];
                        }
                        *yr = acc;
                    }
                }
                None => {
                    for (row, yr) in yc.iter_mut().enumerate() {
                        let fr = &self.fx[row * n..(row + 1) * n];
                        *yr += a * fr.iter().zip(xc).map(|(f, x)| f * x).sum::<f64>();
                    }
                }
            }
        }
    }

    /// `||f_x||_inf`, the largest absolute row sum of the values in `fx` (no allocation: the
    /// auto stepper asks after every Rodas5P step).
    pub(crate) fn row_abs_max(&self) -> f64 {
        let n = self.n;
        match self.rows() {
            Some(s) => (0..n)
                .map(|r| {
                    s.by_row[s.row_start[r]..s.row_start[r + 1]]
                        .iter()
                        .map(|&k| self.fx[k].abs())
                        .sum::<f64>()
                })
                .fold(0.0, f64::max),
            None => (0..n)
                .map(|i| self.fx[i * n..(i + 1) * n].iter().map(|v| v.abs()).sum::<f64>())
                .fold(0.0, f64::max),
        }
    }

    /// `f_x` for [`Self::mul_add`]: in diagonal storage when the pattern fills a band exactly,
    /// else in row order.
    fn fill_products(diag: &mut Vec<f64>, fx_rows: &mut Vec<f64>, rows: &Rows, fx: &[f64], n: usize) {
        if let Some((kl, ku, slots)) = &rows.diagonals {
            diag.resize((kl + ku + 1) * n, 0.0);
            for (&slot, &v) in slots.iter().zip(fx) {
                diag[slot] = v;
            }
        } else {
            fx_rows.clear();
            fx_rows.extend(rows.by_row.iter().map(|&k| fx[k]));
        }
    }

    /// Factors `W = I - hg f_x` with `hg = h gamma`; `false` when singular. (This form, not
    /// `I / hg - f_x`: with `f_x = 0` it is the identity and a stage's solve returns its
    /// right-hand side exactly, which keeps a clock exact.)
    pub(crate) fn factor(&mut self, hg: f64) -> bool {
        let n = self.n;
        match self.current {
            Path::Band(key) => {
                let Some(Some(Some(s))) = self.modes.get(key).map(|m| &m.band) else { return false };
                Self::fill_products(&mut self.diag, &mut self.fx_rows, &s.rows, &self.fx, n);
                self.band.ab.fill(0.0);
                for (&(r, c), &v) in s.at.iter().zip(&self.fx) {
                    let k = self.band.idx(r, c);
                    self.band.ab[k] -= hg * v;
                }
                for i in 0..n {
                    let k = self.band.idx(i, i);
                    self.band.ab[k] += 1.0;
                }
                self.band.factor()
            }
            Path::Sparse(key) => {
                let Some(Some(Some(s))) = self.modes.get(key).map(|m| &m.sparse) else { return false };
                Self::fill_products(&mut self.diag, &mut self.fx_rows, &s.rows, &self.fx, n);
                self.sparse_in_dense = false;
                if self.sparse.factor(&s.sym, &self.fx, hg) {
                    return true;
                }
                // A static pivot failed: this attempt with the dense LU (partial pivoting).
                self.sparse_fallbacks += 1;
                self.sparse_in_dense = true;
                let mut w = DMatrix::identity(n, n);
                for (&(r, c), &v) in s.rows.entries.iter().zip(&self.fx) {
                    w[(r, c)] -= hg * v;
                }
                let lu = w.lu();
                let ok = lu.is_invertible();
                self.lu = Some(lu);
                ok
            }
            Path::Dense => {
                let fx = &self.fx;
                let w = DMatrix::from_fn(n, n, |i, j| if i == j { 1.0 } else { 0.0 } - hg * fx[i * n + j]);
                let lu = w.lu();
                let ok = n == 0 || lu.is_invertible();
                self.lu = Some(lu);
                ok
            }
        }
    }

    /// Solves `W y = b` in place for `cols` right-hand sides stored one after another (`n`
    /// each); `false` when the factorisation is missing or singular.
    pub(crate) fn solve(&mut self, b: &mut [f64], cols: usize) -> bool {
        let n = self.n;
        if n == 0 {
            return true;
        }
        match self.current {
            Path::Band(key) => {
                let Some(Some(Some(s))) = self.modes.get(key).map(|m| &m.band) else { return false };
                if cols == 1 && s.identity {
                    self.band.solve(&mut b[..n], 1);
                    return true;
                }
                // Into the banded order, row-major over the columns, and back, a block of
                // states at a time (its rows of `work` stay in the cache while every column
                // passes).
                let mut work = std::mem::take(&mut self.band.work);
                work.resize(n * cols, 0.0);
                const STATES: usize = 64;
                for start in (0..n).step_by(STATES) {
                    let end = (start + STATES).min(n);
                    for (c, col) in b.chunks_exact(n).take(cols).enumerate() {
                        for (&v, &at) in col[start..end].iter().zip(&s.perm[start..end]) {
                            work[at * cols + c] = v;
                        }
                    }
                }
                self.band.solve(&mut work, cols);
                for start in (0..n).step_by(STATES) {
                    let end = (start + STATES).min(n);
                    for (c, col) in b.chunks_exact_mut(n).take(cols).enumerate() {
                        for (v, &at) in col[start..end].iter_mut().zip(&s.perm[start..end]) {
                            *v = work[at * cols + c];
                        }
                    }
                }
                self.band.work = work;
                true
            }
            Path::Sparse(key) if !self.sparse_in_dense => {
                let Some(Some(Some(s))) = self.modes.get(key).map(|m| &m.sparse) else { return false };
                self.sparse.solve(&s.sym, b, cols);
                true
            }
            Path::Sparse(_) | Path::Dense => match &self.lu {
                Some(lu) => lu.solve_mut(&mut DMatrixViewMut::from_slice(&mut b[..n * cols], n, cols)),
                None => false,
            },
        }
    }
}

impl LinSolve {
    /// Solves `W^T y = b` in place for one right-hand side, with the factorisation of the last
    /// [`Self::factor`] (the adjoint's backward pass through a Rosenbrock stage: the same `W`
    /// the forward step solved with, transposed); `false` when it is missing or singular.
    pub(crate) fn solve_transposed(&mut self, b: &mut [f64]) -> bool {
        let n = self.n;
        if n == 0 {
            return true;
        }
        let b = &mut b[..n];
        match self.current {
            Path::Band(key) => {
                let Some(Some(Some(s))) = self.modes.get(key).map(|m| &m.band) else { return false };
                // `W = Q^T W_Q Q` with `Q` the banded order: `W^T = Q^T W_Q^T Q`.
                let mut work = std::mem::take(&mut self.band.work);
                work.resize(n, 0.0);
                for (&v, &at) in b.iter().zip(&s.perm) {
                    work[at] = v;
                }
                self.band.solve_transposed(&mut work[..n]);
                for (v, &at) in b.iter_mut().zip(&s.perm) {
                    *v = work[at];
                }
                self.band.work = work;
                true
            }
            Path::Sparse(key) if !self.sparse_in_dense => {
                let Some(Some(Some(s))) = self.modes.get(key).map(|m| &m.sparse) else { return false };
                self.sparse.solve_transposed(&s.sym, b);
                true
            }
            Path::Sparse(_) | Path::Dense => match &self.lu {
                Some(lu) => {
                    // `P W = L U`, so `W^T = U^T L^T P`: two triangular solves, then `P^T`.
                    let (p, l, u) = lu.clone().unpack();
                    let mut v = DMatrixViewMut::from_slice(b, n, 1);
                    if !u.tr_solve_upper_triangular_mut(&mut v) || !l.tr_solve_lower_triangular_mut(&mut v) {
                        return false;
                    }
                    p.inv_permute_rows(&mut v);
                    true
                }
                None => false,
            },
        }
    }

    /// `y += a f_x^T x` (`n` each) from the values in `fx` (dense or the pattern's), as of the
    /// last [`Self::factor`]: the transpose of [`Self::mul_add`] for one block.
    pub(crate) fn mul_add_transposed(&self, a: f64, x: &[f64], y: &mut [f64]) {
        let n = self.n;
        match self.rows() {
            Some(s) => {
                for (&(r, c), &v) in s.entries.iter().zip(&self.fx) {
                    y[c] += a * v * x[r];
                }
            }
            None => {
                for (r, &xr) in x.iter().enumerate().take(n) {
                    if xr != 0.0 {
                        for (yc, f) in y.iter_mut().zip(&self.fx[r * n..(r + 1) * n]) {
                            *yc += a * f * xr;
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic pseudo-random number in [-1, 1).
    fn rnd(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    /// `W x = x - hg f_x x` for the pattern's values (the reference product).
    fn w_times(entries: &[(u32, u32)], vals: &[f64], hg: f64, x: &[f64]) -> Vec<f64> {
        let mut y: Vec<f64> = x.to_vec();
        for (&(r, c), &v) in entries.iter().zip(vals) {
            y[r as usize] -= hg * v * x[c as usize];
        }
        y
    }

    /// Solves with the banded path and checks the residual against the dense product; the
    /// entries are shuffled (a scrambled chain: RCM must find the band again).
    /// `y += a f_x x` over `blocks` blocks of `n` and the row sums of `lin` (structured) agree
    /// with `dense`'s.
    fn products_match_the_dense(lin: &LinSolve, dense: &LinSolve, n: usize, blocks: usize, seed: &mut u64) {
        let a = 0.7;
        let x: Vec<f64> = (0..blocks * n).map(|_| rnd(seed)).collect();
        let y0: Vec<f64> = (0..blocks * n).map(|_| rnd(seed)).collect();
        let (mut y, mut want) = (y0.clone(), y0);
        lin.mul_add(a, &x, &mut y);
        dense.mul_add(a, &x, &mut want);
        for (got, want) in y.iter().zip(&want) {
            assert!((got - want).abs() <= 1e-14 * want.abs().max(1.0), "{got} vs {want}");
        }
        let (got, want) = (lin.row_abs_max(), dense.row_abs_max());
        assert!((got - want).abs() <= 1e-14 * want, "{got} vs {want}");
    }

    fn check(n: usize, entries: &[(u32, u32)], inv_hg: f64, expect_band: Option<(usize, usize)>) {
        let hg = 1.0 / inv_hg;
        let mut seed = 7u64;
        let vals: Vec<f64> = entries.iter().map(|_| 3.0 * rnd(&mut seed)).collect();
        let mut lin = LinSolve::new(n);
        assert!(lin.select(LinearSolver::Banded, Some((0, entries))));
        if let Some(band) = expect_band {
            let Some(Some(s)) = &lin.modes[0].band else { panic!("no structure") };
            assert_eq!(s.band(), band);
        }
        lin.fx.copy_from_slice(&vals);
        assert!(lin.factor(hg));
        let mut dense = LinSolve::new(n);
        assert!(!dense.select(LinearSolver::Dense, Some((0, entries))));
        for (&(r, c), &v) in entries.iter().zip(&vals) {
            dense.fx[r as usize * n + c as usize] += v;
        }
        assert!(dense.factor(hg));
        // One column (solved in place when the order is the model's), a few (fixed-size rows),
        // and more than the fixed sizes.
        for cols in [1, 3, 20] {
            let b: Vec<f64> = (0..n * cols).map(|_| rnd(&mut seed)).collect();
            let mut x = b.clone();
            assert!(lin.solve(&mut x, cols));
            for c in 0..cols {
                let wx = w_times(entries, &vals, hg, &x[c * n..(c + 1) * n]);
                for i in 0..n {
                    let r = (wx[i] - b[c * n + i]).abs();
                    assert!(r < 1e-11, "n {n}: residual {r:e} at {i}, column {c} of {cols}");
                }
            }
            // The dense path gives the same solution.
            let mut y = b.clone();
            assert!(dense.solve(&mut y, cols));
            for (a, b) in x.iter().zip(&y) {
                assert!((a - b).abs() < 1e-10 * b.abs().max(1.0), "{a} vs {b}");
            }
        }
        // `y += a f_x x` and the row sums agree with the dense matrix's.
        products_match_the_dense(&lin, &dense, n, 3, &mut seed);
        transposed_solves_hold(&mut lin, entries, &vals, hg, &mut seed);
        transposed_solves_hold(&mut dense, entries, &vals, hg, &mut seed);
    }

    /// `W^T x = b` (the adjoint's solves) against the transpose of the pattern itself: the
    /// residual `x - hg f_x^T x - b` is round-off (1e-11 of the largest `|x|`, as the forward
    /// solves' test), and `y += a f_x^T x` is the pattern's transpose product to 1e-13.
    fn transposed_solves_hold(
        lin: &mut LinSolve,
        entries: &[(u32, u32)],
        vals: &[f64],
        hg: f64,
        seed: &mut u64,
    ) {
        let n = lin.n;
        let wt_times = |x: &[f64]| {
            let mut y = x.to_vec();
            for (&(r, c), &v) in entries.iter().zip(vals) {
                y[c as usize] -= hg * v * x[r as usize];
            }
            y
        };
        for _ in 0..3 {
            let b: Vec<f64> = (0..n).map(|_| rnd(seed)).collect();
            let mut x = b.clone();
            assert!(lin.solve_transposed(&mut x));
            let scale = x.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            for (i, (a, b)) in wt_times(&x).iter().zip(&b).enumerate() {
                assert!((a - b).abs() < 1e-11 * scale, "n {n}: W^T x - b = {:e} at {i}", a - b);
            }
            let mut y = b.clone();
            lin.mul_add_transposed(-0.7, &x, &mut y);
            let mut want = b.clone();
            for (&(r, c), &v) in entries.iter().zip(vals) {
                want[c as usize] += -0.7 * v * x[r as usize];
            }
            for (a, b) in y.iter().zip(&want) {
                assert!((a - b).abs() <= 1e-13 * b.abs().max(scale), "{a} vs {b}");
            }
        }
    }

    /// A chain numbered in order: the model's own order is kept (no permutation) and the
    /// pattern fills the tridiagonal band, so products run along its diagonals.
    #[test]
    fn a_chain_in_order_keeps_its_numbering_and_its_diagonals() {
        let n = 50u32;
        let e: Vec<(u32, u32)> =
            (0..n).flat_map(|i| [(i, i.saturating_sub(1)), (i, i), (i, (i + 1).min(n - 1))]).collect();
        let mut e: Vec<(u32, u32)> =
            e.into_iter().collect::<std::collections::BTreeSet<_>>().into_iter().collect();
        // Not sorted by row: the products must not depend on the pattern's order.
        e.reverse();
        let s = Structure::analyse(n as usize, &e).expect("a band");
        assert!(s.identity);
        assert_eq!(s.band(), (1, 1));
        assert!(s.rows.diagonals.is_some());
        check(n as usize, &e, 0.5, Some((1, 1)));
    }

    /// A band with a hole (the chain without the entry (2, 3)) is not stored by diagonals: a NaN
    /// in `x` at 3, which row 2 does not read, stays out of `y_2`.
    #[test]
    fn a_hole_in_the_band_keeps_a_nan_where_it_is() {
        let n = 8u32;
        let e: Vec<(u32, u32)> = (0..n)
            .flat_map(|i| [(i, i), (i, i + 1), (i + 1, i)])
            .filter(|&(r, c)| r < n && c < n && (r, c) != (2, 3))
            .collect();
        let s = Structure::analyse(n as usize, &e).expect("a band");
        assert!(s.rows.diagonals.is_none());
        check(n as usize, &e, 0.5, None);
        let mut lin = LinSolve::new(n as usize);
        assert!(lin.select(LinearSolver::Banded, Some((0, &e))));
        lin.fx.fill(1.0);
        assert!(lin.factor(0.1));
        let mut x = vec![1.0; n as usize];
        x[3] = f64::NAN;
        let mut y = vec![0.0; n as usize];
        lin.mul_add(1.0, &x, &mut y);
        assert_eq!(y[2], 2.0);
        assert!(y[3].is_nan() && y[4].is_nan());
    }

    /// A chain whose states are numbered in a scrambled order.
    fn scrambled_chain(n: usize) -> Vec<(u32, u32)> {
        let label = |i: usize| ((i * 37 + 11) % n) as u32;
        let mut e = Vec::new();
        for i in 0..n {
            e.push((label(i), label(i)));
            if i > 0 {
                e.push((label(i), label(i - 1)));
                e.push((label(i - 1), label(i)));
            }
        }
        e
    }

    #[test]
    fn a_scrambled_chain_is_found_tridiagonal() {
        // 37 and 101 are coprime, so `label` is a permutation.
        check(101, &scrambled_chain(101), 0.5, Some((1, 1)));
    }

    #[test]
    fn pivoting_in_the_band() {
        // `h gamma = 1e8` with a zero diagonal in `f_x` (a mass-spring chain's position rows):
        // `W = I - 1e8 f_x` has pivots of 1 under entries of 1e8, which only row exchanges keep
        // stable.
        let n = 40;
        let mut e = Vec::new();
        for i in 0..n as u32 {
            if i % 2 == 1 {
                e.push((i, i));
            }
            if i > 0 {
                e.push((i, i - 1));
                e.push((i - 1, i));
            }
        }
        check(n, &e, 1e-8, None);
    }

    #[test]
    fn a_two_dimensional_grid_and_a_missing_diagonal() {
        // A 12 x 12 grid (five-point coupling, no diagonal entries): RCM gives a band of about
        // the side, far below dense.
        let side = 12u32;
        let e: Vec<(u32, u32)> = grid(side).into_iter().filter(|&(r, c)| r != c).collect();
        check((side * side) as usize, &e, 2.0, None);
    }

    #[test]
    fn a_hub_is_left_dense() {
        // State 0 coupled both ways to every other: whatever the order, the hub's row and
        // column span the matrix, and the band costs more than the dense LU.
        let n = 30u32;
        let e: Vec<(u32, u32)> = (1..n).flat_map(|i| [(0, i), (i, 0), (i, i)]).collect();
        assert!(Structure::analyse(n as usize, &e).is_none());
        let mut lin = LinSolve::new(n as usize);
        assert!(!lin.select(LinearSolver::Banded, Some((0, &e))));
        assert_eq!(lin.fx.len(), (n * n) as usize);
    }

    #[test]
    fn a_singular_band_is_refused() {
        // f_x = I and h gamma = 1: W = 0.
        let e: Vec<(u32, u32)> = (0..5).map(|i| (i, i)).collect();
        let mut lin = LinSolve::new(5);
        assert!(lin.select(LinearSolver::Banded, Some((0, &e))));
        lin.fx.fill(1.0);
        assert!(!lin.factor(1.0));
    }

    /// The sparse path against the dense LU on the same values: solutions for 1, 3 and 20
    /// columns agree to `tol` relative to the largest of each (and the residual `W x - b` is
    /// small), and the products and row sums are the dense ones. Returns the sparse solver.
    fn check_sparse(n: usize, entries: &[(u32, u32)], vals: &[f64], hg: f64, tol: f64) -> LinSolve {
        let mut seed = 11u64;
        let mut lin = LinSolve::new(n);
        assert!(lin.select(LinearSolver::Sparse, Some((0, entries))));
        assert_eq!(lin.current, Path::Sparse(0));
        lin.fx.copy_from_slice(vals);
        assert!(lin.factor(hg));
        let mut dense = LinSolve::new(n);
        assert!(!dense.select(LinearSolver::Dense, Some((0, entries))));
        for (&(r, c), &v) in entries.iter().zip(vals) {
            dense.fx[r as usize * n + c as usize] += v;
        }
        assert!(dense.factor(hg));
        for cols in [1, 3, 20] {
            let b: Vec<f64> = (0..n * cols).map(|_| rnd(&mut seed)).collect();
            let (mut x, mut y) = (b.clone(), b.clone());
            assert!(lin.solve(&mut x, cols));
            assert!(dense.solve(&mut y, cols));
            for c in 0..cols {
                let (xc, yc) = (&x[c * n..(c + 1) * n], &y[c * n..(c + 1) * n]);
                let scale = yc.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                for (i, (a, b)) in xc.iter().zip(yc).enumerate() {
                    assert!((a - b).abs() <= tol * scale, "n {n}, column {c} of {cols}, {i}: {a} vs {b}");
                }
                let wx = w_times(entries, vals, hg, xc);
                for (i, (a, b)) in wx.iter().zip(&b[c * n..(c + 1) * n]).enumerate() {
                    assert!((a - b).abs() <= 1e-11 * scale.max(1.0), "residual at {i}: {a} vs {b}");
                }
            }
        }
        products_match_the_dense(&lin, &dense, n, 2, &mut seed);
        transposed_solves_hold(&mut lin, entries, vals, hg, &mut seed);
        transposed_solves_hold(&mut dense, entries, vals, hg, &mut seed);
        lin
    }

    /// The sparse analysis of mode 0 of `lin`.
    fn sparse_of(lin: &LinSolve) -> &SparseStructure {
        let Some(Some(s)) = &lin.modes[0].sparse else { panic!("no sparse analysis") };
        s
    }

    /// A hub (state 0) coupled both ways to every other state: an arrowhead.
    fn arrowhead(n: u32) -> Vec<(u32, u32)> {
        (1..n).flat_map(|i| [(0, i), (i, 0), (i, i)]).chain([(0, 0)]).collect()
    }

    /// The five-point coupling of a `side x side` grid with its diagonal.
    fn grid(side: u32) -> Vec<(u32, u32)> {
        let id = |x: u32, y: u32| y * side + x;
        let mut e = Vec::new();
        for y in 0..side {
            for x in 0..side {
                e.push((id(x, y), id(x, y)));
                if x > 0 {
                    e.push((id(x, y), id(x - 1, y)));
                    e.push((id(x - 1, y), id(x, y)));
                }
                if y > 0 {
                    e.push((id(x, y), id(x, y - 1)));
                    e.push((id(x, y - 1), id(x, y)));
                }
            }
        }
        e
    }

    #[test]
    fn sparse_random_patterns_match_the_dense_lu() {
        let mut seed = 3u64;
        let mut fell_back = 0;
        for n in [5usize, 30, 120] {
            // About three off-diagonal entries per row, unsymmetric, and half the diagonal.
            let mut set = std::collections::BTreeSet::new();
            for r in 0..n {
                if r % 2 == 0 {
                    set.insert((r as u32, r as u32));
                }
                for _ in 0..3 {
                    let c = ((rnd(&mut seed) + 1.0) * 0.5 * n as f64) as usize % n;
                    set.insert((r as u32, c as u32));
                }
            }
            let e: Vec<(u32, u32)> = set.into_iter().collect();
            let vals: Vec<f64> = e.iter().map(|_| 3.0 * rnd(&mut seed)).collect();
            // Small `h gamma`: `W` near the identity, every static pivot accepted.
            let lin = check_sparse(n, &e, &vals, 0.02, 1e-12);
            assert_eq!(lin.sparse_fallbacks, 0);
            // Large: pivots may fail and fall back to the dense LU; the solve is right either way.
            let lin = check_sparse(n, &e, &vals, 2.0, 1e-9);
            fell_back += lin.sparse_fallbacks;
            let s = sparse_of(&lin);
            assert!(s.sym.nnz() >= e.len());
        }
        // Both ways were taken at `h gamma = 2` (these seeds: the 5 states' static pivots pass,
        // the 30's and the 120's do not).
        assert_eq!(fell_back, 2);
    }

    #[test]
    fn the_arrowhead_has_no_fill_with_the_hub_last() {
        let n = 200u32;
        let e = arrowhead(n);
        let mut seed = 5u64;
        // A thermal network: leaves exchange with the hub and leak, the hub gathers.
        let vals: Vec<f64> = e
            .iter()
            .map(|&(r, c)| match (r, c) {
                (0, 0) => -(n as f64 - 1.0),
                (r, c) if r == c => -1.1 - rnd(&mut seed).abs(),
                _ => 1.0,
            })
            .collect();
        let lin = check_sparse(n as usize, &e, &vals, 0.3, 1e-12);
        assert_eq!(lin.sparse_fallbacks, 0);
        let s = sparse_of(&lin);
        assert_eq!(s.sym.fill(), 0);
        // Leaves by increasing number; the hub ties with the last leaf at degree 1 and goes first
        // of the two (the lower number).
        assert_eq!(s.sym.perm[0], n as usize - 2, "the hub is eliminated with the last leaf");
        // Two multiply-adds per leaf.
        assert_eq!(s.sym.flops(), 2.0 * (n - 1) as f64);
        assert_eq!(LinearSolver::Auto.resolve(n as usize, &e), LinearSolver::Sparse);
        assert_eq!(LinearSolver::Banded.resolve(n as usize, &e), LinearSolver::Dense);
    }

    #[test]
    fn a_grid_laplacian_matches_the_dense_lu() {
        let side = 20u32;
        let e = grid(side);
        let n = (side * side) as usize;
        let vals: Vec<f64> = e.iter().map(|&(r, c)| if r == c { -4.0 } else { 1.0 }).collect();
        let lin = check_sparse(n, &e, &vals, 5.0, 1e-12);
        assert_eq!(lin.sparse_fallbacks, 0);
        let s = sparse_of(&lin);
        // Fill, but far below the dense count.
        assert!(s.sym.fill() > 0);
        assert!(s.sym.flops() < dense_cost(n) / 50.0, "{} flops", s.sym.flops());
    }

    #[test]
    fn a_vanishing_static_pivot_falls_back_to_the_dense_lu() {
        // f_x = I + S (S the cyclic shift) and h gamma = 1: W = -S, a permutation with a zero
        // diagonal. Every static pivot is zero; the dense LU exchanges rows.
        let n = 12u32;
        let e: Vec<(u32, u32)> = (0..n).flat_map(|i| [(i, i), (i, (i + 1) % n)]).collect();
        let vals = vec![1.0; e.len()];
        let lin = check_sparse(n as usize, &e, &vals, 1.0, 1e-14);
        assert_eq!(lin.sparse_fallbacks, 1);
        // A tiny pivot under a large entry (|0.001| against 1): refused too, still solved.
        let vals: Vec<f64> = e.iter().map(|&(r, c)| if r == c { 0.999 } else { 1.0 }).collect();
        let mut lin = check_sparse(n as usize, &e, &vals, 1.0, 1e-11);
        assert_eq!(lin.sparse_fallbacks, 1);
        // The next attempt with a small step takes the static pivots again.
        assert!(lin.factor(0.01));
        assert!(!lin.sparse_in_dense);
        assert_eq!(lin.sparse_fallbacks, 1);
    }

    #[test]
    fn auto_keeps_the_band_for_a_chain_and_the_dense_lu_for_two_states() {
        assert_eq!(LinearSolver::Auto.resolve(101, &scrambled_chain(101)), LinearSolver::Banded);
        assert_eq!(LinearSolver::Auto.resolve(2, &[(0, 0), (0, 1), (1, 0), (1, 1)]), LinearSolver::Dense);
        // A full pattern: neither structured path pays.
        let full: Vec<(u32, u32)> = (0..30).flat_map(|r| (0..30).map(move |c| (r, c))).collect();
        assert_eq!(LinearSolver::Auto.resolve(30, &full), LinearSolver::Dense);
        assert_eq!(LinearSolver::Sparse.resolve(30, &full), LinearSolver::Sparse);
    }
}
