//! The abstract syntax tree: what the user wrote, with a span on every node. No name is resolved
//! here; `sema` does that.

use super::Span;

/// A name as written, with where it stands.
#[derive(Clone, Debug, PartialEq)]
pub struct Ident {
    /// The name.
    pub name: String,
    /// Where it stands in the source.
    pub span: Span,
}

/// A number literal.
#[derive(Clone, Debug, PartialEq)]
pub struct Number {
    /// Its value.
    pub value: f64,
    /// Where it stands in the source.
    pub span: Span,
}

/// A whole `.hyb` file.
#[derive(Clone, Debug, PartialEq)]
pub struct File {
    /// The `model NAME` line's name.
    pub model: Ident,
    /// Everything declared in it, in order.
    pub items: Vec<Item>,
}

/// A top-level declaration.
#[derive(Clone, Debug, PartialEq)]
pub enum Item {
    /// `param NAME = DEFAULT [in [LO, HI]]`.
    Param(ParamDecl),
    /// `state NAME = INIT`.
    State(StateDecl),
    /// `der(STATE) = EXPR` (for every mode).
    Der(DerEq),
    /// `let NAME = EXPR`.
    Let(LetDecl),
    /// `event NAME when ... { ... }`.
    Event(Box<EventDecl>),
    /// `mode NAME { ... }`.
    Mode(Box<ModeDecl>),
    /// `output NAME = EXPR`.
    Output(OutputDecl),
    /// `simulate t_end = .., rtol = ..`.
    Simulate(SimulateDecl),
    /// `const N = 8`: a compile-time integer, gone after `expand`.
    Const(ConstDecl),
    /// `for i in A .. B { ... }`: unrolled by `expand`.
    For(Box<ForLoop>),
}

/// `const NAME = EXPR`, an integer expression of earlier constants.
#[derive(Clone, Debug, PartialEq)]
pub struct ConstDecl {
    /// The constant's name.
    pub name: Ident,
    /// Its value, evaluated by `expand`.
    pub value: Expr,
    /// Where it stands in the source.
    pub span: Span,
}

/// `for VAR in LO .. HI { ITEMS }`: the items once for each `VAR = LO .. HI - 1`.
#[derive(Clone, Debug, PartialEq)]
pub struct ForLoop {
    /// The loop variable.
    pub var: Ident,
    /// The first value.
    pub lo: Expr,
    /// One past the last value.
    pub hi: Expr,
    /// The items repeated: states, flows, `let`s, events, outputs, loops.
    pub items: Vec<Item>,
    /// Where it stands in the source.
    pub span: Span,
}

/// `sum(VAR in LO .. HI: BODY)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Reduction {
    /// The summation variable.
    pub var: Ident,
    /// The first value.
    pub lo: Expr,
    /// One past the last value.
    pub hi: Expr,
    /// The term, read once for each value.
    pub body: Expr,
}

/// `param NAME[N] = DEFAULT in [LO, HI]`.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamDecl {
    /// The parameter's name.
    pub name: Ident,
    /// `param u[N]`: a vector of `N` parameters; `None` for a scalar.
    pub size: Option<Size>,
    /// Its default value.
    pub default: Number,
    /// Its declared range, if any.
    pub range: Option<Range>,
    /// Where it stands in the source.
    pub span: Span,
}

/// The length written in `param u[N]`: its digits as written, and their value saturated at
/// `u64::MAX` (sema caps it far below). A length written as an expression of constants
/// (`param m[N]`) has `expr` set until `expand` evaluates it into `len`.
#[derive(Clone, Debug, PartialEq)]
pub struct Size {
    /// The length as an expression of constants, if not written as digits.
    pub expr: Option<Expr>,
    /// The digits as written.
    pub text: String,
    /// Their value.
    pub len: u64,
    /// Where it stands in the source.
    pub span: Span,
}

/// `in [LO, HI]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Range {
    /// The lower end.
    pub lo: Number,
    /// The upper end.
    pub hi: Number,
    /// Where it stands in the source.
    pub span: Span,
}

/// `state NAME = INIT`.
#[derive(Clone, Debug, PartialEq)]
pub struct StateDecl {
    /// The state's name.
    pub name: Ident,
    /// `[i][j]` after the name: an element (in a loop) or the lengths (outside); empty after
    /// `expand`.
    pub index: Vec<Expr>,
    /// Its initial value.
    pub init: Expr,
    /// Where it stands in the source.
    pub span: Span,
}

/// `der(STATE) = RHS`.
#[derive(Clone, Debug, PartialEq)]
pub struct DerEq {
    /// The state.
    pub state: Ident,
    /// `[i][j]` after the name: an element (in a loop) or the lengths (outside); empty after
    /// `expand`.
    pub index: Vec<Expr>,
    /// Its rate.
    pub rhs: Expr,
    /// Where it stands in the source.
    pub span: Span,
}

/// `let NAME = VALUE`.
#[derive(Clone, Debug, PartialEq)]
pub struct LetDecl {
    /// The name.
    pub name: Ident,
    /// `[i][j]` after the name: an element (in a loop) or the lengths (outside); empty after
    /// `expand`.
    pub index: Vec<Expr>,
    /// What it stands for.
    pub value: Expr,
    /// Where it stands in the source.
    pub span: Span,
}

