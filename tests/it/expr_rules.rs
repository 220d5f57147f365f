//! Table tests of the expression engine: one line per derivative rule (input, variable, expected
//! infix text), one line per simplification rule, and the evaluator's edge-case semantics.
//! Every derivative row is also checked by value against a central finite difference, so an
//! expected text cannot silently encode a wrong derivative.

use crate::support::expr::{params, read, states};
use hybc::expr::{apply_binary, apply_unary, diff, eval_one, to_infix, BinaryOp, ExprStore, UnaryOp, Var};

const X: [f64; 2] = [0.3, 0.7];
const P: [f64; 2] = [1.3, 0.4];
const T: f64 = 0.9;

fn show(store: &ExprStore, id: hybc::expr::ExprId) -> String {
    to_infix(store, id, &states(), &params())
}

/// Central difference of `id` along `wrt` at (T, X, P), step 1e-6 (error ~1e-10 for these
/// smooth, O(1) functions away from their kinks).
fn central_difference(store: &ExprStore, id: hybc::expr::ExprId, wrt: Var) -> f64 {
    let h = 1e-6;
    let at = |d: f64| {
        let (mut x, mut p, mut t) = (X, P, T);
        match wrt {
            Var::State(i) => x[i as usize] += d,
            Var::Param(i) => p[i as usize] += d,
            Var::Time => t += d,
            Var::Node(_) => unreachable!("the rules are checked against leaves"),
        }
        eval_one(store, id, t, &x, &p)
    };
    (at(h) - at(-h)) / (2.0 * h)
}

