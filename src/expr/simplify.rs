//! Stage 3: the simplifying constructors of [`ExprStore`]. Knows no spans, no IO and no
//! Cranelift.
//!
//! Every constructor applies a few local rules before interning, so that structurally zero
//! derivatives collapse to the constant 0 and equal expressions share one node. The rules:
//! - constant folding with the evaluator's own semantics ([`apply_unary`], [`apply_binary`]),
//!   only when the result is finite (no NaN or infinite constants are ever created);
//! - neutral elements: `x + 0`, `x * 1`, `x / 1`, `x ^ 1` give `x`; `x * -1` and `x / -1` give
//!   `-x`; `x ^ 0` and `1 ^ x` give 1 (exact for every input, NaN included, as `powf` defines);
//! - negation: `--x` is `x`; `(-a) * b`, `a * (-b)`, `(-a) / b` and `a / (-b)` pull the sign out
//!   (exact in IEEE arithmetic); `abs(-x)` and `abs(abs x)` are `abs x`;
//! - `x + x` is `2 * x` and `x + (-x)` is 0; `min(x, x)`, `max(x, x)` are `x`; `x < x` is 0 and
//!   `x <= x` is 1; `select(c, a, a)` is `a`; a select with a constant condition is its branch;
//! - commutative operations sort their operands by id, so `a + b` and `b + a` are one node;
//! - boolean identities (`c and true` is `c`, ...) only where the other operand is known to be
//!   0.0 / 1.0.
//!
//! NaN policy: absorbing rules assume finite operands. `x * 0` and `0 / x` fold to 0 and
//! `x + (-x)`, `x < x`, `x <= x` fold to constants even though they differ when `x` is NaN or
//! infinite at run time; model values are finite wherever results are meaningful. At finite
//! inputs no rule changes a value (a folded `x * 0` may lose the sign of a zero: `-3 * 0` is `-0`,
//! the folded form `0`; they compare equal).

use super::eval::{apply_binary, apply_unary};
use super::node::{BinaryOp, ExprId, Lookup, LookupKind, Node, UnaryOp};
use super::store::ExprStore;

impl ExprStore {
    /// A constant. Callers should pass finite values; NaN is stored as given.
    pub fn constant(&mut self, value: f64) -> ExprId {
        self.intern(Node::constant(value))
    }

    /// The constant 0.
    pub fn zero(&mut self) -> ExprId {
        self.constant(0.0)
    }

    /// The constant 1.
    pub fn one(&mut self) -> ExprId {
        self.constant(1.0)
    }

    /// State `index`.
    pub fn state(&mut self, index: u32) -> ExprId {
        self.intern(Node::State(index))
    }

    /// Parameter `index`.
    pub fn param(&mut self, index: u32) -> ExprId {
        self.intern(Node::Param(index))
    }

    /// The time `t`.
    pub fn time(&mut self) -> ExprId {
        self.intern(Node::Time)
    }

    /// The constant value of `id`, if it is a constant node.
    pub fn const_value(&self, id: ExprId) -> Option<f64> {
        self.node(id).as_const()
    }

    /// Whether `id` is the constant 0 (either sign).
    pub fn is_zero(&self, id: ExprId) -> bool {
        self.const_value(id) == Some(0.0)
    }

    /// Whether `id` is the constant 1.
    pub fn is_one(&self, id: ExprId) -> bool {
        self.const_value(id) == Some(1.0)
    }

    /// Whether `id` is known to evaluate to exactly 0.0 or 1.0.
    pub fn is_boolean(&self, id: ExprId) -> bool {
        match *self.node(id) {
            Node::Const(bits) => matches!(f64::from_bits(bits), v if v == 0.0 || v == 1.0),
            Node::Unary(UnaryOp::Not, _) => true,
            Node::Binary(op, _, _) => {
                matches!(op, BinaryOp::Lt | BinaryOp::Le | BinaryOp::And | BinaryOp::Or)
            }
            _ => false,
        }
    }

    /// The operand of a negation node.
    fn negated(&self, id: ExprId) -> Option<ExprId> {
        match *self.node(id) {
            Node::Unary(UnaryOp::Neg, a) => Some(a),
            _ => None,
        }
    }

