//! `hybc run --trajectory FILE.csv [--sample DT]`: the trajectory as CSV rows (`-`: to standard
//! output). Rows are written as
//! the run records them (a [`Recorder`] that writes instead of keeping), so a long trajectory costs
//! disk, not memory; only with `--plot`, which draws from the same rows, are they kept. The number
//! of sampled rows is checked against [`MAX_TRAJECTORY_ROWS`] before the run.
//!
//! CSV columns: t, mode, the states, the outputs, then with gradients `d<state>/d<param>` and
//! `d<output>/d<param>` (output sensitivities `h_x S + h_p`, from the compiled output Jacobians).

use std::io::{self, Write};
use std::path::Path;

use crate::report::num;
use crate::sim::{
    HybridSystem, Point, PointKind, Recorder, RowSchedule, SimOptions, SystemInfo, TrajectoryRequest,
};

/// The most rows `--sample` may ask for: 10^7 rows are about 1-2 GB of CSV for a small model.
/// (`--trajectory` without `--sample` writes one row per step, and the steps are capped by the
/// integrator's step limit.)
pub(crate) const MAX_TRAJECTORY_ROWS: f64 = 1e7;

/// Checks that `--sample DT` over the run's span asks for at most `cap` rows.
pub(crate) fn check_rows(opts: &SimOptions, dt: f64, cap: f64) -> Result<(), String> {
    let rows = ((opts.t_end - opts.t_start) / dt).floor() + 1.0;
    if rows > cap {
        return Err(format!(
            "--sample: {dt:e} over t = {}..{} asks for {rows:.0} rows; at most {cap:.0}{} (sample more coarsely)",
            num(opts.t_start),
            num(opts.t_end),
            if cap < MAX_TRAJECTORY_ROWS { " with --plot, which keeps them" } else { "" }
        ));
    }
    Ok(())
}

/// Formats trajectory rows of one system at one parameter vector.
pub(crate) struct TrajectoryCsv<'s, S: HybridSystem + ?Sized> {
    system: &'s S,
    params: &'s [f64],
    /// Scratch for the output Jacobians.
    jac: (Vec<f64>, Vec<f64>, Vec<f64>),
    line: String,
}

impl<'s, S: HybridSystem + ?Sized> TrajectoryCsv<'s, S> {
    pub fn new(system: &'s S, params: &'s [f64]) -> Self {
        let info = system.info();
        let (n, k, m) = (info.n_states(), info.n_outputs(), info.n_grad());
        TrajectoryCsv {
            system,
            params,
            jac: (vec![0.0; k * n], vec![0.0; k * m], vec![0.0; k]),
            line: String::new(),
        }
    }

    pub fn write_header(&self, out: &mut impl Write) -> io::Result<()> {
        let info = self.system.info();
        let mut header: Vec<String> = vec!["t".into(), "mode".into()];
        header.extend(info.state_names.iter().cloned());
        header.extend(info.output_names.iter().cloned());
        for &j in &info.grad_params {
            header.extend(info.state_names.iter().map(|s| format!("d{s}/d{}", info.param_names[j])));
        }
        for &j in &info.grad_params {
            header.extend(info.output_names.iter().map(|o| format!("d{o}/d{}", info.param_names[j])));
        }
        writeln!(out, "{}", header.join(","))
    }

    pub fn write_row(
        &mut self,
        out: &mut impl Write,
        t: f64,
        mode: usize,
        x: &[f64],
        s: &[f64],
        outputs: &[f64],
    ) -> io::Result<()> {
        use std::fmt::Write as _;
        let info: &SystemInfo = self.system.info();
        let (n, k, m) = (info.n_states(), info.n_outputs(), info.n_grad());
        let line = &mut self.line;
        line.clear();
        let mode_name = info.modes.get(mode).map(|m| m.name.as_str()).unwrap_or("?");
        let _ = write!(line, "{},{mode_name}", num(t));
        for v in x.iter().chain(outputs).chain(s) {
            let _ = write!(line, ",{v:e}");
        }
        if m > 0 && s.len() == n * m {
            let (yx, yp, yt) = &mut self.jac;
            self.system.output_jac(t, x, self.params, yx, yp, yt);
            for j in 0..m {
                for i in 0..k {
                    let dy: f64 = (0..n).map(|c| yx[i * n + c] * s[j * n + c]).sum::<f64>() + yp[j * k + i];
                    let _ = write!(line, ",{dy:e}");
                }
            }
        }
        line.push('\n');
        out.write_all(line.as_bytes())
    }
}

/// A recorder that writes the rows `request` asks for as they come; the first write error is
/// kept and ends the writing (the run itself goes on).
pub(crate) struct StreamingTrajectory<'s, S: HybridSystem + ?Sized, W: Write> {
    csv: TrajectoryCsv<'s, S>,
    out: W,
    schedule: RowSchedule,
    error: Option<io::Error>,
}

impl<'s, S: HybridSystem + ?Sized, W: Write> StreamingTrajectory<'s, S, W> {
    pub fn new(
        system: &'s S,
        params: &'s [f64],
        request: TrajectoryRequest,
        t_start: f64,
        mut out: W,
    ) -> io::Result<Self> {
        let csv = TrajectoryCsv::new(system, params);
        csv.write_header(&mut out)?;
        Ok(StreamingTrajectory { csv, out, schedule: RowSchedule::new(request, t_start), error: None })
    }

    /// Flushes the file; the first error met while writing, if any.
    pub fn finish(mut self) -> io::Result<()> {
        match self.error.take() {
            Some(e) => Err(e),
            None => self.out.flush(),
        }
    }
}

impl<S: HybridSystem + ?Sized, W: Write> Recorder for StreamingTrajectory<'_, S, W> {
    fn is_active(&self) -> bool {
        self.schedule.is_active()
    }

    // The same rows as `sim::TrajectoryRecorder` keeps.
    fn wants(&self, kind: PointKind) -> bool {
        self.schedule.wants(kind)
    }

    fn next_grid_time(&self) -> Option<f64> {
        self.schedule.next_grid_time()
    }

    fn record(&mut self, p: &Point<'_>) {
        self.schedule.recorded(p.kind);
        if self.error.is_none() {
            if let Err(e) = self.csv.write_row(&mut self.out, p.t, p.mode, p.x, p.s, p.outputs) {
                self.error = Some(e);
            }
        }
    }
}

/// Writes the rows a run kept (`--trajectory` with `--plot`) to `path` (`-`: standard output).
pub(crate) fn write_kept<S: HybridSystem + ?Sized>(
    path: &Path,
    system: &S,
    params: &[f64],
    rows: &[crate::sim::TrajectoryRow],
) -> io::Result<()> {
    let mut out = super::output::create(path)?;
    let mut csv = TrajectoryCsv::new(system, params);
    let written = (|| {
        csv.write_header(&mut out)?;
        for row in rows {
            csv.write_row(&mut out, row.t, row.mode, &row.x, &row.s, &row.outputs)?;
        }
        out.flush()
    })();
    super::output::closed_pipe_is_done(path, written)
}
