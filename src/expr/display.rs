//! Stage 3: infix text of expressions, for `hybc derive` and snapshots. Knows no spans, no IO and
//! no Cranelift; state and parameter names are passed in.
//!
//! The text uses the `.hyb` expression syntax with as few parentheses as keep the tree: `^` is
//! right-associative and binds tighter than unary minus (`-x^2` is `-(x^2)`), `*` and `/` are
//! left-associative, `a + (-b)` prints as `a - b`, a select prints as `if c then a else b`.
//! `-a * b` is printed for `-(a * b)`; the parser reads it as `(-a) * b`, which has the same value
//! in IEEE arithmetic. Comparisons, `and`, `or`, `not` print as in conditions.
//!
//! Texts are built bottom-up in id order with one text per node, so printing is linear in the
//! size of the printed text.

use std::collections::{HashMap, HashSet};

use super::eval::reachable;
use super::node::{BinaryOp, ExprId, Node, UnaryOp};
use super::store::ExprStore;

// Binding strength, loosest first.
const P_SELECT: u8 = 0;
const P_OR: u8 = 1;
const P_AND: u8 = 2;
const P_NOT: u8 = 3;
const P_CMP: u8 = 4;
const P_SUM: u8 = 5;
const P_PRODUCT: u8 = 6;
const P_NEG: u8 = 7;
const P_POW: u8 = 8;
const P_ATOM: u8 = 9;

/// Text of one expression (no `let`s).
pub fn to_infix(store: &ExprStore, id: ExprId, states: &[String], params: &[String]) -> String {
    to_infix_capped(store, id, states, params, usize::MAX)
}

/// Text of one expression, each subexpression's text cut after `cap` characters and marked with
/// `...`: the text of a DAG can be exponentially longer than the DAG (a `let` that doubles its
/// predecessor, 60 times), so summaries print a capped text in time and memory linear in the
/// DAG.
pub fn to_infix_capped(
    store: &ExprStore,
    id: ExprId,
    states: &[String],
    params: &[String],
    cap: usize,
) -> String {
    let mut p = Printer::new(store, states, params);
    p.cap = cap;
    p.build(&[id], false);
    p.wrap(id, P_SELECT)
}

/// Several expressions printed together, with shared subexpressions hoisted into `let`s where
/// that makes the text shorter.
#[derive(Clone, Debug, PartialEq)]
pub struct Group {
    /// `(name, text)` of each hoisted subexpression, in dependency order.
    pub lets: Vec<(String, String)>,
    /// Text of each root, in the order given.
    pub roots: Vec<String>,
}

impl Group {
    /// The `let` lines, `let name = text`.
    pub fn let_lines(&self) -> impl Iterator<Item = String> + '_ {
        self.lets.iter().map(|(n, t)| format!("let {n} = {t}"))
    }
}

/// Prints `roots` with shared subexpressions hoisted; `taken` lists further names the `let`
/// names must avoid (state and parameter names are always avoided).
pub fn to_infix_group(
    store: &ExprStore,
    roots: &[ExprId],
    states: &[String],
    params: &[String],
    taken: &[String],
) -> Group {
    let mut p = Printer::new(store, states, params);
    p.taken.extend(states.iter().chain(params).chain(taken).cloned());
    p.build(roots, true);
    let roots = roots.iter().map(|&r| p.wrap(r, P_SELECT)).collect();
    Group { lets: p.lets, roots }
}

/// Formats a constant: integers without a fraction, others in Rust's shortest round-trip form.
pub fn format_number(v: f64) -> String {
    if v == v.trunc() && v.abs() < 1e15 {
        format!("{v}")
    } else {
        format!("{v:?}")
    }
}

struct Printer<'a> {
    store: &'a ExprStore,
    states: &'a [String],
    params: &'a [String],
    /// Text and binding strength of each built node.
    memo: HashMap<ExprId, (String, u8)>,
    /// Hoisted nodes and their `let` names.
    bound: HashMap<ExprId, String>,
    lets: Vec<(String, String)>,
    /// Names a hoisted `let` must avoid (filled only when hoisting).
    taken: HashSet<String>,
    /// Longest text kept for one node, in characters.
    cap: usize,
}

