//! Stage 3b: the text `hybc derive` prints: every model function and its derivatives in infix
//! form. Knows `sema::Model` (for names) and `expr`; no IO.
//!
//! Layout, in a stable order: a header, `init`, each mode with its flow and its own events, the
//! top-level events, each output. Vectors and matrices over at most [`DENSE_MAX`] states print
//! densely (`[1, 0]`, `[[1, 0], [0, -e]]`); larger ones list their non-zero entries, one a line.
//! Within each block, subexpressions used more than once are hoisted into `let` lines when that
//! makes the block shorter. `_t` lines are printed only when non-zero.

use std::fmt::Write as _;

use crate::expr::{to_infix_group, ExprId, ModelFunctions, SparseMat, SparseVec};
use crate::sema::{self, ModeId, Model, ParamIdx};

/// Largest state count printed as dense vectors and matrices.
pub const DENSE_MAX: usize = 6;

/// The derivative report of `funcs` (lowered from `model`), with parameter derivatives for
/// `wrt`; `mode` restricts the modes shown (top-level events are always shown).
pub fn derive_report(
    model: &Model,
    funcs: &ModelFunctions,
    wrt: &[ParamIdx],
    mode: Option<ModeId>,
) -> String {
    let r = Reporter { model, funcs, wrt };
    let states: Vec<&str> = model.states.iter().map(|s| s.name.as_str()).collect();
    let wrt_names: Vec<&str> = wrt.iter().map(|&p| r.param_name(p)).collect();
    let mut out = String::new();
    let _ = writeln!(out, "model {}", model.name);
    let _ = writeln!(out, "states: {}", states.join(", "));
    let _ = writeln!(out, "differentiated: {}", list_or_none(&wrt_names));

    let mut init = Block::new("init");
    init.vector("x0", funcs.init.iter().map(|&e| Some(e)).collect());
    r.param_columns(&mut init, "x0", &funcs.init_p);
    r.emit(&mut out, init, "");

    // The knot sets are numbered mode by mode (`lower`'s order).
    let mut knot_sets = 0;
    for (m, mode_fns) in funcs.modes.iter().enumerate() {
        let inputs = model.modes.get(m).map_or(&[][..], |x| x.inputs.as_slice());
        let first_set = knot_sets;
        knot_sets += inputs.len();
        if mode.is_some_and(|only| only.0 as usize != m) {
            continue;
        }
        let name = model.modes.get(m).map_or("?", |x| x.name.as_str());
        let mut block = Block::new(&format!("mode {name}"));
        block.vector("f", mode_fns.flow.iter().map(|&e| Some(e)).collect());
        block.matrix("f_x", &mode_fns.flow_x);
        r.param_columns(&mut block, "f", &mode_fns.flow_p);
        if !mode_fns.flow_t.entries.is_empty() {
            block.vector("f_t", dense(&mode_fns.flow_t, funcs.n_states));
        }
        r.emit(&mut out, block, "");
        for (e, event) in model.events.iter().enumerate() {
            if event.owner == Some(ModeId(m as u16)) {
                r.event(&mut out, e, "  ");
            }
        }
        for (k, input) in inputs.iter().enumerate() {
            r.knots(&mut out, first_set + k, input, "  ");
        }
    }

    let top: Vec<usize> = (0..model.events.len()).filter(|&e| model.events[e].owner.is_none()).collect();
    if !top.is_empty() {
        out.push_str("\ntop-level");
        for e in top {
            r.event(&mut out, e, "  ");
        }
    }

    // Grouped once: a row looked up per output would scan every entry per output.
    let (output_x, output_p) = (rows(&funcs.output_x), rows(&funcs.output_p));
    for k in 0..model.outputs.len() {
        r.output(&mut out, k, &output_x, &output_p);
    }
    out
}

