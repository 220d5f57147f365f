//! The checked model: the output of `sema`, the input of every later stage.
//!
//! Names are resolved to indices, `let`s are resolved to their (shared) definitions, every mode
//! has exactly one flow per state. Spans are kept only where later stages report runtime problems
//! against the source (events); no later stage needs the AST.

use crate::syntax::Span;

/// Index of a continuous state, in declaration order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct StateIdx(pub u32);

/// Index of a parameter, in declaration order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ParamIdx(pub u32);

/// Index of a discrete mode. A model without `mode` blocks has one implicit mode `main`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ModeId(pub u16);

/// Index of an event, in declaration order over the whole file (top-level and mode events
/// interleaved as written): events at one instant fire in this order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct EventIdx(pub u32);

/// A model that parsed and checked: every name resolved to an index, every `let` shared, the
/// flow switches added as implicit events and each mode's input knots listed (`Mode::inputs`).
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    /// The `model NAME` line's name.
    pub name: String,
    /// Every parameter, a vector's elements among them (named `u[0]` .. `u[N-1]`, consecutive).
    pub params: Vec<Param>,
    /// The vector parameters (`param u[N]`), in declaration order: which runs of `params` they are.
    pub vectors: Vec<ParamVector>,
    /// The states, in declaration order.
    pub states: Vec<State>,
    /// The modes, in declaration order (one, `main`, for a model without modes).
    pub modes: Vec<Mode>,
    /// The mode the run starts in.
    pub initial_mode: ModeId,
    /// The events, declared ones in declaration order, then the implicit ones.
    pub events: Vec<Event>,
    /// The outputs, in declaration order.
    pub outputs: Vec<Output>,
    /// The `simulate` line's settings.
    pub simulate: SimulateDefaults,
}

/// A parameter (a scalar, or one element of a vector).
#[derive(Clone, Debug, PartialEq)]
pub struct Param {
    /// Its name (`u[3]` for an element).
    pub name: String,
    /// Its default value.
    pub default: f64,
    /// Allowed closed interval `[lo, hi]`, if declared.
    pub range: Option<(f64, f64)>,
    /// Where it is declared in the source.
    pub span: Span,
}

/// `param u[N] = ...`: the parameters `first .. first + len`, named `u[0]` .. `u[len-1]`. Every
/// later stage sees only those scalars; this record is for names at the front end, the CLI and
/// reports.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamVector {
    /// The vector's name.
    pub name: String,
    /// Its first element's index.
    pub first: ParamIdx,
    /// Its number of elements.
    pub len: u32,
    /// Where it is declared in the source.
    pub span: Span,
}

impl ParamVector {
    /// The parameter index of element `k < len`.
    pub fn element(&self, k: u32) -> ParamIdx {
        ParamIdx(self.first.0 + k)
    }

    /// The elements' indices, in order.
    pub fn elements(&self) -> impl Iterator<Item = ParamIdx> + '_ {
        (0..self.len).map(|k| self.element(k))
    }
}

/// The name of element `k` of vector `name`: `u[3]`, as `--set`, `--grad`, tables and JSON say it.
pub fn element_name(name: &str, k: u32) -> String {
    format!("{name}[{k}]")
}

/// How many parameters a model may declare, counting every element of a vector. It bounds the
/// memory of the checked model and of a run with `--grad` on all of them (sensitivities are
/// states x parameters).
pub const MAX_PARAMS: usize = 100_000;

/// A state.
#[derive(Clone, Debug, PartialEq)]
pub struct State {
    /// Its name.
    pub name: String,
    /// Initial value: an expression of parameters only (no `t`, no states).
    pub init: Expr,
    /// Where it is declared in the source.
    pub span: Span,
}

