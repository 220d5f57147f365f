//! Scopes, name lookup, `let` inlining with cycle detection, and "did you mean" suggestions.
//!
//! Scope tree: the model scope, one scope per mode (child of the model scope) and one per event
//! block (child of its mode's or the model's scope). A name declared in an inner scope may not
//! shadow an outer one: shadowing in a model file is far more often a mistake than an intent.

use std::collections::HashMap;

use super::error::CheckError;
use super::model::*;
use super::walk::{first_non_constant, NonConstant};
use crate::syntax::ast;
use crate::syntax::Span;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ScopeId(pub u32);

impl ScopeId {
    pub const GLOBAL: ScopeId = ScopeId(0);
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LetId(pub u32);

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Binding {
    Param(ParamIdx),
    State(StateIdx),
    Let(LetId),
    /// `param u[len]`: the parameters `first .. first + len`. A length refused by the checker is
    /// declared as 0, and uses of such a vector raise no further errors.
    Vector {
        first: ParamIdx,
        len: u32,
    },
}

impl Binding {
    pub fn kind_name(self) -> &'static str {
        match self {
            Binding::Vector { .. } => "vector parameter",
            Binding::Param(_) => "parameter",
            Binding::State(_) => "state",
            Binding::Let(_) => "let",
        }
    }
}

struct ScopeData {
    parent: Option<ScopeId>,
    names: HashMap<String, (Binding, Span, &'static str)>,
}

enum LetState {
    Unresolved,
    InProgress,
    Done(Expr),
}

struct LetData<'a> {
    decl: &'a ast::LetDecl,
    scope: ScopeId,
    state: LetState,
}

pub struct Scopes<'a> {
    scopes: Vec<ScopeData>,
    lets: Vec<LetData<'a>>,
    state_names: Vec<String>,
    /// Lets being resolved, innermost last: the path reported for a cycle.
    let_stack: Vec<LetId>,
    /// Whether a `let` over `MAX_EXPR_DEPTH` has been reported (the ones built on it are not).
    too_deep_reported: bool,
    /// `sum(u)` and `dot(u, w)`, built once per vector (pair) and shared by every use, keyed by
    /// the vectors' first elements (`u32::MAX` for `sum`'s missing second).
    vector_sums: HashMap<(u32, u32), Expr>,
}

impl Default for Scopes<'_> {
    fn default() -> Self {
        Scopes {
            scopes: vec![ScopeData { parent: None, names: HashMap::new() }],
            lets: Vec::new(),
            state_names: Vec::new(),
            let_stack: Vec::new(),
            too_deep_reported: false,
            vector_sums: HashMap::new(),
        }
    }
}

impl<'a> Scopes<'a> {
    pub fn child(&mut self, parent: ScopeId) -> ScopeId {
        self.scopes.push(ScopeData { parent: Some(parent), names: HashMap::new() });
        ScopeId(self.scopes.len() as u32 - 1)
    }

    pub fn insert(&mut self, scope: ScopeId, name: &ast::Ident, binding: Binding, what: &'static str) {
        self.scopes[scope.0 as usize].names.insert(name.name.clone(), (binding, name.span, what));
    }

    /// Records the name of the next state, whether or not its declaration was valid, so that
    /// state indices and names stay aligned.
    pub fn push_state_name(&mut self, name: &str) {
        self.state_names.push(name.to_string());
    }

    pub fn add_let(&mut self, decl: &'a ast::LetDecl, scope: ScopeId) -> LetId {
        self.lets.push(LetData { decl, scope, state: LetState::Unresolved });
        LetId(self.lets.len() as u32 - 1)
    }

    pub fn n_lets(&self) -> usize {
        self.lets.len()
    }

    fn find(&self, scope: ScopeId, name: &str) -> Option<&(Binding, Span, &'static str)> {
        let mut s = Some(scope);
        while let Some(id) = s {
            let data = &self.scopes[id.0 as usize];
            if let Some(found) = data.names.get(name) {
                return Some(found);
            }
            s = data.parent;
        }
        None
    }

    pub fn lookup(&self, scope: ScopeId, name: &str) -> Option<Binding> {
        self.find(scope, name).map(|f| f.0)
    }

    /// Where `name` is already declared (in `scope` or an enclosing one), and as what.
    pub fn lookup_decl(&self, scope: ScopeId, name: &str) -> Option<(Span, &'static str)> {
        self.find(scope, name).map(|f| (f.1, f.2))
    }

