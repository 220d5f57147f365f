//! Keyword arguments of `simulate`, `sweep`, `sobol`, `fit`, `optimize` and `hybc.jax` to
//! `SimOptions`: the keywords only fill a `hybc::SimOverrides`, which the library lays over the
//! model's `simulate` line and checks as it checks `hybc run`'s flags (the same words, the option
//! named as the keyword).

use pyo3::conversion::FromPyObjectOwned;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use hybc::{SimOptions, SimOverrides, Spelling, TrajectoryRequest};

/// The simulation keywords shared by every entry point, read from the `**options` of the call
/// (one parser, so that every entry point takes the same keywords); unset ones keep the model's
/// value. `at=` is `simulate`'s own argument, and `linear_solver` is the library's only.
#[derive(Clone, Debug, Default)]
pub struct SimKeywords {
    overrides: SimOverrides,
}

/// The keywords [`SimKeywords::from_kwargs`] takes, in the order an error lists them: the
/// library's options but those above.
fn keywords() -> impl Iterator<Item = &'static str> {
    SimOverrides::OPTIONS.into_iter().filter(|o| !matches!(*o, "at" | "of" | "linear_solver"))
}

/// `v` if it is a finite number above 0, else a `ValueError` in the command line's words
/// (`hybc::positive_number`).
pub fn positive(name: &str, v: f64) -> PyResult<f64> {
    hybc::positive_number(name, v).map_err(PyValueError::new_err)
}

fn value_error(e: hybc::OptionError) -> PyErr {
    PyValueError::new_err(e.message)
}

impl SimKeywords {
    /// The keywords in `kwargs` (a call's `**options`); an unknown one is a `TypeError` naming
    /// the known ones, a value of the wrong type one naming the keyword. `None` values are unset.
    pub fn from_kwargs(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<SimKeywords> {
        let mut out = SimOverrides::default();
        let Some(kwargs) = kwargs else { return Ok(SimKeywords { overrides: out }) };
        for (key, value) in kwargs.iter() {
            let key: String = key.extract()?;
            if value.is_none() {
                continue;
            }
            fn get<'py, T: FromPyObjectOwned<'py>>(
                key: &str,
                value: &Bound<'py, PyAny>,
            ) -> PyResult<Option<T>> {
                value.extract().map(Some).map_err(|_| {
                    let found = value.get_type().name().map_or_else(|_| "?".to_string(), |n| n.to_string());
                    PyTypeError::new_err(format!(
                        "{key}: expected {}, found {found}",
                        std::any::type_name::<T>()
                    ))
                })
            }
            match key.as_str() {
                "t_start" => out.t_start = get(&key, &value)?,
                "t_end" => out.t_end = get(&key, &value)?,
                "rtol" => out.rtol = get(&key, &value)?,
                "atol" => out.atol = get(&key, &value)?,
                "max_events" => out.max_events = get(&key, &value)?,
                "max_steps" => out.max_steps = get(&key, &value)?,
                "method" => {
                    let name: Option<String> = get(&key, &value)?;
                    out.method = name
                        .map(|name| hybc::method_named(&name, Spelling::Keyword))
                        .transpose()
                        .map_err(value_error)?;
                }
                "graze_tol" => out.graze_tol = get(&key, &value)?,
                "sens_error_control" => out.sens_error_control = get(&key, &value)?,
                "quadrature_error_control" => out.quadrature_error_control = get(&key, &value)?,
                "land_events" => out.land_events = get(&key, &value)?,
                "h_max" => out.h_max = get(&key, &value)?,
                "sens" => {
                    let name: Option<String> = get(&key, &value)?;
                    out.sens = name
                        .map(|name| hybc::sens_named(&name, Spelling::Keyword))
                        .transpose()
                        .map_err(value_error)?;
                }
                _ => {
                    return Err(PyTypeError::new_err(format!(
                        "unexpected keyword argument '{key}' (the simulation keywords are {})",
                        keywords().collect::<Vec<_>>().join(", ")
                    )))
                }
            }
        }
        Ok(SimKeywords { overrides: out })
    }

    /// The options of a run of `model` with these keywords, checked by the library.
    pub fn options(&self, model: &hybc::Model) -> PyResult<SimOptions> {
        self.overrides.apply(&model.sim_options(), Spelling::Keyword).map_err(value_error)
    }

    /// [`Self::options`] for `sweep`, `fit` and `optimize`, whose gradients default to the cheaper mode
    /// (`hybc::Model::analysis_sim_options`).
    pub fn analysis_options(&self, model: &hybc::Model) -> PyResult<SimOptions> {
        self.overrides.apply(&model.analysis_sim_options(), Spelling::Keyword).map_err(value_error)
    }

    /// [`Self::options`] with the sample times of `at=` (`hybc run --at`), their order and range
    /// checked by the library against the run's span.
    pub fn options_at(&self, model: &hybc::Model, at: Option<Vec<f64>>) -> PyResult<SimOptions> {
        let overrides = SimOverrides { at, ..self.overrides.clone() };
        overrides.apply(&model.sim_options(), Spelling::Keyword).map_err(value_error)
    }

    /// Sets `opts.of` from `of=` (`hybc run --of`), resolved against the compiled model's names
    /// by the library (a `NAME@TIME` adds its sample time).
    pub fn gradients_of(
        of: Option<Vec<String>>,
        info: &hybc::sim::SystemInfo,
        opts: &mut SimOptions,
    ) -> PyResult<()> {
        let overrides = SimOverrides { of, ..SimOverrides::default() };
        overrides.gradients_of(info, opts, Spelling::Keyword).map_err(value_error)
    }
}

/// `trajectory=None` (none), `"steps"` (every accepted step and both sides of every event) or a
/// positive number `dt` (samples at every multiple of `dt`).
pub fn trajectory_request(value: Option<&Bound<'_, PyAny>>) -> PyResult<TrajectoryRequest> {
    let Some(value) = value.filter(|v| !v.is_none()) else {
        return Ok(TrajectoryRequest::None);
    };
    if let Ok(text) = value.extract::<String>() {
        return match text.as_str() {
            "steps" => Ok(TrajectoryRequest::Steps),
            _ => Err(PyValueError::new_err(format!(
                "trajectory: expected None, \"steps\" or a sampling interval dt > 0, found {text:?}"
            ))),
        };
    }
    match value.extract::<f64>() {
        Ok(dt) => Ok(TrajectoryRequest::Every(positive("trajectory", dt)?)),
        Err(_) => Err(PyValueError::new_err(format!(
            "trajectory: expected None, \"steps\" or a sampling interval dt > 0, found {}",
            value.repr().map(|r| r.to_string()).unwrap_or_default()
        ))),
    }
}
