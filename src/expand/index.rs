//! Index arithmetic: an index, a loop bound, a length or a `const` is an integer expression of
//! numbers, loop variables and constants, evaluated exactly in `i64` (every overflow an error).

use super::error::Problem;
use crate::syntax::ast::{BinOp, Expr, ExprKind};
use crate::syntax::Span;

/// The integers an index may read: the loop variables (innermost last) and the constants.
pub trait Env {
    /// The value of `name`, if it is a loop variable or a constant.
    fn int(&self, name: &str) -> Option<i64>;
    /// What `name` is when it is not a compile-time integer (`"a state"`), for the message.
    fn kind_of(&self, name: &str) -> Option<&'static str>;
}

/// Numbers beyond 2^53 are not all integers in a double; an index never needs them.
const EXACT: f64 = 9_007_199_254_740_992.0;

/// Evaluates `e` as an integer, or says what in it is not integer arithmetic, and where.
pub fn eval(e: &Expr, env: &dyn Env) -> Result<i64, (Problem, Span)> {
    let fail = |p: Problem| Err((p, e.span));
    match &e.kind {
        ExprKind::Num(v) => {
            if v.fract() != 0.0 || v.abs() > EXACT {
                return fail(Problem::NotInteger { value: *v });
            }
            Ok(*v as i64)
        }
        ExprKind::Name(n) => match env.int(n) {
            Some(v) => Ok(v),
            None => match env.kind_of(n) {
                Some(kind) => fail(Problem::NotConstant { name: n.clone(), kind }),
                None => fail(Problem::UnknownConst { name: n.clone() }),
            },
        },
        ExprKind::Neg(a) => {
            let a = eval(a, env)?;
            a.checked_neg().map_or_else(|| fail(Problem::Overflow), Ok)
        }
        ExprKind::Binary(op, a, b) => {
            let (x, y) = (eval(a, env)?, eval(b, env)?);
            let r = match op {
                BinOp::Add => x.checked_add(y),
                BinOp::Sub => x.checked_sub(y),
                BinOp::Mul => x.checked_mul(y),
                BinOp::Div => {
                    if y == 0 {
                        return fail(Problem::DivideByZero);
                    }
                    if x % y != 0 {
                        return fail(Problem::InexactDivision { a: x, b: y });
                    }
                    x.checked_div(y)
                }
                BinOp::Pow => match u32::try_from(y) {
                    Ok(y) => x.checked_pow(y),
                    Err(_) => return fail(Problem::NegativePower),
                },
            };
            r.map_or_else(|| fail(Problem::Overflow), Ok)
        }
        ExprKind::Call(f, args) if matches!(f.name.as_str(), "min" | "max" | "div" | "mod") => {
            if args.len() != 2 {
                return fail(Problem::IndexArity { func: f.name.clone(), found: args.len() });
            }
            let (x, y) = (eval(&args[0], env)?, eval(&args[1], env)?);
            let r = match f.name.as_str() {
                "min" => Some(x.min(y)),
                "max" => Some(x.max(y)),
                _ if y == 0 => return fail(Problem::DivideByZero),
                "div" => x.checked_div_euclid(y),
                _ => x.checked_rem_euclid(y),
            };
            r.map_or_else(|| fail(Problem::Overflow), Ok)
        }
        ExprKind::Call(f, _) => {
            fail(Problem::NotIndexArithmetic { what: format!("the function `{}`", f.name) })
        }
        ExprKind::Index(n, _) => {
            fail(Problem::NotIndexArithmetic { what: format!("the element `{}[..]`", n.name) })
        }
        ExprKind::If(..) => fail(Problem::NotIndexArithmetic { what: "`if`".to_string() }),
        ExprKind::Sum(_) => fail(Problem::NotIndexArithmetic { what: "`sum`".to_string() }),
    }
}

/// Whether `e` is built of index arithmetic alone and reads `div` or `mod`, which only index
/// arithmetic has: such an ordinary expression is folded to its number.
pub fn uses_integer_only_functions(e: &Expr) -> bool {
    match &e.kind {
        ExprKind::Call(f, args) => {
            matches!(f.name.as_str(), "div" | "mod") || args.iter().any(uses_integer_only_functions)
        }
        ExprKind::Neg(a) => uses_integer_only_functions(a),
        ExprKind::Binary(_, a, b) => uses_integer_only_functions(a) || uses_integer_only_functions(b),
        _ => false,
    }
}
