//! One row per sweep point, with a fixed column scheme (documented in docs/sweep.md),
//! written as CSV or as JSON lines with the same names. Numbers are printed in Rust's shortest
//! round-trip form, so a row reads back as exactly the `f64`s the run computed.
//!
//! Columns, in order (`K` = the number of events shown, grads = the differentiated parameters
//! shown):
//! - every parameter, in declaration order;
//! - `status` (`crate::status::RunStatus`, the vocabulary Python's `Run.status` and `hybc.jax`
//!   share): `ok` (ended at t_end or by a `stop` event, every derivative exists), `grazing` (an
//!   event grazed its guard: derivatives depending on its time are empty), `not_differentiable`
//!   (some derivative stopped existing), `non_finite` (ended as asked, but a final state or output
//!   is NaN or infinite), `zeno`, `max_events`, `stuck`, `fault` (ended early) or `error` (the run
//!   was refused);
//! - `events`: how many events fired;
//! - for k = 1..=K: `event<k>` (its name), `t<k>` (its time), `dt<k>/d<p>` per grad;
//! - `t_final`: the time the run ended;
//! - the final states, then the outputs;
//! - `d<state>/d<p>`, then `d<output>/d<p>` (for each grad, all states, then for each grad all
//!   outputs); after a `stop` event these are the total derivatives that include the motion of
//!   the stopping time (`dstate_total`), so they are the derivatives of the row's values;
//! - `error`: why the run ended early, else empty.
//!
//! Empty cells (`null` in JSON) mean "does not exist": events beyond the count, gradients after
//! a grazing event, and final values and their gradients of a run that ended early. Values that
//! are not finite are `NaN`, `inf`, `-inf` in CSV and the strings `"NaN"`, `"inf"`, `"-inf"` in
//! JSON, as in `hybc run --format json`.

use std::io::{self, Write};

use serde_json::{Map, Value};

use super::PointResult;
use crate::report::non_finite_name;
use crate::sim::{non_finite_finals, SimResult, StopReason, SystemInfo};

/// How rows are written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Comma-separated values with a header line.
    Csv,
    /// One JSON object per line, keyed by the column names.
    Jsonl,
}

/// One cell of a row.
#[derive(Clone, Debug, PartialEq)]
pub enum Cell {
    /// A number.
    Num(f64),
    /// A count (the events).
    Count(usize),
    /// Text (`status`, `event<k>`, `error`).
    Text(String),
    /// Nothing: the value does not exist.
    Empty,
}

/// What a column holds: the kind of every cell in it but the empty ones (for a front end that
/// keeps columns typed, as Python's NumPy arrays).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CellKind {
    /// Numbers (`Cell::Num`).
    Num,
    /// The event count (`Cell::Count`).
    Count,
    /// Text: `status`, `event<k>` and `error` (`Cell::Text`).
    Text,
}

/// The column scheme of one sweep.
#[derive(Clone, Debug)]
pub struct Columns<'a> {
    info: &'a SystemInfo,
    /// Events shown per row.
    events: usize,
    /// The first `shown_grad` sensitivity columns of the run are shown (a plot may have asked for
    /// one more than the user).
    shown_grad: usize,
    /// The column names, built once.
    header: Vec<String>,
}

impl<'a> Columns<'a> {
    /// Columns for runs of a model with shape `info`, showing `events` events and the gradients
    /// with respect to the first `shown_grad` of `info.grad_params`.
    pub fn new(info: &'a SystemInfo, events: usize, shown_grad: usize) -> Self {
        let mut c = Columns { info, events, shown_grad: shown_grad.min(info.n_grad()), header: Vec::new() };
        c.header = c.build_header();
        c
    }

    /// The column names, in row order.
    pub fn header(&self) -> &[String] {
        &self.header
    }

    /// The kind of each column, in header order: the parameters, `status`, `events`, then per
    /// event slot `event<k>`, `t<k>` and its gradients, then numbers up to `error`.
    pub fn kinds(&self) -> Vec<CellKind> {
        let n_params = self.info.n_params();
        let mut kinds = vec![CellKind::Num; self.header.len()];
        kinds[n_params] = CellKind::Text;
        kinds[n_params + 1] = CellKind::Count;
        for k in 0..self.events {
            kinds[n_params + 2 + k * (2 + self.shown_grad)] = CellKind::Text;
        }
        kinds[self.header.len() - 1] = CellKind::Text;
        kinds
    }

