//! Stage 3: the reference evaluator of the expression DAG. Knows no spans, no IO and no
//! Cranelift.
//!
//! The meaning of every operation is written once, in [`apply_unary`], [`apply_binary`] and
//! [`apply_select`]: the simplifier folds constants with them and the JIT's libm wrappers call
//! them, so the JIT can be checked against this interpreter bit for bit. Each op is the Rust
//! `f64` method of the same name (`Pow` is `f64::powf`, `Log` is `f64::ln`), except:
//! - `Pow` with exponent exactly 2 is `a * a`, correctly rounded (libm's `pow` is only within
//!   about half an ulp more), and what the JIT emits for a constant 2, as C compilers do for
//!   `pow(x, 2)`;
//! - `Sign`: 1.0 for x > 0, -1.0 for x < 0, 0.0 for x == 0 (either zero), NaN for NaN
//!   (`f64::signum` would give 1.0 at +0.0);
//! - comparisons `Lt`, `Le` give 1.0 / 0.0 (false when either side is NaN);
//! - `Not`, `And`, `Or` treat any value other than 0.0 as true (so NaN is true) and give 1.0 / 0.0;
//! - `Select(c, a, b)` is `a` where `c != 0.0` (so a NaN condition takes `a`), else `b`;
//! - `Lookup` ([`apply_lookup`]): a NaN position gives NaN.

use super::node::{BinaryOp, ExprId, Lookup, LookupKind, Node, UnaryOp};
use super::store::ExprStore;

/// The value of a one-argument operation.
pub fn apply_unary(op: UnaryOp, x: f64) -> f64 {
    match op {
        UnaryOp::Neg => -x,
        UnaryOp::Sin => x.sin(),
        UnaryOp::Cos => x.cos(),
        UnaryOp::Tan => x.tan(),
        UnaryOp::Asin => x.asin(),
        UnaryOp::Acos => x.acos(),
        UnaryOp::Atan => x.atan(),
        UnaryOp::Sinh => x.sinh(),
        UnaryOp::Cosh => x.cosh(),
        UnaryOp::Tanh => x.tanh(),
        UnaryOp::Exp => x.exp(),
        UnaryOp::Log => x.ln(),
        UnaryOp::Sqrt => x.sqrt(),
        UnaryOp::Abs => x.abs(),
        UnaryOp::Sign => sign(x),
        UnaryOp::Not => bool_value(x == 0.0),
    }
}

/// The value of a two-argument operation.
pub fn apply_binary(op: BinaryOp, a: f64, b: f64) -> f64 {
    match op {
        BinaryOp::Add => a + b,
        BinaryOp::Mul => a * b,
        BinaryOp::Div => a / b,
        BinaryOp::Pow if b == 2.0 => a * a,
        BinaryOp::Pow => a.powf(b),
        BinaryOp::PowLog => pow_log(a, b),
        // `a + 0.0` is `+0.0` for either zero: the simplifier treats the two zeros as one value
        // (`0 * y` is `0` whatever the sign of `y`), so atan2 must not tell them apart either
        // (`atan2(-0.0, -1)` would be `-pi`, `atan2(0.0, -1)` is `pi`).
        BinaryOp::Atan2 => (a + 0.0).atan2(b),
        BinaryOp::Hypot => a.hypot(b),
        BinaryOp::Min => a.min(b),
        BinaryOp::Max => a.max(b),
        BinaryOp::Lt => bool_value(a < b),
        BinaryOp::Le => bool_value(a <= b),
        BinaryOp::And => bool_value(a != 0.0 && b != 0.0),
        BinaryOp::Or => bool_value(a != 0.0 || b != 0.0),
    }
}

/// `a^b ln(a)` ([`BinaryOp::PowLog`]), with its limits at `a = 0` (either zero): 0 for `b > 0`,
/// since `a^b` vanishes faster than `ln(a)` grows, and `-inf` for `b <= 0`; NaN for a NaN `b`.
/// Elsewhere the product as it stands (NaN for `a < 0`, where `ln` is).
pub fn pow_log(a: f64, b: f64) -> f64 {
    if a == 0.0 {
        if b > 0.0 {
            0.0
        } else if b.is_nan() {
            f64::NAN
        } else {
            f64::NEG_INFINITY
        }
    } else {
        a.powf(b) * a.ln()
    }
}

/// The value of `Select(c, a, b)`.
pub fn apply_select(c: f64, a: f64, b: f64) -> f64 {
    if c != 0.0 {
        a
    } else {
        b
    }
}

/// The segment of a lookup at knot position `pos`: `floor(pos)` clamped to `[0, last]`. The cast
/// truncates towards zero and saturates (NaN gives 0), which is the floor wherever the clamp
/// does not apply; the JIT's `fcvt_to_sint_sat` and `smin`/`smax` compute the same index.
pub fn lookup_segment(pos: f64, last: usize) -> usize {
    (pos as i64).clamp(0, last as i64) as usize
}

