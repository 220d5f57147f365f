//! MathML content markup -> [`Math`], the importer's expression tree: the subset SBML uses
//! (`apply` with its operators, `ci`, `cn`, `csymbol`, `piecewise`, constants, `lambda` for
//! function definitions), normalised on the way (`root` and `log` with a base become powers and
//! quotients of `ln`; relational chains `a < b < c` become `and`s), function calls inlined and
//! constant subtrees folded. Knows nothing of `.hyb`.

use std::collections::HashMap;

use roxmltree::Node;

use super::error::Refusal;
use super::xml::{elements, parse_f64, Xml};

/// Avogadro's number as SBML Level 3 defines its `avogadro` csymbol.
pub(super) const AVOGADRO: f64 = 6.02214179e23;

/// An operator of MathML's `apply`, after normalisation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[allow(missing_docs)]
pub(super) enum Op {
    Plus,
    Minus,
    Times,
    Divide,
    Power,
    Abs,
    Exp,
    Ln,
    Floor,
    Ceiling,
    Factorial,
    Sin,
    Cos,
    Tan,
    Sec,
    Csc,
    Cot,
    Sinh,
    Cosh,
    Tanh,
    Sech,
    Csch,
    Coth,
    Arcsin,
    Arccos,
    Arctan,
    Arcsec,
    Arccsc,
    Arccot,
    Arcsinh,
    Arccosh,
    Arctanh,
    Arcsech,
    Arccsch,
    Arccoth,
    Eq,
    Neq,
    Gt,
    Lt,
    Geq,
    Leq,
    And,
    Or,
    Xor,
    Not,
    Implies,
    Quotient,
    Rem,
    Max,
    Min,
}

impl Op {
    fn named(name: &str) -> Option<Op> {
        use Op::*;
        Some(match name {
            "plus" => Plus,
            "minus" => Minus,
            "times" => Times,
            "divide" => Divide,
            "power" => Power,
            "abs" => Abs,
            "exp" => Exp,
            "ln" => Ln,
            "floor" => Floor,
            "ceiling" => Ceiling,
            "factorial" => Factorial,
            "sin" => Sin,
            "cos" => Cos,
            "tan" => Tan,
            "sec" => Sec,
            "csc" => Csc,
            "cot" => Cot,
            "sinh" => Sinh,
            "cosh" => Cosh,
            "tanh" => Tanh,
            "sech" => Sech,
            "csch" => Csch,
            "coth" => Coth,
            "arcsin" => Arcsin,
            "arccos" => Arccos,
            "arctan" => Arctan,
            "arcsec" => Arcsec,
            "arccsc" => Arccsc,
            "arccot" => Arccot,
            "arcsinh" => Arcsinh,
            "arccosh" => Arccosh,
            "arctanh" => Arctanh,
            "arcsech" => Arcsech,
            "arccsch" => Arccsch,
            "arccoth" => Arccoth,
            "eq" => Eq,
            "neq" => Neq,
            "gt" => Gt,
            "lt" => Lt,
            "geq" => Geq,
            "leq" => Leq,
            "and" => And,
            "or" => Or,
            "xor" => Xor,
            "not" => Not,
            "implies" => Implies,
            "quotient" => Quotient,
            "rem" => Rem,
            "max" => Max,
            "min" => Min,
            _ => return None,
        })
    }

    /// Whether the operator gives a truth value.
    pub fn is_boolean(self) -> bool {
        use Op::*;
        matches!(self, Eq | Neq | Gt | Lt | Geq | Leq | And | Or | Xor | Not | Implies)
    }

    /// Whether it compares two numbers.
    pub fn is_relational(self) -> bool {
        use Op::*;
        matches!(self, Eq | Neq | Gt | Lt | Geq | Leq)
    }

    /// MathML's name of the operator, for messages.
    pub fn name(self) -> String {
        format!("{self:?}").to_lowercase()
    }
}

/// An expression of SBML's math.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Math {
    /// A number (`cn`, `pi`, `exponentiale`, `avogadro`, `infinity`, `notanumber`).
    Num(f64),
    /// `true` or `false`.
    Bool(bool),
    /// A name: an SBML id (or a function's argument before inlining).
    Ci(String),
    /// The `time` csymbol.
    Time,
    /// `rateOf(x)` (SBML Level 3 Version 2): the time derivative of the symbol `x`.
    RateOf(String),
    /// An operator applied to its arguments; `at` is the `apply`'s byte offset.
    Apply(Op, Vec<Math>, usize),
    /// `piecewise`: (value, condition) pieces, then `otherwise`.
    Piecewise(Vec<(Math, Math)>, Option<Box<Math>>),
    /// A call of a function definition (inlined by [`inline`]).
    Call(String, Vec<Math>, usize),
}

