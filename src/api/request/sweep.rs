//! A sweep as a user asks for it (`hybc sweep`, Python's `Model.sweep` and `hybc.dask.sweep`):
//! points, the options of every run, the events shown per row, the worker threads. Runs the
//! points (`sweep::run_points` in memory, `sweep::stream_rows` streamed: the core) and returns
//! the library's report of them, or writes their rows as they complete.

use std::io::Write;

use crate::api::{Compiled, Error, Spelling};
use crate::limits::{MAX_EVENT_COLUMNS, MAX_THREADS};
use crate::sim::SimOptions;
use crate::sweep::{self, Columns, Format, Points, Streamed, SweepReport};

/// What to sweep.
#[derive(Clone, Debug)]
pub struct SweepRequest {
    /// The parameter vectors: a grid, seeded draws or explicit rows.
    pub points: Points,
    /// The options of every run.
    pub sim: SimOptions,
    /// Event slots per row (`event<k>`, `t<k>`, `dt<k>/d<p>`).
    pub events: usize,
    /// Worker threads (0: one per core).
    pub threads: usize,
}

impl SweepRequest {
    /// The caps on the event slots and the threads, each named as the front end spells it.
    pub fn check_counts(events: usize, threads: usize, spelling: Spelling) -> Result<(), String> {
        let cap = |what: &str, value, max| {
            crate::limits::count(&spelling.of(what), value, 0, max).map(drop).map_err(|e| e.to_string())
        };
        cap("events", events, MAX_EVENT_COLUMNS)?;
        cap("threads", threads, MAX_THREADS)
    }

    /// The row scheme of this sweep on `compiled`: every gradient of the model shown.
    pub fn columns<'c>(&self, compiled: &'c Compiled) -> Columns<'c> {
        Columns::new(compiled.info(), self.events, compiled.info().n_grad())
    }

    /// Runs every point on `compiled` and keeps the results (a sweep small enough to hold).
    /// `progress` is called once per point, from any worker. Each result is the one a single run
    /// at its point gives, whatever the threads.
    pub fn run(&self, compiled: &Compiled, progress: &(dyn Fn() + Sync)) -> Result<SweepReport, Error> {
        let points = self.points.to_vec();
        let results = sweep::run_points(compiled.system(), &points, &self.sim, self.threads, progress)?;
        Ok(SweepReport { info: compiled.info().clone(), events: self.events, points, results })
    }

    /// Runs every point on `compiled` and writes the header and one row per point to `out` as
    /// they complete, in order (memory independent of the number of points). With `keep`, the
    /// points and their results are also returned (for a plot).
    pub fn stream(
        &self,
        compiled: &Compiled,
        format: Format,
        keep: bool,
        progress: &(dyn Fn() + Sync),
        out: &mut dyn Write,
    ) -> Result<Streamed, Error> {
        let columns = self.columns(compiled);
        let system = compiled.system();
        Ok(sweep::stream_rows(
            system,
            &self.points,
            &self.sim,
            &columns,
            format,
            self.threads,
            keep,
            progress,
            out,
        )?)
    }
}