/// A mode: a flow for every state, and the events that can fire in it.
#[derive(Clone, Debug, PartialEq)]
pub struct Mode {
    /// Its name.
    pub name: String,
    /// `flows[i]` is `der(states[i])` in this mode.
    pub flows: Vec<Expr>,
    /// Events that can fire in this mode (its own and the top-level ones), ascending.
    pub events: Vec<EventIdx>,
    /// The inputs (`pwl`, `pwc`) its flows read, without repeats, in the order first read: their
    /// knots are the mode's breakpoints (`switches`), times known when a run starts.
    pub inputs: Vec<Input>,
    /// Where it is declared in the source.
    pub span: Span,
}

/// The direction in which the guard function `g = lhs - rhs` must cross zero.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Direction {
    /// `<=` / `<`: from positive to non-positive.
    Falling,
    /// `>=` / `>`: from negative to non-negative.
    Rising,
    /// `crosses`: either way.
    Either,
}

/// An event, declared or implicit.
#[derive(Clone, Debug, PartialEq)]
pub struct Event {
    /// Its name (implicit events are named for what they are: `flow switch of mode main`).
    pub name: String,
    /// The guard function `g = lhs - rhs`; the event fires when `g` crosses zero in `direction`.
    pub guard: Expr,
    /// Which way the guard must cross zero.
    pub direction: Direction,
    /// Enabling condition, evaluated on the state just before the event.
    pub condition: Option<Cond>,
    /// Simultaneous resets `x_i := expr`, ascending by state; unassigned states keep their value.
    pub resets: Vec<(StateIdx, Expr)>,
    /// Mode after the event; `None` keeps the current mode.
    pub target: Option<ModeId>,
    /// Whether the run stops after it fires.
    pub is_stop: bool,
    /// `None` for a top-level event (active in every mode).
    pub owner: Option<ModeId>,
    /// Where it is declared in the source.
    pub span: Span,
    /// Not declared but implied by a discontinuous flow (see `switches`): located and jumped
    /// over like an event, never reported as one.
    pub implicit: bool,
    /// A flow switch where nothing jumps: the kink of a `min`, `max` or `abs` (see `switches`).
    pub kink: bool,
}

/// An output.
#[derive(Clone, Debug, PartialEq)]
pub struct Output {
    /// Its name.
    pub name: String,
    /// Its value.
    pub expr: Expr,
    /// Where it is declared in the source.
    pub span: Span,
}

/// Defaults from the `simulate` statement; the command line overrides them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimulateDefaults {
    /// `t_end`, if set.
    pub t_end: Option<f64>,
    /// `rtol`, if set.
    pub rtol: Option<f64>,
    /// `atol`, if set.
    pub atol: Option<f64>,
}

/// A resolved real-valued expression. A `let` is resolved once and every use refers to that one
/// definition ([`Expr::Shared`]), so the checked model is a DAG as large as the text, however
/// the `let`s nest (24 lines of `let a_k = a_(k-1) + a_(k-1)` would be a tree of 2^24 nodes).
/// Passes over it visit each shared definition once.
#[derive(Clone, Debug, PartialEq)]
pub enum Expr {
    /// A number.
    Num(f64),
    /// A state's value.
    State(StateIdx),
    /// A parameter's value.
    Param(ParamIdx),
    /// The time `t`.
    Time,
    /// `-a`.
    Neg(Box<Expr>),
    /// `a OP b`.
    Binary(BinOp, Box<Expr>, Box<Expr>),
    /// `f(a, ..)`.
    Call(Func, Vec<Expr>),
    /// `if C then A else B`.
    If(Box<Cond>, Box<Expr>, Box<Expr>),
    /// A use of a `let`: its resolved definition, shared by all its uses.
    Shared(Shared),
    /// `pwl(t, t0, t1, u)` or `pwc(t, t0, t1, u)`: a vector parameter interpolated in time.
    Input(Box<Input>),
}

/// How an input interpolates its vector.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum InputKind {
    /// `pwl`: linear between `N` knots `t0 + k (t1 - t0) / (N - 1)`, `k = 0 .. N-1`; `u[0]`
    /// before `t0`, `u[N-1]` after `t1`. Continuous; kinks at the knots.
    Pwl,
    /// `pwc`: `N` intervals of width `(t1 - t0) / N`; `u[k]` on `[t0 + k w, t0 + (k+1) w)`,
    /// `u[0]` before, `u[N-1]` after. Jumps at the `N - 1` interior knots `t0 + k w`.
    Pwc,
}

