//! A gradient check as `hybc run --check-grad` asks for it: every derivative a run reported
//! against finite differences of re-runs of the same compiled model (`gradcheck::check_within`,
//! the core), with the finite differences kept inside the parameters' declared ranges.

use crate::api::{Compiled, Error};
use crate::gradcheck::{check_within, CheckOptions, GradCheck};
use crate::sim::{SimOptions, SimResult};

/// How to check a run's gradients.
#[derive(Clone, Debug)]
pub struct GradCheckRequest {
    /// The options the run was made with (its trajectory left out of the re-runs).
    pub sim: SimOptions,
    /// The step and the tolerance ([`CheckOptions::for_rtol`] for the run's `rtol` by default).
    pub check: CheckOptions,
}

impl GradCheckRequest {
    /// Checks `result`, a run of `compiled` at the parameter values `params` with `self.sim`.
    /// Errors only when a re-run is refused as input, which the run itself was not.
    pub fn run(&self, compiled: &Compiled, params: &[f64], result: &SimResult) -> Result<GradCheck, Error> {
        let ranges: Vec<_> = compiled.model().checked().params.iter().map(|p| p.range).collect();
        Ok(check_within(compiled.system(), params, &ranges, &self.sim, result, &self.check)?)
    }
}