    /// Names the first use of `t`, a state or an input in `e`, if any (what an initial value or
    /// an input's window may not read).
    pub fn non_constant(&self, e: &Expr) -> Option<String> {
        first_non_constant(e).map(|found| match found {
            NonConstant::Time => "time `t`".to_string(),
            NonConstant::State(i) => format!("state `{}`", self.state_name(i)),
            NonConstant::Input => "an input (`pwl`, `pwc`), which varies with `t`".to_string(),
        })
    }

    pub fn state_name(&self, i: usize) -> &str {
        self.state_names.get(i).map(String::as_str).unwrap_or("?")
    }

    pub fn suggest_state(&self, name: &str) -> Option<String> {
        closest(name, self.state_names.iter().map(String::as_str))
    }

    /// The visible name closest to `name`, for "did you mean".
    fn suggest(&self, scope: ScopeId, name: &str) -> Option<String> {
        let mut candidates: Vec<&str> = vec!["t", "pi"];
        let mut s = Some(scope);
        while let Some(id) = s {
            let data = &self.scopes[id.0 as usize];
            candidates.extend(data.names.keys().map(String::as_str));
            s = data.parent;
        }
        closest(name, candidates.into_iter())
    }
}

/// The candidate within a small edit distance of `name` (about a third of its length), if any.
/// A candidate that shares no letter position with `name` is no suggestion (`q` is not a typo
/// of `k`).
pub fn closest<'s>(name: &str, candidates: impl Iterator<Item = &'s str>) -> Option<String> {
    let len = name.chars().count();
    let limit = (len / 3).max(1);
    candidates
        .filter(|c| *c != name)
        .map(|c| (edit_distance(name, c), c))
        .filter(|(d, _)| *d <= limit && *d < len)
        .min()
        .map(|(_, c)| c.to_string())
}

fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diag = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let next = (diag + usize::from(ca != *cb)).min(row[j] + 1).min(row[j + 1] + 1);
            diag = row[j + 1];
            row[j + 1] = next;
        }
    }
    row[b.len()]
}

/// Resolves every `let` once, so that errors inside unused `let`s are reported too.
pub fn resolve_all_lets(scopes: &mut Scopes, errors: &mut Vec<CheckError>) {
    for k in 0..scopes.n_lets() {
        resolve_let(scopes, errors, LetId(k as u32), None);
    }
}

/// The resolved definition of a `let`, resolving it on first use. `use_span` is where it was
/// referenced (None when resolving for its own sake).
fn resolve_let(scopes: &mut Scopes, errors: &mut Vec<CheckError>, id: LetId, use_span: Option<Span>) -> Expr {
    let k = id.0 as usize;
    match &scopes.lets[k].state {
        LetState::Done(e) => return e.clone(),
        LetState::InProgress => {
            let start = scopes.let_stack.iter().position(|l| *l == id).unwrap_or(0);
            let mut path: Vec<&str> = scopes.let_stack[start..]
                .iter()
                .map(|l| scopes.lets[l.0 as usize].decl.name.name.as_str())
                .collect();
            path.push(scopes.lets[k].decl.name.name.as_str());
            errors.push(CheckError::LetCycle {
                name: scopes.lets[k].decl.name.name.clone(),
                path: path.join(" -> "),
                span: use_span.unwrap_or(scopes.lets[k].decl.name.span),
            });
            return Expr::Num(0.0);
        }
        LetState::Unresolved => {}
    }
    scopes.lets[k].state = LetState::InProgress;
    scopes.let_stack.push(id);
    let (decl, scope) = (scopes.lets[k].decl, scopes.lets[k].scope);
    // A `let` used before its definition resolves its definition here, so a chain of them
    // declared last-first recurses once per link.
    let value = crate::stack::deep(|| resolve_names(scopes, errors, &decl.value, scope));
    scopes.let_stack.pop();
    let shared = Shared::new(value);
    let e = if shared.depth() > MAX_EXPR_DEPTH {
        // Reported once, at the first `let` over the cap; every `let` built on it reads as 0.
        if !scopes.too_deep_reported {
            scopes.too_deep_reported = true;
            errors.push(CheckError::TooDeep {
                name: decl.name.name.clone(),
                depth: shared.depth(),
                span: decl.name.span,
            });
        }
        Expr::Num(0.0)
    } else {
        Expr::Shared(shared)
    };
    scopes.lets[k].state = LetState::Done(e.clone());
    e
}