    fn grad_names(&self) -> impl Iterator<Item = &str> + '_ {
        self.info.grad_params[..self.shown_grad].iter().map(|&j| self.info.param_names[j].as_str())
    }

    fn build_header(&self) -> Vec<String> {
        let info = self.info;
        let mut h: Vec<String> = info.param_names.clone();
        h.extend(["status".to_string(), "events".to_string()]);
        for k in 1..=self.events {
            h.push(format!("event{k}"));
            h.push(format!("t{k}"));
            h.extend(self.grad_names().map(|p| format!("dt{k}/d{p}")));
        }
        h.push("t_final".into());
        h.extend(info.state_names.iter().cloned());
        h.extend(info.output_names.iter().cloned());
        for p in self.grad_names() {
            h.extend(info.state_names.iter().map(|s| format!("d{s}/d{p}")));
        }
        for p in self.grad_names() {
            h.extend(info.output_names.iter().map(|o| format!("d{o}/d{p}")));
        }
        h.push("error".into());
        h
    }

    /// The cells of the point `params` with outcome `result`, in header order.
    pub fn cells(&self, params: &[f64], result: &PointResult) -> Vec<Cell> {
        let mut row: Vec<Cell> = params.iter().map(|&v| Cell::Num(v)).collect();
        match result {
            Ok(r) => self.result_cells(r, &mut row),
            Err(e) => {
                row.push(Cell::Text("error".into()));
                row.resize(self.header.len() - 1, Cell::Empty);
                row.push(Cell::Text(e.to_string()));
            }
        }
        row
    }

    /// Whether a point's row says `ok`: its run ended as asked with finite final values.
    pub fn is_ok(&self, result: &PointResult) -> bool {
        result.as_ref().is_ok_and(|r| r.stopped_by.is_complete() && self.non_finite(r).is_none())
    }

    fn non_finite(&self, r: &SimResult) -> Option<String> {
        non_finite_finals(self.info, &r.final_state)
    }

    fn result_cells(&self, r: &SimResult, row: &mut Vec<Cell>) {
        let (n, k, m) = (self.info.n_states(), self.info.n_outputs(), self.info.n_grad());
        let complete = r.stopped_by.is_complete();
        let non_finite = if complete { self.non_finite(r) } else { None };
        row.push(Cell::Text(crate::status::RunStatus::of(self.info, r).name().into()));
        row.push(Cell::Count(r.events.len()));
        for slot in 0..self.events {
            match r.events.get(slot) {
                Some(e) => {
                    row.push(Cell::Text(e.name.to_string()));
                    row.push(Cell::Num(e.time));
                    row.extend(grad_cells(e.dtime.as_deref(), 1, 0, self.shown_grad));
                }
                None => row.extend(std::iter::repeat_n(Cell::Empty, 2 + self.shown_grad)),
            }
        }
        let f = &r.final_state;
        row.push(Cell::Num(f.time));
        let values =
            |v: &[f64]| v.iter().map(|&x| if complete { Cell::Num(x) } else { Cell::Empty }).collect();
        row.extend::<Vec<Cell>>(values(&f.state));
        row.extend::<Vec<Cell>>(values(&f.outputs));
        let by_event = matches!(r.stopped_by, StopReason::Event { .. });
        let (ds, dy) = if by_event { (&f.dstate_total, &f.doutputs_total) } else { (&f.dstate, &f.doutputs) };
        let (ds, dy) = if complete { (ds.as_deref(), dy.as_deref()) } else { (None, None) };
        debug_assert!(ds.is_none_or(|d| d.len() == n * m) && dy.is_none_or(|d| d.len() == k * m));
        for j in 0..self.shown_grad {
            row.extend((0..n).map(|i| ds.map_or(Cell::Empty, |d| num_or_empty(d[j * n + i]))));
        }
        for j in 0..self.shown_grad {
            row.extend((0..k).map(|i| dy.map_or(Cell::Empty, |d| num_or_empty(d[j * k + i]))));
        }
        row.push(match self.failure(r).or(non_finite) {
            Some(message) => Cell::Text(message),
            None => Cell::Empty,
        });
    }

    /// The same message `hybc run` prints for a run that ended early.
    fn failure(&self, r: &SimResult) -> Option<String> {
        r.stopped_by.describe(self.info, &r.events, &r.final_state)
    }

    /// Writes the header (CSV only; JSON lines name every value).
    pub fn write_header(&self, w: &mut (impl Write + ?Sized), format: Format) -> io::Result<()> {
        match format {
            Format::Csv => {
                let names: Vec<String> = self.header().iter().map(|h| csv_field(h)).collect();
                writeln!(w, "{}", names.join(","))
            }
            Format::Jsonl => Ok(()),
        }
    }

    /// One point as a CSV line or a JSON object on one line, with its line break.
    pub fn row_text(&self, format: Format, params: &[f64], result: &PointResult) -> String {
        let cells = self.cells(params, result);
        match format {
            Format::Csv => {
                // One buffer for the line: a String per cell and their join were a quarter of a
                // large sweep's formatting.
                let mut line = String::with_capacity(24 * cells.len());
                for (i, c) in cells.iter().enumerate() {
                    if i > 0 {
                        line.push(',');
                    }
                    match c {
                        Cell::Num(v) => push_number(&mut line, *v),
                        Cell::Count(c) => push_display(&mut line, c),
                        Cell::Text(s) => push_csv_field(&mut line, s),
                        Cell::Empty => {}
                    }
                }
                line.push('\n');
                line
            }
            Format::Jsonl => {
                let object: Map<String, Value> = self
                    .header
                    .iter()
                    .zip(cells)
                    .map(|(name, c)| {
                        let v = match c {
                            Cell::Num(v) => match non_finite_name(v) {
                                Some(name) => Value::String(name.into()),
                                None => Value::from(v),
                            },
                            Cell::Count(c) => Value::from(c),
                            Cell::Text(s) => Value::String(s),
                            Cell::Empty => Value::Null,
                        };
                        (name.clone(), v)
                    })
                    .collect();
                format!("{}\n", Value::Object(object))
            }
        }
    }
}

