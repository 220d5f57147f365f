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
//!
//! Modules: this one holds the expander's state and what both passes use (constants, ranges,
//! the size cap); `needs` decides whether a file needs flattening at all, `declare` is pass 1,
//! `emit` pass 2's items, `exprs` its expressions, `index` the integer arithmetic of indices,
//! `error` the refusals, `sites` the loop values of the checker's errors.

mod declare;
mod emit;
mod error;
mod exprs;
mod index;
mod needs;
mod sites;

use std::borrow::Cow;
use std::collections::{HashMap, HashSet};

pub use error::{quote_head, ExpandError, Problem};
pub use sites::{loop_sites, LoopSite};

use crate::syntax::ast::*;
use crate::syntax::Span;

/// The loop variables' values at one place, outermost first.
type LoopValues = Vec<(String, i64)>;

/// The most items and expression nodes a file may flatten to (each unrolled item and each node
/// of its expressions counts one): a few hundred megabytes of syntax tree at most, and far above
/// any model the later stages handle in reasonable time.
pub const MAX_FLAT_SIZE: usize = 2_000_000;

/// Flattens `file`; a file that uses none of the array syntax is returned as it is.
pub fn expand(file: &File) -> Result<Cow<'_, File>, Vec<ExpandError>> {
    if !file.items.iter().any(needs::item_needs) {
        return Ok(Cow::Borrowed(file));
    }
    flatten(file, Expander::default()).map(|(file, _)| Cow::Owned(file))
}

/// [`expand`] that also returns, for each flat item, the loop values it was unrolled at (empty
/// outside loops): what [`loop_sites`] reads, run again only when `sema` has refused the model.
fn trace(file: &File) -> Option<(File, Vec<LoopValues>)> {
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
    origins: Option<Vec<LoopValues>>,
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