/// A `functionDefinition`: its arguments and body.
#[derive(Clone, Debug)]
pub(super) struct Function {
    pub args: Vec<String>,
    pub body: Math,
}

/// Reads the single expression inside a `<math>` element (a `semantics` wrapper opened).
pub(super) fn read_math(xml: &Xml<'_>, math: Node<'_, '_>) -> Result<Math, Refusal> {
    let mut kids = elements(math);
    let Some(first) = kids.next() else {
        return Err(xml.refuse(math, "a <math> element without an expression"));
    };
    read(xml, first, 0)
}

/// Reads a `lambda` (a function definition's `<math>` content).
pub(super) fn read_lambda(xml: &Xml<'_>, math: Node<'_, '_>) -> Result<Function, Refusal> {
    let mut node =
        elements(math).next().ok_or_else(|| xml.refuse(math, "a function definition without a lambda"))?;
    while node.tag_name().name() == "semantics" {
        node = elements(node).next().ok_or_else(|| xml.refuse(node, "an empty <semantics>"))?;
    }
    if node.tag_name().name() != "lambda" {
        return Err(xml.refuse(node, "a function definition's math must be a <lambda>"));
    }
    let mut args = Vec::new();
    let mut body = None;
    for c in elements(node) {
        match c.tag_name().name() {
            "bvar" => {
                let ci = elements(c).next().ok_or_else(|| xml.refuse(c, "an empty <bvar>"))?;
                args.push(ci.text().unwrap_or("").trim().to_string());
            }
            _ if body.is_none() => body = Some(read(xml, c, 0)?),
            _ => return Err(xml.refuse(c, "a lambda with more than one body")),
        }
    }
    let body = body.ok_or_else(|| xml.refuse(node, "a lambda without a body"))?;
    Ok(Function { args, body })
}

/// MathML nests far less in any real model; the limit keeps recursion bounded on hostile input.
const MAX_DEPTH: usize = 500;

fn read(xml: &Xml<'_>, node: Node<'_, '_>, depth: usize) -> Result<Math, Refusal> {
    if depth > MAX_DEPTH {
        return Err(xml.refuse(node, format!("MathML nested deeper than {MAX_DEPTH} levels")));
    }
    let text = || node.text().unwrap_or("").trim().to_string();
    Ok(match node.tag_name().name() {
        "cn" => Math::Num(read_cn(xml, node)?),
        "ci" => Math::Ci(text()),
        "true" => Math::Bool(true),
        "false" => Math::Bool(false),
        "pi" => Math::Num(std::f64::consts::PI),
        "exponentiale" => Math::Num(std::f64::consts::E),
        "infinity" => Math::Num(f64::INFINITY),
        "notanumber" => Math::Num(f64::NAN),
        "semantics" => {
            let first = elements(node).next().ok_or_else(|| xml.refuse(node, "an empty <semantics>"))?;
            read(xml, first, depth + 1)?
        }
        "csymbol" => match csymbol(node).as_str() {
            "time" => Math::Time,
            "avogadro" => Math::Num(AVOGADRO),
            other => return Err(xml.refuse(node, format!("the csymbol `{other}` is not supported here"))),
        },
        "piecewise" => {
            let mut pieces = Vec::new();
            let mut otherwise = None;
            for c in elements(node) {
                let parts: Vec<_> = elements(c).collect();
                match (c.tag_name().name(), parts.as_slice()) {
                    ("piece", [v, cond]) => {
                        pieces.push((read(xml, *v, depth + 1)?, read(xml, *cond, depth + 1)?))
                    }
                    ("otherwise", [v]) => otherwise = Some(Box::new(read(xml, *v, depth + 1)?)),
                    _ => return Err(xml.refuse(c, "a malformed piece of a <piecewise>")),
                }
            }
            Math::Piecewise(pieces, otherwise)
        }
        "apply" => read_apply(xml, node, depth)?,
        other => return Err(xml.refuse(node, format!("the MathML element <{other}> is not supported"))),
    })
}

/// The last path segment of a csymbol's `definitionURL` (`time`, `avogadro`, `delay`, `rateOf`).
fn csymbol(node: Node<'_, '_>) -> String {
    let url = node.attribute("definitionURL").unwrap_or("");
    url.rsplit('/').next().unwrap_or("").to_string()
}

