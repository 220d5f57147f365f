//! `hybc run FILE`: compile a model, simulate it with sensitivities and report events, final state,
//! outputs and their gradients.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::ValueEnum;

use super::options::{parameter_values, parse_param_list, positive, SimFlags};
use super::trajectory::{self, StreamingTrajectory};
use super::{compile_model, error_chain, load_model, output, usage_error, ModelArg};
use super::{EXIT_CANNOT_JUDGE, EXIT_GOAL_NOT_MET, EXIT_SIM_STOPPED};
use crate::gradcheck::{CheckOptions, Verdict};
use crate::report::RunReport;
use crate::sim::{SimOptions, TrajectoryRequest};
use crate::{Compiled, GradCheckRequest, Model, Params, Spelling};

#[derive(Debug, Clone, Copy, ValueEnum)]
enum Format {
    Table,
    Json,
}

#[derive(Debug, clap::Args)]
#[command(after_help = "Exit codes: 0 success; 1 the model has errors; 2 a usage error; 3 the run \
                        stopped early (Zeno behaviour or a runtime fault); 4 --check-grad found a \
                        derivative outside --check-tol or events that change with the step size; 5 \
                        --check-grad cannot judge a derivative (its differences neither confirm nor \
                        refute it) and nothing failed.")]
pub struct RunArgs {
    #[command(flatten)]
    model: ModelArg,
    /// Parameters to differentiate with respect to: `P1,P2,...` or `all`.
    #[arg(long, value_name = "P1,P2|all")]
    grad: Option<String>,
    /// Set a parameter for this run (repeatable); checked against its declared range.
    #[arg(long = "set", value_name = "P=VALUE")]
    set: Vec<String>,
    #[command(flatten)]
    sim: SimFlags,
    /// Output format.
    #[arg(long, value_enum, default_value = "table")]
    format: Format,
    /// Write the trajectory to this CSV file (every step, or a uniform grid with --sample); `-`:
    /// standard output, the report then to stderr.
    #[arg(long, value_name = "FILE.csv")]
    trajectory: Option<PathBuf>,
    /// Sample the trajectory every DT using the dense output.
    #[arg(long, value_name = "DT", requires = "trajectory")]
    sample: Option<f64>,
    /// Report every output and state with its derivatives at these times, from the dense output
    /// (the steps are not cut): `LO:HI:N` (N evenly spaced, ends included) or `T1,T2,...`
    /// ascending. In the table, the JSON `samples` field and --samples-out. A time at an event
    /// instant gets the values after its events.
    #[arg(long, value_name = "LO:HI:N|T1,T2,...")]
    at: Option<String>,
    /// Write the --at samples, with their derivatives, to this CSV file; `-`: standard output, the
    /// report then to stderr.
    #[arg(long, value_name = "FILE.csv", requires = "at")]
    samples_out: Option<PathBuf>,
    /// Only these quantities get gradients (in either --sens mode; the adjoint then runs one
    /// backward pass per quantity): states and outputs at the final time (NAME), event times
    /// (EVENT#K, K from 1, or EVENT#last) and values at a time (NAME@TIME, sampled as --at
    /// would). Default: every quantity the report holds.
    #[arg(long, value_name = "Q1,Q2,..", value_delimiter = ',', requires = "grad")]
    of: Option<Vec<String>>,
    /// Plot states and outputs against time, with event lines and mode bands, into this file.
    #[arg(long, value_name = "FILE.svg|.png")]
    plot: Option<PathBuf>,
    /// Print nothing but errors; the exit code tells the outcome.
    #[arg(long)]
    quiet: bool,
    /// After the run, check every reported derivative against finite differences of the same
    /// compiled model at p +/- h, h = 1e-5 |p| per parameter (one-sided at a declared bound), and
    /// the events against a re-run at a tenth of the tolerances with steps of at most span/10000;
    /// exit code 4 when a derivative disagrees by more than --check-tol and more than the
    /// differences resolve, or when the events change with the step size; 5 when nothing fails
    /// but a derivative could not be judged (its differences at h, h/2, .. neither converge to
    /// it nor away from it). Changed event
    /// sequences between p - h and p + h are reported as cusps, grazing events skipped.
    #[arg(long, requires = "grad")]
    check_grad: bool,
    /// Largest relative discrepancy --check-grad accepts (default 1e5 rtol, clamped to [1e-4, 1e-2]).
    #[arg(long, value_name = "TOL", requires = "check_grad")]
    check_tol: Option<f64>,
}

