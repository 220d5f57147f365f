//! Global sensitivity: Sobol' indices of a model's outputs over parameter priors: a system run at
//! the rows of a Saltelli design, the results read. Generic over the system; knows no `sim`
//! internals, no door and no CLI.
//!
//! Code map: `sequence` (the scrambled Sobol' sequence, point `i` from `i`), `joe_kuo` (its
//! direction numbers), `design` (priors, the Saltelli design in SALib's row order, row `r` from
//! `r`), `estimate` (S1, ST, S2 and bootstrap errors over one output's values), this file (the
//! outputs a row reports, running the design in parallel keeping only those numbers, the policy
//! for rows without a value, and [`analyze`], which takes the values however they were computed),
//! `report` (`SobolReport`: table, JSON). A whole analysis as a user asks for it is the door's
//! `SobolRequest` (`api/request/sobol.rs`).
//!
//! Seams for other callers: a shard (Dask) computes rows `Design::fill(r)` for its range of `r`
//! and returns the outputs; [`analyze`] turns the values of all rows into indices.

pub mod design;
pub mod estimate;
mod joe_kuo;
mod report;
pub mod sequence;

use rayon::prelude::*;

pub use design::{parse_prior, Design, Prior, PriorError, PriorProblem, RowKind, TooManyVaried, MAX_VARIED};
pub use estimate::{Blocks, Indices};
pub use report::SobolReport;

use crate::fit::{Observable, TargetError};
use crate::sim::{self, HybridSystem, SimOptions, SimResult, SystemInfo};
use crate::status::RunStatus;
use crate::sweep::SweepError;

/// The confidence intervals every interface reports are `estimate +/- Z_95 se` (`se` the bootstrap
/// standard error): the normal 95% interval, SALib's `conf` at its default `conf_level`.
pub const Z_95: f64 = 1.959963984540054;

/// One `--output` of an analysis: what it reads and its label as the user wrote it.
#[derive(Clone, Debug, PartialEq)]
pub struct Output {
    /// The output as the user wrote it.
    pub label: String,
    /// What it reads.
    pub quantity: Observable,
}

impl Output {
    /// Parses `NAME` (an output or a state), `EVENT#K` (K from 1), `EVENT#last` or `NAME@TIME`
    /// (`Observable::parse`).
    pub fn parse(text: &str, info: &SystemInfo) -> Result<Output, TargetError> {
        let text = text.trim();
        Ok(Output { label: text.to_string(), quantity: Observable::parse(text, info)? })
    }

    /// Its value in a run that ended as asked, NaN where it does not exist (the event fired fewer
    /// times, the run stopped before the time) or is not finite. `NAME@TIME` reads the run's
    /// samples: the run's options must sample it (`sample_times`).
    pub fn value(&self, info: &SystemInfo, r: &SimResult) -> f64 {
        let fired = |name_event: usize| {
            let name = &info.events[name_event].name;
            r.events.iter().filter(move |e| e.name == *name)
        };
        let v = match self.quantity {
            Observable::Output(i) => r.final_state.outputs[i],
            Observable::State(i) => r.final_state.state[i],
            Observable::EventTime { name_event, occurrence } => {
                fired(name_event).nth(occurrence - 1).map_or(f64::NAN, |e| e.time)
            }
            Observable::LastFiring { name_event } => {
                fired(name_event).next_back().map_or(f64::NAN, |e| e.time)
            }
            Observable::At { output, index, time } => match r.samples.at_time(time) {
                Some(s) if s.reached => {
                    if output {
                        s.outputs[index]
                    } else {
                        s.state[index]
                    }
                }
                _ => f64::NAN,
            },
        };
        if v.is_finite() {
            v
        } else {
            f64::NAN
        }
    }
}

/// The options of an analysis's runs: `opts` sampling every `NAME@TIME` of `outputs`.
fn sampling(opts: &SimOptions, outputs: &[Output]) -> SimOptions {
    SimOptions { at: crate::fit::sample_times(outputs.iter().map(|o| &o.quantity)), ..opts.clone() }
}

/// What to do with rows that have no value for an output: the run ended early (Zeno, stuck,
/// `max_events`, a fault, refused), the event did not fire that often, or the value is not finite.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OnFail {
    /// No indices for an output with any such row (the default: every index is then an estimate
    /// over the whole prior, as asked).
    Error,
    /// Leave out every base point with such a row (its block is needed together): the indices
    /// are then those of the output conditioned on the region where it exists.
    Drop,
    /// Use this number for the missing value.
    Value(f64),
}

impl OnFail {
    /// `error`, `drop` or `value=X`.
    pub fn parse(text: &str) -> Option<OnFail> {
        match text.trim() {
            "error" => Some(OnFail::Error),
            "drop" => Some(OnFail::Drop),
            t => t
                .strip_prefix("value=")
                .and_then(|x| crate::number::parse_number(x.trim()).ok())
                .map(OnFail::Value),
        }
    }
}

