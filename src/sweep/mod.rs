//! Parameter sweeps: one compiled model run at many parameter vectors in parallel, written as one
//! row per point in input order. Knows `sim` and its results; no CLI and no IO beyond the writer it
//! is given.
//!
//! Code map: `points` (which vectors: grids, lists, seeded samples, each computed from its
//! index), `table` (the row and column scheme, CSV and JSON lines), `stream` (rows written as they
//! complete through a bounded reorder window: memory independent of the number of points),
//! `report` (`SweepReport`: a sweep held in memory, its rows), this file (in-memory runs for
//! library callers and small sweeps). A sweep as a user asks for it is the door's `SweepRequest`
//! (`api/request/sweep.rs`).

pub mod points;
mod report;
mod stream;
pub mod table;

use rayon::prelude::*;

use crate::sim::{self, HybridSystem, SimError, SimOptions, SimResult};

pub use points::{
    full_grid, lerp, linspace, parse_vary, uniform_samples, uniform_samples_from, Axis, AxisSpec, Draws,
    Grid, Points, TooManyPoints, VarySpec, VarySpecError,
};
pub use report::SweepReport;
pub use stream::{stream_rows, Streamed, BATCH, WINDOW_BYTES, WINDOW_ROWS};
pub use table::{CellKind, Columns, Format};

/// The outcome of one point: exactly what `sim::run` returned for it. A run that stopped early
/// (Zeno, a runtime fault) is an `Ok` whose `stopped_by` says so; `Err` is bad input.
pub type PointResult = Result<SimResult, SimError>;

/// Why a sweep could not run or write its rows. (A point whose run failed is a row, not an error.)
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    /// The thread pool could not be built.
    #[error("cannot start {threads} worker threads")]
    ThreadPool {
        /// The threads asked for.
        threads: usize,
        /// Why.
        #[source]
        source: rayon::ThreadPoolBuildError,
    },
    /// A worker thread could not be started.
    #[error("cannot start {threads} worker threads")]
    Spawn {
        /// The threads asked for.
        threads: usize,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// Writing the rows failed.
    #[error("cannot write the rows")]
    Write(#[source] std::io::Error),
    /// A worker panicked (a bug).
    #[error("a worker thread panicked at point {index}")]
    WorkerPanicked {
        /// The point it was running.
        index: usize,
    },
}

/// Rows formatted in parallel per chunk, then written in order: formatting costs about as much
/// as a small model's run, and the chunk bounds the memory the texts take.
const WRITE_CHUNK: usize = 4096;

/// A pool of `threads` workers (0: one per core) for one call, not rayon's global pool.
fn pool(threads: usize) -> Result<rayon::ThreadPool, SweepError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|source| SweepError::ThreadPool { threads, source })
}

/// Runs `sys` at every point with `opts`, on a pool of `threads` threads built for this call
/// (0: one per core). Returns one result per point, in the order of `points`.
///
/// Each point is one independent run with nothing shared but the read-only compiled model (each
/// worker reuses a `sim::Runner` for its scratch buffers, and a reused simulator gives bit for
/// bit the result of a fresh run), so every result is the one a single `sim::run` at that point
/// gives, whatever the number of threads or the scheduling. `progress` is called once after each
/// point (from any worker thread).
pub fn run_points<S: HybridSystem + ?Sized>(
    sys: &S,
    points: &[Vec<f64>],
    opts: &SimOptions,
    threads: usize,
    progress: &(dyn Fn() + Sync),
) -> Result<Vec<PointResult>, SweepError> {
    Ok(pool(threads)?.install(|| {
        points
            .par_iter()
            .map_init(
                || sim::Runner::new(sys, opts),
                |sim, p| {
                    let result = match sim {
                        Ok(sim) => sim.run(p),
                        Err(e) => Err(e.clone()),
                    };
                    progress();
                    result
                },
            )
            .collect()
    }))
}

/// Writes the header and one row per point to `w`, in the order of `points`, formatting on
/// `threads` threads. The bytes do not depend on the thread count.
pub fn write_rows(
    w: &mut impl std::io::Write,
    columns: &Columns,
    format: Format,
    points: &[Vec<f64>],
    results: &[PointResult],
    threads: usize,
) -> Result<(), SweepError> {
    let pool = pool(threads)?;
    columns.write_header(w, format).map_err(SweepError::Write)?;
    for (ps, rs) in points.chunks(WRITE_CHUNK).zip(results.chunks(WRITE_CHUNK)) {
        let texts: Vec<String> =
            pool.install(|| ps.par_iter().zip(rs).map(|(p, r)| columns.row_text(format, p, r)).collect());
        for text in texts {
            w.write_all(text.as_bytes()).map_err(SweepError::Write)?;
        }
    }
    w.flush().map_err(SweepError::Write)
}
