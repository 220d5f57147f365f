//! One finished run as Python values: NumPy arrays and dicts keyed by name.
//!
//! The rules (documented in docs/python.md):
//! - a derivative that does not exist (after a grazing event, ...) is NaN, and `warnings` says why;
//! - after a `stop` event the final values are those at the stop and their derivatives are the
//!   total ones that include the motion of the stopping time (as `hybc sweep` writes them);
//! - `status` is one word of the vocabulary `hybc sweep` and `hybc.jax` use (`hybc::status`);
//! - a run that ended early (`ok` false; status Zeno, max_events, stuck, a fault) has no final
//!   values: `state`, `outputs`, `dstate`, `doutputs` are NaN, `t` is where it stopped and
//!   `error` says why (the events up to there and the trajectory stay).

use numpy::{PyArray1, PyArray2, PyArrayMethods as _};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use hybc::StopReason;

#[pyclass(module = "hybc._hybc", frozen, name = "Run")]
pub struct Run {
    run: hybc::Run,
    t_end: f64,
}

impl Run {
    pub fn new(run: hybc::Run, t_end: f64) -> Run {
        Run { run, t_end }
    }

    fn info(&self) -> &hybc::sim::SystemInfo {
        self.run.compiled().info()
    }

    fn complete(&self) -> bool {
        self.run.is_complete()
    }

    fn n_grad(&self) -> usize {
        self.info().n_grad()
    }

    /// `names[i] -> value`, NaN for every value when the run ended early.
    fn values<'py>(&self, py: Python<'py>, names: &[String], values: &[f64]) -> PyResult<Bound<'py, PyDict>> {
        let dict = PyDict::new(py);
        for (name, &v) in names.iter().zip(values) {
            dict.set_item(name, if self.complete() { v } else { f64::NAN })?;
        }
        Ok(dict)
    }

    /// `names[i] -> ndarray (n_grad,)` from a column-per-parameter array (`d[j * n + i]`) over
    /// the final states (`output` false) or outputs, for the names whose gradients the run
    /// reports (all, unless `of=` named others).
    fn gradients<'py>(
        &self,
        py: Python<'py>,
        output: bool,
        d: Option<&[f64]>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let info = self.info();
        let names = if output { &info.output_names } else { &info.state_names };
        let (n, m) = (names.len(), self.n_grad());
        let d = d.filter(|_| self.complete());
        let dict = PyDict::new(py);
        let result = self.run.result();
        for (i, name) in names.iter().enumerate().filter(|&(i, _)| result.reports_gradient(output, i)) {
            let column: Vec<f64> = (0..m).map(|j| d.map_or(f64::NAN, |d| d[j * n + i])).collect();
            dict.set_item(name, PyArray1::from_vec(py, column))?;
        }
        Ok(dict)
    }

    fn by_event(&self) -> bool {
        matches!(self.run.stopped_by(), StopReason::Event { .. })
    }
}

