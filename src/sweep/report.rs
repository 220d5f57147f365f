//! A finished sweep held in memory: every point with its result, and the row scheme that reports
//! them (`table::Columns`: CSV, JSON lines, typed cells). A streamed sweep never holds one: its
//! rows go out as they complete (`stream`). No IO beyond the writer it is given.

use super::{write_rows, Columns, Format, PointResult, SweepError};
use crate::sim::SystemInfo;

/// The points of a sweep, their results and how to show them.
#[derive(Clone, Debug)]
pub struct SweepReport {
    /// The model's shape (names, gradient columns).
    pub info: SystemInfo,
    /// Events shown per row.
    pub events: usize,
    /// Every point, in order.
    pub points: Vec<Vec<f64>>,
    /// Each point's outcome, in the same order.
    pub results: Vec<PointResult>,
}

impl SweepReport {
    /// The row scheme: every gradient of the run shown.
    pub fn columns(&self) -> Columns<'_> {
        Columns::new(&self.info, self.events, self.info.n_grad())
    }

    /// Writes the header and one row per point to `w` (formatting on `threads` threads; the
    /// bytes do not depend on them), as `hybc sweep` writes them.
    pub fn write(
        &self,
        w: &mut impl std::io::Write,
        format: Format,
        threads: usize,
    ) -> Result<(), SweepError> {
        write_rows(w, &self.columns(), format, &self.points, &self.results, threads)
    }
}
