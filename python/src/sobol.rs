//! `Model.sobol` and `hybc.dask.sobol`: the library's Saltelli design and estimators
//! (`hybc::sobol`) behind three calls the Python layer composes. `design` turns SALib's `problem`
//! (already normalised to `(name, dist, bounds)` triples by python/hybc/_model.py) into a
//! `Design`; `evaluate` runs rows `[start, stop)` of it (a whole design, or one Dask shard: every
//! row is computed from its index, so the shards put end to end are the whole design bit for bit);
//! `analyze` turns the values of all rows into indices. Nothing here estimates anything itself.

use std::collections::HashMap;

use numpy::{PyArray1, PyArray2, PyArrayMethods as _, PyReadonlyArray2, PyUntypedArrayMethods as _};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use hybc::limits::{MAX_BOOTSTRAP, MAX_SOBOL_BASE_POINTS};
use hybc::sobol::{Analysis, AnalysisError, Design, OnFail, Output, Prior, Z_95};
use hybc::{Error, SobolFailure, SobolRequest, VaryPriorError};

use crate::errors::ParameterError;

/// One varied parameter as the Python layer passes it: name, SALib's distribution name, bounds.
pub type PriorArg = (String, String, Vec<f64>);

/// The prior SALib's `dists` entry `dist` with `bounds` describes. SALib's names: `unif` and
/// `logunif` take `[lower, upper]`, `norm` `[mean, sd]`, `lognorm` the mean and sd of the log.
fn prior(i: usize, name: &str, dist: &str, bounds: &[f64]) -> PyResult<Prior> {
    let (make, what): (fn(f64, f64) -> Prior, &str) = match dist {
        "unif" => (|lo, hi| Prior::Uniform { lo, hi }, "[lower, upper]"),
        "logunif" => (|lo, hi| Prior::LogUniform { lo, hi }, "[lower, upper]"),
        "norm" => (|mu, sigma| Prior::Normal { mu, sigma }, "[mean, standard deviation]"),
        "lognorm" => (|mu, sigma| Prior::LogNormal { mu, sigma }, "[mean, standard deviation] of the log"),
        _ => {
            let known = "\"unif\", \"logunif\", \"norm\" and \"lognorm\" (SALib's names)";
            return Err(ParameterError::new_err(format!(
                "problem: dists[{i}] = {dist:?} for `{name}`: hybc's priors are {known}"
            )));
        }
    };
    let &[a, b] = bounds else {
        return Err(ParameterError::new_err(format!(
            "problem: bounds[{i}] for `{name}` ({dist}): expected 2 numbers {what}, found {}",
            bounds.len()
        )));
    };
    let prior = make(a, b);
    prior.check().map_err(|problem| {
        ParameterError::new_err(format!("problem: bounds[{i}] = [{a}, {b}] for `{name}` ({dist}): {problem}"))
    })?;
    Ok(prior)
}

/// The design `problem` describes over `model`'s parameters (the others from `fixed`, else their
/// defaults), checked as `hybc sobol` checks its flags.
pub fn design(
    model: &hybc::Model,
    base: Vec<f64>,
    fixed: &HashMap<String, f64>,
    priors: &[PriorArg],
    n: usize,
    second_order: bool,
    seed: u64,
) -> PyResult<Design> {
    hybc::limits::count("n", n, 2, MAX_SOBOL_BASE_POINTS)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    let mut varied: Vec<(usize, Prior)> = Vec::with_capacity(priors.len());
    for (i, (name, dist, bounds)) in priors.iter().enumerate() {
        let given = prior(i, name, dist, bounds)?;
        let (idx, prior) = SobolRequest::vary(model, name, Some(given)).map_err(|e| match e {
            VaryPriorError::Param(e) => ParameterError::new_err(format!("problem: {e}")),
            other => ParameterError::new_err(format!("problem: `{name}` ({dist}): {other}")),
        })?;
        if varied.iter().any(|v| v.0 == idx) {
            return Err(ParameterError::new_err(format!("problem: `{name}` is named twice")));
        }
        if fixed.contains_key(name) {
            return Err(ParameterError::new_err(format!("`{name}` is given both in problem and in fixed")));
        }
        varied.push((idx, prior));
    }
    let design = Design::new(base, varied, n, second_order, seed)
        .map_err(|e| ParameterError::new_err(format!("problem: {e}")))?;
    SobolRequest::rows(&design).map_err(|e| PyValueError::new_err(format!("n: {e}")))?;
    Ok(design)
}