/// Resolves the names of an AST expression in `scope`, inlining `let`s.
pub fn resolve_names(
    scopes: &mut Scopes,
    errors: &mut Vec<CheckError>,
    e: &ast::Expr,
    scope: ScopeId,
) -> Expr {
    match &e.kind {
        ast::ExprKind::Num(v) => Expr::Num(*v),
        ast::ExprKind::Name(name) => match scopes.lookup(scope, name) {
            Some(Binding::Param(i)) => Expr::Param(i),
            Some(Binding::State(i)) => Expr::State(i),
            Some(Binding::Let(id)) => resolve_let(scopes, errors, id, Some(e.span)),
            Some(Binding::Vector { len, .. }) => {
                if len > 0 {
                    errors.push(CheckError::VectorAsScalar { name: name.clone(), len, span: e.span });
                }
                Expr::Num(0.0)
            }
            None if name == "t" => Expr::Time,
            None if name == "pi" => Expr::Num(std::f64::consts::PI),
            None if Func::from_name(name).is_some() => {
                errors.push(CheckError::WrongKind {
                    name: name.clone(),
                    found: "function",
                    expected: "value (call it as `name(...)`)",
                    span: e.span,
                });
                Expr::Num(0.0)
            }
            None => {
                let suggestion = scopes.suggest(scope, name);
                errors.push(CheckError::UnknownName { name: name.clone(), span: e.span, suggestion });
                Expr::Num(0.0)
            }
        },
        ast::ExprKind::Neg(a) => Expr::Neg(Box::new(resolve_names(scopes, errors, a, scope))),
        ast::ExprKind::Binary(op, a, b) => {
            let op = match op {
                ast::BinOp::Add => BinOp::Add,
                ast::BinOp::Sub => BinOp::Sub,
                ast::BinOp::Mul => BinOp::Mul,
                ast::BinOp::Div => BinOp::Div,
                ast::BinOp::Pow => BinOp::Pow,
            };
            let a = resolve_names(scopes, errors, a, scope);
            let b = resolve_names(scopes, errors, b, scope);
            Expr::Binary(op, Box::new(a), Box::new(b))
        }
        ast::ExprKind::Index(name, at) => match at.as_slice() {
            [at] => resolve_index(scopes, errors, name, at, scope),
            // More indices reach sema only as names of elements (`expand` writes `T[2][5]`).
            _ => {
                errors.push(CheckError::UnknownName {
                    name: name.name.clone(),
                    span: e.span,
                    suggestion: None,
                });
                Expr::Num(0.0)
            }
        },
        // `expand` unrolls every reduction before sema sees the file.
        ast::ExprKind::Sum(_) => {
            errors.push(CheckError::UnknownName { name: "sum".into(), span: e.span, suggestion: None });
            Expr::Num(0.0)
        }
        ast::ExprKind::Call(name, args) if VectorFunc::from_name(&name.name).is_some() => {
            let func = VectorFunc::from_name(&name.name).expect("matched above");
            resolve_vector_call(scopes, errors, func, args, e.span, scope)
        }
        ast::ExprKind::Call(name, args) if InputKind::from_name(&name.name).is_some() => {
            let kind = InputKind::from_name(&name.name).expect("matched above");
            resolve_input(scopes, errors, kind, args, e.span, scope)
        }
        ast::ExprKind::Call(name, args) => {
            let args: Vec<Expr> = args.iter().map(|a| resolve_names(scopes, errors, a, scope)).collect();
            let Some(func) = Func::from_name(&name.name) else {
                if let Some(b) = scopes.lookup(scope, &name.name) {
                    errors.push(CheckError::WrongKind {
                        name: name.name.clone(),
                        found: b.kind_name(),
                        expected: "function",
                        span: name.span,
                    });
                } else {
                    let suggestion = closest(&name.name, Func::ALL.iter().map(|f| f.name()));
                    errors.push(CheckError::UnknownFunction {
                        name: name.name.clone(),
                        span: name.span,
                        suggestion,
                    });
                }
                return Expr::Num(0.0);
            };
            if args.len() != func.arity() {
                errors.push(CheckError::Arity {
                    func: name.name.clone(),
                    expected: func.arity(),
                    found: args.len(),
                    span: e.span,
                });
                return Expr::Num(0.0);
            }
            Expr::Call(func, args)
        }
        ast::ExprKind::If(c, a, b) => {
            let c = resolve_cond(scopes, errors, c, scope);
            let a = resolve_names(scopes, errors, a, scope);
            let b = resolve_names(scopes, errors, b, scope);
            Expr::If(Box::new(c), Box::new(a), Box::new(b))
        }
    }
}

