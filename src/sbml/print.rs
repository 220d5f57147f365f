//! [`Math`] -> `.hyb` expression text: hybc's precedence (so parentheses only where needed), the
//! functions it has (others written out: `sec(x)` as `1 / cos(x)`, `arcsinh` by its logarithm),
//! truth values as conditions (`if C then 1 else 0` where a number is meant), and the text's
//! limits kept: a subexpression longer than [`MAX_TEXT`] characters or nested deeper than
//! [`MAX_PARENS`] parentheses is hoisted into a `let` (hybc reads lines of at most 4096
//! characters and 64 levels of parentheses).

use super::math::{Math, Op};

/// Longest text kept inline; longer subexpressions become `let`s.
pub(super) const MAX_TEXT: usize = 1500;
/// Deepest parentheses kept inline.
const MAX_PARENS: u32 = 40;

const ADD: u8 = 1;
const MUL: u8 = 2;
const NEG: u8 = 3;
const POW: u8 = 4;
const ATOM: u8 = 5;

const OR: u8 = 1;
const AND: u8 = 2;
const NOT: u8 = 3;
const CATOM: u8 = 4;

/// Printed text with its precedence and its depth of parentheses.
#[derive(Clone, Debug)]
pub(super) struct Text {
    /// The text.
    pub s: String,
    prec: u8,
    depth: u32,
}

impl Text {
    fn atom(s: String) -> Text {
        Text { s, prec: ATOM, depth: 0 }
    }
}

/// What names mean where an expression is printed, and where hoisted `let`s go.
pub(super) trait Scope {
    /// The `.hyb` name for the SBML id `id`, or why it cannot be read here.
    fn name(&mut self, id: &str) -> Result<String, String>;
    /// The text of the time (`t`; the start time where initial values are computed).
    fn time(&mut self) -> Result<String, String>;
    /// The text of `rateOf(id)`.
    fn rate_of(&mut self, id: &str) -> Result<String, String>;
    /// Declares `let NAME = text` and returns NAME.
    fn hoist(&mut self, text: String) -> String;
}

/// The number `x` as hybc reads it back bit for bit (Rust's shortest round trip), or a refusal
/// for a value hybc has no literal for.
pub(super) fn number(x: f64) -> Result<Text, String> {
    if x.is_nan() {
        return Err("a NaN (`notanumber`) in math: hybc has no literal for it".to_string());
    }
    if x.is_infinite() {
        // No literal: the product overflows to infinity, as SBML's `INF` means.
        let s = if x > 0.0 { "1e300 * 1e300" } else { "-1e300 * 1e300" };
        return Ok(Text { s: s.to_string(), prec: MUL, depth: 0 });
    }
    let s = format!("{x:?}");
    let s = s.strip_suffix(".0").map_or(s.clone(), str::to_string);
    if x < 0.0 || s.starts_with('-') {
        Ok(Text { s, prec: NEG, depth: 0 })
    } else {
        Ok(Text::atom(s))
    }
}

fn paren(t: Text) -> Text {
    Text { s: format!("({})", t.s), prec: ATOM, depth: t.depth + 1 }
}

/// `t` parenthesised unless its precedence is at least `min`.
fn at_least(t: Text, min: u8) -> Text {
    if t.prec >= min {
        t
    } else {
        paren(t)
    }
}

fn call(name: &str, args: Vec<Text>) -> Text {
    let depth = args.iter().map(|a| a.depth).max().unwrap_or(0) + 1;
    let s = format!("{name}({})", args.into_iter().map(|a| a.s).collect::<Vec<_>>().join(", "));
    Text { s, prec: ATOM, depth }
}

/// Keeps `t` within the text limits, hoisting it into a `let` when it is over them.
fn limit(t: Text, scope: &mut dyn Scope) -> Text {
    if t.s.len() > MAX_TEXT || t.depth > MAX_PARENS {
        Text::atom(scope.hoist(t.s))
    } else {
        t
    }
}

fn binary(a: Text, op: &str, b: Text, prec: u8) -> Text {
    Text { s: format!("{} {op} {}", a.s, b.s), prec, depth: a.depth.max(b.depth) }
}

/// An n-ary `+` or `*` written left to right; a long chain is cut into `let`s as it grows.
fn chain(args: Vec<Text>, op: &str, prec: u8, scope: &mut dyn Scope) -> Text {
    let mut acc: Option<Text> = None;
    for a in args {
        let a = limit(at_least(a, if op == "*" { NEG } else { prec }), scope);
        acc = Some(match acc {
            None => a,
            Some(acc) => {
                let acc =
                    if acc.s.len() + a.s.len() > MAX_TEXT { Text::atom(scope.hoist(acc.s)) } else { acc };
                binary(acc, op, a, prec)
            }
        });
    }
    acc.expect("a chain of at least one term")
}

/// The numeric text of `m`.
pub(super) fn num(m: &Math, scope: &mut dyn Scope) -> Result<Text, String> {
    let t = num_inner(m, scope)?;
    Ok(limit(t, scope))
}

