//! Pass 2: the flat items. Each declaration is emitted once per loop iteration (or once per
//! element of a whole array) under its element name, each reference range-checked.

use super::{element_name, head, item_span, Expander, Problem};
use crate::syntax::ast::*;
use crate::syntax::Span;

impl Expander {
    pub(super) fn emit(&mut self, items: &[Item], depth: usize, out: &mut Vec<Item>) {
        for item in items {
            if self.fatal || !self.grow(1, item_span(item), || "the items".to_string()) {
                return;
            }
            self.emit_one(item, depth, out);
            if let Some(origins) = &mut self.origins {
                origins.resize(out.len(), self.loops.clone());
            }
        }
    }

    fn emit_one(&mut self, item: &Item, depth: usize, out: &mut Vec<Item>) {
        match item {
            Item::Param(p) => {
                let mut p = p.clone();
                if let Some(size) = &mut p.size {
                    if size.expr.take().is_some() {
                        let len = self.arrays.get(&p.name.name).map_or(0, |a| a.extent[0]);
                        size.len = len.max(0) as u64;
                    }
                }
                out.push(Item::Param(p));
            }
            Item::State(s) => {
                let within = head(s.span, s.init.span);
                for name in self.decl_names(&s.name, &s.index, depth, within) {
                    let init = self.expr(&s.init);
                    out.push(Item::State(StateDecl { name, index: vec![], init, span: s.span }));
                }
            }
            Item::Der(d) => out.push(Item::Der(self.der(d))),
            Item::Let(l) => out.extend(self.lets(l, depth).into_iter().map(Item::Let)),
            Item::Output(o) => {
                let within = head(o.span, o.value.span);
                for name in self.decl_names(&o.name, &o.index, depth, within) {
                    let value = self.expr(&o.value);
                    out.push(Item::Output(OutputDecl { name, index: vec![], value, span: o.span }));
                }
            }
            Item::Event(e) => {
                let within = head(e.span, e.lhs.span);
                for name in self.decl_names(&e.name, &e.index, depth, within) {
                    out.push(Item::Event(Box::new(self.event(e, name))));
                }
            }
            Item::Mode(m) => {
                let mut items = Vec::with_capacity(m.items.len());
                for mi in &m.items {
                    match mi {
                        ModeItem::Der(d) => items.push(ModeItem::Der(self.der(d))),
                        ModeItem::Let(l) => items.extend(self.lets(l, depth).into_iter().map(ModeItem::Let)),
                        ModeItem::Event(e) => {
                            let within = head(e.span, e.lhs.span);
                            for name in self.decl_names(&e.name, &e.index, depth, within) {
                                items.push(ModeItem::Event(Box::new(self.event(e, name))));
                            }
                        }
                    }
                }
                out.push(Item::Mode(Box::new(ModeDecl { items, ..(**m).clone() })));
            }
            Item::Simulate(s) => out.push(Item::Simulate(s.clone())),
            Item::Const(_) => {}
            Item::For(f) => {
                let Some(values) = self.range(&f.var, &f.lo, &f.hi) else { return };
                for v in values {
                    self.loops.push((f.var.name.clone(), v));
                    self.emit(&f.items, depth + 1, out);
                    self.loops.pop();
                }
            }
        }
    }