/// `m` gradient cells from a column-per-parameter array with `rows` rows, row `i`.
fn num_or_empty(d: f64) -> Cell {
    if d.is_nan() {
        Cell::Empty
    } else {
        Cell::Num(d)
    }
}

fn grad_cells(a: Option<&[f64]>, rows: usize, i: usize, m: usize) -> Vec<Cell> {
    // A derivative that does not exist (NaN) is an empty cell, as a missing array is.
    (0..m).map(|j| a.map_or(Cell::Empty, |a| num_or_empty(a[j * rows + i]))).collect()
}

/// [`push_number`] into a new string.
#[cfg(test)]
fn number(v: f64) -> String {
    let mut text = String::new();
    push_number(&mut text, v);
    text
}

/// Appends the shortest text that reads back as exactly `v`, in scientific notation when plain
/// digits would be long (Rust's `{}` never uses an exponent: 1e-300 would take 300 zeros).
fn push_number(out: &mut String, v: f64) {
    let a = v.abs();
    if a != 0.0 && !(1e-4..1e15).contains(&a) {
        push_display(out, format_args!("{v:e}"));
    } else {
        push_display(out, v);
    }
}

/// `value`'s `Display`, appended to `out`.
fn push_display(out: &mut String, value: impl std::fmt::Display) {
    use std::fmt::Write as _;
    // Writing to a String cannot fail.
    let _ = write!(out, "{value}");
}

/// A CSV field, quoted (RFC 4180) when it holds a comma, a quote or a line break.
fn csv_field(s: &str) -> String {
    let mut text = String::new();
    push_csv_field(&mut text, s);
    text
}

/// [`csv_field`], appended to `out`.
fn push_csv_field(out: &mut String, s: &str) {
    if s.contains([',', '"', '\n', '\r']) {
        out.push('"');
        out.push_str(&s.replace('"', "\"\""));
        out.push('"');
    } else {
        out.push_str(s);
    }
}

#[cfg(test)]
mod tests {
    use super::{csv_field, number};

    #[test]
    fn numbers_read_back_exactly() {
        for v in [0.1, -2.5, 1e-300, 7.3e-5, 123456789.125, 4.5e20, 0.0, -0.0, f64::MIN_POSITIVE, 1.0 / 3.0] {
            let text = number(v);
            assert_eq!(text.parse::<f64>().map(f64::to_bits), Ok(v.to_bits()), "{text}");
            assert!(text.len() <= 24, "{text}");
        }
    }

    #[test]
    fn csv_fields_are_quoted_only_when_needed() {
        assert_eq!(csv_field("touchdown"), "touchdown");
        assert_eq!(csv_field("a, b"), "\"a, b\"");
        assert_eq!(csv_field("say \"hi\""), "\"say \"\"hi\"\"\"");
    }
}
