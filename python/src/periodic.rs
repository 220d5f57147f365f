//! `Model.periodic`: the library's orbit search (`hybc::PeriodicRequest`, what `hybc periodic`
//! runs) from Python's arguments; the report comes back as the JSON `hybc periodic --format
//! json` prints.

use std::collections::HashMap;

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use hybc::periodic::{self, PeriodicError, Search};
use hybc::{Error, PeriodicRequest};

use crate::errors;
use crate::model::Model;
use crate::options::SimKeywords;

/// Finds the orbit through the section `section` (`EVENT` or `EVENT#K`) whose initial state the
/// parameters `free` set, from `params` (their start and the other parameters' values); returns
/// the report's JSON. The checks and their order are `hybc periodic`'s.
#[pyfunction]
#[pyo3(signature = (model, section, free, params, max_iter, tol, **sim))]
#[allow(clippy::too_many_arguments)]
pub fn periodic_report(
    py: Python<'_>,
    model: PyRef<'_, Model>,
    section: &str,
    free: Vec<String>,
    params: Option<HashMap<String, f64>>,
    max_iter: usize,
    tol: f64,
    sim: Option<&Bound<'_, PyDict>>,
) -> PyResult<String> {
    let keywords = SimKeywords::from_kwargs(sim)?;
    let inner = model.inner().clone();
    let free = inner.param_list(&free).map_err(|e| errors::to_py(e.into()))?;
    hybc::limits::count("max_iter", max_iter, 0, hybc::limits::MAX_FIT_ITER)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    let (section, firing) =
        periodic::parse_section(section).map_err(|e| PyValueError::new_err(format!("section: {e}")))?;
    let search = Search {
        free,
        params: model.param_values(params)?.values().to_vec(),
        sim: keywords.options(&inner)?,
        max_iter,
        tol: crate::options::positive("tol", tol)?,
    };
    let request = PeriodicRequest { section, firing, search };
    match py.detach(|| request.run(&inner)) {
        Ok(report) => Ok(report.to_json().to_string()),
        Err(Error::Periodic(
            e @ (PeriodicError::NoSection { .. }
            | PeriodicError::NoFree
            | PeriodicError::BadFiring { .. }
            | PeriodicError::BadSection { .. }),
        )) => Err(PyValueError::new_err(format!("section/free: {e}"))),
        // No orbit found: the run missed the section, Newton did not converge, its point failed
        // the check by a run of the model, the Jacobian is not finite (`hybc periodic` exits 3 or
        // 4). The error carries the JSON `hybc periodic --format json` prints then, as `report`.
        Err(e @ Error::Periodic(_)) => {
            let err = PyRuntimeError::new_err(e.to_string());
            if let Some(json) = request.failure_json(&inner, &e) {
                err.value(py).setattr("report", json.to_string())?;
            }
            Err(err)
        }
        Err(e) => Err(errors::to_py(e)),
    }
}
