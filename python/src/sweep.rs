//! `Model.sweep`: one compiled model run at many points in parallel (the library's
//! `SweepRequest`, with the GIL released), returned as the columns `hybc sweep` writes (the
//! report's `sweep::Columns`), one NumPy array per column.
//!
//! Column types: numbers are float64 arrays with NaN where `hybc sweep` leaves a cell empty;
//! `events` is int64; `status`, `event<k>` and `error` are lists of str (empty where the CSV cell
//! is empty), made NumPy str arrays by the Python layer.

use std::collections::HashMap;

use numpy::{PyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};
use rayon::prelude::*;

use hybc::sweep::table::Cell;
use hybc::sweep::{CellKind, SweepReport};
use hybc::{Spelling, SweepRequest};

use crate::errors::ParameterError;

/// The caps of every interface (`hybc::limits`): a sweep from Python keeps all its rows, so its
/// points are capped as a sweep held in memory; event columns and threads as `hybc sweep`'s.
pub use hybc::limits::MAX_SWEEP_POINTS_IN_MEMORY as MAX_POINTS;
/// Rows are turned into cells in parallel per chunk; the chunk bounds the memory the cells take.
const CELL_CHUNK: usize = 4096;

/// The parameter vectors of the sweep: `base` with the columns `names` of `points` (one row per
/// point) set, each value checked to be finite and within its parameter's declared range.
pub fn points(
    model: &hybc::Model,
    base: &[f64],
    names: &[String],
    points: &PyReadonlyArray2<'_, f64>,
) -> PyResult<Vec<Vec<f64>>> {
    // Read through the strided view: right whatever the memory order.
    let view = points.as_array();
    let (n, k) = view.dim();
    if k != names.len() {
        return Err(PyValueError::new_err(format!(
            "points: {} columns for {} names ({})",
            k,
            names.len(),
            names.join(", ")
        )));
    }
    if n > MAX_POINTS {
        return Err(PyValueError::new_err(format!("points: {n} points; at most {MAX_POINTS} are supported")));
    }
    let checked = model.checked();
    let mut indices = Vec::with_capacity(k);
    for name in names {
        let idx = model.param_index(name).map_err(|e| ParameterError::new_err(e.to_string()))?.0 as usize;
        if indices.contains(&idx) {
            return Err(ParameterError::new_err(format!("parameter `{name}` is given twice")));
        }
        indices.push(idx);
    }
    let mut rows = Vec::with_capacity(n);
    for (row, values) in view.outer_iter().enumerate() {
        let mut p = base.to_vec();
        for (&idx, &v) in indices.iter().zip(values.iter()) {
            let param = &checked.params[idx];
            if !v.is_finite() {
                return Err(ParameterError::new_err(format!(
                    "{} = {v} (point {row}) is not a finite number",
                    param.name
                )));
            }
            if let Some((lo, hi)) = param.range.filter(|(lo, hi)| !(*lo..=*hi).contains(&v)) {
                return Err(ParameterError::new_err(format!(
                    "{} = {v} (point {row}) is outside its range [{lo}, {hi}]",
                    param.name
                )));
            }
            p[idx] = v;
        }
        rows.push(p);
    }
    Ok(rows)
}

/// Ranges to sample as Python gives them: `(name, (lo, hi))`, `None` for the declared range.
pub type RangeArgs = Vec<(String, Option<(f64, f64)>)>;

/// The `(parameter index, lo, hi)` to sample, checked as `hybc sweep --samples` checks them: a
/// given range must lie within the declared one and have lo < hi; `None` takes the declared range;
/// no list samples every parameter that declares a range.
pub fn sample_ranges(model: &hybc::Model, ranges: Option<RangeArgs>) -> PyResult<Vec<(usize, f64, f64)>> {
    let params = &model.checked().params;
    let Some(ranges) = ranges else {
        let all: Vec<(usize, f64, f64)> =
            params.iter().enumerate().filter_map(|(i, p)| p.range.map(|(lo, hi)| (i, lo, hi))).collect();
        if all.is_empty() {
            return Err(ParameterError::new_err(format!(
                "samples: model `{}` declares no parameter range; give ranges={{name: (lo, hi)}}",
                model.name()
            )));
        }
        return Ok(all);
    };
    if ranges.is_empty() {
        return Err(PyValueError::new_err("samples: ranges is empty; give at least one parameter"));
    }
    let mut out: Vec<(usize, f64, f64)> = Vec::with_capacity(ranges.len());
    for (name, range) in ranges {
        let idx = model.param_index(&name).map_err(|e| ParameterError::new_err(e.to_string()))?.0 as usize;
        if out.iter().any(|r| r.0 == idx) {
            return Err(ParameterError::new_err(format!("parameter `{name}` is given twice")));
        }
        let declared = params[idx].range;
        let (lo, hi) = match (range, declared) {
            (Some(r), _) => r,
            (None, Some(r)) => r,
            (None, None) => {
                return Err(ParameterError::new_err(format!(
                    "samples: `{name}` has no declared range to sample from; give one ({name}: (lo, hi))"
                )))
            }
        };
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(ParameterError::new_err(format!(
                "samples: {name}: expected finite lo < hi, found ({lo}, {hi})"
            )));
        }
        if let Some((dlo, dhi)) = declared.filter(|(dlo, dhi)| lo < *dlo || hi > *dhi) {
            return Err(ParameterError::new_err(format!(
                "samples: {name} range ({lo}, {hi}) is outside its declared range [{dlo}, {dhi}]"
            )));
        }
        out.push((idx, lo, hi));
    }
    Ok(out)
}

