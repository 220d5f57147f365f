//! Stage 3: infix text of expressions, for `hybc derive` and snapshots. Knows no spans, no IO and
//! no Cranelift; state and parameter names are passed in.
//!
//! The text uses the `.hyb` expression syntax with as few parentheses as keep the tree: `^` is
//! right-associative and binds tighter than unary minus (`-x^2` is `-(x^2)`), `*` and `/` are
//! left-associative, `a + (-b)` prints as `a - b`, a select prints as `if c then a else b`.
//! `-a * b` is printed for `-(a * b)`; the parser reads it as `(-a) * b`, which has the same value
//! in IEEE arithmetic. Comparisons, `and`, `or`, `not` print as in conditions. A lookup prints as
//! `pwl(u @ s)`, `pwc(u @ s)` or `pwl_slope(u @ s)`: the vector read at knot position `s`. A sum
//! of every element of a vector parameter in order (`u[0]`, `u[1]`, ... named so by the caller)
//! prints as `sum(u)`, and of their products with another vector's as `dot(u, w)`: the forms the
//! checker expands.
//!
//! Nodes are laid out bottom-up in id order as pieces (literal text and children), and texts are
//! composed only when written, so printing is linear in the size of the DAG and of the printed
//! text: a chain of `n` nested nodes is not `n` texts of up to `n` pieces each.

use std::collections::{HashMap, HashSet};

use super::eval::reachable;
use super::node::{BinaryOp, ExprId, LookupKind, Node, UnaryOp};
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

/// One piece of a node's text: literal text, or a child's text with parentheses if it binds looser
/// than the given strength.
enum Piece {
    Text(String),
    Child(ExprId, u8),
}

/// How a node prints, without its text: the pieces, its binding strength, the length of its
/// text in characters and whether that text starts with `-`. Texts are composed only when written,
/// so a chain of `n` nested nodes costs `O(n)` here rather than the `O(n^2)` of a text per node.
struct Shape {
    pieces: Vec<Piece>,
    strength: u8,
    len: usize,
    starts_with_minus: bool,
}

struct Printer<'a> {
    store: &'a ExprStore,
    states: &'a [String],
    params: &'a [String],
    /// The shape of each built node.
    shapes: HashMap<ExprId, Shape>,
    /// With a cap: the capped text of each built node (at most `cap` characters and `...`).
    capped: HashMap<ExprId, String>,
    /// Hoisted nodes and their `let` names.
    bound: HashMap<ExprId, String>,
    lets: Vec<(String, String)>,
    /// Names a hoisted `let` must avoid (filled only when hoisting).
    taken: HashSet<String>,
    /// Longest text kept for one node, in characters.
    cap: usize,
    /// The built nodes that are a sum over consecutive parameters (see [`Run`]).
    runs: HashMap<ExprId, Run>,
}

/// A sum over a run of consecutive parameters: `p[a] + ... + p[a + count - 1]` (`b` is `None`),
/// or `p[a] p[b] + ... + p[a + count - 1] p[b + count - 1]` (`a < b`), in any association.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Run {
    a: u32,
    b: Option<u32>,
    count: u32,
}

impl<'a> Printer<'a> {
    fn new(store: &'a ExprStore, states: &'a [String], params: &'a [String]) -> Self {
        Printer {
            store,
            states,
            params,
            shapes: HashMap::new(),
            capped: HashMap::new(),
            bound: HashMap::new(),
            lets: Vec::new(),
            taken: HashSet::new(),
            cap: usize::MAX,
            runs: HashMap::new(),
        }
    }

    /// The run `id` sums, from its children's (built before it).
    fn run_of(&self, id: ExprId) -> Option<Run> {
        match *self.store.node(id) {
            Node::Param(i) => Some(Run { a: i, b: None, count: 1 }),
            Node::Binary(BinaryOp::Mul, x, y) => match (*self.store.node(x), *self.store.node(y)) {
                (Node::Param(i), Node::Param(j)) if i != j => {
                    Some(Run { a: i.min(j), b: Some(i.max(j)), count: 1 })
                }
                _ => None,
            },
            Node::Binary(BinaryOp::Add, x, y) => {
                let (l, r) = (*self.runs.get(&x)?, *self.runs.get(&y)?);
                let follows = |l: Run, r: Run| {
                    l.a.checked_add(l.count) == Some(r.a)
                        && match (l.b, r.b) {
                            (None, None) => true,
                            (Some(lb), Some(rb)) => lb.checked_add(l.count) == Some(rb),
                            _ => false,
                        }
                };
                let (first, second) = if follows(l, r) {
                    (l, r)
                } else if follows(r, l) {
                    (r, l)
                } else {
                    return None;
                };
                Some(Run { count: first.count + second.count, ..first })
            }
            _ => None,
        }
    }