/// The value of `Lookup(kind, pos)` over the vector `u` (`u.len()` is the lookup's `len`):
/// - `Pwl`: `(1 - w) u[k] + w u[k+1]` with `k` the segment (`last = len - 2`) and
///   `w = pos - k` clamped to `[0, 1]`, so exactly `u[0]` before the first knot and `u[len-1]`
///   after the last;
/// - `Pwc`: `u[k]` with `last = len - 1`;
/// - `PwlSlope`: `u[k+1] - u[k]` for `0 <= pos < len - 1`, else 0.
///
/// A NaN position gives NaN. A `Pwl` of one element is that element, its slope 0.
pub fn apply_lookup(kind: LookupKind, pos: f64, u: &[f64]) -> f64 {
    if pos.is_nan() {
        return pos;
    }
    let len = u.len();
    if len < 2 && kind != LookupKind::Pwc {
        return if kind == LookupKind::Pwl { u[0] } else { 0.0 };
    }
    match kind {
        LookupKind::Pwl => {
            let k = lookup_segment(pos, len - 2);
            let w = pos - k as f64;
            // As the JIT's two selects: NaN and -0.0 pass through.
            let w = w.clamp(0.0, 1.0);
            (1.0 - w) * u[k] + w * u[k + 1]
        }
        LookupKind::Pwc => u[lookup_segment(pos, len - 1)],
        LookupKind::PwlSlope => {
            let k = lookup_segment(pos, len - 2);
            if pos >= 0.0 && pos < (len - 1) as f64 {
                u[k + 1] - u[k]
            } else {
                0.0
            }
        }
    }
}

/// The elements a lookup's value reads at knot position `pos` and their weights
/// `d apply_lookup(kind, pos, u) / d u[j]`, piece by piece as [`apply_lookup`] computes the value
/// (and as `diff`'s element weights are written): `Pwl`, `(1 - w)` on `u[k]` and `w` on `u[k+1]`
/// of its segment `k` with `w` clamped to `[0, 1]` (so 1 on `u[0]` before the first knot and on
/// `u[len-1]` after the last; at a knot, 1 on it and 0 on the next); `Pwc`, 1 on `u[k]`;
/// `PwlSlope`, -1 on `u[k]` and +1 on `u[k+1]` inside `[0, len - 1)`. Entries whose weight is 0
/// are left out (at most two remain), so the adjoint's scatter touches only what the value reads.
/// A NaN position gives NaN weights (on the elements the value's clamped index reads).
pub fn lookup_weights(kind: LookupKind, pos: f64, len: usize) -> impl Iterator<Item = (usize, f64)> {
    let pair = match kind {
        _ if len == 0 => [(0, 0.0), (0, 0.0)],
        LookupKind::Pwl if len < 2 => [(0, 1.0), (0, 0.0)],
        LookupKind::Pwl => {
            let k = lookup_segment(pos, len - 2);
            let w = (pos - k as f64).clamp(0.0, 1.0);
            [(k, 1.0 - w), (k + 1, w)]
        }
        LookupKind::Pwc => [(lookup_segment(pos, len - 1), if pos.is_nan() { pos } else { 1.0 }), (0, 0.0)],
        LookupKind::PwlSlope if len < 2 => [(0, 0.0), (0, 0.0)],
        LookupKind::PwlSlope => {
            let k = lookup_segment(pos, len - 2);
            if pos.is_nan() {
                [(k, pos), (k + 1, pos)]
            } else if pos >= 0.0 && pos < (len - 1) as f64 {
                [(k, -1.0), (k + 1, 1.0)]
            } else {
                [(0, 0.0), (0, 0.0)]
            }
        }
    };
    pair.into_iter().filter(|&(_, w)| w != 0.0)
}

/// The adjoint's scatter of one lookup's cotangent `c` (`sum_i w_i df_i/dL`): `gp[column[j]] +=
/// c * weight` for each element `j` that `l` reads at `pos` ([`lookup_weights`]) and that has a
/// sensitivity column (`column` maps every parameter to its column, `None` where it is not
/// differentiated). Indices are checked: one out of range is skipped, never read or written.
pub fn scatter_lookup(l: Lookup, pos: f64, c: f64, column: &[Option<usize>], gp: &mut [f64]) {
    for (j, weight) in lookup_weights(l.kind, pos, l.len as usize) {
        let param = l.base as usize + j;
        if let Some(slot) = column.get(param).copied().flatten().and_then(|col| gp.get_mut(col)) {
            *slot += c * weight;
        }
    }
}

fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else if x == 0.0 {
        0.0
    } else {
        x
    }
}

fn bool_value(b: bool) -> f64 {
    if b {
        1.0
    } else {
        0.0
    }
}

/// One instruction of a [`Tape`]; operands are slots of earlier instructions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Inst {
    Const(f64),
    State(u32),
    Param(u32),
    Time,
    Unary(UnaryOp, u32),
    Binary(BinaryOp, u32, u32),
    Select(u32, u32, u32),
    Lookup(Lookup, u32),
}

