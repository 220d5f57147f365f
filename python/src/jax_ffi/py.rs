//! What `hybc/jax.py` calls: the handler's address (to register it as an XLA FFI target) and the
//! registration of a function (model, inputs, value columns, event slots, options) in the
//! process-wide registry, which returns the handle every call passes as an attribute.

use std::collections::HashMap;

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::function::{Engine, Function, Input, Selector};
use super::{handler, registry};
use crate::errors;
use crate::model::Model;
use crate::options::SimKeywords;

/// The most numbers (values and their Jacobian entries) one point of a function returns: 10^7,
/// 80 MB per point, which XLA allocates per call.
const MAX_VALUES_PER_POINT: f64 = 1e7;

/// The address of the FFI handler, for `jax.ffi.pycapsule`.
#[pyfunction]
pub fn jax_handler_address() -> usize {
    handler::hybc_jax_handler as *const () as usize
}

/// Registers a function and returns its handle (an existing one for an identical configuration).
///
/// `params`: the input parameters, in input order; `columns`: outputs or states read at the end;
/// `events`: event slots; `values`: values of other parameters (defaults otherwise); `at`: sample
/// times at which the columns are read too.
#[pyfunction]
#[pyo3(signature = (
    model, params, columns, events, values, at = None, **sim,
))]
#[allow(clippy::too_many_arguments)]
pub fn jax_register(
    py: Python<'_>,
    model: PyRef<'_, Model>,
    params: Vec<String>,
    columns: Vec<String>,
    events: usize,
    values: HashMap<String, f64>,
    at: Option<Vec<f64>>,
    sim: Option<&Bound<'_, PyDict>>,
) -> PyResult<u64> {
    let keywords = SimKeywords::from_kwargs(sim)?;
    // Each slot is a row of every output's Jacobian too: the cap of `hybc sweep --events`.
    hybc::limits::count("events", events, 0, hybc::limits::MAX_EVENT_COLUMNS)
        .map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()))?;
    let inner = model.inner();
    let mut opts = keywords.options_at(inner, at)?;
    // Every point's buffers hold each column at the end and at each time, with a Jacobian row
    // per column and time: bounded like `hybc sweep`'s event columns times the sampled rows.
    let per_point = (columns.len() * (1 + opts.at.len())) as f64 * (1 + params.len()) as f64;
    if per_point > MAX_VALUES_PER_POINT {
        return Err(PyValueError::new_err(format!(
            "at: {} times of {} columns with {} inputs make {per_point:.0} numbers per point, at most \
             {MAX_VALUES_PER_POINT:.0}",
            opts.at.len(),
            columns.len(),
            params.len()
        )));
    }
    let checked = inner.checked();

    let mut inputs = Vec::with_capacity(params.len());
    for name in &params {
        let idx = inner.param_index(name).map_err(|e| errors::to_py(e.into()))?.0 as usize;
        if inputs.iter().any(|i: &Input| i.index == idx) {
            return Err(errors::ParameterError::new_err(format!(
                "parameter `{name}` is given twice in params"
            )));
        }
        inputs.push(Input { index: idx, name: name.clone(), range: checked.params[idx].range });
    }
    let mut base = inner.params();
    let mut fixed: Vec<(&String, &f64)> = values.iter().collect();
    fixed.sort_by(|a, b| a.0.cmp(b.0));
    for (name, &value) in &fixed {
        if params.contains(name) {
            return Err(errors::ParameterError::new_err(format!(
                "parameter `{name}` is an input (in params) and cannot also have a fixed value"
            )));
        }
        base.set(name, value).map_err(|e| errors::to_py(e.into()))?;
    }
    let selectors = columns.iter().map(|name| selector(py, &model, name)).collect::<PyResult<Vec<_>>>()?;
    if let Some(i) = selectors.iter().position(|s| s.is_event()).filter(|_| !opts.at.is_empty()) {
        return Err(PyValueError::new_err(format!(
            "outputs: `{}` is an event's time, which has no value at the `at=` times: read it from a \
             function without `at=`",
            columns[i]
        )));
    }

    let key =
        format!("{:?}", (inner.file_name(), inner.source(), &params, &columns, events, base.values(), &opts));
    if let Some(handle) = registry::find(&key) {
        return Ok(handle);
    }
    // `sens` chooses how reverse mode pulls cotangents back; every run the engines make computes
    // forward sensitivities or none (the adjoint is called by the function itself, per pull-back).
    let reverse = std::mem::replace(&mut opts.sens, hybc::Sens::Forward);
    let plain = model.compiled(py, &[])?;
    let with_jacobians = model.compiled(py, &params)?;
    let base = base.values().to_vec();
    let function = py
        .detach(move || -> Result<Function, hybc::Error> {
            Ok(Function::new(
                inner_name(&plain),
                inputs,
                base,
                selectors,
                events,
                Engine::new(plain, opts.clone())?,
                Engine::new(with_jacobians, opts)?,
                reverse,
            ))
        })
        .map_err(errors::to_py)?;
    Ok(registry::insert(key, function))
}

/// How many points each kind of native work of the function `handle` ran: `plain` (values),
/// `forward` (with forward sensitivities), `adjoint` (cotangents pulled back by the adjoint),
/// `recorded` (runs recorded for the adjoint, also those it then did not carry), `transposed`
/// (pulled back through the forward Jacobians). A debug accessor for the tests.
#[pyfunction]
pub fn jax_counts(handle: u64) -> PyResult<HashMap<&'static str, u64>> {
    let function = registry::get(handle)
        .ok_or_else(|| PyValueError::new_err(format!("no hybc.jax function {handle}")))?;
    Ok(function.counts().snapshot().into_iter().collect())
}

fn inner_name(compiled: &hybc::Compiled) -> String {
    format!("model `{}`", compiled.model().name())
}

/// An output or a state, by name (outputs first: a model cannot declare both with one name), or
/// an event's firing, `EVENT#K` (K from 1) or `EVENT#last`, as `hybc fit` and `hybc sobol` spell
/// it (an event family's element counts its own firings: `low[1]#2`).
fn selector(py: Python<'_>, native: &Model, name: &str) -> PyResult<Selector> {
    let model = native.inner();
    if name.contains('#') {
        let plain = native.compiled(py, &[])?;
        let parsed = hybc::fit::Observable::parse(name, plain.info())
            .map_err(|e| PyValueError::new_err(format!("outputs: {e}")))?;
        return match parsed {
            hybc::fit::Observable::EventTime { name_event, occurrence } => {
                Ok(Selector::EventTime { event: name_event, occurrence })
            }
            hybc::fit::Observable::LastFiring { name_event } => {
                Ok(Selector::LastFiring { event: name_event })
            }
            _ => Err(PyValueError::new_err(format!("outputs: `{name}` is not EVENT#K or EVENT#last"))),
        };
    }
    if let Some(i) = model.output_names().position(|o| o == name) {
        return Ok(Selector::Output(i));
    }
    if let Some(i) = model.state_names().position(|s| s == name) {
        return Ok(Selector::State(i));
    }
    let known: Vec<&str> = model.output_names().chain(model.state_names()).collect();
    Err(PyValueError::new_err(format!(
        "outputs: model `{}` has no output or state `{name}` (it has: {})",
        model.name(),
        known.join(", ")
    )))
}