/// The outputs of every row of a design, and how its runs ended.
#[derive(Clone, Debug, Default)]
pub struct Evaluated {
    /// Row-major: row `r`'s value of output `k` is `values[r * outputs + k]`, NaN where missing.
    pub values: Vec<f64>,
    /// Outputs per row.
    pub outputs: usize,
    /// Runs that did not end as asked, by status word (`zeno`, `fault`, ...; `error` for a run
    /// that was refused), in the order of [`RunStatus`].
    pub ended_early: Vec<(&'static str, usize)>,
    /// The first row whose run ended early.
    pub first_ended_early: Option<usize>,
}

/// Base points per unit of work: a few hundred runs, so the scheduling costs nothing beside them.
const CHUNK_POINTS: usize = 64;

/// Runs `sys` at every row of `design` with `opts` on `threads` workers (0: one per core),
/// keeping only the values of `outputs` (memory: `rows x outputs` numbers, never a run's
/// record). Each row is an independent run of a reused `Runner` (bit for bit a fresh run), and
/// its values land in its own slots, so the result does not depend on the thread count; rayon's
/// work stealing keeps the other workers going while one grinds through a Zeno row. `progress`
/// is called once per row.
pub fn evaluate<S: HybridSystem + ?Sized>(
    sys: &S,
    design: &Design,
    outputs: &[Output],
    opts: &SimOptions,
    threads: usize,
    progress: &(dyn Fn() + Sync),
) -> Result<Evaluated, SweepError> {
    let rows = design.rows().expect("the caller capped the base points");
    evaluate_rows(sys, design, 0..rows, outputs, opts, threads, progress)
}

/// [`evaluate`] over the rows `range` of the design only (a shard): `values` holds those rows
/// in order, `first_ended_early` is a row of the whole design. Since every row is an independent
/// run computed from its index, the shards' values put end to end are the whole design's, bit
/// for bit, however the rows are split.
pub fn evaluate_rows<S: HybridSystem + ?Sized>(
    sys: &S,
    design: &Design,
    range: std::ops::Range<usize>,
    outputs: &[Output],
    opts: &SimOptions,
    threads: usize,
    progress: &(dyn Fn() + Sync),
) -> Result<Evaluated, SweepError> {
    assert!(
        range.end <= design.rows().unwrap_or(usize::MAX),
        "rows {range:?} of a design of {:?} rows",
        design.rows()
    );
    // Every `NAME@TIME` output is read off the run's samples.
    let opts = &sampling(opts, outputs);
    let k = outputs.len();
    let rows = range.len();
    let block = design.block();
    let info = sys.info();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|source| SweepError::ThreadPool { threads, source })?;
    let mut values = vec![f64::NAN; rows * k];
    let chunk = (CHUNK_POINTS * block * k).max(1);
    /// Per status word (RunStatus order, then `error`), and the first row ended early.
    type Tally = ([usize; 9], Option<usize>);
    let tally: Tally = pool.install(|| {
        values
            .par_chunks_mut(chunk)
            .enumerate()
            .map_init(
                || (sim::Runner::new(sys, opts), vec![0.0; design.width()]),
                |(simulator, p), (c, slots)| {
                    let mut tally: Tally = ([0; 9], None);
                    let first_row = range.start + c * CHUNK_POINTS * block;
                    for (j, row_slots) in slots.chunks_mut(k.max(1)).enumerate() {
                        let row = first_row + j;
                        design.fill(row, p);
                        let result = match simulator {
                            Ok(simulator) => simulator.run(p),
                            Err(e) => Err(e.clone()),
                        };
                        progress();
                        let slot = match &result {
                            Ok(r) if r.stopped_by.is_complete() => {
                                for (o, v) in outputs.iter().zip(row_slots.iter_mut()) {
                                    *v = o.value(info, r);
                                }
                                None
                            }
                            Ok(r) => Some(RunStatus::of(info, r) as usize),
                            Err(_) => Some(8),
                        };
                        if let Some(s) = slot {
                            tally.0[s] += 1;
                            tally.1.get_or_insert(row);
                        }
                    }
                    tally
                },
            )
            .reduce(
                || ([0; 9], None),
                |mut a, b| {
                    for (x, y) in a.0.iter_mut().zip(b.0) {
                        *x += y;
                    }
                    a.1 = match (a.1, b.1) {
                        (Some(x), Some(y)) => Some(x.min(y)),
                        (x, y) => x.or(y),
                    };
                    a
                },
            )
    });
    let words = [
        RunStatus::Ok,
        RunStatus::Grazing,
        RunStatus::NotDifferentiable,
        RunStatus::NonFinite,
        RunStatus::Zeno,
        RunStatus::Stuck,
        RunStatus::MaxEvents,
        RunStatus::Fault,
    ]
    .map(RunStatus::name);
    let ended_early =
        words.iter().copied().chain(["error"]).zip(tally.0).filter(|(_, count)| *count > 0).collect();
    Ok(Evaluated { values, outputs: k, ended_early, first_ended_early: tally.1 })
}

