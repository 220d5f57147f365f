//! A periodic orbit as a user asks for it (`hybc periodic`, Python's `Model.periodic`): the
//! section event and its firing, the free parameters that set the initial state, their start,
//! the options. The door compiles the section's two models (`periodic::section_models`: the
//! return map with the section a `stop`, and that with one parameter per initial state) and runs
//! Newton on them (`periodic::find`, the core), so `periodic/` knows no compiler.

use crate::api::{Compiled, Error, Model};
use crate::periodic::{self, PeriodicError, PeriodicProblem, PeriodicReport};
use crate::sema::{self, ParamIdx};
use crate::sim::SimOptions;

/// What orbit to find.
#[derive(Clone, Debug)]
pub struct PeriodicRequest {
    /// The section event's name.
    pub section: String,
    /// Which of its firings closes the orbit (1-based; `periodic::parse_section` reads
    /// `EVENT#K`).
    pub firing: usize,
    /// The parameters that set the initial state, solved for.
    pub free: Vec<ParamIdx>,
    /// Every parameter's value: the free ones start there, the others stay there.
    pub params: Vec<f64>,
    /// The options of every run of the return map.
    pub sim: SimOptions,
    /// The most Newton iterations (one run each).
    pub max_iter: usize,
    /// Converged when every state returns within `tol (1 + |x0|)` of its initial value.
    pub tol: f64,
}

impl PeriodicRequest {
    /// Finds the orbit of `model` (its section's models compiled here, by the door).
    pub fn run(&self, model: &Model) -> Result<PeriodicReport, Error> {
        let checked = model.checked();
        let derived = periodic::section_models(checked, &self.section, self.firing)?;
        if self.free.is_empty() {
            return Err(PeriodicError::NoFree.into());
        }
        let compile = |m: sema::Model, grad: &[ParamIdx]| -> Result<Compiled, Error> {
            model.derived(m).compile_params(grad).map_err(|e| match e {
                Error::Compile { source, .. } => PeriodicError::Compile(source.to_string()).into(),
                e => e,
            })
        };
        let initial = compile(derived.stopping, &self.free)?;
        let map = compile(derived.seeded, &derived.seeds)?;
        let problem = PeriodicProblem {
            name: self.section.clone(),
            section: derived.section,
            orbit: derived.orbit,
            n_states: checked.states.len(),
            free: self.free.clone(),
            params: self.params.clone(),
            sim: self.sim.clone(),
            max_iter: self.max_iter,
            tol: self.tol,
        };
        let result = periodic::find(initial.system(), map.system(), &problem)?;
        Ok(PeriodicReport {
            model: model.name().to_string(),
            section: self.section.clone(),
            firing: self.firing,
            params: checked.params.iter().map(|p| p.name.clone()).collect(),
            free: self.free.clone(),
            states: checked.states.iter().map(|s| s.name.clone()).collect(),
            result,
        })
    }
}