/// What `hybc derive --only` keeps: states (their initial value and their rows of each mode's
/// flow), events and outputs, each an index into the model's list.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Only {
    /// States, by index.
    pub states: Vec<usize>,
    /// Events, by index.
    pub events: Vec<usize>,
    /// Outputs, by index.
    pub outputs: Vec<usize>,
}

/// The part of [`derive_report`] about the states, events and outputs `only` names: for each
/// state its initial value and, in each mode (`mode` only, when given), its flow with that row's
/// derivatives, each non-zero entry named by its state (`f_x = {v[3]: 1}`); each event and
/// output as the whole report prints it.
pub fn derive_report_only(
    model: &Model,
    funcs: &ModelFunctions,
    wrt: &[ParamIdx],
    mode: Option<ModeId>,
    only: &Only,
) -> String {
    let r = Reporter { model, funcs, wrt };
    let name_of = |names: &[usize], f: &dyn Fn(usize) -> String| -> Vec<String> {
        names.iter().map(|&i| f(i)).collect()
    };
    let mut shown = name_of(&only.states, &|i| model.states[i].name.clone());
    shown.extend(name_of(&only.events, &|i| model.events[i].name.clone()));
    shown.extend(name_of(&only.outputs, &|i| model.outputs[i].name.clone()));
    let wrt_names: Vec<&str> = wrt.iter().map(|&p| r.param_name(p)).collect();
    let mut out = String::new();
    let _ = writeln!(out, "model {}", model.name);
    let _ = writeln!(out, "only: {}", shown.join(", "));
    let _ = writeln!(out, "differentiated: {}", list_or_none(&wrt_names));

    let init_p = rows(&funcs.init_p);
    for &i in &only.states {
        let mut block = Block::new(&format!("state {}", model.states[i].name));
        block.scalar("x0", funcs.init.get(i).copied());
        for &p in wrt {
            let entry = init_p.get(i).and_then(|row| row.iter().find(|&&(k, _)| k == p.0)).map(|&(_, e)| e);
            block.scalar(&format!("x0_{}", r.param_name(p)), entry);
        }
        r.emit(&mut out, block, "");
        for (m, mode_fns) in funcs.modes.iter().enumerate() {
            if mode.is_some_and(|only| only.0 as usize != m) {
                continue;
            }
            let name = model.modes.get(m).map_or("?", |x| x.name.as_str());
            let mut block = Block::new(&format!("mode {name}"));
            block.scalar("f", mode_fns.flow.get(i).copied());
            let row = |mat: &SparseMat| {
                let mut row: Vec<(u32, ExprId)> = mat
                    .entries
                    .iter()
                    .filter(|&&(r, _, _)| r as usize == i)
                    .map(|&(_, k, e)| (k, e))
                    .collect();
                row.sort_by_key(|&(k, _)| k);
                row
            };
            block.lines.push(("f_x".to_string(), Shape::Row(row(&mode_fns.flow_x))));
            let f_p = row(&mode_fns.flow_p);
            for &p in wrt {
                let entry = f_p.iter().find(|&&(k, _)| k == p.0).map(|&(_, e)| e);
                block.scalar(&format!("f_{}", r.param_name(p)), entry);
            }
            if let Some(&(_, t)) = mode_fns.flow_t.entries.iter().find(|&&(k, _)| k as usize == i) {
                block.scalar("f_t", Some(t));
            }
            r.emit(&mut out, block, "  ");
        }
    }

    // Events under their mode's heading, or the top level's, in the model's order.
    let mut heading = None;
    for &e in &only.events {
        let owner = model.events[e].owner;
        if owner.is_some() && mode.is_some_and(|m| owner != Some(m)) {
            continue;
        }
        if heading != Some(owner) {
            let title = owner.map_or("top-level".to_string(), |m| {
                format!("mode {}", model.modes.get(m.0 as usize).map_or("?", |x| x.name.as_str()))
            });
            let _ = write!(out, "\n{title}");
            heading = Some(owner);
        }
        r.event(&mut out, e, "  ");
    }

    let (output_x, output_p) = (rows(&funcs.output_x), rows(&funcs.output_p));
    for &k in &only.outputs {
        r.output(&mut out, k, &output_x, &output_p);
    }
    out
}

