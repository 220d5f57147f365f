//! Test helper: a tiny s-expression reader that builds expressions with the simplifying
//! constructors, so rule tables stay one line each. `x`, `y` are states 0, 1; `p`, `q` are
//! parameters 0, 1; `t` is time. Operators: `+ * / ^ -` (unary or binary), `< <= > >= and or
//! not if`, and every function name.

use hybc::expr::{BinaryOp, ExprId, ExprStore, UnaryOp};

pub fn states() -> Vec<String> {
    vec!["x".into(), "y".into()]
}

pub fn params() -> Vec<String> {
    vec!["p".into(), "q".into()]
}

pub fn read(store: &mut ExprStore, src: &str) -> ExprId {
    let tokens: Vec<String> =
        src.replace('(', " ( ").replace(')', " ) ").split_whitespace().map(String::from).collect();
    let mut pos = 0;
    let id = parse(store, &tokens, &mut pos);
    assert_eq!(pos, tokens.len(), "trailing tokens in `{src}`");
    id
}

fn parse(s: &mut ExprStore, tokens: &[String], pos: &mut usize) -> ExprId {
    let tok = tokens[*pos].as_str();
    *pos += 1;
    if tok != "(" {
        return match tok {
            "x" => s.state(0),
            "y" => s.state(1),
            "p" => s.param(0),
            "q" => s.param(1),
            "t" => s.time(),
            num => s.constant(num.parse().unwrap_or_else(|_| panic!("bad atom `{num}`"))),
        };
    }
    let head = tokens[*pos].clone();
    *pos += 1;
    let mut args = Vec::new();
    while tokens[*pos] != ")" {
        args.push(parse(s, tokens, pos));
    }
    *pos += 1;
    let unary = |op| (op, args[0]);
    match (head.as_str(), args.len()) {
        ("-", 1) => s.neg(args[0]),
        ("-", 2) => s.sub(args[0], args[1]),
        ("+", 2) => s.add(args[0], args[1]),
        ("*", 2) => s.mul(args[0], args[1]),
        ("/", 2) => s.div(args[0], args[1]),
        ("^", 2) => s.pow(args[0], args[1]),
        ("<", 2) => s.lt(args[0], args[1]),
        ("<=", 2) => s.le(args[0], args[1]),
        (">", 2) => s.gt(args[0], args[1]),
        (">=", 2) => s.ge(args[0], args[1]),
        ("and", 2) => s.and(args[0], args[1]),
        ("or", 2) => s.or(args[0], args[1]),
        ("not", 1) => s.not(args[0]),
        ("if", 3) => s.select(args[0], args[1], args[2]),
        (name, 2) => {
            let op = binary_op(name).unwrap_or_else(|| panic!("unknown binary `{name}`"));
            s.binary(op, args[0], args[1])
        }
        (name, 1) => {
            let (op, a) = unary(unary_op(name).unwrap_or_else(|| panic!("unknown unary `{name}`")));
            s.unary(op, a)
        }
        (name, n) => panic!("`{name}` with {n} arguments"),
    }
}

pub fn unary_op(name: &str) -> Option<UnaryOp> {
    use UnaryOp::*;
    [Sin, Cos, Tan, Asin, Acos, Atan, Sinh, Cosh, Tanh, Exp, Log, Sqrt, Abs, Sign]
        .into_iter()
        .find(|&op| hybc::expr::display::unary_name(op) == name)
}

pub fn binary_op(name: &str) -> Option<BinaryOp> {
    match name {
        "atan2" => Some(BinaryOp::Atan2),
        "hypot" => Some(BinaryOp::Hypot),
        "min" => Some(BinaryOp::Min),
        "max" => Some(BinaryOp::Max),
        "pow" => Some(BinaryOp::Pow),
        _ => None,
    }
}

/// Whether `(t, x, p)` lies safely inside one smooth piece of every node under `root`: every
/// value finite and below `max_abs`, arguments away from kinks (abs, sign, min, max,
/// comparisons, select conditions), domain edges (log, sqrt, asin, acos, pow bases) and poles
/// (division, tan, atan2 and hypot at the origin). It looks only at the expression's own
/// values at the point, never at a derivative, so it filters inputs, not results.
pub fn is_smooth_at(s: &ExprStore, root: ExprId, t: f64, x: &[f64], p: &[f64], max_abs: f64) -> bool {
    use hybc::expr::eval::reachable;
    use hybc::expr::{Node, Tape};
    use std::collections::HashMap;
    const KINK: f64 = 1e-3;
    const POLE: f64 = 0.05;
    let nodes = reachable(s, &[root]);
    let values = Tape::new(s, &nodes).eval(t, x, p);
    let v: HashMap<ExprId, f64> = nodes.iter().copied().zip(values).collect();
    let a = |id: ExprId| v[&id];
    let is_bool = |id: ExprId| {
        matches!(s.node(id), Node::Unary(UnaryOp::Not, _))
            || matches!(
                s.node(id),
                Node::Binary(BinaryOp::Lt | BinaryOp::Le | BinaryOp::And | BinaryOp::Or, _, _)
            )
    };
    let truthy_safe = |id: ExprId| is_bool(id) || a(id).abs() > KINK;
    nodes.iter().all(|&id| {
        let val = a(id);
        if !(val.is_finite() && val.abs() < max_abs) {
            return false;
        }
        match *s.node(id) {
            Node::Unary(op, x) => match op {
                UnaryOp::Abs | UnaryOp::Sign => a(x).abs() > KINK,
                UnaryOp::Not => truthy_safe(x),
                UnaryOp::Log | UnaryOp::Sqrt => a(x) > POLE,
                UnaryOp::Asin | UnaryOp::Acos => a(x).abs() < 1.0 - POLE,
                UnaryOp::Tan => a(x).cos().abs() > POLE,
                _ => true,
            },
            Node::Binary(op, x, y) => match op {
                BinaryOp::Div => a(y).abs() > POLE,
                BinaryOp::Pow => a(x).abs() > POLE,
                BinaryOp::Atan2 | BinaryOp::Hypot => a(x).hypot(a(y)) > POLE,
                BinaryOp::Min | BinaryOp::Max | BinaryOp::Lt | BinaryOp::Le => {
                    (a(x) - a(y)).abs() > KINK * (1.0 + a(x).abs())
                }
                BinaryOp::And | BinaryOp::Or => truthy_safe(x) && truthy_safe(y),
                _ => true,
            },
            Node::Select(c, _, _) => truthy_safe(c),
            _ => true,
        }
    })
}
