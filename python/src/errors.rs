//! The exception classes of `hybc` and how the library's errors map onto them.
//!
//! - `ModelError` (a `ValueError`): the model text does not parse or check, or an SBML document
//!   is refused; the message is the rendered diagnostic (file:line:column, the line, a caret; for
//!   SBML the element refused).
//! - `ParameterError` (a `ValueError`): an unknown parameter name, a value outside its declared
//!   range or not finite, a name given twice.
//! - `ValueError`: simulation options refused before running (a negative tolerance, ...).
//! - `OSError`: a model file that cannot be read.
//!
//! A run that ends early (Zeno, a fault, max_events) is not an exception: it is a `Run` whose
//! `stopped_by` and `error` say why (so a sweep keeps its other points).

use pyo3::create_exception;
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;

create_exception!(hybc, ModelError, PyValueError, "The model text does not parse or check.");
create_exception!(hybc, ParameterError, PyValueError, "A parameter name or value the model refuses.");

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("ModelError", py.get_type::<ModelError>())?;
    m.add("ParameterError", py.get_type::<ParameterError>())?;
    Ok(())
}

/// The Python exception for a library error.
pub fn to_py(error: hybc::Error) -> PyErr {
    match error {
        hybc::Error::Model(e) => ModelError::new_err(e.rendered),
        hybc::Error::Import(e) => ModelError::new_err(e.rendered),
        hybc::Error::Param(e) => ParameterError::new_err(e.to_string()),
        hybc::Error::Read { .. } | hybc::Error::TooLarge { .. } => PyOSError::new_err(chain(&error)),
        other => PyValueError::new_err(chain(&other)),
    }
}

/// The message with its causes, `a: b: c`.
pub fn chain(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(e) = source {
        text.push_str(": ");
        text.push_str(&e.to_string());
        source = e.source();
    }
    text
}