/// `u[k]`: the parameter of element `k`, with `k` an integer literal in range. A constant index is
/// what makes `u[k]` an ordinary parameter for every later stage.
fn resolve_index(
    scopes: &mut Scopes,
    errors: &mut Vec<CheckError>,
    name: &ast::Ident,
    at: &ast::Expr,
    scope: ScopeId,
) -> Expr {
    let (first, len) = match scopes.lookup(scope, &name.name) {
        Some(Binding::Vector { first, len }) => (first, len),
        Some(other) => {
            errors.push(CheckError::WrongKind {
                name: name.name.clone(),
                found: other.kind_name(),
                expected: "vector parameter",
                span: name.span,
            });
            return Expr::Num(0.0);
        }
        None => {
            let suggestion = scopes.suggest(scope, &name.name);
            errors.push(CheckError::UnknownName { name: name.name.clone(), span: name.span, suggestion });
            return Expr::Num(0.0);
        }
    };
    if len == 0 {
        return Expr::Num(0.0);
    }
    let k = match at.kind {
        ast::ExprKind::Num(k) => k,
        _ => {
            errors.push(CheckError::BadIndex { name: name.name.clone(), len, span: at.span });
            return Expr::Num(0.0);
        }
    };
    if k.fract() != 0.0 {
        errors.push(CheckError::BadIndex { name: name.name.clone(), len, span: at.span });
        return Expr::Num(0.0);
    }
    if !(0.0..f64::from(len)).contains(&k) {
        errors.push(CheckError::IndexOutOfRange { name: name.name.clone(), index: k, len, span: at.span });
        return Expr::Num(0.0);
    }
    Expr::Param(ParamIdx(first.0 + k as u32))
}

/// `sum(u)` or `dot(u, w)`: the sum over the elements, built as a balanced tree (depth
/// `log2 N`, far under `MAX_EXPR_DEPTH` for any length) and shared by all uses like a `let`.
fn resolve_vector_call(
    scopes: &mut Scopes,
    errors: &mut Vec<CheckError>,
    func: VectorFunc,
    args: &[ast::Expr],
    span: Span,
    scope: ScopeId,
) -> Expr {
    if args.len() != func.arity() {
        errors.push(CheckError::Arity {
            func: func.name().to_string(),
            expected: func.arity(),
            found: args.len(),
            span,
        });
        return Expr::Num(0.0);
    }
    let mut vectors: Vec<(&str, ParamIdx, u32)> = Vec::new();
    for arg in args {
        match &arg.kind {
            ast::ExprKind::Name(n) => match scopes.lookup(scope, n) {
                Some(Binding::Vector { first, len }) => vectors.push((n, first, len)),
                Some(_) => errors.push(CheckError::NotAVector { func: func.name(), span: arg.span }),
                None => {
                    let suggestion = scopes.suggest(scope, n);
                    errors.push(CheckError::UnknownName { name: n.clone(), span: arg.span, suggestion });
                }
            },
            _ => errors.push(CheckError::NotAVector { func: func.name(), span: arg.span }),
        }
    }
    if vectors.len() != args.len() || vectors.iter().any(|v| v.2 == 0) {
        return Expr::Num(0.0);
    }
    let (a, first_a, len_a) = vectors[0];
    let (second, len_b) = match vectors.get(1) {
        Some(&(b, first_b, len_b)) => {
            if len_b != len_a {
                errors.push(CheckError::VectorLengths {
                    a: a.to_string(),
                    len_a,
                    b: b.to_string(),
                    len_b,
                    span,
                });
                return Expr::Num(0.0);
            }
            (Some(first_b), len_b)
        }
        None => (None, len_a),
    };
    let key = (first_a.0, second.map_or(u32::MAX, |b| b.0));
    if let Some(e) = scopes.vector_sums.get(&key) {
        return e.clone();
    }
    debug_assert_eq!(len_a, len_b);
    let terms: Vec<Expr> = (0..len_a)
        .map(|k| {
            let u = Expr::Param(ParamIdx(first_a.0 + k));
            match second {
                Some(b) => Expr::Binary(BinOp::Mul, Box::new(u), Box::new(Expr::Param(ParamIdx(b.0 + k)))),
                None => u,
            }
        })
        .collect();
    let e = Expr::Shared(Shared::new(balanced_sum(terms)));
    scopes.vector_sums.insert(key, e.clone());
    e
}

