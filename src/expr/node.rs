//! The nodes of the expression DAG. Knows no spans, no IO and no Cranelift.

/// Handle of a node in an [`ExprStore`](super::ExprStore). Equal ids mean structurally equal
/// expressions (hash-consing); ids are dense and children always have smaller ids than parents,
/// so ascending id order is a valid evaluation order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ExprId(pub u32);

impl ExprId {
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// One-argument operations. Boolean-valued nodes (comparisons, `Not`, `And`, `Or`) produce
/// exactly 0.0 or 1.0.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum UnaryOp {
    Neg,
    Sin,
    Cos,
    Tan,
    Asin,
    Acos,
    Atan,
    Sinh,
    Cosh,
    Tanh,
    Exp,
    Log,
    Sqrt,
    Abs,
    Sign,
    /// Boolean negation: 1.0 where the argument is 0.0, else 0.0.
    Not,
}

/// Two-argument operations. There is no `Sub`: `a - b` is `a + (-b)`, so sums stay canonical.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum BinaryOp {
    Add,
    Mul,
    Div,
    Pow,
    Atan2,
    Hypot,
    Min,
    Max,
    /// Comparisons yield 1.0 (true) or 0.0 (false).
    Lt,
    Le,
    /// Boolean and/or of two 0.0/1.0 values.
    And,
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
    pub const ALL: [BinaryOp; 12] = [
        BinaryOp::Add,
        BinaryOp::Mul,
        BinaryOp::Div,
        BinaryOp::Pow,
        BinaryOp::Atan2,
        BinaryOp::Hypot,
        BinaryOp::Min,
        BinaryOp::Max,
        BinaryOp::Lt,
        BinaryOp::Le,
        BinaryOp::And,
        BinaryOp::Or,
    ];

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
    pub kind: LookupKind,
    pub base: u32,
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
    Const(u64),
    State(u32),
    Param(u32),
    Time,
    Unary(UnaryOp, ExprId),
    Binary(BinaryOp, ExprId, ExprId),
    /// `Select(c, a, b)` is `a` where `c != 0.0`, else `b`.
    Select(ExprId, ExprId, ExprId),
    /// `Lookup(l, pos)`: the vector `l` read at the knot position `pos` (see
    /// [`eval::apply_lookup`](super::eval::apply_lookup)). Its parameters are not children: the
    /// index is known only at run time.
    Lookup(Lookup, ExprId),
}

impl Node {
    pub fn constant(value: f64) -> Node {
        Node::Const(value.to_bits())
    }

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
