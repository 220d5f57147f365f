//! Rows written as the points complete, in input order, with memory independent of the number of
//! points: workers take batches of [`BATCH`] consecutive points in order from a shared counter,
//! run and format them, and leave the text in a reorder window; the calling thread writes the
//! window's batches as soon as the next one in order is there. A worker may not start a batch more
//! than [`WINDOW_ROWS`] rows ahead of the next row to write, nor while the window holds more than
//! [`WINDOW_BYTES`] of text, except the very next batch itself (so a slow point never deadlocks the
//! window, and one huge row still gets written). Batches, not single points, because a small
//! model's run takes a few microseconds: one lock and one wake-up per point cost more than the run.
//!
//! Why not chunks on rayon: a chunk waits for its slowest point (a Zeno point can take 1000 times
//! longer than the rest) while every other core idles; the window only holds the others back
//! once they are `WINDOW_ROWS` ahead.
//!
//! The bytes do not depend on the thread count or the scheduling: row `i` is a function of point
//! `i` alone (`Points::fill`, a fresh or reused `Runner`, which gives bit for bit the same
//! result) and rows are written in index order.

use std::collections::BTreeMap;
use std::io::Write;
use std::sync::{Condvar, Mutex, MutexGuard, PoisonError};

use super::{Columns, Format, PointResult, Points, SweepError};
use crate::sim::{self, HybridSystem, SimOptions};

/// Points per batch: enough to amortise the lock and the writer's wake-up over runs of a few
/// microseconds, few enough that a batch holding a slow point holds back little.
pub const BATCH: usize = 64;
/// The most rows a worker may run ahead of the next row to write.
pub const WINDOW_ROWS: usize = 4096;
/// The most text the reorder window holds before workers wait (64 MiB).
pub const WINDOW_BYTES: usize = 64 << 20;

/// What a streamed sweep did.
#[derive(Debug, Default)]
pub struct Streamed {
    /// Rows written.
    pub rows: usize,
    /// Rows whose status is not `ok`: the run ended early, was refused, or has final values that
    /// are not finite.
    pub ended_early: usize,
    /// The index of the first of them.
    pub first_ended_early: Option<usize>,
    /// Every point and its result, in order, when asked for (`keep`); else empty.
    pub kept: Vec<(Vec<f64>, PointResult)>,
}

/// One finished batch of rows waiting for its turn.
#[derive(Default)]
struct Batch {
    rows: usize,
    text: String,
    ended_early: usize,
    first_ended_early: Option<usize>,
    kept: Vec<(Vec<f64>, PointResult)>,
}

struct Window {
    /// The next batch a worker takes.
    next: usize,
    /// The next batch to write: every batch before it is written.
    written: usize,
    batches: BTreeMap<usize, Batch>,
    bytes: usize,
    /// Set when the writer failed or a worker panicked: everyone stops.
    stop: bool,
    panicked_at: Option<usize>,
}

struct Shared {
    window: Mutex<Window>,
    changed: Condvar,
}

impl Shared {
    /// The lock, also after a panicking worker poisoned it (the window's fields stay consistent:
    /// every change is a whole statement).
    fn lock(&self) -> MutexGuard<'_, Window> {
        self.window.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn wait<'a>(&self, guard: MutexGuard<'a, Window>) -> MutexGuard<'a, Window> {
        self.changed.wait(guard).unwrap_or_else(PoisonError::into_inner)
    }
}

/// Runs `sys` at every point of `points` with `opts` on `threads` worker threads (0: one per
/// core) and writes the header and one row per point to `w` in index order as they complete.
/// `progress` is called once after each point (from any worker). With `keep`, every point and
/// its result are also returned (for a plot: memory then grows with the points).
#[allow(clippy::too_many_arguments)]
pub fn stream_rows<S: HybridSystem + ?Sized>(
    sys: &S,
    points: &Points,
    opts: &SimOptions,
    columns: &Columns<'_>,
    format: Format,
    threads: usize,
    keep: bool,
    progress: &(dyn Fn() + Sync),
    w: &mut dyn Write,
) -> Result<Streamed, SweepError> {
    columns.write_header(w, format).map_err(SweepError::Write)?;
    let total = points.len();
    let threads = match threads {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        n => n,
    }
    .min(total.div_ceil(BATCH).max(1));
    let shared = Shared {
        window: Mutex::new(Window {
            next: 0,
            written: 0,
            batches: BTreeMap::new(),
            bytes: 0,
            stop: false,
            panicked_at: None,
        }),
        changed: Condvar::new(),
    };
    std::thread::scope(|scope| {
        let mut workers = Vec::with_capacity(threads);
        for _ in 0..threads {
            let spawned = std::thread::Builder::new()
                .name("hybc-sweep".into())
                .spawn_scoped(scope, || work(sys, points, opts, columns, format, keep, progress, &shared));
            match spawned {
                Ok(worker) => workers.push(worker),
                Err(source) => {
                    shared.lock().stop = true;
                    shared.changed.notify_all();
                    return Err(SweepError::Spawn { threads, source });
                }
            }
        }
        let written = write_in_order(&shared, total, w);
        if written.is_err() {
            shared.lock().stop = true;
            shared.changed.notify_all();
        }
        // Joined here, so that a worker's panic is this error rather than a panic of the scope.
        let panicked = workers.into_iter().map(|worker| worker.join().is_err()).fold(false, |a, b| a | b);
        match shared.lock().panicked_at {
            Some(index) if panicked => Err(SweepError::WorkerPanicked { index }),
            _ => written,
        }
    })
}