/// `pwl(t, t0, t1, u)` or `pwc(t, t0, t1, u)`: the first argument is `t` itself, `t0` and `t1`
/// expressions of parameters (the knots are fixed for a run), `u` a vector parameter (of at
/// least 2 elements for `pwl`).
fn resolve_input(
    scopes: &mut Scopes,
    errors: &mut Vec<CheckError>,
    kind: InputKind,
    args: &[ast::Expr],
    span: Span,
    scope: ScopeId,
) -> Expr {
    let func = kind.name();
    let [time, t0, t1, u] = args else {
        errors.push(CheckError::Arity { func: func.to_string(), expected: 4, found: args.len(), span });
        return Expr::Num(0.0);
    };
    let before = errors.len();
    // `t` cannot be declared, so the name is always the time.
    if !matches!(&time.kind, ast::ExprKind::Name(n) if n == "t") {
        errors.push(CheckError::InputTime { func, span: time.span });
    }
    let [t0, t1] = [t0, t1].map(|arg| {
        let e = resolve_names(scopes, errors, arg, scope);
        if let Some(what) = scopes.non_constant(&e) {
            errors.push(CheckError::InputWindow { func, what, span: arg.span });
        }
        e
    });
    let vector = match &u.kind {
        ast::ExprKind::Name(n) => match scopes.lookup(scope, n) {
            Some(Binding::Vector { first, len }) => Some((n, first, len)),
            Some(_) => {
                errors.push(CheckError::NotAVector { func, span: u.span });
                None
            }
            None => {
                let suggestion = scopes.suggest(scope, n);
                errors.push(CheckError::UnknownName { name: n.clone(), span: u.span, suggestion });
                None
            }
        },
        _ => {
            errors.push(CheckError::NotAVector { func, span: u.span });
            None
        }
    };
    let Some((name, first, len)) = vector else { return Expr::Num(0.0) };
    if len == 0 {
        return Expr::Num(0.0);
    }
    if kind == InputKind::Pwl && len < 2 {
        errors.push(CheckError::InputTooShort { name: name.clone(), len, span: u.span });
    }
    if errors.len() > before {
        return Expr::Num(0.0);
    }
    Expr::Input(Box::new(Input { kind, t0, t1, first, len }))
}

/// `terms[0] + ... + terms[n-1]` (n >= 1) as a balanced tree, left to right.
fn balanced_sum(mut terms: Vec<Expr>) -> Expr {
    if terms.len() == 1 {
        return terms.pop().expect("one term");
    }
    let right = terms.split_off(terms.len() / 2);
    Expr::Binary(BinOp::Add, Box::new(balanced_sum(terms)), Box::new(balanced_sum(right)))
}

pub fn resolve_cond(
    scopes: &mut Scopes,
    errors: &mut Vec<CheckError>,
    c: &ast::Cond,
    scope: ScopeId,
) -> Cond {
    match &c.kind {
        ast::CondKind::Cmp(op, a, b) => {
            let op = match op {
                ast::CmpOp::Lt => CmpOp::Lt,
                ast::CmpOp::Le => CmpOp::Le,
                ast::CmpOp::Gt => CmpOp::Gt,
                ast::CmpOp::Ge => CmpOp::Ge,
            };
            let a = resolve_names(scopes, errors, a, scope);
            let b = resolve_names(scopes, errors, b, scope);
            Cond::Cmp(op, a, b)
        }
        ast::CondKind::And(a, b) => Cond::And(
            Box::new(resolve_cond(scopes, errors, a, scope)),
            Box::new(resolve_cond(scopes, errors, b, scope)),
        ),
        ast::CondKind::Or(a, b) => Cond::Or(
            Box::new(resolve_cond(scopes, errors, a, scope)),
            Box::new(resolve_cond(scopes, errors, b, scope)),
        ),
        ast::CondKind::Not(a) => Cond::Not(Box::new(resolve_cond(scopes, errors, a, scope))),
    }
}
