//! Stage 1b: flattening. A file that uses arrays, `const`s, `for` loops or `sum(k in ..)`
//! becomes an ordinary flat file whose names are the element names (`x[3]`, `low[3]`,
//! `hit[2][5]`): constants and index expressions evaluated, every index range-checked, loops and
//! reductions unrolled. `sema` checks the result like any file, so no later stage knows arrays.
//!
//! Two passes over the items: the first declares every array (its kind and extent, from whole
//! declarations `state x[N]` and from the elements loops declare), so that references may come
//! before declarations as everywhere in the language; the second emits the flat items. Both
//! count what they unroll against [`MAX_FLAT_SIZE`], so no input unrolls without bound. Names are
//! found in hash maps, the loop variables on a stack as deep as the loops' nesting: linear time in
//! the flattened size.

mod error;
mod index;
mod sites;

use std::borrow::Cow;
use std::collections::{HashMap, HashSet};

pub use error::{quote_head, ExpandError, Problem};
pub use sites::{loop_sites, LoopSite};

use crate::syntax::ast::*;
use crate::syntax::Span;

/// The most items and expression nodes a file may flatten to (each unrolled item and each node
/// of its expressions counts one): a few hundred megabytes of syntax tree at most, and far above
/// any model the later stages handle in reasonable time.
pub const MAX_FLAT_SIZE: usize = 2_000_000;

/// Flattens `file`; a file that uses none of the array syntax is returned as it is.
pub fn expand(file: &File) -> Result<Cow<'_, File>, Vec<ExpandError>> {
    if !file.items.iter().any(item_needs) {
        return Ok(Cow::Borrowed(file));
    }
    flatten(file, Expander::default()).map(|(file, _)| Cow::Owned(file))
}

/// [`expand`] that also returns, for each flat item, the loop values it was unrolled at (empty
/// outside loops): what [`loop_sites`] reads, run again only when `sema` has refused the model.
fn trace(file: &File) -> Option<(File, Vec<Vec<(String, i64)>>)> {
    let (flat, x) = flatten(file, Expander { origins: Some(Vec::new()), ..Expander::default() }).ok()?;
    Some((flat, x.origins.unwrap_or_default()))
}

fn flatten(file: &File, mut x: Expander) -> Result<(File, Expander), Vec<ExpandError>> {
    for item in &file.items {
        if let Item::Const(c) = item {
            x.define_const(c);
        }
    }
    x.declare(&file.items, 0);
    if x.errors.is_empty() {
        x.size = 0;
        let mut items = Vec::new();
        x.emit(&file.items, 0, &mut items);
        if x.errors.is_empty() {
            return Ok((File { model: file.model.clone(), items }, x));
        }
    }
    x.errors.sort_by_key(|e| e.span.start);
    Err(x.errors)
}

/// Whether an item uses array syntax (a flat file skips the copy).
fn item_needs(item: &Item) -> bool {
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

/// An array as declared: what its elements are and one past the largest index of each dimension.
struct Array {
    kind: &'static str,
    extent: Vec<i64>,
    /// Declared whole (`state x[N]`), rather than element by element in loops.
    whole: bool,
}

const VECTOR_PARAM: &str = "a vector parameter";

/// Names a loop variable or a constant would silently replace by a number in every expression.
const BUILT_IN: [&str; 2] = ["t", "pi"];

#[derive(Default)]
struct Expander {
    consts: HashMap<String, i64>,
    /// The loop variables and their values, outermost first.
    loops: Vec<(String, i64)>,
    arrays: HashMap<String, Array>,
    /// Declared names that are not arrays, and what they are.
    scalars: HashMap<String, &'static str>,
    errors: Vec<ExpandError>,
    /// Each span is reported once: an error inside a loop would otherwise repeat per iteration.
    reported: HashSet<Span>,
    size: usize,
    /// The size cap was hit: nothing more is unrolled.
    fatal: bool,
    /// When tracing ([`trace`]): the loop values each emitted top-level item was unrolled at.
    origins: Option<Vec<Vec<(String, i64)>>>,
}

impl index::Env for Expander {
    fn int(&self, name: &str) -> Option<i64> {
        self.loops
            .iter()
            .rev()
            .find(|(n, _)| n == name)
            .map(|&(_, v)| v)
            .or_else(|| self.consts.get(name).copied())
    }

    fn kind_of(&self, name: &str) -> Option<&'static str> {
        self.arrays.get(name).map(|a| a.kind).or_else(|| self.scalars.get(name).copied())
    }
}

/// `x[3]`, `hit[2][5]`: the name every later stage and every interface sees.
fn element_name(name: &str, idx: &[i64]) -> String {
    let mut s = name.to_string();
    for k in idx {
        s.push_str(&format!("[{k}]"));
    }
    s
}

/// From `a`'s start to `b`'s start: a declaration's head (`der(v[i]) = `), which the message
/// quotes trimmed.
fn head(a: Span, b: Span) -> Span {
    Span::new(a.start, b.start.max(a.start))
}

impl Expander {
    fn fail(&mut self, problem: Problem, span: Span, within: Option<Span>) {
        if self.reported.insert(span) {
            self.errors.push(ExpandError { problem, span, within, at: self.loops.clone() });
        }
    }

    fn eval(&mut self, e: &Expr, within: Option<Span>) -> Option<i64> {
        match index::eval(e, self) {
            Ok(v) => Some(v),
            Err((p, span)) => {
                self.fail(p, span, within);
                None
            }
        }
    }

    /// Counts `n` toward the cap; false (and one error) past it.
    fn grow(&mut self, n: usize, span: Span, what: impl FnOnce() -> String) -> bool {
        if self.fatal {
            return false;
        }
        self.size = self.size.saturating_add(n);
        if self.size > MAX_FLAT_SIZE {
            self.fatal = true;
            self.fail(Problem::TooLarge { what: what() }, span, None);
            return false;
        }
        true
    }