/// One worker: takes batches while the window allows, runs and formats each point.
#[allow(clippy::too_many_arguments)]
fn work<S: HybridSystem + ?Sized>(
    sys: &S,
    points: &Points,
    opts: &SimOptions,
    columns: &Columns<'_>,
    format: Format,
    keep: bool,
    progress: &(dyn Fn() + Sync),
    shared: &Shared,
) {
    let total = points.len();
    let batches = total.div_ceil(BATCH);
    let mut simulator = sim::Runner::new(sys, opts);
    let mut p = vec![0.0; points.width()];
    loop {
        let b = {
            let mut win = shared.lock();
            loop {
                if win.stop || win.next >= batches {
                    return;
                }
                let ahead = win.next - win.written;
                if ahead == 0 || (ahead * BATCH < WINDOW_ROWS && win.bytes < WINDOW_BYTES) {
                    break;
                }
                win = shared.wait(win);
            }
            win.next += 1;
            win.next - 1
        };
        let mut batch = Batch::default();
        for index in b * BATCH..((b + 1) * BATCH).min(total) {
            // A panic in a run must not leave the writer waiting for this batch forever.
            let guard = PanicFlag { shared, index };
            points.fill(index, &mut p);
            let result: PointResult = match &mut simulator {
                Ok(simulator) => simulator.run(&p),
                Err(e) => Err(e.clone()),
            };
            progress();
            batch.text.push_str(&columns.row_text(format, &p, &result));
            batch.rows += 1;
            if !columns.is_ok(&result) {
                batch.ended_early += 1;
                batch.first_ended_early.get_or_insert(index);
            }
            if keep {
                batch.kept.push((p.clone(), result));
            }
            std::mem::forget(guard);
        }
        let mut win = shared.lock();
        win.bytes += batch.text.len();
        win.batches.insert(b, batch);
        // Only the batch the writer waits for lets it go on.
        let wake = b == win.written;
        drop(win);
        if wake {
            shared.changed.notify_all();
        }
    }
}

/// Stops the sweep when dropped during a panic (it is forgotten on success).
struct PanicFlag<'a> {
    shared: &'a Shared,
    index: usize,
}

impl Drop for PanicFlag<'_> {
    fn drop(&mut self) {
        let mut win = self.shared.lock();
        win.stop = true;
        win.panicked_at.get_or_insert(self.index);
        drop(win);
        self.shared.changed.notify_all();
    }
}

/// The writer: takes the batches that are next in order out of the window and writes them outside
/// the lock.
fn write_in_order(shared: &Shared, total: usize, w: &mut dyn Write) -> Result<Streamed, SweepError> {
    let mut done = Streamed::default();
    let mut ready: Vec<Batch> = Vec::new();
    while done.rows < total {
        {
            let mut win = shared.lock();
            loop {
                if let Some(index) = win.panicked_at {
                    return Err(SweepError::WorkerPanicked { index });
                }
                if win.stop {
                    // The writer itself set it: its error is being returned elsewhere.
                    return Err(SweepError::Write(std::io::Error::other("the sweep was stopped")));
                }
                if win.batches.contains_key(&win.written) {
                    break;
                }
                win = shared.wait(win);
            }
            loop {
                let b = win.written;
                let Some(batch) = win.batches.remove(&b) else { break };
                win.bytes -= batch.text.len();
                ready.push(batch);
                win.written += 1;
            }
        }
        // The window has room again.
        shared.changed.notify_all();
        for batch in ready.drain(..) {
            w.write_all(batch.text.as_bytes()).map_err(SweepError::Write)?;
            done.rows += batch.rows;
            done.ended_early += batch.ended_early;
            if done.first_ended_early.is_none() {
                done.first_ended_early = batch.first_ended_early;
            }
            done.kept.extend(batch.kept);
        }
    }
    w.flush().map_err(SweepError::Write)?;
    Ok(done)
}
