//! `Model.fit`: the library's whole fit (`hybc::FitRequest`, what `hybc fit` runs) from Python's
//! arguments. The Python layer turns a DataFrame-like mapping into the CSV text `hybc fit --data`
//! reads, so one parser gives both front ends the same rules and messages; the report comes back
//! as the JSON `hybc fit --format json` prints.

use std::collections::HashMap;

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use hybc::fit::FitOptions;
use hybc::{Error, FitFailure, FitRequest};

use crate::errors::{self, ParameterError};
use crate::model::Model;
use crate::options::SimKeywords;

/// Fits `free` to `targets` (`NAME=VALUE[@W]`) and the measurements of `data` (CSV text) from
/// `params` (start values and fixed values); returns the report's JSON and the warnings.
#[pyfunction]
#[pyo3(signature = (
    model, free, targets, data, params,
    max_iter, xtol, gtol, ftol, **sim))]
#[allow(clippy::too_many_arguments)]
pub fn fit_report(
    py: Python<'_>,
    model: PyRef<'_, Model>,
    free: Vec<String>,
    targets: Vec<String>,
    data: Option<String>,
    params: Option<HashMap<String, f64>>,
    max_iter: usize,
    xtol: f64,
    gtol: f64,
    ftol: f64,
    sim: Option<&Bound<'_, PyDict>>,
) -> PyResult<(String, Vec<String>)> {
    let keywords = SimKeywords::from_kwargs(sim)?;
    let inner = model.inner();
    let sim = keywords.analysis_options(inner)?;
    if free.is_empty() {
        return Err(ParameterError::new_err("free: name at least one parameter to fit"));
    }
    if targets.is_empty() && data.is_none() {
        return Err(PyValueError::new_err("fit: give targets= or data= (or both)"));
    }
    if max_iter == 0 || max_iter > hybc::limits::MAX_FIT_ITER {
        return Err(PyValueError::new_err(format!(
            "max_iter: expected 1 to {}, found {max_iter}",
            hybc::limits::MAX_FIT_ITER
        )));
    }
    for (name, v) in [("xtol", xtol), ("gtol", gtol), ("ftol", ftol)] {
        crate::options::positive(name, v)?;
    }
    let start = model.param_values(params)?.values().to_vec();
    let compiled = model.compiled(py, &free)?;
    let options = FitOptions { max_iter, xtol, gtol, ftol };
    let (report, warnings) = py.detach(move || {
        let request = FitRequest {
            targets: &targets,
            data: data.as_deref().map(|text| (text, "data")),
            start,
            sim,
            options,
        };
        let mut warnings = Vec::new();
        let report = request.run(&compiled, &mut |w| warnings.push(w.to_string()));
        (report, warnings)
    });
    match report {
        Ok(report) => Ok((report.to_json().to_string(), warnings)),
        Err(Error::Fit(FitFailure::Target(e))) => Err(PyValueError::new_err(format!("targets: {e}"))),
        Err(Error::Fit(FitFailure::Data(e))) => Err(PyValueError::new_err(format!("data: {e}"))),
        Err(Error::Fit(FitFailure::StartRun(e) | FitFailure::StartObjective(e))) => {
            Err(PyRuntimeError::new_err(e.to_string()))
        }
        Err(e) => Err(errors::to_py(e)),
    }
}