fn list_or_none(names: &[&str]) -> String {
    if names.is_empty() {
        "(none)".to_string()
    } else {
        names.join(", ")
    }
}

/// A sparse vector as `n` optional entries.
fn dense(v: &SparseVec, n: u32) -> Vec<Option<ExprId>> {
    let mut out = vec![None; n as usize];
    for &(i, e) in &v.entries {
        if let Some(slot) = out.get_mut(i as usize) {
            *slot = Some(e);
        }
    }
    out
}

/// The entries of each row of a sparse matrix, `(column, entry)` in column order, in one pass.
fn rows(m: &SparseMat) -> Vec<Vec<(u32, ExprId)>> {
    let mut out = vec![Vec::new(); m.n_rows as usize];
    for &(i, k, e) in &m.entries {
        if let Some(row) = out.get_mut(i as usize) {
            row.push((k, e));
        }
    }
    for row in &mut out {
        row.sort_by_key(|&(k, _)| k);
    }
    out
}

/// One row of `rows` as `n_cols` optional entries (a later entry of one column wins).
fn dense_row(row: Option<&Vec<(u32, ExprId)>>, n_cols: u32) -> Vec<Option<ExprId>> {
    let mut out = vec![None; n_cols as usize];
    for &(k, e) in row.into_iter().flatten() {
        if let Some(slot) = out.get_mut(k as usize) {
            *slot = Some(e);
        }
    }
    out
}

/// Column `j` of a sparse matrix with `n_rows` rows.
fn column(m: &SparseMat, j: u32, n_rows: u32) -> Vec<Option<ExprId>> {
    let mut out = vec![None; n_rows as usize];
    for &(i, k, e) in &m.entries {
        if k == j {
            if let Some(slot) = out.get_mut(i as usize) {
                *slot = Some(e);
            }
        }
    }
    out
}

/// What one report line shows; `None` entries are structural zeros.
enum Shape {
    Scalar(Option<ExprId>),
    Vector(Vec<Option<ExprId>>),
    /// Rows of `(column, entry)`, `n_cols` columns: a matrix with `n` states has up to `n^2`
    /// entries, and a dense grid of a sparse one would cost `n^2` for few.
    Matrix(Vec<Vec<(u32, ExprId)>>, u32),
    /// One row's non-zero entries `(column, entry)`, printed with the columns' state names
    /// (`{x[3]: 1, v[3]: -1}`) at any size: `hybc derive --only`'s flow rows.
    Row(Vec<(u32, ExprId)>),
}

/// A titled group of lines that shares one set of `let`s.
struct Block {
    title: String,
    lines: Vec<(String, Shape)>,
}

impl Block {
    fn new(title: &str) -> Block {
        Block { title: title.to_string(), lines: Vec::new() }
    }
    fn scalar(&mut self, label: &str, e: Option<ExprId>) {
        self.lines.push((label.to_string(), Shape::Scalar(e)));
    }
    fn vector(&mut self, label: &str, v: Vec<Option<ExprId>>) {
        self.lines.push((label.to_string(), Shape::Vector(v)));
    }
    fn matrix(&mut self, label: &str, m: &SparseMat) {
        self.lines.push((label.to_string(), Shape::Matrix(rows(m), m.n_cols)));
    }
    fn roots(&self) -> Vec<ExprId> {
        let mut roots = Vec::new();
        for (_, shape) in &self.lines {
            match shape {
                Shape::Scalar(e) => roots.extend(e),
                Shape::Vector(v) => roots.extend(v.iter().flatten()),
                Shape::Matrix(m, _) => roots.extend(m.iter().flatten().map(|&(_, e)| e)),
                Shape::Row(r) => roots.extend(r.iter().map(|&(_, e)| e)),
            }
        }
        roots
    }
}