/// One output's indices and what went into them.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputIndices {
    /// The output as the user wrote it.
    pub label: String,
    /// Rows without a value (the run ended early, the event did not fire, not finite).
    pub failed_rows: usize,
    /// Base points left out (`OnFail::Drop`), and those the indices use.
    pub dropped_points: usize,
    /// Base points the indices use.
    pub used_points: usize,
    /// The indices.
    pub indices: Indices,
    /// Bootstrap standard errors (the same shape), when resamples were asked for.
    pub errors: Option<Indices>,
}

/// Why an output has no indices.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum AnalysisError {
    #[error(
        "output `{label}`: {failed_rows} of {rows} rows have no value (the first is row {first_row}); \
         choose --on-fail drop or --on-fail value=X to analyse anyway"
    )]
    /// Rows without a value under `OnFail::Error`.
    Failed {
        /// The output.
        label: String,
        /// Rows without a value.
        failed_rows: usize,
        /// Rows of the design.
        rows: usize,
        /// The first of them (1-based).
        first_row: usize,
    },
    /// Fewer than 2 base points left under `OnFail::Drop`.
    #[error("output `{label}`: {used} base points left after dropping {dropped}; at least 2 are needed")]
    TooFewPoints {
        /// The output.
        label: String,
        /// Base points left.
        used: usize,
        /// Base points dropped.
        dropped: usize,
    },
}

impl AnalysisError {
    /// The output it is about, as the user wrote it.
    pub fn label(&self) -> &str {
        match self {
            AnalysisError::Failed { label, .. } | AnalysisError::TooFewPoints { label, .. } => label,
        }
    }
}

/// What [`analyze`] needs besides the values.
#[derive(Clone, Copy, Debug)]
pub struct Analysis {
    /// Varied parameters.
    pub d: usize,
    /// Whether second-order indices are estimated.
    pub second_order: bool,
    /// What to do with rows without a value.
    pub on_fail: OnFail,
    /// Bootstrap resamples (0: none).
    pub bootstrap: usize,
    /// The bootstrap's seed.
    pub seed: u64,
}

impl Analysis {
    /// The indices of every output from `values` (row-major, `labels.len()` per row, NaN where a
    /// row has none), each with its label, or why it has none ([`analyze`]).
    pub fn outputs(&self, labels: &[String], values: &[f64]) -> Vec<Result<OutputIndices, AnalysisError>> {
        labels.iter().enumerate().map(|(k, label)| analyze(label, values, labels.len(), k, self)).collect()
    }
}

/// The indices of output `offset` of row-major `values` (`stride` values per row, `block` rows
/// per base point in SALib's order), NaN marking a missing value, under the policy of `how`.
pub fn analyze(
    label: &str,
    values: &[f64],
    stride: usize,
    offset: usize,
    how: &Analysis,
) -> Result<OutputIndices, AnalysisError> {
    let mut owned;
    let mut blocks = Blocks { y: values, stride, offset, d: how.d, second_order: how.second_order };
    let block = if how.second_order { 2 * how.d + 2 } else { how.d + 2 };
    let n = blocks.n();
    let missing = |b: &Blocks<'_>, p: usize| (0..block).filter(|&j| b.at(p, j).is_nan()).count();
    let failed_rows: usize = (0..n).map(|p| missing(&blocks, p)).sum();
    let mut points: Vec<u32> = (0..n as u32).collect();
    match how.on_fail {
        OnFail::Error if failed_rows > 0 => {
            let first = (0..n * block).find(|&r| values[r * stride + offset].is_nan()).unwrap_or(0);
            return Err(AnalysisError::Failed {
                label: label.to_string(),
                failed_rows,
                rows: n * block,
                first_row: first + 1,
            });
        }
        OnFail::Drop => points.retain(|&p| missing(&blocks, p as usize) == 0),
        OnFail::Value(x) if failed_rows > 0 => {
            owned = (0..n * block).map(|r| values[r * stride + offset]).collect::<Vec<f64>>();
            owned.iter_mut().filter(|v| v.is_nan()).for_each(|v| *v = x);
            blocks = Blocks { y: &owned, stride: 1, offset: 0, ..blocks };
        }
        _ => {}
    }
    let dropped = n - points.len();
    if points.len() < 2 {
        return Err(AnalysisError::TooFewPoints { label: label.to_string(), used: points.len(), dropped });
    }
    let centre = estimate::centre(&blocks, &points);
    let indices = estimate::indices(&blocks, &points, centre);
    let errors =
        (how.bootstrap > 0).then(|| estimate::bootstrap(&blocks, &points, centre, how.bootstrap, how.seed));
    Ok(OutputIndices {
        label: label.to_string(),
        failed_rows,
        dropped_points: dropped,
        used_points: points.len(),
        indices,
        errors,
    })
}