/// The varied parameters' values at rows `[start, stop)`: SALib's `X`, one row per run.
pub fn rows<'py>(
    py: Python<'py>,
    design: &Design,
    start: usize,
    stop: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    check_range(design, start, stop)?;
    let d = design.d();
    let flat = py.detach(|| {
        let mut p = vec![0.0; design.width()];
        let mut flat = Vec::with_capacity((stop - start) * d);
        for r in start..stop {
            design.fill(r, &mut p);
            flat.extend(design.varied().iter().map(|(idx, _)| p[*idx]));
        }
        flat
    });
    PyArray1::from_vec(py, flat).reshape([stop - start, d])
}

fn check_range(design: &Design, start: usize, stop: usize) -> PyResult<()> {
    let rows = design.rows().unwrap_or(usize::MAX);
    if start > stop || stop > rows {
        return Err(PyValueError::new_err(format!("rows {start}..{stop} of a design of {rows}")));
    }
    Ok(())
}

/// The request's outputs (`energy`, `touchdown#2`, `touchdown#last`) parsed against `compiled`,
/// and the check that the whole design's values fit the cap of what an analysis keeps.
pub fn outputs(compiled: &hybc::Compiled, request: &SobolRequest<'_>) -> PyResult<Vec<Output>> {
    request.outputs(compiled).map_err(refused)
}

/// A refusal of the request, named by the keyword it is about.
fn refused(e: Error) -> PyErr {
    match e {
        Error::Sobol(e @ (SobolFailure::NoOutputs | SobolFailure::Output(_))) => {
            PyValueError::new_err(format!("outputs: {e}"))
        }
        Error::Sobol(e @ (SobolFailure::TooManyRuns { .. } | SobolFailure::TooManyValues { .. })) => {
            PyValueError::new_err(format!("n: {e}"))
        }
        Error::Sobol(SobolFailure::Pool(e)) => {
            PyValueError::new_err(format!("threads: {}", crate::errors::chain(&e)))
        }
        e => crate::errors::to_py(e),
    }
}

/// What `evaluate` returns to Python: the values of rows `[start, stop)` (one row per run, one
/// column per output, NaN where a row has no value), the runs that ended early by status word,
/// and the first such row (0-based, of the whole design).
pub type Evaluated<'py> = (Bound<'py, PyArray2<f64>>, Vec<(String, usize)>, Option<usize>);

/// Runs rows `[start, stop)` of the request's design (GIL released).
pub fn evaluate<'py>(
    py: Python<'py>,
    compiled: &hybc::Compiled,
    request: &SobolRequest<'_>,
    outputs: &[Output],
    range: (usize, usize),
) -> PyResult<Evaluated<'py>> {
    let (start, stop) = range;
    check_range(&request.design, start, stop)?;
    let evaluated =
        py.detach(|| request.evaluate(compiled, outputs, start..stop, &|| ())).map_err(refused)?;
    let early = evaluated.ended_early.iter().map(|(w, c)| (w.to_string(), *c)).collect();
    let values = PyArray1::from_vec(py, evaluated.values).reshape([stop - start, outputs.len()])?;
    Ok((values, early, evaluated.first_ended_early))
}