impl<'a> Printer<'a> {
    fn new(store: &'a ExprStore, states: &'a [String], params: &'a [String]) -> Self {
        Printer {
            store,
            states,
            params,
            memo: HashMap::new(),
            bound: HashMap::new(),
            lets: Vec::new(),
            taken: HashSet::new(),
            cap: usize::MAX,
        }
    }

    fn build(&mut self, roots: &[ExprId], hoist: bool) {
        let nodes = reachable(self.store, roots);
        let mut uses: HashMap<ExprId, usize> = HashMap::new();
        for &r in roots {
            *uses.entry(r).or_default() += 1;
        }
        for &id in &nodes {
            for c in self.store.node(id).children() {
                *uses.entry(c).or_default() += 1;
            }
        }
        for id in nodes {
            let mut rendered = self.render(id);
            if let Some((cut, _)) = rendered.0.char_indices().nth(self.cap) {
                rendered.0.truncate(cut);
                rendered.0.push_str("...");
            }
            let n_uses = uses.get(&id).copied().unwrap_or(0);
            let is_leaf = self.store.node(id).children().next().is_none();
            if hoist && !is_leaf && n_uses >= 2 {
                let name = self.fresh_name();
                let len = rendered.0.chars().count();
                let inline = n_uses * len;
                let hoisted = n_uses * name.len() + "let  = ".len() + name.len() + len + 1;
                if hoisted < inline {
                    self.lets.push((name.clone(), rendered.0.clone()));
                    self.bound.insert(id, name.clone());
                    self.taken.insert(name);
                }
            }
            self.memo.insert(id, rendered);
        }
    }

    fn fresh_name(&self) -> String {
        (1..)
            .map(|k| format!("w{}", self.lets.len() + k))
            .find(|n| !self.taken.contains(n))
            .unwrap_or_default()
    }

    /// The text of a built node and its binding strength (a hoisted node is an atom).
    fn text(&self, id: ExprId) -> (&str, u8) {
        if let Some(name) = self.bound.get(&id) {
            return (name, P_ATOM);
        }
        match self.memo.get(&id) {
            Some((t, p)) => (t, *p),
            None => ("?", P_ATOM),
        }
    }

    /// The text of `id`, parenthesised if it binds looser than `min`.
    fn wrap(&self, id: ExprId, min: u8) -> String {
        let (t, p) = self.text(id);
        if p < min {
            format!("({t})")
        } else {
            t.to_string()
        }
    }

    /// The operand of `id` if it is an unhoisted negation.
    fn negated(&self, id: ExprId) -> Option<ExprId> {
        match *self.store.node(id) {
            Node::Unary(UnaryOp::Neg, a) if !self.bound.contains_key(&id) => Some(a),
            _ => None,
        }
    }

    /// `-x` in a sum: the text of `x`, if `id` prints as a negation.
    fn subtrahend(&self, id: ExprId) -> Option<String> {
        if let Some(a) = self.negated(id) {
            return Some(self.wrap(a, P_PRODUCT));
        }
        match self.store.const_value(id) {
            Some(v) if v < 0.0 && !self.bound.contains_key(&id) => Some(format_number(-v)),
            _ => None,
        }
    }

    fn is_constant_factor(&self, id: ExprId) -> bool {
        self.store.const_value(id).is_some() && !self.bound.contains_key(&id)
    }

