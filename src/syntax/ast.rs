//! The abstract syntax tree: what the user wrote, with a span on every node. No name is resolved
//! here; `sema` does that.

use super::Span;

#[derive(Clone, Debug, PartialEq)]
pub struct Ident {
    pub name: String,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Number {
    pub value: f64,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub struct File {
    pub model: Ident,
    pub items: Vec<Item>,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Item {
    Param(ParamDecl),
    State(StateDecl),
    Der(DerEq),
    Let(LetDecl),
    Event(Box<EventDecl>),
    Mode(Box<ModeDecl>),
    Output(OutputDecl),
    Simulate(SimulateDecl),
}

#[derive(Clone, Debug, PartialEq)]
pub struct ParamDecl {
    pub name: Ident,
    /// `param u[N]`: a vector of `N` parameters; `None` for a scalar.
    pub size: Option<Size>,
    pub default: Number,
    pub range: Option<Range>,
    pub span: Span,
}

/// The length written in `param u[N]`: its digits as written, and their value saturated at
/// `u64::MAX` (sema caps it far below).
#[derive(Clone, Debug, PartialEq)]
pub struct Size {
    pub text: String,
    pub len: u64,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Range {
    pub lo: Number,
    pub hi: Number,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub struct StateDecl {
    pub name: Ident,
    pub init: Expr,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub struct DerEq {
    pub state: Ident,
    pub rhs: Expr,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub struct LetDecl {
    pub name: Ident,
    pub value: Expr,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub struct OutputDecl {
    pub name: Ident,
    pub value: Expr,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub struct SimulateDecl {
    pub settings: Vec<Setting>,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Setting {
    pub name: Ident,
    pub value: Number,
    pub span: Span,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GuardOp {
    Le,
    Lt,
    Ge,
    Gt,
    Crosses,
}

#[derive(Clone, Debug, PartialEq)]
pub struct EventDecl {
    pub name: Ident,
    pub lhs: Expr,
    pub op: GuardOp,
    pub rhs: Expr,
    pub condition: Option<Cond>,
    pub target: Option<Ident>,
    pub body: Vec<EventStmt>,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub enum EventStmt {
    Reset { state: Ident, value: Expr, span: Span },
    Let(LetDecl),
    Stop { span: Span },
}

#[derive(Clone, Debug, PartialEq)]
pub struct ModeDecl {
    pub name: Ident,
    pub is_initial: bool,
    pub items: Vec<ModeItem>,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub enum ModeItem {
    Der(DerEq),
    Let(LetDecl),
    Event(Box<EventDecl>),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BinOp {
    Add,
    Sub,
    Mul,
    Div,
    Pow,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Expr {
    pub kind: ExprKind,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub enum ExprKind {
    Num(f64),
    Name(String),
    Neg(Box<Expr>),
    Binary(BinOp, Box<Expr>, Box<Expr>),
    Call(Ident, Vec<Expr>),
    /// `u[k]`: an element of a vector parameter.
    Index(Ident, Box<Expr>),
    If(Box<Cond>, Box<Expr>, Box<Expr>),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CmpOp {
    Lt,
    Le,
    Gt,
    Ge,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Cond {
    pub kind: CondKind,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub enum CondKind {
    Cmp(CmpOp, Expr, Expr),
    And(Box<Cond>, Box<Cond>),
    Or(Box<Cond>, Box<Cond>),
    Not(Box<Cond>),
}
