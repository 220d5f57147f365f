//! Keyword arguments of `simulate` and `sweep` to `SimOptions`: the model's `simulate` line over
//! the run defaults, then the keywords, checked as `hybc run` checks its flags (the message names
//! the keyword and the value).

use pyo3::conversion::FromPyObjectOwned;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use hybc::{Method, SimOptions, TrajectoryRequest};

/// The simulation keywords shared by `simulate`, `sweep`, `sobol`, `fit` and `optimize`, read
/// from the `**options` of the call (one parser, so that every entry point takes the same
/// keywords with the same checks); `None` keeps the model's value.
#[derive(Clone, Debug, Default)]
pub struct SimKeywords {
    pub t_start: Option<f64>,
    pub t_end: Option<f64>,
    pub rtol: Option<f64>,
    pub atol: Option<f64>,
    pub max_events: Option<usize>,
    pub max_steps: Option<usize>,
    pub method: Option<String>,
    pub graze_tol: Option<f64>,
    pub sens_error_control: Option<bool>,
    pub quadrature_error_control: Option<bool>,
    pub land_events: Option<bool>,
    pub h_max: Option<f64>,
}

/// The keywords [`SimKeywords::from_kwargs`] takes, in the order an error lists them.
const KEYWORDS: [&str; 12] = [
    "t_end",
    "rtol",
    "atol",
    "max_events",
    "max_steps",
    "method",
    "graze_tol",
    "sens_error_control",
    "quadrature_error_control",
    "land_events",
    "h_max",
    "t_start",
];

fn positive(name: &str, v: f64) -> PyResult<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(PyValueError::new_err(format!("{name}: expected a positive finite number, found {v}")))
    }
}

impl SimKeywords {
    /// The keywords in `kwargs` (a call's `**options`); an unknown one is a `TypeError` naming
    /// the known ones, a value of the wrong type one naming the keyword. `None` values are unset.
    pub fn from_kwargs(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<SimKeywords> {
        let mut out = SimKeywords::default();
        let Some(kwargs) = kwargs else { return Ok(out) };
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
                "method" => out.method = get(&key, &value)?,
                "graze_tol" => out.graze_tol = get(&key, &value)?,
                "sens_error_control" => out.sens_error_control = get(&key, &value)?,
                "quadrature_error_control" => out.quadrature_error_control = get(&key, &value)?,
                "land_events" => out.land_events = get(&key, &value)?,
                "h_max" => out.h_max = get(&key, &value)?,
                _ => {
                    return Err(PyTypeError::new_err(format!(
                        "unexpected keyword argument '{key}' (the simulation keywords are {})",
                        KEYWORDS.join(", ")
                    )))
                }
            }
        }
        Ok(out)
    }

    /// The options of a run of `model` with these keywords.
    pub fn options(&self, model: &hybc::Model) -> PyResult<SimOptions> {
        let base = model.sim_options();
        let rtol = positive("rtol", self.rtol.unwrap_or(base.rtol))?;
        if rtol >= 1.0 {
            return Err(PyValueError::new_err(format!("rtol: expected a number below 1, found {rtol}")));
        }
        let method = match self.method.as_deref() {
            None | Some("auto") => Method::Auto,
            Some("dopri5") => Method::Dopri5,
            Some("dop853") => Method::Dop853,
            Some("rodas5p") => Method::Rodas5p,
            Some("rodas4") => Method::Rodas4,
            Some(other) => {
                return Err(PyValueError::new_err(format!(
                    "method: expected \"auto\", \"dopri5\", \"dop853\", \"rodas5p\" or \"rodas4\", found {other:?}"
                )))
            }
        };
        let h_max = match self.h_max {
            None => base.h_max,
            Some(h) => positive("h_max", h)?,
        };
        let (t_start, t_end) = hybc::time_span(self.t_start, self.t_end, &base, ("t_start", "t_end"))
            .map_err(PyValueError::new_err)?;
        Ok(SimOptions {
            t_start,
            t_end,
            rtol,
            atol: positive("atol", self.atol.unwrap_or(base.atol))?,
            method,
            // The caps and the refusal of 0 are the CLI's (`hybc::limits`).
            max_events: hybc::limits::count(
                "max_events",
                self.max_events.unwrap_or(base.max_events),
                1,
                hybc::limits::MAX_EVENTS,
            )
            .map_err(|e| PyValueError::new_err(e.to_string()))?,
            max_steps: hybc::limits::count(
                "max_steps",
                self.max_steps.unwrap_or(base.max_steps),
                1,
                hybc::limits::MAX_STEPS,
            )
            .map_err(|e| PyValueError::new_err(e.to_string()))?,
            graze_tol: positive("graze_tol", self.graze_tol.unwrap_or(base.graze_tol))?,
            sens_error_control: self.sens_error_control.unwrap_or(base.sens_error_control),
            quadrature_error_control: self.quadrature_error_control.unwrap_or(base.quadrature_error_control),
            land_events: self.land_events.or(base.land_events),
            h_max,
            ..base
        })
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
        Ok(dt) => Ok(TrajectoryRequest::Sample(positive("trajectory", dt)?)),
        Err(_) => Err(PyValueError::new_err(format!(
            "trajectory: expected None, \"steps\" or a sampling interval dt > 0, found {}",
            value.repr().map(|r| r.to_string()).unwrap_or_default()
        ))),
    }
}

/// The sample times of `at=` (`hybc run --at`), at most `hybc::sim::MAX_SAMPLED_ROWS` of them;
/// the run checks their order and range.
pub fn sample_times(at: Option<Vec<f64>>) -> PyResult<Vec<f64>> {
    let at = at.unwrap_or_default();
    if at.len() as f64 > hybc::sim::MAX_SAMPLED_ROWS {
        return Err(PyValueError::new_err(format!(
            "at: {} times, at most {:.0}",
            at.len(),
            hybc::sim::MAX_SAMPLED_ROWS
        )));
    }
    Ok(at)
}