#[test]
fn derivative_rules() {
    let (dx, dy, dp, dt) = (Var::State(0), Var::State(1), Var::Param(0), Var::Time);
    #[rustfmt::skip]
    let table: &[(&str, Var, &str)] = &[
        ("x", dx, "1"),
        ("y", dx, "0"),
        ("p", dp, "1"),
        ("t", dt, "1"),
        ("(- x)", dx, "-1"),
        ("(+ x y)", dx, "1"),
        ("(- y x)", dx, "-1"),
        ("(* x y)", dx, "y"),
        ("(* x x)", dx, "2 * x"),
        ("(* p x)", dp, "x"),
        ("(* t x)", dt, "x"),
        ("(/ x y)", dx, "1 / y"),
        ("(/ x y)", dy, "-x / y / y"),
        ("(^ x 3)", dx, "3 * x^2"),
        ("(^ x 2)", dx, "2 * x"),
        ("(^ x 0.5)", dx, "0.5 * x^(-0.5)"),
        ("(* 0.5 (^ x 2))", dx, "x"),
        ("(^ 2 x)", dx, "0.6931471805599453 * 2^x"),
        ("(^ x y)", dx, "y * x^(y - 1)"),
        // The exponent's derivative with its limit at x = 0 (`pow_log`): 0 for y > 0.
        ("(^ x y)", dy, "pow_log(x, y)"),
        ("(^ 0 x)", dx, "pow_log(0, x)"),
        ("(sin x)", dx, "cos(x)"),
        ("(cos x)", dx, "-sin(x)"),
        ("(tan x)", dx, "1 / cos(x)^2"),
        ("(asin x)", dx, "1 / sqrt(1 - x^2)"),
        ("(acos x)", dx, "-1 / sqrt(1 - x^2)"),
        ("(atan x)", dx, "1 / (1 + x^2)"),
        ("(sinh x)", dx, "cosh(x)"),
        ("(cosh x)", dx, "sinh(x)"),
        ("(tanh x)", dx, "1 - tanh(x)^2"),
        ("(exp x)", dx, "exp(x)"),
        ("(log x)", dx, "1 / x"),
        ("(sqrt x)", dx, "1 / (2 * sqrt(x))"),
        ("(abs x)", dx, "sign(x)"),
        ("(sign x)", dx, "0"),
        ("(atan2 y x)", dx, "-y / (y^2 + x^2)"),
        ("(atan2 y x)", dy, "x / (y^2 + x^2)"),
        ("(hypot x y)", dx, "x / hypot(x, y)"),
        ("(min x y)", dx, "if x <= y then 1 else 0"),
        ("(max x y)", dx, "if y <= x then 1 else 0"),
        ("(if (< x y) (* x x) y)", dx, "if x < y then 2 * x else 0"),
        ("(< x y)", dx, "0"),
        ("(sin (* p x))", dx, "p * cos(p * x)"),
        ("(exp (sin x))", dx, "exp(sin(x)) * cos(x)"),
    ];
    let mut failures = Vec::new();
    for &(src, wrt, expected) in table {
        let mut store = ExprStore::new();
        let e = read(&mut store, src);
        let d = diff(&mut store, e, wrt);
        if show(&store, d) != expected {
            failures.push(format!("d/d{wrt:?} {src}: got `{}`, expected `{expected}`", show(&store, d)));
        }
        let (symbolic, numeric) = (eval_one(&store, d, T, &X, &P), central_difference(&store, e, wrt));
        assert!(
            (symbolic - numeric).abs() <= 1e-7 * (1.0 + numeric.abs()),
            "d/d{wrt:?} {src}: {symbolic} vs {numeric}"
        );
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn simplification_rules() {
    #[rustfmt::skip]
    let table: &[(&str, &str)] = &[
        ("(+ x 0)", "x"),
        ("(+ 0 x)", "x"),
        ("(* x 1)", "x"),
        ("(* x 0)", "0"),
        ("(* x -1)", "-x"),
        ("(/ x 1)", "x"),
        ("(/ 0 x)", "0"),
        ("(^ x 1)", "x"),
        ("(^ x 0)", "1"),
        ("(^ 1 x)", "1"),
        ("(- (- x))", "x"),
        ("(- x x)", "0"),
        ("(+ x x)", "2 * x"),
        ("(+ 2 3)", "5"),
        ("(* (- x) y)", "-x * y"),
        ("(/ x (- y))", "-x / y"),
        ("(abs (- x))", "abs(x)"),
        ("(/ 1 0)", "1 / 0"),
        ("(sqrt -1)", "sqrt(-1)"),
        ("(log 0)", "log(0)"),
        ("(if (< 1 2) x y)", "x"),
        ("(if (< 2 1) x y)", "y"),
        ("(if (< x y) x x)", "x"),
        ("(min x x)", "x"),
        ("(< x x)", "0"),
        ("(<= x x)", "1"),
        ("(> x y)", "y < x"),
        ("(and (< x y) (< 0 1))", "x < y"),
        ("(or (< x y) (< 0 1))", "1"),
        ("(and (< x y) (< 1 0))", "0"),
        ("(not (not (< x y)))", "x < y"),
        ("(not (not x))", "not not x"),
    ];
    for &(src, expected) in table {
        let mut store = ExprStore::new();
        let e = read(&mut store, src);
        assert_eq!(show(&store, e), expected, "{src}");
    }
}

#[test]
fn commutative_operands_share_one_node() {
    for (a, b) in [
        ("(+ x y)", "(+ y x)"),
        ("(* p (sin x))", "(* (sin x) p)"),
        ("(min x y)", "(min y x)"),
        ("(hypot x 2)", "(hypot 2 x)"),
    ] {
        let mut store = ExprStore::new();
        let (ia, ib) = (read(&mut store, a), read(&mut store, b));
        assert_eq!(ia, ib, "{a} vs {b}");
    }
}

#[test]
fn display_uses_minimal_parentheses() {
    #[rustfmt::skip]
    let table: &[(&str, &str)] = &[
        ("(- x (+ y 1))", "x - (y + 1)"),
        ("(+ (- x) y)", "y - x"),
        ("(^ (^ x y) 2)", "(x^y)^2"),
        ("(^ x (^ y 2))", "x^y^2"),
        ("(- (^ x 2))", "-x^2"),
        ("(^ (- x) 2)", "(-x)^2"),
        ("(/ x (* y p))", "x / (y * p)"),
        ("(* (/ x y) p)", "x / y * p"),
        ("(* (+ x 1) y)", "(x + 1) * y"),
        ("(- (+ x y))", "-(x + y)"),
        ("(* x (- (sin y)))", "-x * sin(y)"),
        ("(+ x (if (< x y) 1 2))", "x + (if x < y then 1 else 2)"),
        ("(if (or (< x y) (and (< y p) (< p q))) t 0.25)", "if x < y or y < p and p < q then t else 0.25"),
        ("(+ x 1e-20)", "x + 1e-20"),
    ];
    for &(src, expected) in table {
        let mut store = ExprStore::new();
        let e = read(&mut store, src);
        assert_eq!(show(&store, e), expected, "{src}");
    }
}

#[test]
fn evaluator_semantics_at_edge_cases() {
    assert_eq!(apply_unary(UnaryOp::Sign, 0.0), 0.0);
    assert_eq!(apply_unary(UnaryOp::Sign, -0.0), 0.0);
    assert_eq!(apply_unary(UnaryOp::Sign, -3.0), -1.0);
    assert_eq!(apply_unary(UnaryOp::Sign, 1e-300), 1.0);
    assert!(apply_unary(UnaryOp::Sign, f64::NAN).is_nan());
    assert_eq!(apply_unary(UnaryOp::Not, 0.0), 1.0);
    assert_eq!(apply_unary(UnaryOp::Not, 2.0), 0.0);
    assert_eq!(apply_binary(BinaryOp::Lt, f64::NAN, 1.0), 0.0);
    assert_eq!(apply_binary(BinaryOp::Le, 1.0, 1.0), 1.0);
    assert_eq!(apply_binary(BinaryOp::Min, f64::NAN, 1.0), 1.0);
    assert_eq!(apply_binary(BinaryOp::Pow, -8.0, 1.0 / 3.0).to_bits(), (-8.0f64).powf(1.0 / 3.0).to_bits());
    assert_eq!(apply_binary(BinaryOp::Atan2, 1.0, -1.0), 1.0f64.atan2(-1.0));
    assert_eq!(apply_binary(BinaryOp::And, 2.0, -1.0), 1.0);
    assert_eq!(apply_binary(BinaryOp::Or, 0.0, 0.0), 0.0);
    assert_eq!(hybc::expr::apply_select(f64::NAN, 1.0, 2.0), 1.0);
    assert_eq!(hybc::expr::apply_select(0.0, 1.0, 2.0), 2.0);
}
