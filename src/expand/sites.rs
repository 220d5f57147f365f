//! Where in a loop an error of the checker arose. `sema` checks the flat model, whose unrolled
//! items all carry their loop's span: an error there names the text but not the loop values. On
//! a refused model only (the flattening is run again, this time recording each item's loop
//! values), each error is traced to the first unrolled item whose span holds it and which
//! mentions every element the message quotes (`x[3]` in "state `x[3]` has two flow equations"),
//! so that the checker's errors read as `expand`'s: "in `der(x[i + 1])` at `i = 2`: ...".

use std::collections::HashSet;

use super::{head, trace};
use crate::syntax::ast::*;
use crate::syntax::Span;

/// An error's place in a loop: the loop values and the declaration it stands in.
#[derive(Clone, Debug, PartialEq)]
pub struct LoopSite {
    /// The loop variables' values, outermost first.
    pub at: Vec<(String, i64)>,
    /// The declaration's head (`der(x[i + 1]) = `), which the message quotes trimmed.
    pub within: Span,
}

/// For each error `(span, message)` the checker found in `file` flattened: its place in a loop,
/// or `None` for an error outside every loop (or in a file that does not flatten).
pub fn loop_sites(file: &File, errors: &[(Span, String)]) -> Vec<Option<LoopSite>> {
    let Some((flat, origins)) = trace(file) else {
        return vec![None; errors.len()];
    };
    errors
        .iter()
        .map(|(span, message)| {
            let quoted = quoted_elements(message);
            let mut candidates = flat
                .items
                .iter()
                .zip(&origins)
                .filter(|(item, at)| !at.is_empty() && contains(item_span(item), *span));
            let first = candidates.clone().next();
            let (item, at) = candidates.find(|(item, _)| mentions_all(item, &quoted)).or(first)?;
            Some(LoopSite { at: at.clone(), within: item_head(item) })
        })
        .collect()
}

fn contains(outer: Span, inner: Span) -> bool {
    outer.start <= inner.start && inner.end <= outer.end
}

/// The element names a message quotes: each `` `..` `` holding a bracket (`x[3]`, `hit[2][5]`).
fn quoted_elements(message: &str) -> Vec<&str> {
    message.split('`').skip(1).step_by(2).filter(|q| q.contains('[')).collect()
}

fn mentions_all(item: &Item, names: &[&str]) -> bool {
    if names.is_empty() {
        return true;
    }
    let mut found = HashSet::new();
    item_names(item, &mut found);
    names.iter().all(|n| found.contains(*n))
}

/// Every name a flat item declares or reads (`u[3]` for a vector parameter's element).
fn item_names(item: &Item, out: &mut HashSet<String>) {
    match item {
        Item::State(s) => {
            out.insert(s.name.name.clone());
            expr_names(&s.init, out);
        }
        Item::Der(d) => {
            out.insert(d.state.name.clone());
            expr_names(&d.rhs, out);
        }
        Item::Let(l) => {
            out.insert(l.name.name.clone());
            expr_names(&l.value, out);
        }
        Item::Output(o) => {
            out.insert(o.name.name.clone());
            expr_names(&o.value, out);
        }
        Item::Event(e) => {
            out.insert(e.name.name.clone());
            expr_names(&e.lhs, out);
            expr_names(&e.rhs, out);
            if let Some(c) = &e.condition {
                cond_names(c, out);
            }
            for s in &e.body {
                match s {
                    EventStmt::Reset { state, value, .. } => {
                        out.insert(state.name.clone());
                        expr_names(value, out);
                    }
                    EventStmt::Let(l) => {
                        out.insert(l.name.name.clone());
                        expr_names(&l.value, out);
                    }
                    EventStmt::Stop { .. } => {}
                }
            }
        }
        Item::Param(_) | Item::Mode(_) | Item::Simulate(_) | Item::Const(_) | Item::For(_) => {}
    }
}

fn expr_names(e: &Expr, out: &mut HashSet<String>) {
    match &e.kind {
        ExprKind::Num(_) => {}
        ExprKind::Name(n) => {
            out.insert(n.clone());
        }
        ExprKind::Index(name, index) => {
            if let [Expr { kind: ExprKind::Num(k), .. }] = index.as_slice() {
                out.insert(format!("{}[{k}]", name.name));
            }
            index.iter().for_each(|i| expr_names(i, out));
        }
        ExprKind::Neg(a) => expr_names(a, out),
        ExprKind::Binary(_, a, b) => {
            expr_names(a, out);
            expr_names(b, out);
        }
        ExprKind::Call(_, args) => args.iter().for_each(|a| expr_names(a, out)),
        ExprKind::If(c, a, b) => {
            cond_names(c, out);
            expr_names(a, out);
            expr_names(b, out);
        }
        ExprKind::Sum(r) => expr_names(&r.body, out),
    }
}

fn cond_names(c: &Cond, out: &mut HashSet<String>) {
    match &c.kind {
        CondKind::Cmp(_, a, b) => {
            expr_names(a, out);
            expr_names(b, out);
        }
        CondKind::And(a, b) | CondKind::Or(a, b) => {
            cond_names(a, out);
            cond_names(b, out);
        }
        CondKind::Not(a) => cond_names(a, out),
    }
}

/// A loop body's item's head, as `expand`'s own errors quote it.
fn item_head(item: &Item) -> Span {
    match item {
        Item::State(s) => head(s.span, s.init.span),
        Item::Der(d) => head(d.span, d.rhs.span),
        Item::Let(l) => head(l.span, l.value.span),
        Item::Output(o) => head(o.span, o.value.span),
        Item::Event(e) => head(e.span, e.lhs.span),
        other => item_span(other),
    }
}

fn item_span(item: &Item) -> Span {
    super::item_span(item)
}
