//! Pass 1: every array declared (its kind and extent, from whole declarations `state x[N]` and
//! from the elements loops declare), so that references may come before declarations.

use super::{item_span, Array, Expander, Problem, VECTOR_PARAM};
use crate::syntax::ast::*;

impl Expander {
    pub(super) fn declare(&mut self, items: &[Item], depth: usize) {
        for item in items {
            if self.fatal || !self.grow(1, item_span(item), || "the declarations".to_string()) {
                return;
            }
            match item {
                Item::Param(p) => match &p.size {
                    Some(size) => {
                        let len = match &size.expr {
                            Some(e) => self.eval(e, None).unwrap_or(0),
                            None => i64::try_from(size.len).unwrap_or(i64::MAX),
                        };
                        if size.expr.is_some() && len < 1 {
                            let name = p.name.name.clone();
                            self.fail(Problem::BadLength { name, len }, size.span, None);
                        }
                        self.new_array(&p.name, VECTOR_PARAM, vec![len.max(0)], true);
                    }
                    None => self.new_scalar(&p.name, "a parameter"),
                },
                Item::State(s) => self.declare_name(&s.name, &s.index, depth, "a state"),
                Item::Let(l) => self.declare_name(&l.name, &l.index, depth, "a `let`"),
                Item::Output(o) => self.declare_name(&o.name, &o.index, depth, "an output"),
                Item::Mode(m) => {
                    for mi in &m.items {
                        if let ModeItem::Let(l) = mi {
                            self.declare_name(&l.name, &l.index, depth, "a `let`");
                        }
                    }
                }
                Item::For(f) => {
                    let Some(values) = self.range(&f.var, &f.lo, &f.hi) else { continue };
                    for v in values {
                        self.loops.push((f.var.name.clone(), v));
                        self.declare(&f.items, depth + 1);
                        self.loops.pop();
                    }
                }
                Item::Der(_) | Item::Event(_) | Item::Simulate(_) | Item::Const(_) => {}
            }
        }
    }

    pub(super) fn new_scalar(&mut self, name: &Ident, kind: &'static str) {
        if self.consts.contains_key(&name.name) {
            self.fail(Problem::Shadows { name: name.name.clone(), what: "a const" }, name.span, None);
        }
        self.scalars.entry(name.name.clone()).or_insert(kind);
    }

    pub(super) fn new_array(&mut self, name: &Ident, kind: &'static str, extent: Vec<i64>, whole: bool) {
        if self.consts.contains_key(&name.name) {
            self.fail(Problem::Shadows { name: name.name.clone(), what: "a const" }, name.span, None);
            return;
        }
        let describe = |whole: bool, dims: usize| {
            let how = if whole { "whole" } else { "by elements" };
            format!("{how} with {dims} index(es)")
        };
        match self.arrays.get_mut(&name.name) {
            None => {
                self.arrays.insert(name.name.clone(), Array { kind, extent, whole });
            }
            Some(a) if !whole && !a.whole && a.extent.len() == extent.len() => {
                for (e, n) in a.extent.iter_mut().zip(extent) {
                    *e = (*e).max(n);
                }
            }
            Some(a) => {
                let (first, second) = (describe(a.whole, a.extent.len()), describe(whole, extent.len()));
                let problem = Problem::MixedDeclaration { name: name.name.clone(), first, second };
                self.fail(problem, name.span, None);
            }
        }
    }

    /// `state x = ..`, `state x[N] = ..` (outside loops: the lengths) or `state x[i] = ..`
    /// (inside: an element).
    pub(super) fn declare_name(&mut self, name: &Ident, index: &[Expr], depth: usize, kind: &'static str) {
        if index.is_empty() {
            return self.new_scalar(name, kind);
        }
        let mut values = Vec::with_capacity(index.len());
        for e in index {
            let Some(v) = self.eval(e, None) else { return };
            if depth == 0 && v < 1 {
                self.fail(Problem::BadLength { name: name.name.clone(), len: v }, e.span, None);
                return;
            }
            if depth > 0 && v < 0 {
                self.fail(Problem::NegativeElement { name: name.name.clone(), index: v }, e.span, None);
                return;
            }
            values.push(if depth == 0 { v } else { v + 1 });
        }
        self.new_array(name, kind, values, depth == 0);
    }
}