fn read_cn(xml: &Xml<'_>, node: Node<'_, '_>) -> Result<f64, Refusal> {
    // `e-notation` and `rational` put their two parts around a `<sep/>`.
    let parts: Vec<String> = node
        .children()
        .filter(|c| c.is_text())
        .map(|c| c.text().unwrap_or("").trim().to_string())
        .filter(|s| !s.is_empty())
        .collect();
    let bad = || xml.refuse(node, "a <cn> that is not a number");
    let num = |s: &String| parse_f64(s).ok_or_else(bad);
    match (node.attribute("type").unwrap_or("real"), parts.as_slice()) {
        ("e-notation", [m, e]) => Ok(num(m)? * 10f64.powf(num(e)?)),
        ("rational", [a, b]) => Ok(num(a)? / num(b)?),
        (_, [x]) => num(x),
        _ => Err(bad()),
    }
}

fn read_apply(xml: &Xml<'_>, node: Node<'_, '_>, depth: usize) -> Result<Math, Refusal> {
    let at = node.range().start;
    let mut kids = elements(node);
    let head = kids.next().ok_or_else(|| xml.refuse(node, "an empty <apply>"))?;
    let mut qualifiers: HashMap<&str, Node<'_, '_>> = HashMap::new();
    let mut args = Vec::new();
    for c in kids {
        match c.tag_name().name() {
            q @ ("logbase" | "degree") => {
                qualifiers.insert(q, c);
            }
            _ => args.push(read(xml, c, depth + 1)?),
        }
    }
    let qualifier = |q: &str| -> Result<Option<Math>, Refusal> {
        match qualifiers.get(q) {
            None => Ok(None),
            Some(n) => {
                let inner = elements(*n).next().ok_or_else(|| xml.refuse(*n, format!("an empty <{q}>")))?;
                Ok(Some(read(xml, inner, depth + 1)?))
            }
        }
    };
    let name = head.tag_name().name();
    let arity = |n: usize, args: &Vec<Math>| -> Result<(), Refusal> {
        if args.len() == n {
            Ok(())
        } else {
            Err(xml.refuse(
                node,
                format!("<{name}> takes {n} argument{}, found {}", if n == 1 { "" } else { "s" }, args.len()),
            ))
        }
    };
    let one = |args: Vec<Math>| args.into_iter().next().expect("arity checked");
    match name {
        "ci" => return Ok(Math::Call(head.text().unwrap_or("").trim().to_string(), args, at)),
        "csymbol" => {
            return match csymbol(head).as_str() {
                "rateOf" => match args.as_slice() {
                    [Math::Ci(id)] => Ok(Math::RateOf(id.clone())),
                    _ => Err(xml.refuse(node, "rateOf takes one symbol")),
                },
                "delay" => Err(xml.refuse(
                    node,
                    "`delay(x, tau)` in math needs the past of the state (a delay differential equation), which hybc does not integrate",
                )),
                other => Err(xml.refuse(head, format!("the csymbol `{other}` is not a function hybc supports"))),
            }
        }
        "root" => {
            arity(1, &args)?;
            let degree = qualifier("degree")?.unwrap_or(Math::Num(2.0));
            let inv = Math::Apply(Op::Divide, vec![Math::Num(1.0), degree], at);
            return Ok(Math::Apply(Op::Power, vec![one(args), inv], at));
        }
        "log" => {
            arity(1, &args)?;
            let base = qualifier("logbase")?.unwrap_or(Math::Num(10.0));
            let ln = |m: Math| Math::Apply(Op::Ln, vec![m], at);
            return Ok(Math::Apply(Op::Divide, vec![ln(one(args)), ln(base)], at));
        }
        _ => {}
    }
    let Some(op) = Op::named(name) else {
        return Err(xml.refuse(head, format!("the MathML operator <{name}> is not supported")));
    };
    use Op::*;
    let n = args.len();
    let ok = match op {
        Plus | Times | And | Or | Xor | Max | Min => true,
        Minus => n == 1 || n == 2,
        Eq | Neq | Gt | Lt | Geq | Leq => n >= 2,
        Divide | Power | Implies | Quotient | Rem => n == 2,
        _ => n == 1,
    };
    if !ok {
        return Err(xml.refuse(node, format!("<{name}> with {n} argument{}", if n == 1 { "" } else { "s" })));
    }
    // `a < b < c` is `a < b and b < c`; `neq` compares exactly two.
    if op.is_relational() && n > 2 {
        if op == Neq {
            return Err(xml.refuse(node, "<neq> takes two arguments"));
        }
        let pairs = args.windows(2).map(|w| Math::Apply(op, w.to_vec(), at)).collect();
        return Ok(Math::Apply(And, pairs, at));
    }
    Ok(Math::Apply(op, args, at))
}

