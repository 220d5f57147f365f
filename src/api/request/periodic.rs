//! A periodic orbit as a user asks for it (`hybc periodic`, Python's `Model.periodic`): the
//! section event and its firing, the free parameters that set the initial state, their start,
//! the options. The door compiles the section's models (`periodic::section_models`: the return
//! map with the section a `stop`, that with one parameter per initial state, and the model as
//! written seeded the same way, which verifies the fixed point) and runs Newton on them
//! (`periodic::find`, the core), so `periodic/` knows no compiler.

use crate::api::{Compiled, Error, Model};
use crate::periodic::{self, PeriodicError, PeriodicReport, Search};
use crate::sema::{self, ParamIdx};

/// What orbit to find.
#[derive(Clone, Debug)]
pub struct PeriodicRequest {
    /// The section event's name.
    pub section: String,
    /// Which of its firings closes the orbit (1-based; `periodic::parse_section` reads
    /// `EVENT#K`).
    pub firing: usize,
    /// The free parameters that set the initial state, their start, the options, the Newton
    /// iterations and the tolerance.
    pub search: Search,
}

impl PeriodicRequest {
    /// Finds the orbit of `model` (its section's models compiled here, by the door).
    pub fn run(&self, model: &Model) -> Result<PeriodicReport, Error> {
        let checked = model.checked();
        let derived = periodic::section_models(checked, &self.section, self.firing, self.search.sim.t_start)?;
        if self.search.free.is_empty() {
            return Err(PeriodicError::NoFree.into());
        }
        let compile = |m: sema::Model, grad: &[ParamIdx]| -> Result<Compiled, Error> {
            model.derived(m).compile_params(grad).map_err(|e| match e {
                Error::Compile { source, .. } => PeriodicError::Compile(source.to_string()).into(),
                e => e,
            })
        };
        let initial = compile(derived.stopping, &self.search.free)?;
        let map = compile(derived.seeded, &derived.seeds)?;
        let verify = compile(derived.verifying, &derived.seeds)?;
        let result =
            periodic::find(initial.system(), map.system(), verify.system(), &derived.section, &self.search)?;
        Ok(PeriodicReport {
            model: model.name().to_string(),
            section: self.section.clone(),
            firing: self.firing,
            params: checked.params.iter().map(|p| p.name.clone()).collect(),
            free: self.search.free.clone(),
            states: checked.states.iter().map(|s| s.name.clone()).collect(),
            result,
        })
    }

    /// The JSON object of a search of `model` that ended in `error` without an orbit (what
    /// `hybc periodic --format json` prints then, and Python's `RuntimeError` carries); `None`
    /// for a refusal of the question.
    pub fn failure_json(&self, model: &Model, error: &Error) -> Option<serde_json::Value> {
        let Error::Periodic(e) = error else { return None };
        let params: Vec<String> = model.checked().params.iter().map(|p| p.name.clone()).collect();
        periodic::failure_json(model.name(), &self.section, self.firing, &params, &self.search.free, e)
    }
}