struct Reporter<'a> {
    model: &'a Model,
    funcs: &'a ModelFunctions,
    wrt: &'a [ParamIdx],
}

impl Reporter<'_> {
    fn param_name(&self, p: ParamIdx) -> &str {
        self.model.params.get(p.0 as usize).map_or("?", |x| x.name.as_str())
    }

    /// One `<prefix>_<p>` vector line per differentiated parameter.
    fn param_columns(&self, block: &mut Block, prefix: &str, m: &SparseMat) {
        for &p in self.wrt {
            let label = format!("{prefix}_{}", self.param_name(p));
            block.vector(&label, column(m, p.0, m.n_rows));
        }
    }

    fn event(&self, out: &mut String, e: usize, indent: &str) {
        let (Some(event), Some(fns)) = (self.model.events.get(e), self.funcs.events.get(e)) else {
            return;
        };
        let n = self.funcs.n_states;
        let direction = match event.direction {
            sema::Direction::Falling => "falling",
            sema::Direction::Rising => "rising",
            sema::Direction::Either => "either",
        };
        let mut block = Block::new(&format!("event {} ({direction})", event.name));
        block.scalar("g", Some(fns.guard));
        if let Some(c) = fns.condition {
            block.scalar("condition", Some(c));
        }
        block.vector("g_x", dense(&fns.guard_x, n));
        for &p in self.wrt {
            let entry = fns.guard_p.entries.iter().find(|&&(k, _)| k == p.0).map(|&(_, d)| d);
            block.scalar(&format!("g_{}", self.param_name(p)), entry);
        }
        if !self.funcs.store.is_zero(fns.guard_t) {
            block.scalar("g_t", Some(fns.guard_t));
        }
        block.vector("R", fns.reset.iter().map(|&r| Some(r)).collect());
        block.matrix("R_x", &fns.reset_x);
        self.param_columns(&mut block, "R", &fns.reset_p);
        if !fns.reset_t.entries.is_empty() {
            block.vector("R_t", dense(&fns.reset_t, n));
        }
        self.emit(out, block, indent);
    }

    /// The knots of `input` (knot set `set`): its knot position `s`, knot `k` where `s = k`, with
    /// its derivatives (the knots' motion is `-s_p / s_t`).
    fn knots(&self, out: &mut String, set: usize, input: &sema::Input, indent: &str) {
        let Some(fns) = self.funcs.knots.get(set) else {
            return;
        };
        let vector =
            self.model.vectors.iter().find(|v| v.first == input.first).map_or("?", |v| v.name.as_str());
        let knots = input.knots();
        let what = match input.kind {
            sema::InputKind::Pwl => "kinks",
            sema::InputKind::Pwc => "jumps",
        };
        let title = format!(
            "knots of {}(t, .., {vector}): s = k, k = {} .. {} ({what})",
            input.kind.name(),
            knots.start,
            knots.end.saturating_sub(1)
        );
        let mut block = Block::new(&title);
        block.scalar("s", Some(fns.position));
        for &p in self.wrt {
            let entry = fns.position_p.entries.iter().find(|&&(k, _)| k == p.0).map(|&(_, d)| d);
            block.scalar(&format!("s_{}", self.param_name(p)), entry);
        }
        block.scalar("s_t", Some(fns.position_t));
        self.emit(out, block, indent);
    }

    /// Output `k`'s block: `h`, `h_x`, `h_p` for each differentiated parameter, `h_t` if
    /// non-zero; `output_x` and `output_p` are the rows of those matrices.
    fn output(
        &self,
        out: &mut String,
        k: usize,
        output_x: &[Vec<(u32, ExprId)>],
        output_p: &[Vec<(u32, ExprId)>],
    ) {
        let (Some(output), Some(&h)) = (self.model.outputs.get(k), self.funcs.outputs.get(k)) else {
            return;
        };
        let funcs = self.funcs;
        let mut block = Block::new(&format!("output {}", output.name));
        block.scalar("h", Some(h));
        block.vector("h_x", dense_row(output_x.get(k), funcs.n_states));
        let h_p = dense_row(output_p.get(k), funcs.n_params);
        for &p in self.wrt {
            let entry = h_p.get(p.0 as usize).copied().flatten();
            block.scalar(&format!("h_{}", self.param_name(p)), entry);
        }
        if let Some(&(_, t)) = funcs.output_t.entries.iter().find(|&&(i, _)| i as usize == k) {
            block.scalar("h_t", Some(t));
        }
        self.emit(out, block, "");
    }

    /// Prints a block: title, `let`s, then its lines.
    fn emit(&self, out: &mut String, block: Block, indent: &str) {
        let states: Vec<String> = self.model.states.iter().map(|s| s.name.clone()).collect();
        let params: Vec<String> = self.model.params.iter().map(|p| p.name.clone()).collect();
        let roots = block.roots();
        let group = to_infix_group(&self.funcs.store, &roots, &states, &params, &[]);
        let mut texts = group.roots.iter();
        let mut next = |e: &Option<ExprId>| match e {
            Some(_) => texts.next().cloned().unwrap_or_default(),
            None => "0".to_string(),
        };
        let _ = writeln!(out, "\n{indent}{}", block.title);
        let inner = format!("{indent}  ");
        for line in group.let_lines() {
            let _ = writeln!(out, "{inner}{line}");
        }
        let dense_ok = states.len() <= DENSE_MAX;
        for (label, shape) in &block.lines {
            match shape {
                Shape::Scalar(e) => {
                    let _ = writeln!(out, "{inner}{label} = {}", next(e));
                }
                Shape::Row(r) if r.is_empty() => {
                    let _ = writeln!(out, "{inner}{label} = 0");
                }
                Shape::Row(r) => {
                    let cells: Vec<String> = r
                        .iter()
                        .map(|&(k, e)| {
                            format!(
                                "{}: {}",
                                states.get(k as usize).map_or("?", |s| s.as_str()),
                                next(&Some(e))
                            )
                        })
                        .collect();
                    let _ = writeln!(out, "{inner}{label} = {{{}}}", cells.join(", "));
                }
                Shape::Vector(v) if dense_ok => {
                    let cells: Vec<String> = v.iter().map(&mut next).collect();
                    let _ = writeln!(out, "{inner}{label} = [{}]", cells.join(", "));
                }
                Shape::Matrix(m, n_cols) if dense_ok => {
                    let rows: Vec<String> = m
                        .iter()
                        .map(|r| {
                            let r = dense_row(Some(r), *n_cols);
                            format!("[{}]", r.iter().map(&mut next).collect::<Vec<_>>().join(", "))
                        })
                        .collect();
                    let _ = writeln!(out, "{inner}{label} = [{}]", rows.join(", "));
                }
                Shape::Vector(v) => {
                    let _ = writeln!(
                        out,
                        "{inner}{label}:{}",
                        if v.iter().all(Option::is_none) { " 0" } else { "" }
                    );
                    for (i, e) in v.iter().enumerate().filter(|(_, e)| e.is_some()) {
                        let _ = writeln!(
                            out,
                            "{inner}  ({i}) {}: {}",
                            states.get(i).map_or("?", |s| s.as_str()),
                            next(e)
                        );
                    }
                }
                Shape::Matrix(m, _) => {
                    let empty = m.iter().all(Vec::is_empty);
                    let _ = writeln!(out, "{inner}{label}:{}", if empty { " 0" } else { "" });
                    for (i, r) in m.iter().enumerate() {
                        for &(k, e) in r {
                            let row_name = states.get(i).map_or("?", |s| s.as_str());
                            let _ = writeln!(
                                out,
                                "{inner}  ({i}, {k}) {row_name}/{}: {}",
                                states.get(k as usize).map_or("?", |s| s.as_str()),
                                next(&Some(e))
                            );
                        }
                    }
                }
            }
        }
    }
}
