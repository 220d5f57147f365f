//! The nodes of the expression DAG. Knows no spans, no IO and no Cranelift.

/// Handle of a node in an [`ExprStore`](super::ExprStore). Equal ids mean structurally equal
/// expressions (hash-consing); ids are dense and children always have smaller ids than parents,
/// so ascending id order is a valid evaluation order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ExprId(pub u32);

impl ExprId {
    /// The id as an index into the store's nodes.
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// One-argument operations. Boolean-valued nodes (comparisons, `Not`, `And`, `Or`) produce
/// exactly 0.0 or 1.0.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum UnaryOp {
    /// `-a`.
    Neg,
    /// `sin`.
    Sin,
    /// `cos`.
    Cos,
    /// `tan`.
    Tan,
    /// `asin`.
    Asin,
    /// `acos`.
    Acos,
    /// `atan`.
    Atan,
    /// `sinh`.
    Sinh,
    /// `cosh`.
    Cosh,
    /// `tanh`.
    Tanh,
    /// `exp`.
    Exp,
    /// `log` (natural).
    Log,
    /// `sqrt`.
    Sqrt,
    /// `abs`.
    Abs,
    /// `sign`: -1, 0 or 1.
    Sign,
    /// Boolean negation: 1.0 where the argument is 0.0, else 0.0.
    Not,
}

/// Two-argument operations. There is no `Sub`: `a - b` is `a + (-b)`, so sums stay canonical.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum BinaryOp {
    /// `a + b`.
    Add,
    /// `a * b`.
    Mul,
    /// `a / b`.
    Div,
    /// `a ^ b`.
    Pow,
    /// `a^b ln(a)`, the derivative of `a^b` with respect to its exponent, with its limits where
    /// `a = 0`: 0 for `b > 0` (`x^p ln x -> 0`), `-inf` for `b <= 0`. Made by differentiation
    /// only (`hybc derive` prints it as `pow_log(a, b)`); a model cannot write it.
    PowLog,
    /// `atan2(a, b)`.
    Atan2,
    /// `hypot(a, b)`.
    Hypot,
    /// `min(a, b)`.
    Min,
    /// `max(a, b)`.
    Max,
    /// Comparisons yield 1.0 (true) or 0.0 (false).
    Lt,
    /// `a <= b`.
    Le,
    /// Boolean and/or of two 0.0/1.0 values.
    And,
    /// `a or b`.
    Or,
}

impl UnaryOp {
    /// Every unary operation, for tables and exhaustive tests.
    pub const ALL: [UnaryOp; 16] = [
        UnaryOp::Neg,
        UnaryOp::Sin,
        UnaryOp::Cos,
        UnaryOp::Tan,
        UnaryOp::Asin,
        UnaryOp::Acos,
        UnaryOp::Atan,
        UnaryOp::Sinh,
        UnaryOp::Cosh,
        UnaryOp::Tanh,
        UnaryOp::Exp,
        UnaryOp::Log,
        UnaryOp::Sqrt,
        UnaryOp::Abs,
        UnaryOp::Sign,
        UnaryOp::Not,
    ];
}

impl BinaryOp {
    /// Every binary operation, for tables and exhaustive tests.
    pub const ALL: [BinaryOp; 13] = [
        BinaryOp::Add,
        BinaryOp::Mul,
        BinaryOp::Div,
        BinaryOp::Pow,
        BinaryOp::PowLog,
        BinaryOp::Atan2,
        BinaryOp::Hypot,
        BinaryOp::Min,
        BinaryOp::Max,
        BinaryOp::Lt,
        BinaryOp::Le,
        BinaryOp::And,
        BinaryOp::Or,
    ];

    /// Whether the operands may be swapped (the store orders them by id).
    pub fn is_commutative(self) -> bool {
        matches!(
            self,
            BinaryOp::Add
                | BinaryOp::Mul
                | BinaryOp::Hypot
                | BinaryOp::Min
                | BinaryOp::Max
                | BinaryOp::And
                | BinaryOp::Or
        )
    }
}

/// How a [`Node::Lookup`] reads its vector: the inputs `pwl` and `pwc` of the language and the
/// slope of `pwl` (its derivative with respect to the knot position).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum LookupKind {
    /// Linear between knots `k = floor(pos)` and `k + 1`, held at the end values outside
    /// `[0, len - 1]`.
    Pwl,
    /// The value of knot `clamp(floor(pos), 0, len - 1)`.
    Pwc,
    /// `u[k+1] - u[k]` of `Pwl`'s segment for `0 <= pos < len - 1`, else 0 (a right derivative).
    PwlSlope,
}

/// A run of parameters `base .. base + len` read at an index computed at run time (a vector
/// parameter interpolated in time). `len >= 1` (`>= 2` for `Pwl`, `PwlSlope`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Lookup {
    /// How the vector is read.
    pub kind: LookupKind,
    /// The vector's first parameter.
    pub base: u32,
    /// Its number of parameters.
    pub len: u32,
}

impl Lookup {
    /// Whether this lookup reads parameter `i`.
    pub fn reads(&self, i: u32) -> bool {
        i >= self.base && i - self.base < self.len
    }
}

/// A node. `Const` holds the bit pattern of an f64 so nodes can be hashed; `-0.0` and `0.0` are
/// distinct constants, and NaN constants are never created by simplification.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Node {
    /// A constant, as the bits of its f64.
    Const(u64),
    /// State `i`.
    State(u32),
    /// Parameter `i`.
    Param(u32),
    /// The time `t`.
    Time,
    /// `op(a)`.
    Unary(UnaryOp, ExprId),
    /// `op(a, b)`.
    Binary(BinaryOp, ExprId, ExprId),
    /// `Select(c, a, b)` is `a` where `c != 0.0`, else `b`.
    Select(ExprId, ExprId, ExprId),
    /// `Lookup(l, pos)`: the vector `l` read at the knot position `pos` (see
    /// [`eval::apply_lookup`](super::eval::apply_lookup)). Its parameters are not children: the
    /// index is known only at run time.
    Lookup(Lookup, ExprId),
}

impl Node {
    /// The constant `value`.
    pub fn constant(value: f64) -> Node {
        Node::Const(value.to_bits())
    }

    /// Its value, when the node is a constant.
    pub fn as_const(&self) -> Option<f64> {
        match *self {
            Node::Const(bits) => Some(f64::from_bits(bits)),
            _ => None,
        }
    }

    /// The node's operands, in order.
    pub fn children(&self) -> impl Iterator<Item = ExprId> {
        let (a, b, c) = match *self {
            Node::Const(_) | Node::State(_) | Node::Param(_) | Node::Time => (None, None, None),
            Node::Unary(_, a) | Node::Lookup(_, a) => (Some(a), None, None),
            Node::Binary(_, a, b) => (Some(a), Some(b), None),
            Node::Select(c, a, b) => (Some(c), Some(a), Some(b)),
        };
        a.into_iter().chain(b).chain(c)
    }
}