    /// The name of the vector whose elements are exactly the parameters `first .. first + count`
    /// (named `v[0]` .. `v[count-1]`, and no `v[count]` after them).
    fn whole_vector(&self, first: u32, count: u32) -> Option<String> {
        let name = |i: u32| self.params.get(i as usize).map(String::as_str);
        let vector = name(first)?.strip_suffix("[0]")?;
        let last = first.checked_add(count - 1)?;
        let whole = name(last) == Some(format!("{vector}[{}]", count - 1).as_str())
            && name(last + 1) != Some(format!("{vector}[{count}]").as_str());
        whole.then(|| vector.to_string())
    }

    fn is_capped(&self) -> bool {
        self.cap != usize::MAX
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
            if let Some(run) = self.run_of(id) {
                self.runs.insert(id, run);
            }
            let mut shape = self.shape(id);
            if self.is_capped() {
                // Capped texts are short, so each is kept and composed from its children's.
                let mut text = String::new();
                self.write_pieces(&shape.pieces, &mut text);
                if let Some((cut, _)) = text.char_indices().nth(self.cap) {
                    text.truncate(cut);
                    text.push_str("...");
                }
                shape.starts_with_minus = text.starts_with('-');
                self.capped.insert(id, text);
            }
            let n_uses = uses.get(&id).copied().unwrap_or(0);
            let is_leaf = self.store.node(id).children().next().is_none();
            if hoist && !is_leaf && n_uses >= 2 {
                let name = self.fresh_name();
                let len = shape.len;
                let inline = n_uses.saturating_mul(len);
                let hoisted = (n_uses * name.len() + "let  = ".len() + name.len() + 1).saturating_add(len);
                if hoisted < inline {
                    let mut text = String::new();
                    self.write_pieces(&shape.pieces, &mut text);
                    self.lets.push((name.clone(), text));
                    self.bound.insert(id, name.clone());
                    self.taken.insert(name);
                }
            }
            self.shapes.insert(id, shape);
        }
    }

    fn fresh_name(&self) -> String {
        (1..)
            .map(|k| format!("w{}", self.lets.len() + k))
            .find(|n| !self.taken.contains(n))
            .unwrap_or_default()
    }

    /// The binding strength of a built node (a hoisted node is an atom).
    fn strength(&self, id: ExprId) -> u8 {
        if self.bound.contains_key(&id) {
            return P_ATOM;
        }
        self.shapes.get(&id).map_or(P_ATOM, |s| s.strength)
    }

    /// Whether `id` printed at binding `min` gets parentheses.
    fn is_wrapped(&self, id: ExprId, min: u8) -> bool {
        self.strength(id) < min
    }

    /// Length in characters of `id` printed at binding `min`.
    fn wrapped_len(&self, id: ExprId, min: u8) -> usize {
        let len = match self.bound.get(&id) {
            Some(name) => name.chars().count(),
            None => self.shapes.get(&id).map_or(1, |s| s.len),
        };
        if self.is_wrapped(id, min) {
            len.saturating_add(2)
        } else {
            len
        }
    }

    /// Whether the text of `id` printed at binding `min` starts with `-`.
    fn wrapped_starts_with_minus(&self, id: ExprId, min: u8) -> bool {
        !self.is_wrapped(id, min)
            && !self.bound.contains_key(&id)
            && self.shapes.get(&id).is_some_and(|s| s.starts_with_minus)
    }

    /// The text of `id` (a root: never parenthesised).
    fn wrap(&self, id: ExprId, min: u8) -> String {
        let mut out = String::new();
        self.write_pieces(&[Piece::Child(id, min)], &mut out);
        out
    }

    /// Appends the text of `pieces` to `out`. Children's texts are written in place, with a work
    /// list rather than recursion (a chain of `let`s nests as deep as it is long); with a cap,
    /// children's capped texts are copied.
    fn write_pieces<'s>(&'s self, pieces: &'s [Piece], out: &mut String) {
        enum Work<'p> {
            Text(&'p str),
            Child(ExprId, u8),
        }
        let mut work: Vec<Work<'s>> = Vec::new();
        for piece in pieces.iter().rev() {
            match piece {
                Piece::Text(t) => work.push(Work::Text(t)),
                Piece::Child(id, min) => work.push(Work::Child(*id, *min)),
            }
        }
        while let Some(w) = work.pop() {
            let (id, min) = match w {
                Work::Text(t) => {
                    out.push_str(t);
                    continue;
                }
                Work::Child(id, min) => (id, min),
            };
            let wrapped = self.is_wrapped(id, min);
            if wrapped {
                out.push('(');
            }
            if let Some(name) = self.bound.get(&id) {
                out.push_str(name);
            } else if let Some(text) = self.capped.get(&id) {
                out.push_str(text);
            } else if let Some(shape) = self.shapes.get(&id) {
                if wrapped {
                    work.push(Work::Text(")"));
                }
                for piece in shape.pieces.iter().rev() {
                    work.push(match piece {
                        Piece::Text(t) => Work::Text(t),
                        Piece::Child(c, m) => Work::Child(*c, *m),
                    });
                }
                continue;
            } else {
                out.push('?');
            }
            if wrapped {
                out.push(')');
            }
        }
    }

    /// The operand of `id` if it is an unhoisted negation.
    fn negated(&self, id: ExprId) -> Option<ExprId> {
        match *self.store.node(id) {
            Node::Unary(UnaryOp::Neg, a) if !self.bound.contains_key(&id) => Some(a),
            _ => None,
        }
    }

    /// `-x` in a sum: the pieces of `x`, if `id` prints as a negation.
    fn subtrahend(&self, id: ExprId) -> Option<Piece> {
        if let Some(a) = self.negated(id) {
            return Some(Piece::Child(a, P_PRODUCT));
        }
        match self.store.const_value(id) {
            Some(v) if v < 0.0 && !self.bound.contains_key(&id) => Some(Piece::Text(format_number(-v))),
            _ => None,
        }
    }

    fn is_constant_factor(&self, id: ExprId) -> bool {
        self.store.const_value(id).is_some() && !self.bound.contains_key(&id)
    }

    /// The shape of `id`, its children built.
    fn shape(&self, id: ExprId) -> Shape {
        let (pieces, strength) = self.pieces(id);
        let piece_len = |p: &Piece| match p {
            Piece::Text(t) => t.chars().count(),
            Piece::Child(c, min) => self.wrapped_len(*c, *min),
        };
        let len = pieces.iter().fold(0usize, |sum, p| sum.saturating_add(piece_len(p)));
        let starts_with_minus = match pieces.first() {
            Some(Piece::Text(t)) => t.starts_with('-'),
            Some(Piece::Child(c, min)) => self.wrapped_starts_with_minus(*c, *min),
            None => false,
        };
        Shape { pieces, strength, len, starts_with_minus }
    }

    fn pieces(&self, id: ExprId) -> (Vec<Piece>, u8) {
        use Piece::{Child, Text};
        let text = |t: &str| Text(t.to_string());
        match *self.store.node(id) {
            Node::Const(bits) => {
                let v = f64::from_bits(bits);
                let p = if v.is_sign_negative() { P_NEG } else { P_ATOM };
                (vec![Text(format_number(v))], p)
            }
            Node::State(i) => (vec![Text(name_or(self.states, i, "x"))], P_ATOM),
            Node::Param(i) => (vec![Text(name_or(self.params, i, "p"))], P_ATOM),
            Node::Time => (vec![text("t")], P_ATOM),
            Node::Unary(UnaryOp::Neg, a) => {
                // `-a * b` stays a product; anything looser than a product gets parentheses.
                let (min, p) =
                    if self.strength(a) == P_PRODUCT { (P_PRODUCT, P_PRODUCT) } else { (P_NEG, P_NEG) };
                if self.wrapped_starts_with_minus(a, min) {
                    (vec![text("-("), Child(a, min), text(")")], P_NEG)
                } else {
                    (vec![text("-"), Child(a, min)], p)
                }
            }
            Node::Unary(UnaryOp::Not, a) => (vec![text("not "), Child(a, P_NOT)], P_NOT),
            Node::Unary(op, a) => {
                (vec![Text(format!("{}(", unary_name(op))), Child(a, 0), text(")")], P_ATOM)
            }
            Node::Binary(BinaryOp::Add, ..) if self.vector_sum(id).is_some() => {
                (vec![Text(self.vector_sum(id).unwrap_or_default())], P_ATOM)
            }
            Node::Binary(op, a, b) => self.binary_pieces(op, a, b),
            Node::Lookup(l, pos) => {
                let func = match l.kind {
                    LookupKind::Pwl => "pwl",
                    LookupKind::Pwc => "pwc",
                    LookupKind::PwlSlope => "pwl_slope",
                };
                // The vector's name is its first element's without the index.
                let first = name_or(self.params, l.base, "p");
                let vector = first.strip_suffix("[0]").unwrap_or(&first).to_string();
                (vec![Text(format!("{func}({vector} @ ")), Child(pos, 0), text(")")], P_ATOM)
            }
            Node::Select(c, a, b) => (
                vec![text("if "), Child(c, 0), text(" then "), Child(a, 0), text(" else "), Child(b, 0)],
                P_SELECT,
            ),
        }
    }

    /// `sum(u)` or `dot(u, w)` if `id` sums every element of whole vectors.
    fn vector_sum(&self, id: ExprId) -> Option<String> {
        let run = self.runs.get(&id)?;
        let u = self.whole_vector(run.a, run.count)?;
        match run.b {
            None => Some(format!("sum({u})")),
            Some(b) => Some(format!("dot({u}, {})", self.whole_vector(b, run.count)?)),
        }
    }

    fn binary_pieces(&self, op: BinaryOp, a: ExprId, b: ExprId) -> (Vec<Piece>, u8) {
        use Piece::{Child, Text};
        let infix = |sym: &str, p: u8, left: u8, right: u8| {
            (vec![Child(a, left), Text(format!(" {sym} ")), Child(b, right)], p)
        };
        match op {
            BinaryOp::Add => {
                if let Some(rhs) = self.subtrahend(b) {
                    (vec![Child(a, P_SUM), Text(" - ".to_string()), rhs], P_SUM)
                } else if let Some(rhs) = self.subtrahend(a) {
                    // `-a + b` reads better as `b - a`; addition commutes exactly.
                    (vec![Child(b, P_SUM), Text(" - ".to_string()), rhs], P_SUM)
                } else {
                    infix("+", P_SUM, P_SUM, P_PRODUCT)
                }
            }
            BinaryOp::Mul if self.is_constant_factor(b) && !self.is_constant_factor(a) => {
                // Coefficients read first (`2 * x`); multiplication commutes exactly.
                (vec![Child(b, P_PRODUCT), Text(" * ".to_string()), Child(a, P_NEG)], P_PRODUCT)
            }
            BinaryOp::Mul => infix("*", P_PRODUCT, P_PRODUCT, P_NEG),
            BinaryOp::Div => infix("/", P_PRODUCT, P_PRODUCT, P_NEG),
            BinaryOp::Pow => (vec![Child(a, P_ATOM), Text("^".to_string()), Child(b, P_POW)], P_POW),
            BinaryOp::Lt => infix("<", P_CMP, P_SUM, P_SUM),
            BinaryOp::Le => infix("<=", P_CMP, P_SUM, P_SUM),
            BinaryOp::And => infix("and", P_AND, P_AND, P_NOT),
            BinaryOp::Or => infix("or", P_OR, P_OR, P_AND),
            BinaryOp::Atan2 | BinaryOp::Hypot | BinaryOp::Min | BinaryOp::Max | BinaryOp::PowLog => {
                let name = match op {
                    BinaryOp::Atan2 => "atan2",
                    BinaryOp::Hypot => "hypot",
                    BinaryOp::PowLog => "pow_log",
                    BinaryOp::Min => "min",
                    _ => "max",
                };
                let open = Text(format!("{name}("));
                (vec![open, Child(a, 0), Text(", ".to_string()), Child(b, 0), Text(")".to_string())], P_ATOM)
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