fn num_inner(m: &Math, scope: &mut dyn Scope) -> Result<Text, String> {
    match m {
        Math::Num(x) => number(*x),
        Math::Bool(b) => Ok(Text::atom(if *b { "1" } else { "0" }.to_string())),
        Math::Ci(id) => Ok(Text::atom(scope.name(id)?)),
        Math::Time => Ok(Text::atom(scope.time()?)),
        Math::RateOf(id) => Ok(Text::atom(scope.rate_of(id)?)),
        Math::Call(name, _, _) => Err(format!("no function definition `{name}`")),
        Math::Piecewise(pieces, otherwise) => {
            let Some(otherwise) = otherwise else {
                return Err("a <piecewise> without <otherwise> has no value where no piece holds".to_string());
            };
            let mut text = num(otherwise, scope)?;
            for (v, c) in pieces.iter().rev() {
                let c = cond(c, scope)?;
                let v = num(v, scope)?;
                let depth = c.depth.max(v.depth).max(text.depth);
                text = Text { s: format!("if {} then {} else {}", c.s, v.s, text.s), prec: 0, depth };
                text = limit(paren(text), scope);
            }
            Ok(text)
        }
        Math::Apply(op, args, _) => apply(*op, args, scope),
    }
}

fn apply(op: Op, args: &[Math], scope: &mut dyn Scope) -> Result<Text, String> {
    use Op::*;
    if op.is_boolean() {
        let c = cond(&Math::Apply(op, args.to_vec(), 0), scope)?;
        let depth = c.depth;
        return Ok(Text { s: format!("(if {} then 1 else 0)", c.s), prec: ATOM, depth: depth + 1 });
    }
    let mut a: Vec<Text> = Vec::with_capacity(args.len());
    for x in args {
        a.push(num(x, scope)?);
    }
    let f = |name: &str, a: Vec<Text>| call(name, a);
    let one = |a: Vec<Text>| a.into_iter().next().expect("arity checked");
    // 1 / f(x), for the reciprocal functions.
    let recip = |name: &str, a: Vec<Text>| binary(Text::atom("1".into()), "/", call(name, a), MUL);
    let inv = |a: Vec<Text>| binary(Text::atom("1".into()), "/", at_least(one(a), NEG), MUL);
    Ok(match op {
        Plus if a.is_empty() => Text::atom("0".into()),
        Times if a.is_empty() => Text::atom("1".into()),
        Plus => chain(a, "+", ADD, scope),
        Times => chain(a, "*", MUL, scope),
        Minus if a.len() == 1 => {
            let x = one(a);
            Text { s: format!("-{}", at_least(x.clone(), NEG).s), prec: NEG, depth: at_least(x, NEG).depth }
        }
        Minus => {
            let mut it = a.into_iter();
            let (x, y) = (it.next().expect("two"), it.next().expect("two"));
            binary(at_least(x, ADD), "-", at_least(y, MUL), ADD)
        }
        Divide => {
            let mut it = a.into_iter();
            let (x, y) = (it.next().expect("two"), it.next().expect("two"));
            binary(at_least(x, NEG), "/", at_least(y, NEG.max(MUL + 1)), MUL)
        }
        Power => {
            let mut it = a.into_iter();
            let (x, y) = (it.next().expect("two"), it.next().expect("two"));
            binary(at_least(x, ATOM), "^", at_least(y, POW), POW)
        }
        Abs => f("abs", a),
        Exp => f("exp", a),
        Ln => f("log", a),
        Sin => f("sin", a),
        Cos => f("cos", a),
        Tan => f("tan", a),
        Sinh => f("sinh", a),
        Cosh => f("cosh", a),
        Tanh => f("tanh", a),
        Arcsin => f("asin", a),
        Arccos => f("acos", a),
        Arctan => f("atan", a),
        Sec => recip("cos", a),
        Csc => recip("sin", a),
        Cot => recip("tan", a),
        Sech => recip("cosh", a),
        Csch => recip("sinh", a),
        Coth => recip("tanh", a),
        Arcsec => call("acos", vec![inv(a)]),
        Arccsc => call("asin", vec![inv(a)]),
        Arccot => call("atan", vec![inv(a)]),
        Arcsinh => arcsinh(one(a)),
        Arccosh => arccosh(one(a)),
        Arctanh => arctanh(one(a)),
        Arcsech => arccosh(inv(a)),
        Arccsch => arcsinh(inv(a)),
        Arccoth => arctanh(inv(a)),
        Max | Min if a.is_empty() => return Err(format!("<{}> without arguments", op.name())),
        Max | Min => {
            let name = if op == Max { "max" } else { "min" };
            let mut it = a.into_iter().rev();
            let mut acc = it.next().expect("one");
            for x in it {
                acc = limit(call(name, vec![x, acc]), scope);
            }
            acc
        }
        Floor | Ceiling | Factorial | Quotient | Rem => {
            return Err(format!(
                "`{}` of an expression that can change: hybc's language has no such function (a jump in a flow is an `if`)",
                op.name()
            ))
        }
        Eq | Neq | Gt | Lt | Geq | Leq | And | Or | Xor | Not | Implies => unreachable!("booleans handled above"),
    })
}