    /// Folds `value` to a constant if it is finite.
    fn fold(&mut self, value: f64) -> Option<ExprId> {
        value.is_finite().then(|| self.constant(value))
    }

    /// `-a`, simplified.
    pub fn neg(&mut self, a: ExprId) -> ExprId {
        self.unary(UnaryOp::Neg, a)
    }

    /// `a + b`, simplified.
    pub fn add(&mut self, a: ExprId, b: ExprId) -> ExprId {
        self.binary(BinaryOp::Add, a, b)
    }

    /// `a - b`, stored as `a + (-b)`.
    pub fn sub(&mut self, a: ExprId, b: ExprId) -> ExprId {
        let nb = self.neg(b);
        self.add(a, nb)
    }

    /// `a * b`, simplified.
    pub fn mul(&mut self, a: ExprId, b: ExprId) -> ExprId {
        self.binary(BinaryOp::Mul, a, b)
    }

    /// `a / b`, simplified.
    pub fn div(&mut self, a: ExprId, b: ExprId) -> ExprId {
        self.binary(BinaryOp::Div, a, b)
    }

    /// `a ^ b`, simplified.
    pub fn pow(&mut self, a: ExprId, b: ExprId) -> ExprId {
        self.binary(BinaryOp::Pow, a, b)
    }

    /// `a^b ln(a)` with its limits at `a = 0` ([`BinaryOp::PowLog`]), simplified.
    pub fn pow_log(&mut self, a: ExprId, b: ExprId) -> ExprId {
        self.binary(BinaryOp::PowLog, a, b)
    }

    /// `a ^ c` for a constant exponent.
    pub fn powi(&mut self, a: ExprId, c: f64) -> ExprId {
        let c = self.constant(c);
        self.pow(a, c)
    }

    /// `a < b` (1 or 0), simplified.
    pub fn lt(&mut self, a: ExprId, b: ExprId) -> ExprId {
        self.binary(BinaryOp::Lt, a, b)
    }

    /// `a <= b` (1 or 0), simplified.
    pub fn le(&mut self, a: ExprId, b: ExprId) -> ExprId {
        self.binary(BinaryOp::Le, a, b)
    }

    /// `a > b`, stored as `b < a`.
    pub fn gt(&mut self, a: ExprId, b: ExprId) -> ExprId {
        self.lt(b, a)
    }

    /// `a >= b`, stored as `b <= a`.
    pub fn ge(&mut self, a: ExprId, b: ExprId) -> ExprId {
        self.le(b, a)
    }

    /// `a and b` (1 or 0), simplified.
    pub fn and(&mut self, a: ExprId, b: ExprId) -> ExprId {
        self.binary(BinaryOp::And, a, b)
    }

    /// `a or b` (1 or 0), simplified.
    pub fn or(&mut self, a: ExprId, b: ExprId) -> ExprId {
        self.binary(BinaryOp::Or, a, b)
    }

    /// `not a` (1 or 0), simplified.
    pub fn not(&mut self, a: ExprId) -> ExprId {
        self.unary(UnaryOp::Not, a)
    }

    /// A one-argument operation, simplified.
    pub fn unary(&mut self, op: UnaryOp, a: ExprId) -> ExprId {
        if let Some(x) = self.const_value(a) {
            if let Some(id) = self.fold(apply_unary(op, x)) {
                return id;
            }
        }
        match op {
            UnaryOp::Neg => {
                if let Some(inner) = self.negated(a) {
                    return inner;
                }
            }
            UnaryOp::Abs => {
                if let Some(inner) = self.negated(a) {
                    return self.unary(UnaryOp::Abs, inner);
                }
                if matches!(self.node(a), Node::Unary(UnaryOp::Abs, _)) {
                    return a;
                }
            }
            UnaryOp::Not => {
                if let Node::Unary(UnaryOp::Not, inner) = *self.node(a) {
                    if self.is_boolean(inner) {
                        return inner;
                    }
                }
            }
            _ => {}
        }
        self.intern(Node::Unary(op, a))
    }