impl InputKind {
    /// The function's name in the language (`pwl`, `pwc`).
    pub fn name(self) -> &'static str {
        match self {
            InputKind::Pwl => "pwl",
            InputKind::Pwc => "pwc",
        }
    }

    /// The kind named `name`, if any.
    pub fn from_name(name: &str) -> Option<InputKind> {
        [InputKind::Pwl, InputKind::Pwc].into_iter().find(|k| k.name() == name)
    }
}

/// An input: the vector `first .. first + len` at the knots spread over `[t0, t1]` (both
/// expressions of parameters only, checked by `sema`).
#[derive(Clone, Debug, PartialEq)]
pub struct Input {
    /// `pwl` (linear between knots) or `pwc` (constant from each knot on).
    pub kind: InputKind,
    /// The window's start (an expression of parameters).
    pub t0: Expr,
    /// The window's end.
    pub t1: Expr,
    /// The vector's first element.
    pub first: ParamIdx,
    /// Its number of elements (the knots).
    pub len: u32,
}

impl Input {
    /// The number of knot spacings in `[t0, t1]`: `N - 1` for `pwl`, `N` for `pwc`.
    pub fn spacings(&self) -> u32 {
        match self.kind {
            InputKind::Pwl => self.len - 1,
            InputKind::Pwc => self.len,
        }
    }

    /// The knot position `s = (t - t0) * spacings / (t1 - t0)`: knot `k` is at `s = k`. Every
    /// later stage reads the input and its knots through this one expression, so a knot's
    /// event and the value's segment agree to the last bit about which side of it `t` is on.
    pub fn position(&self) -> Expr {
        let since = Expr::Binary(BinOp::Sub, Box::new(Expr::Time), Box::new(self.t0.clone()));
        let width = Expr::Binary(BinOp::Sub, Box::new(self.t1.clone()), Box::new(self.t0.clone()));
        let scaled =
            Expr::Binary(BinOp::Mul, Box::new(since), Box::new(Expr::Num(f64::from(self.spacings()))));
        Expr::Binary(BinOp::Div, Box::new(scaled), Box::new(width))
    }

    /// The knots `k` (positions `s = k`) where the input is not smooth: `pwl`'s `0 .. N-1`
    /// (kinks), `pwc`'s interior `1 .. N-1` (jumps).
    pub fn knots(&self) -> std::ops::Range<u32> {
        match self.kind {
            InputKind::Pwl => 0..self.len,
            InputKind::Pwc => 1..self.len,
        }
    }
}

/// How deep a checked expression may nest, counting through `let`s. It bounds the work and stack
/// of every pass over an expression; `sema` reports a `let` that would exceed it.
pub const MAX_EXPR_DEPTH: usize = 100_000;

/// A `let`'s resolved definition, shared by every use; equal when it is the same definition or
/// the definitions are equal.
#[derive(Clone, Debug)]
pub struct Shared(std::sync::Arc<SharedDef>);

/// A `let`'s definition.
#[derive(Debug)]
pub struct SharedDef {
    /// What the `let` stands for.
    pub expr: Expr,
    /// Nesting depth of `expr`, counting through the `let`s it uses.
    pub depth: usize,
}

impl Shared {
    /// A definition of `expr`, its depth computed once.
    pub fn new(expr: Expr) -> Shared {
        let depth = expr.depth();
        Shared(std::sync::Arc::new(SharedDef { expr, depth }))
    }

    /// What the `let` stands for.
    pub fn expr(&self) -> &Expr {
        &self.0.expr
    }

    /// The nesting depth of its definition, counting through the `let`s it uses.
    pub fn depth(&self) -> usize {
        self.0.depth
    }