/// The indices of every column of `values` (all rows of a design with `d` varied parameters, in
/// row order), each as a dict with SALib's keys, or `{"error": message}` for an output its
/// policy refused.
#[pyfunction]
#[pyo3(signature = (values, labels, d, second_order, on_fail, bootstrap, seed))]
#[allow(clippy::too_many_arguments)]
pub fn sobol_analyze<'py>(
    py: Python<'py>,
    values: PyReadonlyArray2<'py, f64>,
    labels: Vec<String>,
    d: usize,
    second_order: bool,
    on_fail: &str,
    bootstrap: usize,
    seed: u64,
) -> PyResult<Bound<'py, PyList>> {
    let on_fail = OnFail::parse(on_fail).ok_or_else(|| {
        PyValueError::new_err(format!(
            "on_fail: expected \"error\", \"drop\" or \"value=X\" with X a finite number, found {on_fail:?}"
        ))
    })?;
    hybc::limits::count("bootstrap", bootstrap, 0, MAX_BOOTSTRAP)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    if bootstrap == 1 {
        return Err(PyValueError::new_err(
            "bootstrap: 1 resample has no spread; give 0 (no intervals) or at least 2",
        ));
    }
    let (rows, k) = (values.shape()[0], values.shape()[1]);
    let block = if second_order { 2 * d + 2 } else { d + 2 };
    if k != labels.len() || d == 0 || rows % block != 0 {
        return Err(PyValueError::new_err(format!(
            "values: {rows} x {k} for {} outputs and blocks of {block} rows",
            labels.len()
        )));
    }
    let values =
        values.as_slice().map_err(|_| PyValueError::new_err("values: expected a C-ordered array"))?;
    let how = Analysis { d, second_order, on_fail, bootstrap, seed };
    let results = py.detach(|| how.outputs(&labels, values));
    let list = PyList::empty(py);
    for result in results {
        let dict = PyDict::new(py);
        match result {
            Err(e) => dict.set_item("error", python_message(&e))?,
            Ok(r) => {
                dict.set_item("S1", PyArray1::from_slice(py, &r.indices.s1))?;
                if let Some(e) = &r.errors {
                    dict.set_item("S1_conf", conf(py, &e.s1))?;
                }
                dict.set_item("ST", PyArray1::from_slice(py, &r.indices.st))?;
                if let Some(e) = &r.errors {
                    dict.set_item("ST_conf", conf(py, &e.st))?;
                }
                if second_order {
                    // A D x D matrix with NaN off the upper triangle, as SALib's S2.
                    let matrix = |pick: &dyn Fn(usize) -> f64| -> PyResult<Bound<'py, PyArray2<f64>>> {
                        let mut m = vec![f64::NAN; d * d];
                        for (at, (i, j, _)) in r.indices.s2.iter().enumerate() {
                            m[i * d + j] = pick(at);
                        }
                        PyArray1::from_vec(py, m).reshape([d, d])
                    };
                    dict.set_item("S2", matrix(&|at| r.indices.s2[at].2)?)?;
                    if let Some(e) = &r.errors {
                        dict.set_item("S2_conf", matrix(&|at| Z_95 * e.s2[at].2)?)?;
                    }
                }
                dict.set_item("variance", r.indices.variance)?;
                dict.set_item("failed_rows", r.failed_rows)?;
                dict.set_item("dropped_base_points", r.dropped_points)?;
                dict.set_item("base_points", r.used_points)?;
            }
        }
        list.append(dict)?;
    }
    Ok(list)
}

fn conf<'py>(py: Python<'py>, se: &[f64]) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_vec(py, se.iter().map(|s| Z_95 * s).collect())
}

/// The library's message in the keyword's words (`on_fail=`, not `--on-fail`).
fn python_message(e: &AnalysisError) -> String {
    match e {
        AnalysisError::Failed { label, failed_rows, rows, first_row } => format!(
            "output `{label}`: {failed_rows} of {rows} rows have no value (the first is row {first_row}, \
             1-based); choose on_fail=\"drop\" or on_fail=\"value=X\" to analyse anyway"
        ),
        other => other.to_string(),
    }
}