    fn define_const(&mut self, c: &ConstDecl) {
        let what = if BUILT_IN.contains(&c.name.name.as_str()) {
            Some("a built-in name")
        } else if self.consts.contains_key(&c.name.name) {
            Some("a const")
        } else {
            None
        };
        if let Some(what) = what {
            self.fail(Problem::Shadows { name: c.name.name.clone(), what }, c.name.span, None);
            return;
        }
        if let Some(v) = self.eval(&c.value, None) {
            self.consts.insert(c.name.name.clone(), v);
        }
    }

    /// A loop's (or reduction's) values, checked: its variable new, its count under the cap.
    fn range(&mut self, var: &Ident, lo: &Expr, hi: &Expr) -> Option<std::ops::Range<i64>> {
        let what = if BUILT_IN.contains(&var.name.as_str()) {
            Some("a built-in name")
        } else if self.consts.contains_key(&var.name) {
            Some("a const")
        } else if self.loops.iter().any(|(n, _)| *n == var.name) {
            Some("an enclosing loop variable")
        } else if self.arrays.contains_key(&var.name) || self.scalars.contains_key(&var.name) {
            Some("declared in the model")
        } else {
            None
        };
        if let Some(what) = what {
            self.fail(Problem::Shadows { name: var.name.clone(), what }, var.span, None);
            return None;
        }
        let (lo, hi) = (self.eval(lo, None)?, self.eval(hi, None)?);
        let count = hi.saturating_sub(lo).max(0);
        if count as u128 > MAX_FLAT_SIZE as u128 {
            self.fatal = true;
            let what = format!("a range of {count} values");
            self.fail(Problem::TooLarge { what }, Span::new(var.span.start, var.span.end), None);
            return None;
        }
        Some(lo..hi.max(lo))
    }

    // ---- pass 1: declarations --------------------------------------------------------------

    fn declare(&mut self, items: &[Item], depth: usize) {
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

    fn new_scalar(&mut self, name: &Ident, kind: &'static str) {
        if self.consts.contains_key(&name.name) {
            self.fail(Problem::Shadows { name: name.name.clone(), what: "a const" }, name.span, None);
        }
        self.scalars.entry(name.name.clone()).or_insert(kind);
    }

    fn new_array(&mut self, name: &Ident, kind: &'static str, extent: Vec<i64>, whole: bool) {
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
    fn declare_name(&mut self, name: &Ident, index: &[Expr], depth: usize, kind: &'static str) {
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

    // ---- pass 2: the flat items ------------------------------------------------------------

    fn emit(&mut self, items: &[Item], depth: usize, out: &mut Vec<Item>) {
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
        {
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
                            ModeItem::Let(l) => {
                                items.extend(self.lets(l, depth).into_iter().map(ModeItem::Let))
                            }
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
    }

    /// The names a declaration declares: itself, every element of a whole array (row-major), or
    /// the one element a loop declares.
    fn decl_names(&mut self, name: &Ident, index: &[Expr], depth: usize, within: Span) -> Vec<Ident> {
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

    fn lets(&mut self, l: &LetDecl, depth: usize) -> Vec<LetDecl> {
        let within = head(l.span, l.value.span);
        let names = self.decl_names(&l.name, &l.index, depth, within);
        names
            .into_iter()
            .map(|name| LetDecl { name, index: vec![], value: self.expr(&l.value), span: l.span })
            .collect()
    }

    fn der(&mut self, d: &DerEq) -> DerEq {
        let state = self.reference(&d.state, &d.index, head(d.span, d.rhs.span));
        DerEq { state, index: vec![], rhs: self.expr(&d.rhs), span: d.span }
    }

    fn event(&mut self, e: &EventDecl, name: Ident) -> EventDecl {
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
    fn reference(&mut self, name: &Ident, index: &[Expr], within: Span) -> Ident {
        if index.is_empty() {
            return name.clone();
        }
        let span = Span::new(name.span.start, index.last().map_or(name.span.end, |e| e.span.end + 1));
        let values = self.indices(name, index, within).unwrap_or_default();
        Ident { name: element_name(&name.name, &values), span }
    }

    /// The indices' values, each checked against the array's extent (an unknown name is left for
    /// `sema`, which suggests the closest).
    fn indices(&mut self, name: &Ident, index: &[Expr], within: Span) -> Option<Vec<i64>> {
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

    fn node(&mut self, e: &Expr) -> bool {
        self.grow(1, e.span, || "the expressions".to_string())
    }

    fn expr(&mut self, e: &Expr) -> Expr {
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
    fn reads_array(&self, args: &[Expr]) -> bool {
        args.iter().any(|a| match &a.kind {
            ExprKind::Name(n) => self.arrays.get(n).is_some_and(|a| a.kind != VECTOR_PARAM),
            _ => false,
        })
    }

    /// `sum(x)` and `dot(x, w)` over a one-index array of states (or `let`s), `w` of either kind.
    fn vector_call(&mut self, f: &Ident, args: &[Expr], span: Span) -> Expr {
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

    fn cond(&mut self, c: &Cond) -> Cond {
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

fn item_span(item: &Item) -> Span {
    match item {
        Item::Param(p) => p.span,
        Item::State(s) => s.span,
        Item::Der(d) => d.span,
        Item::Let(l) => l.span,
        Item::Event(e) => e.span,
        Item::Mode(m) => m.span,
        Item::Output(o) => o.span,
        Item::Simulate(s) => s.span,
        Item::Const(c) => c.span,
        Item::For(f) => f.span,
    }
}