    fn render(&self, id: ExprId) -> (String, u8) {
        match *self.store.node(id) {
            Node::Const(bits) => {
                let v = f64::from_bits(bits);
                let p = if v.is_sign_negative() { P_NEG } else { P_ATOM };
                (format_number(v), p)
            }
            Node::State(i) => (name_or(self.states, i, "x"), P_ATOM),
            Node::Param(i) => (name_or(self.params, i, "p"), P_ATOM),
            Node::Time => ("t".to_string(), P_ATOM),
            Node::Unary(UnaryOp::Neg, a) => {
                // `-a * b` stays a product; anything looser than a product gets parentheses.
                let (_, pa) = self.text(a);
                let (min, mut p) = if pa == P_PRODUCT { (P_PRODUCT, P_PRODUCT) } else { (P_NEG, P_NEG) };
                let mut inner = self.wrap(a, min);
                if inner.starts_with('-') {
                    inner = format!("({inner})");
                    p = P_NEG;
                }
                (format!("-{inner}"), p)
            }
            Node::Unary(UnaryOp::Not, a) => (format!("not {}", self.wrap(a, P_NOT)), P_NOT),
            Node::Unary(op, a) => (format!("{}({})", unary_name(op), self.wrap(a, 0)), P_ATOM),
            Node::Binary(op, a, b) => self.render_binary(op, a, b),
            Node::Select(c, a, b) => (
                format!("if {} then {} else {}", self.wrap(c, 0), self.wrap(a, 0), self.wrap(b, 0)),
                P_SELECT,
            ),
        }
    }

    fn render_binary(&self, op: BinaryOp, a: ExprId, b: ExprId) -> (String, u8) {
        let infix = |sym: &str, p: u8, left: u8, right: u8| {
            (format!("{} {sym} {}", self.wrap(a, left), self.wrap(b, right)), p)
        };
        match op {
            BinaryOp::Add => {
                if let Some(rhs) = self.subtrahend(b) {
                    (format!("{} - {rhs}", self.wrap(a, P_SUM)), P_SUM)
                } else if let Some(rhs) = self.subtrahend(a) {
                    // `-a + b` reads better as `b - a`; addition commutes exactly.
                    (format!("{} - {rhs}", self.wrap(b, P_SUM)), P_SUM)
                } else {
                    infix("+", P_SUM, P_SUM, P_PRODUCT)
                }
            }
            BinaryOp::Mul if self.is_constant_factor(b) && !self.is_constant_factor(a) => {
                // Coefficients read first (`2 * x`); multiplication commutes exactly.
                let text = format!("{} * {}", self.wrap(b, P_PRODUCT), self.wrap(a, P_NEG));
                (text, P_PRODUCT)
            }
            BinaryOp::Mul => infix("*", P_PRODUCT, P_PRODUCT, P_NEG),
            BinaryOp::Div => infix("/", P_PRODUCT, P_PRODUCT, P_NEG),
            BinaryOp::Pow => (format!("{}^{}", self.wrap(a, P_ATOM), self.wrap(b, P_POW)), P_POW),
            BinaryOp::Lt => infix("<", P_CMP, P_SUM, P_SUM),
            BinaryOp::Le => infix("<=", P_CMP, P_SUM, P_SUM),
            BinaryOp::And => infix("and", P_AND, P_AND, P_NOT),
            BinaryOp::Or => infix("or", P_OR, P_OR, P_AND),
            BinaryOp::Atan2 | BinaryOp::Hypot | BinaryOp::Min | BinaryOp::Max => {
                let name = match op {
                    BinaryOp::Atan2 => "atan2",
                    BinaryOp::Hypot => "hypot",
                    BinaryOp::Min => "min",
                    _ => "max",
                };
                (format!("{name}({}, {})", self.wrap(a, 0), self.wrap(b, 0)), P_ATOM)
            }
        }
    }
}

fn name_or(names: &[String], i: u32, prefix: &str) -> String {
    names.get(i as usize).cloned().unwrap_or_else(|| format!("{prefix}{i}"))
}

/// The `.hyb` function name of a unary op (`Neg` and `Not` print as operators).
pub fn unary_name(op: UnaryOp) -> &'static str {
    match op {
        UnaryOp::Neg => "-",
        UnaryOp::Sin => "sin",
        UnaryOp::Cos => "cos",
        UnaryOp::Tan => "tan",
        UnaryOp::Asin => "asin",
        UnaryOp::Acos => "acos",
        UnaryOp::Atan => "atan",
        UnaryOp::Sinh => "sinh",
        UnaryOp::Cosh => "cosh",
        UnaryOp::Tanh => "tanh",
        UnaryOp::Exp => "exp",
        UnaryOp::Log => "log",
        UnaryOp::Sqrt => "sqrt",
        UnaryOp::Abs => "abs",
        UnaryOp::Sign => "sign",
        UnaryOp::Not => "not",
    }
}