/// The checks on `events` and `threads`, as `hybc sweep` makes them.
pub fn check_counts(events: usize, threads: usize) -> PyResult<()> {
    SweepRequest::check_counts(events, threads, Spelling::Keyword).map_err(PyValueError::new_err)
}

/// One column's values while they are gathered.
enum Column {
    Num(Vec<f64>),
    Count(Vec<i64>),
    Text(Vec<String>),
}

/// Runs the request's points (GIL released) and returns the columns of `hybc sweep`, in its
/// order.
pub fn run<'py>(
    py: Python<'py>,
    compiled: &hybc::Compiled,
    request: &SweepRequest,
) -> PyResult<Bound<'py, PyDict>> {
    let gathered = py.detach(|| -> Result<(Vec<String>, Vec<Column>), String> {
        let report =
            request.run(compiled, &|| ()).map_err(|e| format!("threads: {}", crate::errors::chain(&e)))?;
        let columns = gather(&report, request.threads)?;
        Ok((report.columns().header().to_vec(), columns))
    });
    let (header, gathered) = gathered.map_err(PyValueError::new_err)?;
    let dict = PyDict::new(py);
    for (name, column) in header.iter().zip(gathered) {
        match column {
            Column::Num(v) => dict.set_item(name, PyArray1::from_vec(py, v))?,
            Column::Count(v) => dict.set_item(name, PyArray1::from_vec(py, v))?,
            Column::Text(v) => dict.set_item(name, text_list(py, &v)?)?,
        }
    }
    Ok(dict)
}

/// The cells of every row, transposed into columns of the kinds the scheme gives them
/// (`Columns::kinds`); an empty cell is NaN, -1 or "".
fn gather(report: &SweepReport, threads: usize) -> Result<Vec<Column>, String> {
    let columns = report.columns();
    let (points, results) = (&report.points, &report.results);
    let mut out: Vec<Column> = columns
        .kinds()
        .iter()
        .map(|k| match k {
            CellKind::Num => Column::Num(Vec::with_capacity(points.len())),
            CellKind::Count => Column::Count(Vec::with_capacity(points.len())),
            CellKind::Text => Column::Text(Vec::with_capacity(points.len())),
        })
        .collect();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| format!("threads: cannot start {threads} worker threads: {e}"))?;
    for (ps, rs) in points.chunks(CELL_CHUNK).zip(results.chunks(CELL_CHUNK)) {
        let rows: Vec<Vec<Cell>> =
            pool.install(|| ps.par_iter().zip(rs).map(|(p, r)| columns.cells(p, r)).collect());
        for row in rows {
            debug_assert_eq!(row.len(), out.len());
            for (column, cell) in out.iter_mut().zip(row) {
                match (column, cell) {
                    (Column::Num(v), Cell::Num(x)) => v.push(x),
                    (Column::Num(v), _) => v.push(f64::NAN),
                    (Column::Count(v), Cell::Count(c)) => v.push(c as i64),
                    (Column::Count(v), _) => v.push(-1),
                    (Column::Text(v), Cell::Text(s)) => v.push(s),
                    (Column::Text(v), _) => v.push(String::new()),
                }
            }
        }
    }
    Ok(out)
}

/// A list of Python strings, each distinct text made once (statuses and event names repeat).
fn text_list<'py>(py: Python<'py>, values: &[String]) -> PyResult<Bound<'py, PyList>> {
    let mut made: HashMap<&str, Bound<'py, PyString>> = HashMap::new();
    let items: Vec<Bound<'py, PyString>> = values
        .iter()
        .map(|s| made.entry(s.as_str()).or_insert_with(|| PyString::new(py, s)).clone())
        .collect();
    PyList::new(py, items)
}
