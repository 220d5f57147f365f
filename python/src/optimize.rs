//! `Model.optimize`: the library's whole optimisation (`hybc::OptimizeRequest`, what
//! `hybc optimize` runs) from Python's arguments; the report comes back as the JSON
//! `hybc optimize --format json` prints (the Python layer adds the run at the optimum).

use std::collections::HashMap;

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use hybc::optimize::{OptimizeOptions, SolverChoice};
use hybc::{Error, OptimizeFailure, OptimizeRequest};

use crate::errors::{self, ParameterError};
use crate::model::Model;
use crate::options::SimKeywords;

/// Minimises `minimize` over `free` subject to `subject_to`, within the declared ranges narrowed
/// by `bounds`, from `params` (and `starts - 1` seeded starts); returns the report's JSON.
#[pyfunction]
#[pyo3(signature = (
    model, free, minimize, subject_to, bounds, params,
    max_iter, kkt_tol, xtol, ftol, starts, seed, threads,
    solver = "auto", shard = None, **sim))]
#[allow(clippy::too_many_arguments)]
pub fn optimize_report(
    py: Python<'_>,
    model: PyRef<'_, Model>,
    free: Vec<String>,
    minimize: String,
    subject_to: Vec<String>,
    bounds: Option<HashMap<String, (f64, f64)>>,
    params: Option<HashMap<String, f64>>,
    max_iter: usize,
    kkt_tol: f64,
    xtol: f64,
    ftol: f64,
    starts: usize,
    seed: u64,
    threads: usize,
    solver: &str,
    shard: Option<(usize, usize)>,
    sim: Option<&Bound<'_, PyDict>>,
) -> PyResult<String> {
    let keywords = SimKeywords::from_kwargs(sim)?;
    let sim = keywords.analysis_options(model.inner())?;
    if free.is_empty() {
        return Err(ParameterError::new_err("free: name at least one parameter to optimise"));
    }
    let count = |what: &str, v: usize, min: usize, max: usize| {
        hybc::limits::count(what, v, min, max).map_err(|e| PyValueError::new_err(e.to_string()))
    };
    count("max_iter", max_iter, 1, hybc::limits::MAX_OPTIMIZE_RUNS)?;
    count("starts", starts, 1, hybc::limits::MAX_STARTS)?;
    count("threads", threads, 0, hybc::limits::MAX_THREADS)?;
    for (name, v) in [("kkt_tol", kkt_tol), ("xtol", xtol), ("ftol", ftol)] {
        crate::options::positive(name, v)?;
    }
    let choice = SolverChoice::parse(solver).map_err(|e| PyValueError::new_err(format!("solver: {e}")))?;
    let boxes = free_boxes(&model, &free, bounds, choice, subject_to.len())?;
    let start = model.param_values(params)?.values().to_vec();
    let compiled = model.compiled(py, &free)?;
    if let Some((first, last)) = shard {
        if !(first < last && last <= starts) {
            return Err(PyValueError::new_err(format!(
                "shard: expected FIRST < LAST <= starts ({starts}), found ({first}, {last})"
            )));
        }
    }
    let options = OptimizeOptions { max_iter, kkt_tol, xtol, ftol, starts, seed, threads, shard };
    let report = py.detach(move || {
        let request = OptimizeRequest {
            minimize: &minimize,
            subject_to: &subject_to,
            bounds: boxes,
            start,
            sim,
            options,
            solver: choice,
        };
        request.run(&compiled, None)
    });
    match report {
        Ok(report) => Ok(report.to_json().to_string()),
        Err(Error::Optimize(OptimizeFailure::Objective(e))) => {
            Err(PyValueError::new_err(format!("minimize: {e}")))
        }
        Err(Error::Optimize(OptimizeFailure::Constraint(e))) => {
            Err(PyValueError::new_err(format!("subject_to: {e}")))
        }
        Err(Error::Optimize(OptimizeFailure::Solver(e))) => {
            Err(PyValueError::new_err(format!("solver: {e}")))
        }
        Err(Error::Optimize(OptimizeFailure::Refused(e))) => Err(PyRuntimeError::new_err(e.to_string())),
        Err(e) => Err(errors::to_py(e)),
    }
}

/// The box of every free parameter: declared ranges narrowed by `bounds`. The free parameters
/// are counted against the cap of the solver `choice` runs with `constraints` constraints, and
/// `lbfgsb` with constraints is refused, before anything is compiled (as `hybc optimize` does).
fn free_boxes(
    model: &Model,
    free: &[String],
    bounds: Option<HashMap<String, (f64, f64)>>,
    choice: SolverChoice,
    constraints: usize,
) -> PyResult<Vec<hybc::fit::Bounds>> {
    let inner = model.inner();
    let free_idx = inner.param_list(free).map_err(|e| errors::to_py(e.into()))?;
    let (cap, solver) = choice.cap(constraints > 0);
    hybc::limits::count(
        &format!("free (parameters, vector elements counted; the cap of {solver})"),
        free_idx.len(),
        1,
        cap,
    )
    .map_err(|e| PyValueError::new_err(e.to_string()))?;
    choice.pick(free_idx.len(), constraints).map_err(|e| PyValueError::new_err(format!("solver: {e}")))?;
    let mut narrow: Vec<(String, f64, f64)> =
        bounds.unwrap_or_default().into_iter().map(|(name, (lo, hi))| (name, lo, hi)).collect();
    narrow.sort_by(|a, b| a.0.cmp(&b.0));
    OptimizeRequest::bounds(inner, &free_idx, &narrow)
        .map_err(|e| PyValueError::new_err(format!("bounds: {e}")))
}

/// The report of a whole multi-start from the JSON reports of its shards (in start order), as
/// `hybc::optimize::merge_shards`: what one process running every start reports.
#[pyfunction]
pub fn optimize_merge(
    model: PyRef<'_, Model>,
    free: Vec<String>,
    bounds: Option<HashMap<String, (f64, f64)>>,
    reports: Vec<String>,
) -> PyResult<String> {
    // The shards ran; the merge only needs the boxes (no solver picks here: the widest cap).
    let boxes = free_boxes(&model, &free, bounds, SolverChoice::Lbfgsb, 0)?;
    let shards = reports
        .iter()
        .map(|r| serde_json::from_str(r).map_err(|e| PyValueError::new_err(format!("reports: {e}"))))
        .collect::<PyResult<Vec<serde_json::Value>>>()?;
    let merged = hybc::optimize::merge_shards(&shards, &boxes).map_err(PyValueError::new_err)?;
    Ok(merged.to_string())
}