/// Inlines every call of a function definition, argument by argument (SBML forbids recursion;
/// a cycle is refused by depth). `Err` holds the reason and the call's offset.
pub(super) fn inline(
    m: &Math,
    functions: &HashMap<String, Function>,
    depth: usize,
) -> Result<Math, (String, Option<usize>)> {
    if depth > 64 {
        return Err(("function definitions call each other more than 64 deep (a cycle?)".to_string(), None));
    }
    Ok(match m {
        Math::Call(name, args, at) => {
            let f =
                functions.get(name).ok_or_else(|| (format!("no function definition `{name}`"), Some(*at)))?;
            if f.args.len() != args.len() {
                return Err((
                    format!("function `{name}` takes {} arguments, called with {}", f.args.len(), args.len()),
                    Some(*at),
                ));
            }
            let actual: Vec<Math> =
                args.iter().map(|a| inline(a, functions, depth)).collect::<Result<_, _>>()?;
            let bound: HashMap<&str, &Math> = f.args.iter().map(String::as_str).zip(actual.iter()).collect();
            let body = substitute(&f.body, &bound);
            inline(&body, functions, depth + 1)?
        }
        Math::Apply(op, args, at) => {
            Math::Apply(*op, args.iter().map(|a| inline(a, functions, depth)).collect::<Result<_, _>>()?, *at)
        }
        Math::Piecewise(pieces, otherwise) => Math::Piecewise(
            pieces
                .iter()
                .map(|(v, c)| Ok((inline(v, functions, depth)?, inline(c, functions, depth)?)))
                .collect::<Result<_, _>>()?,
            match otherwise {
                Some(o) => Some(Box::new(inline(o, functions, depth)?)),
                None => None,
            },
        ),
        other => other.clone(),
    })
}

/// `m` with the names in `bound` replaced (a function body's arguments).
pub(super) fn substitute(m: &Math, bound: &HashMap<&str, &Math>) -> Math {
    match m {
        Math::Ci(name) => bound.get(name.as_str()).map_or_else(|| m.clone(), |v| (*v).clone()),
        Math::Apply(op, args, at) => {
            Math::Apply(*op, args.iter().map(|a| substitute(a, bound)).collect(), *at)
        }
        Math::Call(name, args, at) => {
            Math::Call(name.clone(), args.iter().map(|a| substitute(a, bound)).collect(), *at)
        }
        Math::Piecewise(pieces, otherwise) => Math::Piecewise(
            pieces.iter().map(|(v, c)| (substitute(v, bound), substitute(c, bound))).collect(),
            otherwise.as_ref().map(|o| Box::new(substitute(o, bound))),
        ),
        other => other.clone(),
    }
}

/// A value of folding: a number or a truth value.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Value {
    N(f64),
    B(bool),
}

fn value(m: &Math) -> Option<Value> {
    match m {
        Math::Num(x) => Some(Value::N(*x)),
        Math::Bool(b) => Some(Value::B(*b)),
        _ => None,
    }
}

/// `m` with every subtree of constants evaluated (SBML's semantics: a truth value used as a
/// number is 1 or 0, a number used as a truth value is true when not 0). Operators that hybc's
/// language lacks (`floor`, `factorial`, `rem`, ...) are kept where their arguments vary: the
/// printer refuses them there.
pub(super) fn fold(m: &Math) -> Math {
    match m {
        Math::Apply(op, args, at) => {
            let args: Vec<Math> = args.iter().map(fold).collect();
            let values: Option<Vec<Value>> = args.iter().map(value).collect();
            if let Some(values) = values {
                if let Some(v) = apply(*op, &values) {
                    return match v {
                        Value::N(x) => Math::Num(x),
                        Value::B(b) => Math::Bool(b),
                    };
                }
            }
            // Short cuts that keep a truth value exact: `and` with a false, `or` with a true.
            if *op == Op::And && args.contains(&Math::Bool(false)) {
                return Math::Bool(false);
            }
            if *op == Op::Or && args.contains(&Math::Bool(true)) {
                return Math::Bool(true);
            }
            if matches!(op, Op::And | Op::Or) {
                let neutral = Math::Bool(*op == Op::And);
                let kept: Vec<Math> = args.into_iter().filter(|a| *a != neutral).collect();
                return match kept.len() {
                    0 => neutral,
                    1 => kept.into_iter().next().expect("one"),
                    _ => Math::Apply(*op, kept, *at),
                };
            }
            Math::Apply(*op, args, *at)
        }
        Math::Piecewise(pieces, otherwise) => {
            let mut kept = Vec::new();
            for (v, c) in pieces {
                let c = fold(c);
                match value(&c) {
                    Some(Value::B(false)) => continue,
                    Some(Value::N(0.0)) => continue,
                    Some(_) if kept.is_empty() => return fold(v),
                    Some(_) => {
                        return Math::Piecewise(kept, Some(Box::new(fold(v))));
                    }
                    None => kept.push((fold(v), c)),
                }
            }
            let otherwise = otherwise.as_ref().map(|o| Box::new(fold(o)));
            if kept.is_empty() {
                if let Some(o) = otherwise {
                    return *o;
                }
            }
            Math::Piecewise(kept, otherwise)
        }
        Math::Call(name, args, at) => Math::Call(name.clone(), args.iter().map(fold).collect(), *at),
        other => other.clone(),
    }
}

