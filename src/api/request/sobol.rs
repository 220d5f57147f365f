//! A Sobol' analysis as a user asks for it (`hybc sobol`, Python's `Model.sobol` and
//! `hybc.dask.sobol`): a design over the varied parameters, the outputs as text, the policy for
//! rows without a value, run on a model compiled without gradient parameters. Checks the outputs
//! and the design's size, runs the rows (`sobol::evaluate_rows`, the core: the whole design, or
//! a shard of it) and analyses the values (`sobol::analyze`) into the library's report.

use std::ops::Range;

use crate::api::{Compiled, Error, Model, ParamError};
use crate::fit::TargetError;
use crate::limits::{MAX_SOBOL_VALUES, MAX_SWEEP_POINTS};
use crate::sim::SimOptions;
use crate::sobol::{
    self, Analysis, AnalysisError, Design, Evaluated, OnFail, Output, OutputIndices, Prior, SobolReport,
};
use crate::sweep::SweepError;

/// What to analyse.
#[derive(Clone, Debug)]
pub struct SobolRequest<'a> {
    /// The varied parameters with their priors, the other parameters' values, the base points,
    /// second order or not, the scramble's seed.
    pub design: Design,
    /// The seed of the design, which also seeds the bootstrap.
    pub seed: u64,
    /// The quantities to analyse as the user wrote them: outputs or states (final values),
    /// `EVENT#K`, `EVENT#last`, `NAME@TIME`.
    pub outputs: &'a [String],
    /// What to do with rows without a value, as the user wrote it (`error`, `drop`, `value=X`):
    /// the report repeats it ([`SobolRequest::on_fail`] reads it).
    pub on_fail: &'a str,
    /// Bootstrap resamples for the intervals (0: none).
    pub bootstrap: usize,
    /// The options of every run.
    pub sim: SimOptions,
    /// Worker threads (0: one per core).
    pub threads: usize,
}

/// Why a Sobol' analysis gave no report. (An output without indices is not one: the report
/// holds its [`AnalysisError`] beside the others' indices.)
#[derive(Debug, thiserror::Error)]
pub enum SobolFailure {
    /// No output named.
    #[error("name at least one output, state or EVENT#K")]
    NoOutputs,
    /// An output does not parse against the model.
    #[error(transparent)]
    Output(TargetError),
    /// The policy for rows without a value is neither `error`, `drop` nor `value=X`.
    #[error("`{text}` is not error, drop or value=X with X a finite number")]
    OnFail {
        /// The policy as written.
        text: String,
    },
    /// The design has more rows than a sweep may run.
    #[error("{n} base points of {block} rows are more than {MAX_SWEEP_POINTS} runs")]
    TooManyRuns {
        /// Base points.
        n: usize,
        /// Rows per base point.
        block: usize,
    },
    /// The design's rows times the outputs are more values than an analysis keeps.
    #[error("{rows} rows x {outputs} outputs are more than the {MAX_SOBOL_VALUES} values an analysis keeps")]
    TooManyValues {
        /// Rows of the design.
        rows: usize,
        /// Outputs analysed.
        outputs: usize,
    },
    /// The worker threads could not be started.
    #[error(transparent)]
    Pool(SweepError),
}

/// Why a parameter cannot be varied with a prior.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum VaryPriorError {
    /// An unknown parameter, or a vector named whole.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// No prior given and no declared range to take one from.
    #[error("`{name}` has no declared range; give its prior")]
    NoRange {
        /// The parameter.
        name: String,
    },
    /// A prior whose support leaves the parameter's declared range.
    #[error("the prior reaches [{from}, {to}], outside `{name}`'s declared range [{lo}, {hi}]")]
    OutsideRange {
        /// The parameter.
        name: String,
        /// The prior's support, lower end.
        from: f64,
        /// The prior's support, upper end.
        to: f64,
        /// The declared range, lower end.
        lo: f64,
        /// The declared range, upper end.
        hi: f64,
    },
}