pub fn run(args: &RunArgs) -> ExitCode {
    let model = match load_model(&args.model.file) {
        Ok(model) => model,
        Err(code) => return code,
    };
    match run_model(&model, args) {
        Ok(code) => code,
        Err(message) => usage_error(&message),
    }
}

/// The most rows `--trajectory` with `--plot` keeps in memory for the figure.
const MAX_PLOTTED_ROWS: f64 = crate::sim::MAX_SAMPLED_ROWS;

/// The trajectory `--trajectory`/`--sample` ask for, its number of rows checked.
fn trajectory_request(args: &RunArgs, opts: &SimOptions) -> Result<TrajectoryRequest, String> {
    Ok(match (&args.trajectory, args.sample) {
        (None, _) => TrajectoryRequest::None,
        (Some(_), None) => TrajectoryRequest::Steps,
        (Some(_), Some(dt)) => {
            let dt = positive("--sample", dt)?;
            let cap = if args.plot.is_some() { MAX_PLOTTED_ROWS } else { trajectory::MAX_TRAJECTORY_ROWS };
            trajectory::check_rows(opts, dt, cap)?;
            TrajectoryRequest::Every(dt)
        }
    })
}

/// One run whose trajectory rows are written to `path` as they are recorded, never kept.
fn run_streaming(
    compiled: &Compiled,
    params: &Params,
    opts: &SimOptions,
    path: &Path,
) -> Result<RunReport, String> {
    let cannot_write = |e: std::io::Error| format!("--trajectory: cannot write `{}`: {e}", path.display());
    let out = output::create(path).map_err(cannot_write)?;
    let p = params.values();
    let mut recorder = StreamingTrajectory::new(compiled.system(), p, opts.trajectory, opts.t_start, out)
        .map_err(cannot_write)?;
    // The recorder takes the rows; the run keeps none.
    let run_opts = SimOptions { trajectory: TrajectoryRequest::None, ..opts.clone() };
    let mut simulator = compiled.simulator(&run_opts).map_err(|e| error_chain(&e))?;
    let run = simulator.run_with(params, &mut recorder).map_err(|e| error_chain(&e))?;
    output::closed_pipe_is_done(path, recorder.finish()).map_err(cannot_write)?;
    Ok(run.into_report())
}