/// `output NAME = VALUE`.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputDecl {
    /// The output's name.
    pub name: Ident,
    /// `[i][j]` after the name: an element (in a loop) or the lengths (outside); empty after
    /// `expand`.
    pub index: Vec<Expr>,
    /// Its value.
    pub value: Expr,
    /// Where it stands in the source.
    pub span: Span,
}

/// `simulate NAME = VALUE, ...`.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulateDecl {
    /// The settings, in order.
    pub settings: Vec<Setting>,
    /// Where it stands in the source.
    pub span: Span,
}

/// One `NAME = VALUE` of a `simulate` line.
#[derive(Clone, Debug, PartialEq)]
pub struct Setting {
    /// The setting.
    pub name: Ident,
    /// Its value.
    pub value: Number,
    /// Where it stands in the source.
    pub span: Span,
}

/// How an event's guard compares its sides.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GuardOp {
    /// `<=`: falling.
    Le,
    /// `<`: falling (the same as `<=`).
    Lt,
    /// `>=`: rising.
    Ge,
    /// `>`: rising (the same as `>=`).
    Gt,
    /// `crosses`: either way.
    Crosses,
}

/// `event NAME when LHS OP RHS [if COND] [-> MODE] { BODY }`.
#[derive(Clone, Debug, PartialEq)]
pub struct EventDecl {
    /// The event's name.
    pub name: Ident,
    /// `[i][j]` after the name: an element (in a loop) or the lengths (outside); empty after
    /// `expand`.
    pub index: Vec<Expr>,
    /// The guard's left side.
    pub lhs: Expr,
    /// The comparison.
    pub op: GuardOp,
    /// The guard's right side.
    pub rhs: Expr,
    /// The enabling condition, if any.
    pub condition: Option<Cond>,
    /// The mode it switches to, if any.
    pub target: Option<Ident>,
    /// The body: resets, `let`s, `stop`.
    pub body: Vec<EventStmt>,
    /// Where it stands in the source.
    pub span: Span,
}

/// A statement of an event's body.
#[derive(Clone, Debug, PartialEq)]
pub enum EventStmt {
    /// `STATE := VALUE`.
    Reset {
        /// The state reset.
        state: Ident,
        /// Its element's indices, empty after `expand`.
        index: Vec<Expr>,
        /// Its new value.
        value: Expr,
        /// Where it stands in the source.
        span: Span,
    },
    /// A `let` visible in the body only.
    Let(LetDecl),
    /// `stop`: the run ends after the event.
    Stop {
        /// Where it stands in the source.
        span: Span,
    },
}

/// `[initial] mode NAME { ... }`.
#[derive(Clone, Debug, PartialEq)]
pub struct ModeDecl {
    /// The mode's name.
    pub name: Ident,
    /// Whether it is marked `initial`.
    pub is_initial: bool,
    /// Its flows, `let`s and events.
    pub items: Vec<ModeItem>,
    /// Where it stands in the source.
    pub span: Span,
}

/// A declaration inside a mode.
#[derive(Clone, Debug, PartialEq)]
pub enum ModeItem {
    /// A flow of this mode.
    Der(DerEq),
    /// A `let` of this mode.
    Let(LetDecl),
    /// An event of this mode.
    Event(Box<EventDecl>),
}

/// A binary arithmetic operator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BinOp {
    /// `+`.
    Add,
    /// `-`.
    Sub,
    /// `*`.
    Mul,
    /// `/`.
    Div,
    /// `^`.
    Pow,
}

/// An expression, with where it stands.
#[derive(Clone, Debug, PartialEq)]
pub struct Expr {
    /// What it is.
    pub kind: ExprKind,
    /// Where it stands in the source.
    pub span: Span,
}

/// The kinds of expression.
#[derive(Clone, Debug, PartialEq)]
pub enum ExprKind {
    /// A number.
    Num(f64),
    /// A name (`t`, a parameter, a state, a `let`).
    Name(String),
    /// `-a`.
    Neg(Box<Expr>),
    /// `a OP b`.
    Binary(BinOp, Box<Expr>, Box<Expr>),
    /// `f(a, ..)`.
    Call(Ident, Vec<Expr>),
    /// `u[k]`, `T[i][j]`: an element of an array (after `expand`, of a vector parameter, with
    /// one index).
    Index(Ident, Vec<Expr>),
    /// `sum(k in A .. B: e)`, gone after `expand`.
    Sum(Box<Reduction>),
    /// `if C then A else B`.
    If(Box<Cond>, Box<Expr>, Box<Expr>),
}

/// A comparison in a condition.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CmpOp {
    /// `<`.
    Lt,
    /// `<=`.
    Le,
    /// `>`.
    Gt,
    /// `>=`.
    Ge,
}

/// A condition (`if`, an event's enabling condition), with where it stands.
#[derive(Clone, Debug, PartialEq)]
pub struct Cond {
    /// What it is.
    pub kind: CondKind,
    /// Where it stands in the source.
    pub span: Span,
}

/// The kinds of condition.
#[derive(Clone, Debug, PartialEq)]
pub enum CondKind {
    /// `a OP b`.
    Cmp(CmpOp, Expr, Expr),
    /// `A and B`.
    And(Box<Cond>, Box<Cond>),
    /// `A or B`.
    Or(Box<Cond>, Box<Cond>),
    /// `not A`.
    Not(Box<Cond>),
}