/// The nodes needed by a set of roots, flattened into straight-line code in ascending id order
/// (children have smaller ids, so that order is a valid schedule). Built once per function group
/// and evaluated many times; it does not borrow the store.
#[derive(Clone, Debug, PartialEq)]
pub struct Tape {
    insts: Vec<Inst>,
    roots: Vec<u32>,
}

impl Tape {
    /// The tape of every node `roots` need, in evaluation order.
    pub fn new(store: &ExprStore, roots: &[ExprId]) -> Tape {
        let needed = reachable(store, roots);
        // slot[id] = position of node `id` in `insts`; only set for needed nodes.
        let mut slot = vec![u32::MAX; needed.last().map_or(0, |id| id.index() + 1)];
        let mut insts = Vec::with_capacity(needed.len());
        for id in needed {
            let s = |c: ExprId| slot[c.index()];
            let inst = match *store.node(id) {
                Node::Const(bits) => Inst::Const(f64::from_bits(bits)),
                Node::State(i) => Inst::State(i),
                Node::Param(i) => Inst::Param(i),
                Node::Time => Inst::Time,
                Node::Unary(op, a) => Inst::Unary(op, s(a)),
                Node::Binary(op, a, b) => Inst::Binary(op, s(a), s(b)),
                Node::Select(c, a, b) => Inst::Select(s(c), s(a), s(b)),
                Node::Lookup(l, a) => Inst::Lookup(l, s(a)),
            };
            slot[id.index()] = insts.len() as u32;
            insts.push(inst);
        }
        let roots = roots.iter().map(|r| slot[r.index()]).collect();
        Tape { insts, roots }
    }

    /// The instructions, in evaluation order (for the other evaluators of the store's
    /// semantics: `enclose`).
    pub(super) fn insts(&self) -> &[Inst] {
        &self.insts
    }

    /// The slots of the roots' values.
    pub(super) fn roots(&self) -> &[u32] {
        &self.roots
    }

    /// Number of root values `eval` writes.
    pub fn n_roots(&self) -> usize {
        self.roots.len()
    }

    /// Number of instructions (distinct nodes evaluated).
    pub fn len(&self) -> usize {
        self.insts.len()
    }

    /// Whether it evaluates nothing.
    pub fn is_empty(&self) -> bool {
        self.insts.is_empty()
    }

    /// Evaluates every root at `(t, x, p)` into `out` (length `n_roots`), using `scratch` for
    /// intermediate values. State and parameter indices must be in range for `x` and `p`.
    pub fn eval_into(&self, t: f64, x: &[f64], p: &[f64], scratch: &mut Vec<f64>, out: &mut [f64]) {
        scratch.clear();
        scratch.reserve(self.insts.len());
        for inst in &self.insts {
            let v = match *inst {
                Inst::Const(c) => c,
                Inst::State(i) => x[i as usize],
                Inst::Param(i) => p[i as usize],
                Inst::Time => t,
                Inst::Unary(op, a) => apply_unary(op, scratch[a as usize]),
                Inst::Binary(op, a, b) => apply_binary(op, scratch[a as usize], scratch[b as usize]),
                Inst::Select(c, a, b) => {
                    apply_select(scratch[c as usize], scratch[a as usize], scratch[b as usize])
                }
                Inst::Lookup(l, a) => {
                    let u = &p[l.base as usize..(l.base + l.len) as usize];
                    apply_lookup(l.kind, scratch[a as usize], u)
                }
            };
            scratch.push(v);
        }
        for (o, &r) in out.iter_mut().zip(&self.roots) {
            *o = scratch[r as usize];
        }
    }

    /// Evaluates every root at `(t, x, p)`.
    pub fn eval(&self, t: f64, x: &[f64], p: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.roots.len()];
        self.eval_into(t, x, p, &mut Vec::new(), &mut out);
        out
    }
}

/// Evaluates `roots` at `(t, x, p)` in one pass (convenience for tests and one-off use).
pub fn eval(store: &ExprStore, roots: &[ExprId], t: f64, x: &[f64], p: &[f64]) -> Vec<f64> {
    Tape::new(store, roots).eval(t, x, p)
}

/// Evaluates one expression at `(t, x, p)`.
pub fn eval_one(store: &ExprStore, root: ExprId, t: f64, x: &[f64], p: &[f64]) -> f64 {
    eval(store, &[root], t, x, p)[0]
}

/// Every node reachable from `roots`, ascending by id.
///
/// Costs time proportional to the number of reachable nodes, not to the size of the store, so
/// differentiating many small expressions in a large store stays cheap.
pub fn reachable(store: &ExprStore, roots: &[ExprId]) -> Vec<ExprId> {
    let mut seen = std::collections::HashSet::new();
    let mut stack: Vec<ExprId> = roots.to_vec();
    let mut out = Vec::new();
    while let Some(id) = stack.pop() {
        if !seen.insert(id) {
            continue;
        }
        out.push(id);
        stack.extend(store.node(id).children());
    }
    out.sort_unstable();
    out
}