fn run_model(model: &Model, args: &RunArgs) -> Result<ExitCode, String> {
    let grad = match &args.grad {
        Some(list) => parse_param_list(model, list, "--grad")?,
        None => Vec::new(),
    };
    let params = parameter_values(model, &args.set)?;
    let mut overrides = args.sim.overrides();
    overrides.at = args.at.as_deref().map(super::samples::parse_at).transpose()?;
    overrides.of = args.of.clone();
    let mut opts = overrides.apply(&model.sim_options(), Spelling::Flag).map_err(|e| e.message)?;
    opts.trajectory = trajectory_request(args, &opts)?;
    plot_trajectory(args, &mut opts)?;
    let check_opts = check_options(&opts, args)?;
    // A file written to standard output (`-`) leaves it to that file: the report goes to stderr.
    let report_to = output::report_stream(&[
        ("--trajectory", args.trajectory.as_deref()),
        ("--samples-out", args.samples_out.as_deref()),
    ])?;

    let compiled = match compile_model(model, &grad) {
        Ok(c) => c,
        Err(code) => return Ok(code),
    };
    overrides.gradients_of(compiled.info(), &mut opts, Spelling::Flag).map_err(|e| e.message)?;
    let report = match (&args.trajectory, &args.plot) {
        // Rows go to the file as the run records them.
        (Some(path), None) => run_streaming(&compiled, &params, &opts, path)?,
        (trajectory, _) => {
            let report = compiled.simulate(&params, &opts).map_err(|e| error_chain(&e))?.into_report();
            if let Some(path) = trajectory {
                let rows = report.result().trajectory.as_deref().unwrap_or_default();
                trajectory::write_kept(path, compiled.system(), report.params(), rows)
                    .map_err(|e| format!("--trajectory: cannot write `{}`: {e}", path.display()))?;
            }
            report
        }
    };
    if let Some(path) = &args.plot {
        crate::plot::plot_run(&report, path).map_err(|e| format!("--plot: {e}"))?;
    }
    if let Some(path) = &args.samples_out {
        super::samples::write_csv(path, &report)?;
    }
    // A run into a Zeno point grazes ever more often; the first few warnings say it all.
    const SHOWN_WARNINGS: usize = 3;
    for w in report.result().warnings.iter().take(SHOWN_WARNINGS) {
        eprintln!("warning: {w}");
    }
    if report.result().warnings.len() > SHOWN_WARNINGS {
        eprintln!(
            "warning: ... and {} more (all are in --format json)",
            report.result().warnings.len() - SHOWN_WARNINGS
        );
    }
    let check = match check_opts {
        Some(check) => {
            let request = GradCheckRequest { sim: opts.clone(), check };
            Some(request.run(&compiled, report.params(), report.result()).map_err(|e| error_chain(&e))?)
        }
        None => None,
    };
    if !args.quiet {
        match args.format {
            Format::Table => {
                // Streamed as the JSON is: 10^6 event lines are about 90 MB of text.
                output::write_to(report_to, |out| {
                    let mut out = super::FmtIo::new(out);
                    let written = report.write_table(&mut out);
                    out.result(written)
                });
                if let Some(check) = &check {
                    super::print_to(report_to, &format!("\n{}", check.to_table()));
                }
            }
            Format::Json => {
                let extra: Vec<_> = check.iter().map(|check| ("check_grad", check.to_json())).collect();
                // Streamed: the text of 10^6 events is never held whole (docs/cli.md, Limits).
                output::write_to(report_to, |mut out| {
                    report.write_json(&mut out, &extra)?;
                    out.write_all(b"\n")
                });
            }
        }
    }
    if let Some(message) = report.failure() {
        eprintln!("error: {message}");
        return Ok(ExitCode::from(EXIT_SIM_STOPPED));
    }
    // Values that are not numbers are not a result, even from a run that ended as asked.
    if let Some(message) = report.non_finite() {
        eprintln!("warning: {message}");
        return Ok(ExitCode::from(EXIT_SIM_STOPPED));
    }
    Ok(match check {
        Some(check) => match check.verdict() {
            Verdict::Passed => ExitCode::SUCCESS,
            Verdict::Failed => ExitCode::from(EXIT_GOAL_NOT_MET),
            Verdict::CannotJudge => ExitCode::from(EXIT_CANNOT_JUDGE),
        },
        _ => ExitCode::SUCCESS,
    })
}

/// `--check-grad` options: the defaults for the run's rtol, `--check-tol` if given.
fn check_options(opts: &SimOptions, args: &RunArgs) -> Result<Option<CheckOptions>, String> {
    if !args.check_grad {
        return Ok(None);
    }
    let mut check = CheckOptions::for_rtol(opts.rtol);
    if let Some(tol) = args.check_tol {
        check.tol = positive("--check-tol", tol)?;
    }
    Ok(Some(check))
}

/// `--plot`: checks the file's extension before the run and, unless `--trajectory` asked for
/// rows, samples the dense output 1000 times over the run for the curves.
fn plot_trajectory(args: &RunArgs, opts: &mut SimOptions) -> Result<(), String> {
    if let Some(path) = &args.plot {
        crate::plot::ImageFormat::from_path(path).map_err(|e| format!("--plot: {e}"))?;
        if opts.trajectory == TrajectoryRequest::None {
            opts.trajectory = TrajectoryRequest::Every((opts.t_end - opts.t_start) / 1000.0);
        }
    }
    Ok(())
}