    /// The names a declaration declares: itself, every element of a whole array (row-major), or
    /// the one element a loop declares.
    pub(super) fn decl_names(
        &mut self,
        name: &Ident,
        index: &[Expr],
        depth: usize,
        within: Span,
    ) -> Vec<Ident> {
        if index.is_empty() {
            return vec![name.clone()];
        }
        let span = Span::new(name.span.start, index.last().map_or(name.span.end, |e| e.span.end + 1));
        let mut values = Vec::with_capacity(index.len());
        for e in index {
            match self.eval(e, Some(within)) {
                Some(v) => values.push(v),
                None => return vec![],
            }
        }
        if depth > 0 {
            return vec![Ident { name: element_name(&name.name, &values), span }];
        }
        let total: i64 =
            values.iter().try_fold(1i64, |acc, &n| acc.checked_mul(n.max(0))).unwrap_or(i64::MAX);
        if !self.grow(usize::try_from(total).unwrap_or(usize::MAX), span, || {
            format!("`{}` of {total} elements", name.name)
        }) {
            return vec![];
        }
        let mut out = Vec::with_capacity(total as usize);
        let mut idx = vec![0i64; values.len()];
        'all: loop {
            out.push(Ident { name: element_name(&name.name, &idx), span });
            for d in (0..idx.len()).rev() {
                idx[d] += 1;
                if idx[d] < values[d] {
                    continue 'all;
                }
                idx[d] = 0;
            }
            break;
        }
        out
    }

    pub(super) fn lets(&mut self, l: &LetDecl, depth: usize) -> Vec<LetDecl> {
        let within = head(l.span, l.value.span);
        let names = self.decl_names(&l.name, &l.index, depth, within);
        names
            .into_iter()
            .map(|name| LetDecl { name, index: vec![], value: self.expr(&l.value), span: l.span })
            .collect()
    }

    pub(super) fn der(&mut self, d: &DerEq) -> DerEq {
        let state = self.reference(&d.state, &d.index, head(d.span, d.rhs.span));
        DerEq { state, index: vec![], rhs: self.expr(&d.rhs), span: d.span }
    }

    pub(super) fn event(&mut self, e: &EventDecl, name: Ident) -> EventDecl {
        let body = e
            .body
            .iter()
            .map(|s| match s {
                EventStmt::Reset { state, index, value, span } => EventStmt::Reset {
                    state: self.reference(state, index, head(*span, value.span)),
                    index: vec![],
                    value: self.expr(value),
                    span: *span,
                },
                EventStmt::Let(l) => {
                    let value = self.expr(&l.value);
                    let lname = self.reference(&l.name, &l.index, head(l.span, l.value.span));
                    EventStmt::Let(LetDecl { name: lname, index: vec![], value, span: l.span })
                }
                EventStmt::Stop { span } => EventStmt::Stop { span: *span },
            })
            .collect();
        EventDecl {
            name,
            index: vec![],
            lhs: self.expr(&e.lhs),
            op: e.op,
            rhs: self.expr(&e.rhs),
            condition: e.condition.as_ref().map(|c| self.cond(c)),
            target: e.target.clone(),
            body,
            span: e.span,
        }
    }

    /// The element `name[index]` names, range-checked against its array; the name itself when
    /// there is no index.
    pub(super) fn reference(&mut self, name: &Ident, index: &[Expr], within: Span) -> Ident {
        if index.is_empty() {
            return name.clone();
        }
        let span = Span::new(name.span.start, index.last().map_or(name.span.end, |e| e.span.end + 1));
        let values = self.indices(name, index, within).unwrap_or_default();
        Ident { name: element_name(&name.name, &values), span }
    }

    /// The indices' values, each checked against the array's extent (an unknown name is left for
    /// `sema`, which suggests the closest).
    pub(super) fn indices(&mut self, name: &Ident, index: &[Expr], within: Span) -> Option<Vec<i64>> {
        let mut values = Vec::with_capacity(index.len());
        for e in index {
            values.push(self.eval(e, Some(within))?);
        }
        match self.arrays.get(&name.name) {
            Some(a) => {
                if a.extent.len() != index.len() {
                    let problem = Problem::IndexCount {
                        array: name.name.clone(),
                        dims: a.extent.len(),
                        found: index.len(),
                    };
                    self.fail(problem, within, Some(within));
                    return None;
                }
                for (k, (&v, e)) in values.iter().zip(index).enumerate() {
                    if !(0..a.extent[k]).contains(&v) {
                        let extent = a.extent.clone();
                        let problem = Problem::OutOfRange { array: name.name.clone(), index: v, extent };
                        self.fail(problem, e.span, Some(within));
                        return None;
                    }
                }
            }
            None => {
                if let Some(&kind) = self.scalars.get(&name.name) {
                    self.fail(Problem::NotAnArray { name: name.name.clone(), kind }, name.span, Some(within));
                    return None;
                }
            }
        }
        Some(values)
    }
}