    /// Identifies the definition, for passes that visit each shared definition once.
    pub fn key(&self) -> *const SharedDef {
        std::sync::Arc::as_ptr(&self.0)
    }
}

impl PartialEq for Shared {
    fn eq(&self, other: &Shared) -> bool {
        std::sync::Arc::ptr_eq(&self.0, &other.0) || self.0.expr == other.0.expr
    }
}

impl Expr {
    /// Nesting depth, reading a `let`'s depth from its definition: the walk stays within this
    /// expression's own text.
    pub fn depth(&self) -> usize {
        match self {
            Expr::Num(_) | Expr::State(_) | Expr::Param(_) | Expr::Time => 1,
            Expr::Shared(s) => s.depth(),
            Expr::Neg(a) => 1 + a.depth(),
            Expr::Binary(_, a, b) => 1 + a.depth().max(b.depth()),
            Expr::Call(_, args) => 1 + args.iter().map(Expr::depth).max().unwrap_or(0),
            Expr::If(c, a, b) => 1 + c.depth().max(a.depth()).max(b.depth()),
            Expr::Input(i) => 2 + i.t0.depth().max(i.t1.depth()),
        }
    }
}

impl Cond {
    fn depth(&self) -> usize {
        match self {
            Cond::Cmp(_, a, b) => 1 + a.depth().max(b.depth()),
            Cond::And(a, b) | Cond::Or(a, b) => 1 + a.depth().max(b.depth()),
            Cond::Not(a) => 1 + a.depth(),
        }
    }
}

/// Dropping the last use of a long chain of `let`s would recurse once per link; the links are
/// taken apart with a work list instead.
impl Drop for SharedDef {
    fn drop(&mut self) {
        let mut work = vec![std::mem::replace(&mut self.expr, Expr::Num(0.0))];
        let mut conds: Vec<Cond> = Vec::new();
        loop {
            if let Some(e) = work.pop() {
                match e {
                    Expr::Shared(Shared(arc)) => {
                        if let Some(mut def) = std::sync::Arc::into_inner(arc) {
                            work.push(std::mem::replace(&mut def.expr, Expr::Num(0.0)));
                        }
                    }
                    Expr::Neg(a) => work.push(*a),
                    Expr::Binary(_, a, b) => work.extend([*a, *b]),
                    Expr::Call(_, args) => work.extend(args),
                    Expr::If(c, a, b) => {
                        conds.push(*c);
                        work.extend([*a, *b]);
                    }
                    Expr::Input(i) => {
                        let Input { t0, t1, .. } = *i;
                        work.extend([t0, t1]);
                    }
                    Expr::Num(_) | Expr::State(_) | Expr::Param(_) | Expr::Time => {}
                }
            } else if let Some(c) = conds.pop() {
                match c {
                    Cond::Cmp(_, a, b) => work.extend([a, b]),
                    Cond::And(a, b) | Cond::Or(a, b) => conds.extend([*a, *b]),
                    Cond::Not(a) => conds.push(*a),
                }
            } else {
                break;
            }
        }
    }
}

/// A binary arithmetic operator.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
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

/// The language's functions. `arity` is checked by `sema`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Func {
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
    /// `atan2(y, x)`.
    Atan2,
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
    /// `sign` (a flow switch where its argument crosses 0).
    Sign,
    /// `min(a, b)`.
    Min,
    /// `max(a, b)`.
    Max,
    /// `pow(a, b)`.
    Pow,
    /// `hypot(a, b)`.
    Hypot,
}

impl Func {
    /// Every function, in the order the language documents them.
    pub const ALL: [Func; 19] = [
        Func::Sin,
        Func::Cos,
        Func::Tan,
        Func::Asin,
        Func::Acos,
        Func::Atan,
        Func::Atan2,
        Func::Sinh,
        Func::Cosh,
        Func::Tanh,
        Func::Exp,
        Func::Log,
        Func::Sqrt,
        Func::Abs,
        Func::Sign,
        Func::Min,
        Func::Max,
        Func::Pow,
        Func::Hypot,
    ];

