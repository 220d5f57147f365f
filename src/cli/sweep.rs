//! `hybc sweep FILE`: compile a model once, run it at many parameter points in parallel and write
//! one row per point (CSV or JSON lines), optionally with a plot. Flags to points and a
//! `SweepRequest`, its rows streamed to the output; the plot, exit codes.

use std::io::{IsTerminal as _, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::ValueEnum;
use indicatif::{ProgressBar, ProgressStyle};

use super::options::{analysis_sim_options, parameter_values, parse_param_list, SimFlags};
use super::{compile_model, load_model, usage_error, ModelArg, EXIT_SIM_STOPPED};
use crate::plot::{self, Shown, SweepFigure};
use crate::sema::ParamIdx;
use crate::sim::SimOptions;
use crate::sweep::{self, Axis, AxisSpec, Format, Grid, PointResult, Points, SweepError};
use crate::{Compiled, Error, Model, Spelling, SweepRequest};

/// Caps on the counts the flags accept (docs/cli.md, "Limits"), shared with the Python interface
/// (`crate::limits`). Rows are streamed, so the number of points costs time, not memory; the cap
/// turns a typo (`--samples 10000000000000`) into a usage error rather than a run of years.
pub(crate) use crate::limits::MAX_SWEEP_POINTS as MAX_POINTS;
/// With `--plot` every point's result is kept until the figure is drawn (about 4 KB each).
const MAX_PLOT_POINTS: usize = 100_000;
/// Tangents drawn per panel of a sweep plot.
const PLOT_TANGENTS: usize = 5;

#[derive(Debug, Clone, Copy, ValueEnum)]
enum FormatArg {
    /// Comma-separated values with a header line.
    Csv,
    /// One JSON object per line, keyed by the CSV column names.
    Jsonl,
}

#[derive(Debug, clap::Args)]
pub struct SweepArgs {
    #[command(flatten)]
    model: ModelArg,
    /// A parameter to vary (repeatable; several make a full grid, the first varying slowest):
    /// `P=LO:HI:N` (N points from LO to HI), `P=V1,V2,...`, or with --samples `P=LO:HI` or `P`
    /// (its declared range).
    #[arg(long, value_name = "P=LO:HI:N|P=V1,V2|P=LO:HI|P")]
    vary: Vec<String>,
    /// Draw N points uniformly from the ranges of the varied parameters (without --vary: every
    /// parameter with a declared range).
    #[arg(long, value_name = "N")]
    samples: Option<usize>,
    /// Seed of the sampling; the same seed gives the same points [default: 0].
    #[arg(long, value_name = "S", requires = "samples")]
    seed: Option<u64>,
    /// Parameters to differentiate with respect to: `P1,P2,...` or `all`.
    #[arg(long, value_name = "P1,P2|all")]
    grad: Option<String>,
    /// Set a parameter for every point (repeatable); checked against its declared range.
    #[arg(long = "set", value_name = "P=VALUE")]
    set: Vec<String>,
    #[command(flatten)]
    sim: SimFlags,
    /// Worker threads (0: one per core).
    #[arg(long, value_name = "N", default_value_t = 0)]
    threads: usize,
    /// Output format.
    #[arg(long, value_enum, default_value = "csv")]
    format: FormatArg,
    /// Write the rows to this file instead of stdout (`-`: stdout).
    #[arg(long, short = 'o', value_name = "FILE")]
    output: Option<PathBuf>,
    /// Events shown per row (their names, times and time gradients).
    #[arg(long, value_name = "K", default_value_t = 5)]
    events: usize,
    /// Plot each output (or final state) against the first varied parameter, with gradient
    /// tangents, into this file.
    #[arg(long, value_name = "FILE.svg|.png")]
    plot: Option<PathBuf>,
    /// The outputs and states the plot shows, a panel each (default: every output, or every
    /// state for a model without outputs).
    #[arg(long, value_name = "NAME1,NAME2", requires = "plot")]
    show: Option<String>,
}

pub fn run(args: &SweepArgs) -> ExitCode {
    let model = match load_model(&args.model.file) {
        Ok(model) => model,
        Err(code) => return code,
    };
    match sweep_model(&model, args) {
        Ok(code) => code,
        Err(message) => usage_error(&message),
    }
}

/// The points of the sweep and the varied parameters, in flag order.
fn points(model: &Model, args: &SweepArgs) -> Result<(Points, Vec<usize>), String> {
    let base = parameter_values(model, &args.set)?.values().to_vec();
    let checked = model.checked();
    let mut specs: Vec<(usize, AxisSpec, &str)> = Vec::new();
    for text in &args.vary {
        let spec = sweep::parse_vary(text).map_err(|e| format!("--vary: {e}"))?;
        let idx = model.param_index(&spec.name).map_err(|e| format!("--vary: {e}"))?.0 as usize;
        if specs.iter().any(|s| s.0 == idx) {
            return Err(format!("--vary: `{}` is varied twice", spec.name));
        }
        // `--set u=...` sets every element of `u`, `u[3]` among them.
        let set_too = args.set.iter().filter_map(|s| s.split_once('=')).any(|(n, _)| {
            let n = n.trim();
            n == spec.name || model.vector(n).is_some_and(|v| v.elements().any(|p| p.0 as usize == idx))
        });
        if set_too {
            return Err(format!("`{}` is given both by --set and by --vary", spec.name));
        }
        specs.push((idx, spec.axis, text));
    }
    let range_of = |idx: usize| checked.params[idx].range;
    let in_range = |idx: usize, v: f64| -> Result<f64, String> {
        match range_of(idx) {
            Some((lo, hi)) if !(lo..=hi).contains(&v) => {
                Err(format!("--vary: {} = {v} is outside its range [{lo}, {hi}]", checked.params[idx].name))
            }
            _ => Ok(v),
        }
    };
    match args.samples {
        Some(n) => {
            if n == 0 || n > MAX_POINTS {
                return Err(format!("--samples: expected 1 to {MAX_POINTS} points, found {n}"));
            }
            let ranges: Vec<(usize, f64, f64)> = if specs.is_empty() {
                (0..checked.params.len()).filter_map(|i| range_of(i).map(|(lo, hi)| (i, lo, hi))).collect()
            } else {
                specs
                    .iter()
                    .map(|(idx, axis, text)| match axis {
                        AxisSpec::Range { lo, hi } => Ok((*idx, in_range(*idx, *lo)?, in_range(*idx, *hi)?)),
                        AxisSpec::Declared => range_of(*idx).map(|(lo, hi)| (*idx, lo, hi)).ok_or_else(|| {
                            format!(
                                "--vary {text}: `{text}` has no declared range to sample from; give one \
                                 (--vary {text}=LO:HI)"
                            )
                        }),
                        AxisSpec::Grid { .. } | AxisSpec::List(_) => Err(format!(
                            "--vary {text}: --samples draws from ranges; give P=LO:HI or P, not a grid or list"
                        )),
                    })
                    .collect::<Result<_, String>>()?
            };
            if ranges.is_empty() {
                return Err(format!(
                    "--samples: model `{}` declares no parameter range; name the parameters to sample \
                     with --vary P=LO:HI",
                    model.name()
                ));
            }
            let varied = ranges.iter().map(|r| r.0).collect();
            Ok((Points::Draws(sweep::Draws::new(base, ranges, n, args.seed.unwrap_or(0))), varied))
        }
        None => {
            if specs.is_empty() {
                return Err(
                    "nothing to vary: give --vary P=LO:HI:N, --vary P=V1,V2,... or --samples N".into()
                );
            }
            let mut axes: Vec<(usize, Axis)> = Vec::new();
            let mut count: usize = 1;
            for (idx, axis, text) in &specs {
                let values = match axis {
                    AxisSpec::Grid { lo, hi, n } => {
                        in_range(*idx, *lo)?;
                        in_range(*idx, *hi)?;
                        if *n > MAX_POINTS {
                            return Err(format!("--vary {text}: at most {MAX_POINTS} points"));
                        }
                        Axis::Even { lo: *lo, hi: *hi, n: *n }
                    }
                    AxisSpec::List(values) => Axis::List(
                        values.iter().map(|&v| in_range(*idx, v)).collect::<Result<Vec<f64>, String>>()?,
                    ),
                    AxisSpec::Range { .. } | AxisSpec::Declared => {
                        return Err(format!(
                            "--vary {text}: a grid needs P=LO:HI:N or P=V1,V2,...; ranges are for --samples N"
                        ))
                    }
                };
                count = count.saturating_mul(values.len());
                axes.push((*idx, values));
            }
            if count > MAX_POINTS {
                // `count` saturates: a product past 2^64 - 1 is only known to be larger.
                let count =
                    if count == usize::MAX { format!("more than {count}") } else { count.to_string() };
                return Err(format!(
                    "--vary: the grid has {count} points; at most {MAX_POINTS} are supported"
                ));
            }
            let varied = axes.iter().map(|a| a.0).collect();
            let grid = Grid::new(base, axes).map_err(|e| format!("--vary: {e}"))?;
            Ok((Points::Grid(grid), varied))
        }
    }
}

/// A progress bar on stderr when stderr is a terminal, else a hidden one.
pub(super) fn progress_bar(points: usize) -> ProgressBar {
    if std::io::stderr().is_terminal() {
        let style = ProgressStyle::with_template("{bar:40} {pos}/{len} points, eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar());
        ProgressBar::new(points as u64).with_style(style)
    } else {
        ProgressBar::hidden()
    }
}

fn sweep_model(model: &Model, args: &SweepArgs) -> Result<ExitCode, String> {
    let grad = match &args.grad {
        Some(list) => parse_param_list(model, list, "--grad")?,
        None => Vec::new(),
    };
    // Columns per event and worker threads are allocated per row or up front: a typo is a usage
    // error rather than an out-of-memory abort.
    SweepRequest::check_counts(args.events, args.threads, Spelling::Flag)?;
    let (points, varied) = points(model, args)?;
    let opts = analysis_sim_options(model, &args.sim)?;
    if let Some(path) = &args.plot {
        plot::ImageFormat::from_path(path).map_err(|e| format!("--plot: {e}"))?;
        for name in args.show.iter().flat_map(|list| list.split(',')).map(str::trim) {
            if !model.output_names().chain(model.state_names()).any(|known| known == name) {
                let known: Vec<&str> = model.output_names().chain(model.state_names()).collect();
                return Err(format!(
                    "--show: `{name}` is not an output or state of the model (it has {})",
                    known.join(", ")
                ));
            }
        }
        if points.len() > MAX_PLOT_POINTS {
            return Err(format!(
                "--plot: the sweep has {} points; a plot keeps every result until it is drawn and takes \
                 at most {MAX_PLOT_POINTS} (sweep without --plot: rows are streamed)",
                points.len()
            ));
        }
    }
    // Open the output before the work, so that a bad path fails at once.
    // `--output -` is standard output, as no --output is.
    let output = args.output.as_deref().filter(|path| !super::output::is_stdout(path));
    let mut out: Box<dyn Write> = match output {
        Some(path) => Box::new(std::io::BufWriter::new(
            std::fs::File::create(path)
                .map_err(|e| format!("--output: cannot write `{}`: {e}", path.display()))?,
        )),
        None => Box::new(std::io::BufWriter::new(std::io::stdout().lock())),
    };

    let compiled = match compile_model(model, &grad) {
        Ok(c) => c,
        Err(code) => return Ok(code),
    };
    let format = match args.format {
        FormatArg::Csv => Format::Csv,
        FormatArg::Jsonl => Format::Jsonl,
    };
    let bar = progress_bar(points.len());
    let request = SweepRequest { points, sim: opts.clone(), events: args.events, threads: args.threads };
    let streamed = request.stream(&compiled, format, args.plot.is_some(), &|| bar.inc(1), &mut out);
    bar.finish_and_clear();
    let streamed = match streamed {
        Ok(streamed) => streamed,
        // A closed stdout pipe (`hybc sweep ... | head`) means the reader has what it wanted.
        Err(Error::Sweep(SweepError::Write(_))) if output.is_none() => return Ok(ExitCode::SUCCESS),
        Err(Error::Sweep(SweepError::Write(e))) => {
            let path = output.unwrap_or(std::path::Path::new(super::output::STDOUT));
            return Err(format!("--output: cannot write `{}`: {e}", path.display()));
        }
        Err(Error::Sweep(e @ SweepError::WorkerPanicked { .. })) => {
            return Err(format!("internal error: {e}"))
        }
        Err(e) => return Err(format!("--threads: {}", super::error_chain(&e))),
    };
    drop(out);

    if let Some(path) = &args.plot {
        let (kept_points, results): (Vec<Vec<f64>>, Vec<PointResult>) = streamed.kept.into_iter().unzip();
        let show = args.show.as_deref();
        plot_sweep(
            model,
            &compiled,
            &grad,
            &kept_points,
            &results,
            &varied,
            &opts,
            args.threads,
            path,
            show,
        )?;
    }
    Ok(match streamed.first_ended_early {
        None => ExitCode::SUCCESS,
        Some(first) => {
            eprintln!(
                "error: {} of {} points ended early or have final values that are not finite (status and \
                 error columns); the first is row {}",
                streamed.ended_early,
                streamed.rows,
                first + 1
            );
            ExitCode::from(EXIT_SIM_STOPPED)
        }
    })
}

/// Draws the sweep against its first varied parameter. Tangents come from the sweep's own
/// gradients when `--grad` has that parameter, else from extra runs at the tangent points with a
/// model compiled to differentiate it (the table is not affected).
#[allow(clippy::too_many_arguments)]
fn plot_sweep(
    model: &Model,
    compiled: &Compiled,
    grad: &[ParamIdx],
    points: &[Vec<f64>],
    results: &[PointResult],
    varied: &[usize],
    opts: &SimOptions,
    threads: usize,
    path: &std::path::Path,
    show: Option<&str>,
) -> Result<(), String> {
    let param = varied[0];
    let info = compiled.info();
    // The names were checked against the model before the sweep ran.
    let shown = match show {
        None => Shown::default_for(info),
        Some(list) => list.split(',').filter_map(|name| Shown::by_name(info, name.trim())).collect(),
    };
    let mut figure = SweepFigure::showing("", info, param, points, results, varied.len() == 1, shown);
    let shown = figure.series.first().map_or(0, |s| s.points.len());
    figure.title = format!("{}: final values against {}", model.name(), info.param_names[param]);
    if shown < points.len() {
        figure.title += &format!(" ({} of {} points; the others ended early)", shown, points.len());
    }
    let at = SweepFigure::tangent_points(points, results, param, PLOT_TANGENTS);
    let at_points: Vec<Vec<f64>> = at.iter().map(|&i| points[i].clone()).collect();
    let added = if grad.iter().any(|g| g.0 as usize == param) {
        let at_results: Vec<PointResult> = at.iter().map(|&i| results[i].clone()).collect();
        figure.add_tangents(info, param, &at_points, &at_results)
    } else {
        let with_param = model
            .compile_params(&[ParamIdx(param as u32)])
            .map_err(|e| format!("--plot: {}", super::error_chain(&e)))?;
        let request = SweepRequest { points: Points::Rows(at_points), sim: opts.clone(), events: 0, threads };
        let at = request.run(&with_param, &|| ()).map_err(|e| format!("--threads: {e}"))?;
        figure.add_tangents(with_param.info(), param, &at.points, &at.results)
    };
    added.and_then(|()| plot::plot_sweep(&figure, path)).map_err(|e| format!("--plot: {e}"))
}
