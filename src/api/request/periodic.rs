//! A periodic orbit as a user asks for it (`hybc periodic`, Python's `Model.periodic`): the
//! section event and its firing, the free parameters that set the initial state, their start,
//! the options. The door compiles the section's two models (`periodic::section_models`: the
//! return map with the section a `stop`, and that with one parameter per initial state) and runs
//! Newton on them (`periodic::find`, the core), so `periodic/` knows no compiler.

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
        let derived = periodic::section_models(checked, &self.section, self.firing)?;
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
        let result = periodic::find(initial.system(), map.system(), &derived.section, &self.search)?;
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
}
