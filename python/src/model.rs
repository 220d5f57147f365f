//! A checked model as a Python object, with its compiled forms cached per gradient set.

use std::collections::HashMap;
use std::sync::Mutex;

use pyo3::prelude::*;

use numpy::{PyArray1, PyArray2, PyArrayMethods as _, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::types::PyDict;

use crate::errors::{self, ParameterError};
use crate::options::{trajectory_request, SimKeywords};
use crate::run::Run;
use crate::sobol;
use crate::sweep;
use hybc::sweep::Points;

/// A checked model. Compiling is the costly step (milliseconds to seconds), so each gradient set
/// is compiled once and kept: `Compiled` is `Send + Sync + 'static` and cheap to clone.
#[pyclass(module = "hybc._hybc", frozen)]
pub struct Model {
    model: hybc::Model,
    compiled: Mutex<HashMap<Vec<String>, hybc::Compiled>>,
}

impl Model {
    /// The model compiled with gradients with respect to `grad` (in that column order), from the
    /// cache or compiled now (with the GIL released).
    pub fn compiled(&self, py: Python<'_>, grad: &[String]) -> PyResult<hybc::Compiled> {
        if let Some(c) = self.lock().get(grad) {
            return Ok(c.clone());
        }
        let model = self.model.clone();
        let compiled = py.detach(|| model.compile(grad)).map_err(errors::to_py)?;
        self.lock().insert(grad.to_vec(), compiled.clone());
        Ok(compiled)
    }

    pub fn inner(&self) -> &hybc::Model {
        &self.model
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<Vec<String>, hybc::Compiled>> {
        // A panic while holding the lock cannot leave the map half-updated (insert is the only
        // write), so a poisoned lock is still usable.
        self.compiled.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The parameter values: the defaults with `params` set (each checked against its range).
    pub fn param_values(&self, params: Option<HashMap<String, f64>>) -> PyResult<hybc::Params> {
        let mut values = self.model.params();
        for (name, value) in params.unwrap_or_default() {
            values.set(&name, value).map_err(|e| errors::to_py(e.into()))?;
        }
        Ok(values)
    }

    fn wrap(model: hybc::Model) -> Model {
        Model { model, compiled: Mutex::new(HashMap::new()) }
    }
}

#[pymethods]
impl Model {
    /// Parses and checks a model text; diagnostics name the file `file_name`.
    #[new]
    #[pyo3(signature = (text, file_name = "model.hyb"))]
    fn new(py: Python<'_>, text: &str, file_name: &str) -> PyResult<Model> {
        let text = text.to_string();
        let file_name = file_name.to_string();
        py.detach(|| hybc::Model::parse_named(&text, &file_name)).map(Model::wrap).map_err(errors::to_py)
    }

    /// Reads, parses and checks a model file.
    #[staticmethod]
    fn from_file(py: Python<'_>, path: std::path::PathBuf) -> PyResult<Model> {
        py.detach(|| hybc::Model::from_file(&path)).map(Model::wrap).map_err(errors::to_py)
    }

    /// Imports an SBML file (Level 2 or 3) and checks the model it becomes.
    #[staticmethod]
    fn from_sbml(py: Python<'_>, path: std::path::PathBuf) -> PyResult<Model> {
        py.detach(|| hybc::Model::from_sbml_file(&path)).map(Model::wrap).map_err(errors::to_py)
    }

    #[getter]
    fn name(&self) -> &str {
        self.model.name()
    }

    #[getter]
    fn source(&self) -> &str {
        self.model.source()
    }

    #[getter]
    fn file_name(&self) -> &str {
        self.model.file_name()
    }

    /// Parameter names and defaults, in declaration order.
    #[getter]
    fn params(&self) -> Vec<(String, f64)> {
        self.model.params().iter().map(|(n, v)| (n.to_string(), v)).collect()
    }

    /// Vector parameters (`param u[N]`) and their lengths, in declaration order; their elements
    /// are in `params` as `u[0]` ..
    #[getter]
    fn vectors(&self) -> Vec<(String, usize)> {
        self.model.checked().vectors.iter().map(|v| (v.name.clone(), v.len as usize)).collect()
    }

    #[getter]
    fn states(&self) -> Vec<String> {
        self.model.state_names().map(String::from).collect()
    }

    #[getter]
    fn outputs(&self) -> Vec<String> {
        self.model.output_names().map(String::from).collect()
    }

    /// Declared event names, in declaration order (firing order at one instant).
    #[getter]
    fn events(&self) -> Vec<String> {
        self.model.checked().events.iter().map(|e| e.name.to_string()).collect()
    }

    #[getter]
    fn modes(&self) -> Vec<String> {
        self.model.checked().modes.iter().map(|m| m.name.to_string()).collect()
    }

    /// The gradient sets compiled so far (each is compiled once per `Model` object).
    #[getter]
    fn compiled_grad_sets(&self) -> Vec<Vec<String>> {
        let mut sets: Vec<Vec<String>> = self.lock().keys().cloned().collect();
        sets.sort();
        sets
    }

    /// Declared parameter ranges `name -> (lo, hi)`, for the parameters that declare one.
    #[getter]
    fn param_ranges(&self) -> Vec<(String, (f64, f64))> {
        let params = &self.model.checked().params;
        params.iter().filter_map(|p| p.range.map(|r| (p.name.clone(), r))).collect()
    }

    /// One run; see `hybc.Model.simulate`.
    #[pyo3(signature = (params = None, *, grad = None, trajectory = None, at = None, of = None, **sim))]
    #[allow(clippy::too_many_arguments)]
    fn simulate(
        &self,
        py: Python<'_>,
        params: Option<HashMap<String, f64>>,
        grad: Option<Vec<String>>,
        trajectory: Option<&Bound<'_, PyAny>>,
        at: Option<Vec<f64>>,
        of: Option<Vec<String>>,
        sim: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Run> {
        let keywords = SimKeywords::from_kwargs(sim)?;
        let mut opts = keywords.options_at(&self.model, at)?;
        opts.trajectory = trajectory_request(trajectory)?;
        let values = self.param_values(params)?;
        let compiled = self.compiled(py, &grad.unwrap_or_default())?;
        SimKeywords::gradients_of(of, compiled.info(), &mut opts)?;
        let t_end = opts.t_end;
        let run = py.detach(|| compiled.simulate(&values, &opts)).map_err(errors::to_py)?;
        Ok(Run::new(run, t_end))
    }

    /// Rows `[start, stop)` of the seeded uniform samples of `hybc sweep --samples n --seed seed`:
    /// `ranges` lists `(name, (lo, hi))` in draw order (`None` for the declared range; no list:
    /// every parameter with a declared range). Returns the sampled names and one row per point.
    #[pyo3(signature = (n, seed, ranges, start, stop))]
    fn sample_points<'py>(
        &self,
        py: Python<'py>,
        n: usize,
        seed: u64,
        ranges: Option<sweep::RangeArgs>,
        start: usize,
        stop: usize,
    ) -> PyResult<(Vec<String>, Bound<'py, PyArray2<f64>>)> {
        let ranges = sweep::sample_ranges(&self.model, ranges)?;
        if n == 0 || n > sweep::MAX_POINTS {
            return Err(PyValueError::new_err(format!(
                "samples: expected 1 to {} points, found {n}",
                sweep::MAX_POINTS
            )));
        }
        if start > stop || stop > n {
            return Err(PyValueError::new_err(format!("samples: rows {start}..{stop} of {n}")));
        }
        let base = vec![0.0; self.model.checked().params.len()];
        let rows = py.detach(|| hybc::sweep::uniform_samples_from(&base, &ranges, seed, start..stop));
        let names = ranges.iter().map(|r| self.model.checked().params[r.0].name.clone()).collect();
        let flat: Vec<f64> = rows.iter().flat_map(|p| ranges.iter().map(|r| p[r.0])).collect();
        Ok((names, PyArray1::from_vec(py, flat).reshape([stop - start, ranges.len()])?))
    }

    /// Runs every row of `points` (columns `names`; the other parameters from `fixed`, else their
    /// defaults) in parallel; see `hybc.Model.sweep`.
    ///
    /// With `check_only`, everything is checked (points, options, gradient names) and nothing is
    /// compiled or run: an empty dict comes back.
    #[pyo3(signature = (names, points, fixed = None, *, grad = None, events = 5, threads = 0, check_only = false, **sim))]
    #[allow(clippy::too_many_arguments)]
    fn sweep<'py>(
        &self,
        py: Python<'py>,
        names: Vec<String>,
        points: PyReadonlyArray2<'py, f64>,
        fixed: Option<HashMap<String, f64>>,
        grad: Option<Vec<String>>,
        events: usize,
        threads: usize,
        check_only: bool,
        sim: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let keywords = SimKeywords::from_kwargs(sim)?;
        // Gradients by the cheaper mode, as `hybc sweep` (docs/sweep.md).
        let opts = keywords.analysis_options(&self.model)?;
        sweep::check_counts(events, threads)?;
        if let Some(name) = names.iter().find(|n| fixed.as_ref().is_some_and(|f| f.contains_key(*n))) {
            return Err(ParameterError::new_err(format!(
                "parameter `{name}` is given both as a column and as a fixed value"
            )));
        }
        let base = self.param_values(fixed)?;
        let rows = sweep::points(&self.model, base.values(), &names, &points)?;
        drop(points);
        let grad = grad.unwrap_or_default();
        if check_only {
            check_grad_names(&self.model, &grad)?;
            return Ok(PyDict::new(py));
        }
        let compiled = self.compiled(py, &grad)?;
        let request = hybc::SweepRequest { points: Points::Rows(rows), sim: opts, events, threads };
        sweep::run(py, &compiled, &request)
    }

    /// Rows `[start, stop)` of the Saltelli design of `Model.sobol`: the varied parameters'
    /// values, one row per run in SALib's order (SALib's `X`). `priors` are `(name, dist,
    /// bounds)` with SALib's distribution names; `fixed` sets other parameters.
    #[pyo3(signature = (priors, n, second_order, seed, fixed, start, stop))]
    #[allow(clippy::too_many_arguments)]
    fn sobol_design<'py>(
        &self,
        py: Python<'py>,
        priors: Vec<sobol::PriorArg>,
        n: usize,
        second_order: bool,
        seed: u64,
        fixed: Option<HashMap<String, f64>>,
        start: usize,
        stop: usize,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let fixed = fixed.unwrap_or_default();
        let base = self.param_values(Some(fixed.clone()))?.values().to_vec();
        let design = sobol::design(&self.model, base, &fixed, &priors, n, second_order, seed)?;
        sobol::rows(py, &design, start, stop)
    }

    /// Runs rows `[start, stop)` of the design (GIL released) and returns `(values, ended_early,
    /// first_ended_early)`: one row of `outputs` values per run (NaN where a row has none), the
    /// runs that ended early by status word, the first such row (0-based). With `check_only`,
    /// everything is checked (problem, outputs, options) and nothing is run: `None` comes back.
    #[pyo3(signature = (priors, n, second_order, seed, fixed, outputs, start, stop, *, threads = 0,
        check_only = false, **sim))]
    #[allow(clippy::too_many_arguments)]
    fn sobol_evaluate<'py>(
        &self,
        py: Python<'py>,
        priors: Vec<sobol::PriorArg>,
        n: usize,
        second_order: bool,
        seed: u64,
        fixed: Option<HashMap<String, f64>>,
        outputs: Vec<String>,
        start: usize,
        stop: usize,
        threads: usize,
        check_only: bool,
        sim: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<Option<sobol::Evaluated<'py>>> {
        let keywords = SimKeywords::from_kwargs(sim)?;
        let opts = keywords.options(&self.model)?;
        sweep::check_counts(0, threads)?;
        let fixed = fixed.unwrap_or_default();
        let base = self.param_values(Some(fixed.clone()))?.values().to_vec();
        let design = sobol::design(&self.model, base, &fixed, &priors, n, second_order, seed)?;
        // Compiled without gradient parameters: indices need values only, and a run without
        // sensitivities is several times cheaper (as `hybc sobol`).
        let compiled = self.compiled(py, &[])?;
        // The policy and the bootstrap are the analysis's (`sobol_analyze`), not the runs'.
        let request = hybc::SobolRequest {
            design,
            seed,
            outputs: &outputs,
            on_fail: "error",
            bootstrap: 0,
            sim: opts,
            threads,
        };
        let outputs = sobol::outputs(&compiled, &request)?;
        if check_only {
            return Ok(None);
        }
        sobol::evaluate(py, &compiled, &request, &outputs, (start, stop)).map(Some)
    }
}

/// The errors `compile` would give for the gradient names, without compiling.
fn check_grad_names(model: &hybc::Model, grad: &[String]) -> PyResult<()> {
    model.param_list(grad).map(drop).map_err(|e| errors::to_py(e.into()))
}
