//! Whether a file uses array syntax at all: a flat file is handed to the checker as it is, not
//! copied.

use crate::syntax::ast::*;

/// Whether an item uses array syntax (a flat file skips the copy).
pub(super) fn item_needs(item: &Item) -> bool {
    match item {
        Item::Const(_) | Item::For(_) => true,
        Item::Param(p) => p.size.as_ref().is_some_and(|s| s.expr.is_some()),
        Item::State(s) => !s.index.is_empty() || expr_needs(&s.init),
        Item::Der(d) => der_needs(d),
        Item::Let(l) => let_needs(l),
        Item::Output(o) => !o.index.is_empty() || expr_needs(&o.value),
        Item::Event(e) => event_needs(e),
        Item::Mode(m) => m.items.iter().any(|i| match i {
            ModeItem::Der(d) => der_needs(d),
            ModeItem::Let(l) => let_needs(l),
            ModeItem::Event(e) => event_needs(e),
        }),
        Item::Simulate(_) => false,
    }
}

fn der_needs(d: &DerEq) -> bool {
    !d.index.is_empty() || expr_needs(&d.rhs)
}

fn let_needs(l: &LetDecl) -> bool {
    !l.index.is_empty() || expr_needs(&l.value)
}

fn event_needs(e: &EventDecl) -> bool {
    !e.index.is_empty()
        || expr_needs(&e.lhs)
        || expr_needs(&e.rhs)
        || e.condition.as_ref().is_some_and(cond_needs)
        || e.body.iter().any(|s| match s {
            EventStmt::Reset { index, value, .. } => !index.is_empty() || expr_needs(value),
            EventStmt::Let(l) => let_needs(l),
            EventStmt::Stop { .. } => false,
        })
}

/// A reduction, or an element with other than one index: syntax only arrays have. (`u[k]` with one
/// index is a vector parameter's element, which `sema` has always resolved.)
fn expr_needs(e: &Expr) -> bool {
    match &e.kind {
        ExprKind::Num(_) | ExprKind::Name(_) => false,
        ExprKind::Sum(_) => true,
        ExprKind::Index(_, idx) => idx.len() != 1 || idx.iter().any(expr_needs),
        ExprKind::Neg(a) => expr_needs(a),
        ExprKind::Binary(_, a, b) => expr_needs(a) || expr_needs(b),
        ExprKind::Call(_, args) => args.iter().any(expr_needs),
        ExprKind::If(c, a, b) => cond_needs(c) || expr_needs(a) || expr_needs(b),
    }
}

fn cond_needs(c: &Cond) -> bool {
    match &c.kind {
        CondKind::Cmp(_, a, b) => expr_needs(a) || expr_needs(b),
        CondKind::And(a, b) | CondKind::Or(a, b) => cond_needs(a) || cond_needs(b),
        CondKind::Not(a) => cond_needs(a),
    }
}
