//! Expressions: loop variables and constants become numbers, element references names,
//! reductions balanced sums, `div`/`mod` their integers.

use super::{element_name, index, Expander, Problem, VECTOR_PARAM};
use crate::syntax::ast::*;
use crate::syntax::Span;

impl Expander {
    pub(super) fn node(&mut self, e: &Expr) -> bool {
        self.grow(1, e.span, || "the expressions".to_string())
    }

    pub(super) fn expr(&mut self, e: &Expr) -> Expr {
        let zero = Expr { kind: ExprKind::Num(0.0), span: e.span };
        if !self.node(e) {
            return zero;
        }
        let kind = match &e.kind {
            ExprKind::Num(v) => ExprKind::Num(*v),
            ExprKind::Name(n) => {
                if let Some(v) = index::Env::int(self, n) {
                    ExprKind::Num(v as f64)
                } else if self.arrays.get(n).is_some_and(|a| a.kind != VECTOR_PARAM) {
                    self.fail(Problem::ArrayAsScalar { name: n.clone() }, e.span, None);
                    return zero;
                } else {
                    ExprKind::Name(n.clone())
                }
            }
            ExprKind::Neg(a) => ExprKind::Neg(Box::new(self.expr(a))),
            ExprKind::Binary(op, a, b) => {
                ExprKind::Binary(*op, Box::new(self.expr(a)), Box::new(self.expr(b)))
            }
            ExprKind::If(c, a, b) => {
                ExprKind::If(Box::new(self.cond(c)), Box::new(self.expr(a)), Box::new(self.expr(b)))
            }
            ExprKind::Index(name, index) => {
                let Some(values) = self.indices(name, index, e.span) else { return zero };
                let is_param = self.arrays.get(&name.name).is_none_or(|a| a.kind == VECTOR_PARAM);
                if is_param && values.len() == 1 {
                    // A vector parameter's element stays `u[k]` for sema's vector machinery.
                    let at = Expr { kind: ExprKind::Num(values[0] as f64), span: index[0].span };
                    ExprKind::Index(name.clone(), vec![at])
                } else {
                    ExprKind::Name(element_name(&name.name, &values))
                }
            }
            ExprKind::Sum(r) => {
                let Some(values) = self.range(&r.var, &r.lo, &r.hi) else { return zero };
                let mut terms = Vec::with_capacity(values.size_hint().0);
                for v in values {
                    self.loops.push((r.var.name.clone(), v));
                    terms.push(self.expr(&r.body));
                    self.loops.pop();
                }
                return balanced_sum(terms, e.span);
            }
            ExprKind::Call(f, _)
                if index::uses_integer_only_functions(e) && matches!(f.name.as_str(), "div" | "mod") =>
            {
                match self.eval(e, Some(e.span)) {
                    Some(v) => ExprKind::Num(v as f64),
                    None => return zero,
                }
            }
            ExprKind::Call(f, args) if matches!(f.name.as_str(), "sum" | "dot") && self.reads_array(args) => {
                return self.vector_call(f, args, e.span);
            }
            ExprKind::Call(f, args) => ExprKind::Call(f.clone(), args.iter().map(|a| self.expr(a)).collect()),
        };
        Expr { kind, span: e.span }
    }

    /// Whether a `sum`/`dot` argument names an array other than a vector parameter (those sums
    /// stay `sema`'s, built once and shared).
    pub(super) fn reads_array(&self, args: &[Expr]) -> bool {
        args.iter().any(|a| match &a.kind {
            ExprKind::Name(n) => self.arrays.get(n).is_some_and(|a| a.kind != VECTOR_PARAM),
            _ => false,
        })
    }

    /// `sum(x)` and `dot(x, w)` over a one-index array of states (or `let`s), `w` of either kind.
    pub(super) fn vector_call(&mut self, f: &Ident, args: &[Expr], span: Span) -> Expr {
        let zero = Expr { kind: ExprKind::Num(0.0), span };
        let mut arrays = Vec::new();
        for a in args.iter().take(2) {
            let ExprKind::Name(n) = &a.kind else {
                self.fail(
                    Problem::NotAnArray { name: "this argument".into(), kind: "an expression" },
                    a.span,
                    None,
                );
                return zero;
            };
            match self.arrays.get(n) {
                Some(arr) if arr.extent.len() == 1 => {
                    arrays.push((n.clone(), arr.kind == VECTOR_PARAM, arr.extent[0], a.span))
                }
                Some(arr) => {
                    let problem = Problem::IndexCount { array: n.clone(), dims: arr.extent.len(), found: 1 };
                    self.fail(problem, a.span, None);
                    return zero;
                }
                None => {
                    let kind = self.scalars.get(n).copied().unwrap_or("not declared");
                    self.fail(Problem::NotAnArray { name: n.clone(), kind }, a.span, None);
                    return zero;
                }
            }
        }
        if f.name == "dot" && arrays.len() == 2 && arrays[0].2 != arrays[1].2 {
            let (a, b) = (&arrays[0], &arrays[1]);
            let problem = Problem::Lengths { a: a.0.clone(), len_a: a.2, b: b.0.clone(), len_b: b.2 };
            self.fail(problem, span, None);
            return zero;
        }
        let len = arrays.first().map_or(0, |a| a.2);
        if !self.grow(usize::try_from(len).unwrap_or(usize::MAX).saturating_mul(arrays.len()), span, || {
            format!("a `{}` of {len} terms", f.name)
        }) {
            return zero;
        }
        let element = |(name, is_param, _, at): &(String, bool, i64, Span), k: i64| {
            let kind = if *is_param {
                ExprKind::Index(
                    Ident { name: name.clone(), span: *at },
                    vec![Expr { kind: ExprKind::Num(k as f64), span: *at }],
                )
            } else {
                ExprKind::Name(element_name(name, &[k]))
            };
            Expr { kind, span: *at }
        };
        let terms = (0..len)
            .map(|k| {
                let mut term = element(&arrays[0], k);
                if let Some(b) = arrays.get(1) {
                    let kind = ExprKind::Binary(BinOp::Mul, Box::new(term), Box::new(element(b, k)));
                    term = Expr { kind, span };
                }
                term
            })
            .collect();
        balanced_sum(terms, span)
    }

    pub(super) fn cond(&mut self, c: &Cond) -> Cond {
        let kind = match &c.kind {
            CondKind::Cmp(op, a, b) => CondKind::Cmp(*op, self.expr(a), self.expr(b)),
            CondKind::And(a, b) => CondKind::And(Box::new(self.cond(a)), Box::new(self.cond(b))),
            CondKind::Or(a, b) => CondKind::Or(Box::new(self.cond(a)), Box::new(self.cond(b))),
            CondKind::Not(a) => CondKind::Not(Box::new(self.cond(a))),
        };
        Cond { kind, span: c.span }
    }
}

/// The terms summed as a balanced tree: depth `log2 n`, far under the expression depth cap.
fn balanced_sum(mut terms: Vec<Expr>, span: Span) -> Expr {
    match terms.len() {
        0 => Expr { kind: ExprKind::Num(0.0), span },
        1 => terms.pop().expect("one term"),
        n => {
            let right = terms.split_off(n / 2);
            let (a, b) = (balanced_sum(terms, span), balanced_sum(right, span));
            Expr { kind: ExprKind::Binary(BinOp::Add, Box::new(a), Box::new(b)), span }
        }
    }
}