#[pymethods]
impl Run {
    /// Event times, in firing order.
    #[getter]
    fn event_times<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_iter(py, self.run.events().iter().map(|e| e.time))
    }

    #[getter]
    fn event_names(&self) -> Vec<String> {
        self.run.events().iter().map(|e| e.name.to_string()).collect()
    }

    /// `d t_k / d p_j`, shape (n_events, n_grad); NaN where the derivative does not exist, or
    /// where `of=` did not ask for it.
    #[getter]
    fn event_dtime<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let m = self.n_grad();
        let events = self.run.events();
        let flat: Vec<f64> = events
            .iter()
            .flat_map(|e| (0..m).map(move |j| e.dtime.as_ref().map_or(f64::NAN, |d| d[j])))
            .collect();
        PyArray1::from_vec(py, flat).reshape([events.len(), m])
    }

    /// Modes before and after each event.
    #[getter]
    fn event_modes(&self) -> Vec<(String, String)> {
        let modes = &self.info().modes;
        self.run
            .events()
            .iter()
            .map(|e| (modes[e.mode_before].name.clone(), modes[e.mode_after].name.clone()))
            .collect()
    }

    /// Final states by name (NaN when the run ended early).
    #[getter]
    fn state<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.values(py, &self.info().state_names, &self.run.result().final_state.state)
    }

    /// Final outputs by name (NaN when the run ended early).
    #[getter]
    fn outputs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.values(py, &self.info().output_names, &self.run.result().final_state.outputs)
    }

    /// `d state / d grad`: state name -> ndarray (n_grad,).
    #[getter]
    fn dstate<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let f = &self.run.result().final_state;
        let d = if self.by_event() { &f.dstate_total } else { &f.dstate };
        self.gradients(py, false, d.as_deref())
    }

    /// `d output / d grad`: output name -> ndarray (n_grad,).
    #[getter]
    fn doutputs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let f = &self.run.result().final_state;
        let d = if self.by_event() { &f.doutputs_total } else { &f.doutputs };
        self.gradients(py, true, d.as_deref())
    }

    /// Names of the differentiated parameters, in gradient column order.
    #[getter]
    fn grad(&self) -> Vec<String> {
        self.run.compiled().grad_names().map(String::from).collect()
    }

    /// The parameter values of the run.
    #[getter]
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let dict = PyDict::new(py);
        for (name, v) in self.info().param_names.iter().zip(self.run.param_values()) {
            dict.set_item(name, v)?;
        }
        Ok(dict)
    }

    /// Why the run ended: "t_end", the stop event's name, "zeno", "max_events", "stuck" or
    /// "fault".
    #[getter]
    fn stopped_by(&self) -> String {
        self.run.stopped_by().name().to_string()
    }

    /// The run's status in the one vocabulary of sweep rows and `hybc.jax` (`hybc::status`):
    /// "ok", "grazing", "not_differentiable", "non_finite" (complete runs), or "zeno", "stuck",
    /// "max_events", "fault" (ended early).
    #[getter]
    fn status(&self) -> String {
        hybc::status::RunStatus::of(self.info(), self.run.result()).name().into()
    }

    /// Whether the run ended as asked (at t_end or by a stop event): its final values exist,
    /// whatever `status` says of its derivatives.
    #[getter]
    fn ok(&self) -> bool {
        self.complete()
    }

    /// Why the run ended early (time, mode, state named), else None.
    #[getter]
    fn error(&self) -> Option<String> {
        self.run.report().failure()
    }

    /// Every warning of the run (grazing, near-grazing, derivatives that stopped existing).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.run.warnings().iter().map(|w| w.to_string()).collect()
    }

    /// The time the run ended.
    #[getter]
    fn t(&self) -> f64 {
        self.run.final_time()
    }

    /// The end time asked for.
    #[getter]
    fn t_end(&self) -> f64 {
        self.t_end
    }

    /// The final mode's name.
    #[getter]
    fn mode(&self) -> String {
        self.info().modes[self.run.result().final_state.mode].name.clone()
    }

    /// The run's counts as the JSON report's `stats` holds them: "steps", "rejected",
    /// "rhs_calls", "events", "switches", "sens" (how the gradients were computed: "forward" or
    /// "adjoint", None when no parameter was differentiated), "compile_seconds", "run_seconds".
    #[getter]
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = &self.run.result().stats;
        let dict = PyDict::new(py);
        dict.set_item("steps", s.steps)?;
        dict.set_item("rejected", s.rejected)?;
        dict.set_item("rhs_calls", s.rhs_calls)?;
        dict.set_item("events", s.events)?;
        dict.set_item("switches", s.switches)?;
        dict.set_item("sens", self.sens())?;
        dict.set_item("compile_seconds", self.compile_seconds())?;
        dict.set_item("run_seconds", self.run_seconds())?;
        Ok(dict)
    }

    /// How the gradients were computed: "forward" or "adjoint" (`stats["sens"]`); None when no
    /// parameter was differentiated.
    #[getter]
    fn sens(&self) -> Option<&'static str> {
        self.run.result().stats.sens.map(|s| s.name())
    }

    #[getter]
    fn compile_seconds(&self) -> f64 {
        self.run.compiled().compile_seconds()
    }

    #[getter]
    fn run_seconds(&self) -> f64 {
        self.run.run_seconds()
    }

    /// The trajectory asked for with `trajectory=`, as columns: "t", "mode" (names), every state,
    /// every output, then `d<state>/d<p>` per gradient parameter; None when none was asked for.
    #[getter]
    fn trajectory<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(rows) = self.run.result().trajectory.as_ref() else {
            return Ok(None);
        };
        let info = self.info();
        let n = info.n_states();
        let dict = PyDict::new(py);
        let column =
            |f: &dyn Fn(&hybc::sim::TrajectoryRow) -> f64| PyArray1::from_iter(py, rows.iter().map(f));
        dict.set_item("t", column(&|r| r.t))?;
        let modes: Vec<&str> = rows.iter().map(|r| info.modes[r.mode].name.as_str()).collect();
        dict.set_item("mode", modes)?;
        for (i, name) in info.state_names.iter().enumerate() {
            dict.set_item(name, column(&|r| r.x[i]))?;
        }
        for (i, name) in info.output_names.iter().enumerate() {
            dict.set_item(name, column(&|r| r.outputs[i]))?;
        }
        for (j, p) in self.run.compiled().grad_names().enumerate() {
            for (i, s) in info.state_names.iter().enumerate() {
                dict.set_item(
                    format!("d{s}/d{p}"),
                    column(&|r| r.s.get(j * n + i).copied().unwrap_or(f64::NAN)),
                )?;
            }
        }
        Ok(Some(dict))
    }

    /// The values at the times asked for with `at=` (`hybc run --at`), as arrays: "t" (T,),
    /// "names" (the outputs, then the states), "values" (T, K) and "dvalues" (T, K, n_grad), NaN
    /// where a value or derivative does not exist or the run stopped before the time; "reached",
    /// "after_events" (bool, (T,)) and "near_event" (the index of an event within whose time
    /// resolution the sample lies, -1 for none). None when no times were asked for.
    #[getter]
    fn samples<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let samples = self.run.samples();
        if samples.is_empty() {
            return Ok(None);
        }
        let info = self.info();
        let (k, n, m) = (info.n_outputs(), info.n_states(), self.n_grad());
        let width = k + n;
        let mut values: Vec<f64> = Vec::with_capacity(samples.len() * width);
        let mut dvalues: Vec<f64> = Vec::with_capacity(samples.len() * width * m);
        for s in samples.iter() {
            values.extend(s.outputs.iter().chain(s.state));
            for i in 0..width {
                let (d, rows, row) = if i < k { (s.doutputs, k, i) } else { (s.dstate, n, i - k) };
                dvalues.extend((0..m).map(|j| d.map_or(f64::NAN, |d| d[j * rows + row])));
            }
        }
        let dict = PyDict::new(py);
        dict.set_item("t", PyArray1::from_iter(py, samples.iter().map(|s| s.time)))?;
        let names: Vec<&String> = info.output_names.iter().chain(&info.state_names).collect();
        dict.set_item("names", names)?;
        dict.set_item("values", PyArray1::from_vec(py, values).reshape([samples.len(), width])?)?;
        dict.set_item("dvalues", PyArray1::from_vec(py, dvalues).reshape([samples.len(), width, m])?)?;
        dict.set_item("reached", samples.iter().map(|s| s.reached).collect::<Vec<bool>>())?;
        dict.set_item("after_events", samples.iter().map(|s| s.after_events).collect::<Vec<bool>>())?;
        let near: Vec<i64> = samples.iter().map(|s| s.near_event.map_or(-1, |e| e as i64)).collect();
        dict.set_item("near_event", PyArray1::from_vec(py, near))?;
        Ok(Some(dict))
    }

    /// The run as `hybc run --format json` prints it.
    fn to_json(&self) -> String {
        self.run.report().to_json().to_string()
    }

    fn __repr__(&self) -> String {
        format!(
            "<hybc.Run {}: {} events, stopped_by {:?}, t = {}{}>",
            self.run.compiled().model().name(),
            self.run.events().len(),
            self.stopped_by(),
            self.t(),
            if self.run.warnings().is_empty() {
                String::new()
            } else {
                format!(", {} warnings", self.run.warnings().len())
            }
        )
    }
}