    /// The function's name in the language.
    pub fn name(self) -> &'static str {
        match self {
            Func::Sin => "sin",
            Func::Cos => "cos",
            Func::Tan => "tan",
            Func::Asin => "asin",
            Func::Acos => "acos",
            Func::Atan => "atan",
            Func::Atan2 => "atan2",
            Func::Sinh => "sinh",
            Func::Cosh => "cosh",
            Func::Tanh => "tanh",
            Func::Exp => "exp",
            Func::Log => "log",
            Func::Sqrt => "sqrt",
            Func::Abs => "abs",
            Func::Sign => "sign",
            Func::Min => "min",
            Func::Max => "max",
            Func::Pow => "pow",
            Func::Hypot => "hypot",
        }
    }

    /// The function named `name`, if any.
    pub fn from_name(name: &str) -> Option<Func> {
        Func::ALL.into_iter().find(|f| f.name() == name)
    }

    /// How many arguments it takes.
    pub fn arity(self) -> usize {
        match self {
            Func::Atan2 | Func::Min | Func::Max | Func::Pow | Func::Hypot => 2,
            _ => 1,
        }
    }
}

/// The functions of vector parameters, expanded by `sema` into sums over their elements.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum VectorFunc {
    /// `sum(u)`: `u[0] + ... + u[N-1]`.
    Sum,
    /// `dot(u, w)`: `u[0] w[0] + ... + u[N-1] w[N-1]`, both of length `N`.
    Dot,
}

impl VectorFunc {
    /// The function's name in the language.
    pub fn name(self) -> &'static str {
        match self {
            VectorFunc::Sum => "sum",
            VectorFunc::Dot => "dot",
        }
    }

    /// The function named `name`, if any.
    pub fn from_name(name: &str) -> Option<VectorFunc> {
        [VectorFunc::Sum, VectorFunc::Dot].into_iter().find(|f| f.name() == name)
    }

    /// How many vectors it takes.
    pub fn arity(self) -> usize {
        match self {
            VectorFunc::Sum => 1,
            VectorFunc::Dot => 2,
        }
    }
}

/// A resolved boolean expression (in `if` and event conditions).
#[derive(Clone, Debug, PartialEq)]
pub enum Cond {
    /// `a OP b`.
    Cmp(CmpOp, Expr, Expr),
    /// `A and B`.
    And(Box<Cond>, Box<Cond>),
    /// `A or B`.
    Or(Box<Cond>, Box<Cond>),
    /// `not A`.
    Not(Box<Cond>),
}

/// A comparison in a condition.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
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

impl Model {
    /// How many states.
    pub fn n_states(&self) -> usize {
        self.states.len()
    }
    /// How many parameters (a vector's elements counted).
    pub fn n_params(&self) -> usize {
        self.params.len()
    }
    /// The index of parameter `name`: a scalar's name or an element's, `u[3]` (the text exactly
    /// as `element_name` writes it: no spaces, no leading zeros).
    pub fn param_index(&self, name: &str) -> Option<ParamIdx> {
        // An element is found through its vector, so a lookup does not scan every element.
        if let Some((base, rest)) = name.split_once('[') {
            let text = rest.strip_suffix(']')?;
            let v = self.vector(base)?;
            let k: u32 = text.parse().ok()?;
            // `u[03]` and `u[+3]` parse as 3 but are not the element's name.
            return (k < v.len && k.to_string() == text).then(|| v.element(k));
        }
        self.params.iter().position(|p| p.name == name).map(|i| ParamIdx(i as u32))
    }
    /// The vector parameter `name`, if there is one.
    pub fn vector(&self, name: &str) -> Option<&ParamVector> {
        self.vectors.iter().find(|v| v.name == name)
    }
    /// The index of mode `name`, if the model has one.
    pub fn mode_index(&self, name: &str) -> Option<ModeId> {
        self.modes.iter().position(|m| m.name == name).map(|i| ModeId(i as u16))
    }
}