/// `log(x + sqrt(x^2 + 1))`.
fn arcsinh(x: Text) -> Text {
    let x = at_least(x, ATOM);
    Text::atom(format!("log({0} + sqrt({0} ^ 2 + 1))", x.s)).with_depth(x.depth + 2)
}

/// `log(x + sqrt(x^2 - 1))`.
fn arccosh(x: Text) -> Text {
    let x = at_least(x, ATOM);
    Text::atom(format!("log({0} + sqrt({0} ^ 2 - 1))", x.s)).with_depth(x.depth + 2)
}

/// `0.5 * log((1 + x) / (1 - x))`.
fn arctanh(x: Text) -> Text {
    let x = at_least(x, MUL);
    Text { s: format!("0.5 * log((1 + {0}) / (1 - {0}))", x.s), prec: MUL, depth: x.depth + 2 }
}

impl Text {
    fn with_depth(mut self, depth: u32) -> Text {
        self.depth = depth;
        self
    }
}

/// The condition text of `m` (a number used as a truth value is true when not 0).
pub(super) fn cond(m: &Math, scope: &mut dyn Scope) -> Result<Text, String> {
    use Op::*;
    let ctext = |s: String, prec: u8, depth: u32| Ok(Text { s, prec, depth });
    match m {
        // hybc has no truth literals: a comparison that always holds (or never does).
        Math::Bool(true) => ctext("0 < 1".into(), CATOM, 0),
        Math::Bool(false) => ctext("1 < 0".into(), CATOM, 0),
        Math::Apply(op, args, at) if op.is_boolean() => match op {
            Gt | Lt | Geq | Leq | Eq | Neq => {
                let x = num(&args[0], scope)?;
                let y = num(&args[1], scope)?;
                let depth = x.depth.max(y.depth);
                let s = match op {
                    Gt => format!("{} > {}", x.s, y.s),
                    Lt => format!("{} < {}", x.s, y.s),
                    Geq => format!("{} >= {}", x.s, y.s),
                    Leq => format!("{} <= {}", x.s, y.s),
                    Eq => format!("({0} <= {1} and {0} >= {1})", x.s, y.s),
                    _ => format!("({0} < {1} or {0} > {1})", x.s, y.s),
                };
                ctext(s, CATOM, depth + u32::from(matches!(op, Eq | Neq)))
            }
            And | Or if args.is_empty() => cond(&Math::Bool(*op == And), scope),
            And | Or => {
                let (word, prec) = if *op == And { ("and", AND) } else { ("or", OR) };
                let mut parts = Vec::new();
                let mut depth = 0;
                for a in args {
                    let c = cond_at_least(cond(a, scope)?, prec);
                    depth = depth.max(c.depth);
                    parts.push(c.s);
                }
                ctext(parts.join(&format!(" {word} ")), prec, depth)
            }
            Not => {
                let c = cond_at_least(cond(&args[0], scope)?, NOT);
                ctext(format!("not {}", c.s), NOT, c.depth)
            }
            Implies => cond(
                &Math::Apply(Or, vec![Math::Apply(Not, vec![args[0].clone()], *at), args[1].clone()], *at),
                scope,
            ),
            Xor if args.is_empty() => cond(&Math::Bool(false), scope),
            Xor => {
                // Left to right: xor(a, b, c) = xor(xor(a, b), c).
                let mut acc = args[0].clone();
                for b in &args[1..] {
                    let not = |m: &Math| Math::Apply(Not, vec![m.clone()], *at);
                    acc = Math::Apply(
                        Or,
                        vec![
                            Math::Apply(And, vec![acc.clone(), not(b)], *at),
                            Math::Apply(And, vec![not(&acc), b.clone()], *at),
                        ],
                        *at,
                    );
                }
                cond(&acc, scope)
            }
            _ => unreachable!("relational and logical operators only"),
        },
        Math::Piecewise(pieces, otherwise) => {
            // (c1 and v1) or (not c1 and c2 and v2) or ... (not c1 and ... and otherwise).
            let mut terms = Vec::new();
            let mut before: Vec<Math> = Vec::new();
            let not = |m: &Math| Math::Apply(Not, vec![m.clone()], 0);
            for (v, c) in pieces {
                let mut all = before.clone();
                all.push(c.clone());
                all.push(v.clone());
                terms.push(Math::Apply(And, all, 0));
                before.push(not(c));
            }
            match otherwise {
                Some(o) => {
                    before.push((**o).clone());
                    terms.push(Math::Apply(And, before, 0));
                }
                None => {
                    return Err(
                        "a <piecewise> without <otherwise> has no value where no piece holds".to_string()
                    )
                }
            }
            cond(&Math::Apply(Or, terms, 0), scope)
        }
        other => {
            let x = num(other, scope)?;
            let depth = x.depth + 1;
            ctext(format!("({0} < 0 or {0} > 0)", x.s), CATOM, depth)
        }
    }
}

fn cond_at_least(t: Text, min: u8) -> Text {
    if t.prec >= min {
        t
    } else {
        Text { s: format!("({})", t.s), prec: CATOM, depth: t.depth + 1 }
    }
}