    /// A two-argument operation, simplified.
    pub fn binary(&mut self, op: BinaryOp, a: ExprId, b: ExprId) -> ExprId {
        let (ca, cb) = (self.const_value(a), self.const_value(b));
        if let (Some(x), Some(y)) = (ca, cb) {
            if let Some(id) = self.fold(apply_binary(op, x, y)) {
                return id;
            }
        }
        // Canonical operand order: the rules below then only need to look at one side for
        // commutative ops, and `a + b`, `b + a` intern to the same node.
        let (a, b) = if op.is_commutative() && b < a { (b, a) } else { (a, b) };
        let (ca, cb) = (self.const_value(a), self.const_value(b));
        match op {
            BinaryOp::Add => {
                if ca == Some(0.0) {
                    return b;
                }
                if cb == Some(0.0) {
                    return a;
                }
                if a == b {
                    let two = self.constant(2.0);
                    return self.mul(two, a);
                }
                if self.negated(a) == Some(b) || self.negated(b) == Some(a) {
                    return self.zero();
                }
            }
            BinaryOp::Mul => {
                for (c, other) in [(ca, b), (cb, a)] {
                    match c {
                        Some(0.0) => return self.zero(),
                        Some(1.0) => return other,
                        Some(-1.0) => return self.neg(other),
                        _ => {}
                    }
                }
                if let Some(na) = self.negated(a) {
                    let m = self.mul(na, b);
                    return self.neg(m);
                }
                if let Some(nb) = self.negated(b) {
                    let m = self.mul(a, nb);
                    return self.neg(m);
                }
            }
            BinaryOp::Div => {
                if ca == Some(0.0) {
                    return self.zero();
                }
                match cb {
                    Some(1.0) => return a,
                    Some(-1.0) => return self.neg(a),
                    _ => {}
                }
                if let Some(na) = self.negated(a) {
                    let d = self.div(na, b);
                    return self.neg(d);
                }
                if let Some(nb) = self.negated(b) {
                    let d = self.div(a, nb);
                    return self.neg(d);
                }
            }
            BinaryOp::Pow => {
                if cb == Some(1.0) {
                    return a;
                }
                if cb == Some(0.0) || ca == Some(1.0) {
                    return self.one();
                }
            }
            BinaryOp::PowLog => {
                // a^0 ln(a) = ln(a), -inf at a = 0 as the limit says; 1^b ln(1) = 0.
                if cb == Some(0.0) {
                    return self.unary(UnaryOp::Log, a);
                }
                if ca == Some(1.0) {
                    return self.zero();
                }
            }
            BinaryOp::Min | BinaryOp::Max if a == b => return a,
            BinaryOp::Lt if a == b => return self.zero(),
            BinaryOp::Le if a == b => return self.one(),
            BinaryOp::And | BinaryOp::Or => {
                let is_and = op == BinaryOp::And;
                for (c, other) in [(ca, b), (cb, a)] {
                    if let Some(v) = c {
                        let truthy = v != 0.0;
                        if truthy != is_and {
                            // `false and x` is false, `true or x` is true, whatever x is.
                            return if is_and { self.zero() } else { self.one() };
                        }
                        if self.is_boolean(other) {
                            return other;
                        }
                    }
                }
                if a == b && self.is_boolean(a) {
                    return a;
                }
            }
            _ => {}
        }
        self.intern(Node::Binary(op, a, b))
    }

    /// `a` where `c != 0`, else `b`; simplified.
    pub fn select(&mut self, c: ExprId, a: ExprId, b: ExprId) -> ExprId {
        if let Some(v) = self.const_value(c) {
            return if v != 0.0 { a } else { b };
        }
        if a == b {
            return a;
        }
        self.intern(Node::Select(c, a, b))
    }

    /// The vector `l` read at knot position `pos` (see [`apply_lookup`](super::eval::apply_lookup)).
    /// A vector of one element is that parameter (a `Pwl` slope then 0); the parameters are not
    /// constants, so nothing else folds.
    pub fn lookup(&mut self, l: Lookup, pos: ExprId) -> ExprId {
        assert!(l.len >= 1, "a lookup reads at least one parameter");
        if l.len == 1 {
            return match l.kind {
                LookupKind::Pwl | LookupKind::Pwc => self.param(l.base),
                LookupKind::PwlSlope => self.zero(),
            };
        }
        self.intern(Node::Lookup(l, pos))
    }
}