fn num(v: Value) -> f64 {
    match v {
        Value::N(x) => x,
        Value::B(b) => f64::from(u8::from(b)),
    }
}

fn truth(v: Value) -> bool {
    match v {
        Value::N(x) => x != 0.0,
        Value::B(b) => b,
    }
}

/// The value of `op` at constant arguments (`None`: not folded, e.g. a factorial of a non-integer).
fn apply(op: Op, a: &[Value]) -> Option<Value> {
    use Op::*;
    let x = |i: usize| num(a[i]);
    let n = |v: f64| Some(Value::N(v));
    let b = |v: bool| Some(Value::B(v));
    match op {
        Plus => n(a.iter().map(|v| num(*v)).sum()),
        Times => n(a.iter().map(|v| num(*v)).product()),
        Minus if a.len() == 1 => n(-x(0)),
        Minus => n(x(0) - x(1)),
        Divide => n(x(0) / x(1)),
        Power => n(x(0).powf(x(1))),
        Abs => n(x(0).abs()),
        Exp => n(x(0).exp()),
        Ln => n(x(0).ln()),
        Floor => n(x(0).floor()),
        Ceiling => n(x(0).ceil()),
        Factorial => {
            let k = x(0);
            if k >= 0.0 && k.fract() == 0.0 && k <= 170.0 {
                n((1..=k as u32).map(f64::from).product())
            } else {
                None
            }
        }
        Sin => n(x(0).sin()),
        Cos => n(x(0).cos()),
        Tan => n(x(0).tan()),
        Sec => n(1.0 / x(0).cos()),
        Csc => n(1.0 / x(0).sin()),
        Cot => n(1.0 / x(0).tan()),
        Sinh => n(x(0).sinh()),
        Cosh => n(x(0).cosh()),
        Tanh => n(x(0).tanh()),
        Sech => n(1.0 / x(0).cosh()),
        Csch => n(1.0 / x(0).sinh()),
        Coth => n(1.0 / x(0).tanh()),
        Arcsin => n(x(0).asin()),
        Arccos => n(x(0).acos()),
        Arctan => n(x(0).atan()),
        Arcsec => n((1.0 / x(0)).acos()),
        Arccsc => n((1.0 / x(0)).asin()),
        Arccot => n((1.0 / x(0)).atan()),
        Arcsinh => n(x(0).asinh()),
        Arccosh => n(x(0).acosh()),
        Arctanh => n(x(0).atanh()),
        Arcsech => n((1.0 / x(0)).acosh()),
        Arccsch => n((1.0 / x(0)).asinh()),
        Arccoth => n((1.0 / x(0)).atanh()),
        Eq => b(x(0) == x(1)),
        Neq => b(x(0) != x(1)),
        Gt => b(x(0) > x(1)),
        Lt => b(x(0) < x(1)),
        Geq => b(x(0) >= x(1)),
        Leq => b(x(0) <= x(1)),
        And => b(a.iter().all(|v| truth(*v))),
        Or => b(a.iter().any(|v| truth(*v))),
        Xor => b(a.iter().filter(|v| truth(**v)).count() % 2 == 1),
        Not => b(!truth(a[0])),
        Implies => b(!truth(a[0]) || truth(a[1])),
        Quotient => n((x(0) / x(1)).trunc()),
        Rem => n(x(0) % x(1)),
        Max => a.iter().map(|v| num(*v)).reduce(f64::max).and_then(&n),
        Min => a.iter().map(|v| num(*v)).reduce(f64::min).and_then(n),
    }
}