impl SobolRequest<'_> {
    /// The parameter `name` of `model` and its prior: `prior`, or uniform on its declared range
    /// for `None`. A prior whose support leaves the declared range is refused, not truncated:
    /// hybc never runs a parameter outside the range its model declares.
    pub fn vary(model: &Model, name: &str, prior: Option<Prior>) -> Result<(usize, Prior), VaryPriorError> {
        let idx = model.param_index(name)?.0 as usize;
        let range = model.checked().params[idx].range;
        let prior = match (prior, range) {
            (Some(prior), None) => prior,
            (None, Some((lo, hi))) => Prior::Uniform { lo, hi },
            (None, None) => return Err(VaryPriorError::NoRange { name: name.to_string() }),
            (Some(prior), Some((lo, hi))) => {
                let (from, to) = prior.support();
                if from < lo || to > hi {
                    return Err(VaryPriorError::OutsideRange { name: name.to_string(), from, to, lo, hi });
                }
                prior
            }
        };
        Ok((idx, prior))
    }

    /// The rows of `design`, refused beyond what a sweep may run.
    pub fn rows(design: &Design) -> Result<usize, SobolFailure> {
        design
            .rows()
            .filter(|r| *r <= MAX_SWEEP_POINTS)
            .ok_or(SobolFailure::TooManyRuns { n: design.n(), block: design.block() })
    }

    /// The policy `text` (`error`, `drop`, `value=X`) names.
    pub fn on_fail(text: &str) -> Result<OnFail, SobolFailure> {
        OnFail::parse(text).ok_or_else(|| SobolFailure::OnFail { text: text.to_string() })
    }

    /// The outputs parsed against `compiled`, with the design's size checked: what a run of the
    /// request reads, refused before anything runs.
    pub fn outputs(&self, compiled: &Compiled) -> Result<Vec<Output>, Error> {
        let outputs: Vec<Output> = self
            .outputs
            .iter()
            .map(|s| Output::parse(s, compiled.info()).map_err(SobolFailure::Output))
            .collect::<Result<_, _>>()?;
        if outputs.is_empty() {
            return Err(SobolFailure::NoOutputs.into());
        }
        let rows = Self::rows(&self.design)?;
        if rows.saturating_mul(outputs.len()) > MAX_SOBOL_VALUES {
            return Err(SobolFailure::TooManyValues { rows, outputs: outputs.len() }.into());
        }
        Ok(outputs)
    }

    /// Runs the rows `range` of the design on `compiled` (the whole design, or a shard of it:
    /// every row is computed from its index, so shards put end to end are the whole design bit
    /// for bit), keeping only the values of `outputs` ([`Self::outputs`]). `progress` is called
    /// once per row.
    pub fn evaluate(
        &self,
        compiled: &Compiled,
        outputs: &[Output],
        range: Range<usize>,
        progress: &(dyn Fn() + Sync),
    ) -> Result<Evaluated, Error> {
        let system = compiled.system();
        sobol::evaluate_rows(system, &self.design, range, outputs, &self.sim, self.threads, progress)
            .map_err(|e| SobolFailure::Pool(e).into())
    }

    /// The indices of every output from the values of all the design's rows (in row order,
    /// `outputs` per row, NaN where a row has none), by the request's policy and bootstrap.
    pub fn analyze(
        &self,
        labels: &[String],
        values: &[f64],
    ) -> Result<Vec<Result<OutputIndices, AnalysisError>>, Error> {
        let how = Analysis {
            d: self.design.d(),
            second_order: self.design.second_order(),
            on_fail: Self::on_fail(self.on_fail)?,
            bootstrap: self.bootstrap,
            seed: self.seed,
        };
        Ok(how.outputs(labels, values))
    }

    /// The whole analysis on `compiled`: every row run, every output analysed, the report.
    pub fn run(&self, compiled: &Compiled, progress: &(dyn Fn() + Sync)) -> Result<SobolReport, Error> {
        let outputs = self.outputs(compiled)?;
        Self::on_fail(self.on_fail)?;
        let rows = Self::rows(&self.design)?;
        let evaluated = self.evaluate(compiled, &outputs, 0..rows, progress)?;
        let labels: Vec<String> = outputs.iter().map(|o| o.label.clone()).collect();
        let results = self.analyze(&labels, &evaluated.values)?;
        let info = compiled.info();
        Ok(SobolReport {
            model: compiled.model().name().to_string(),
            params: self.design.varied().iter().map(|(p, _)| info.param_names[*p].clone()).collect(),
            n: self.design.n(),
            block: self.design.block(),
            rows,
            second_order: self.design.second_order(),
            seed: self.seed,
            bootstrap: self.bootstrap,
            on_fail: self.on_fail.trim().to_string(),
            evaluated,
            outputs: results,
        })
    }
}
