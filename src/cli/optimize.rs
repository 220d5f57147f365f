//! `hybc optimize FILE --free P,.. --minimize Q [--subject-to "Q OP V" ..]`: compile a model once
//! with the free parameters as gradient parameters, then minimise (`crate::optimize`) from one or
//! several starts; progress on stderr, the result as a table or JSON, the optimum's trajectory as
//! a plot.

use std::process::ExitCode;

use clap::ValueEnum;

use super::options::{analysis_sim_options, at_most, parameter_values, parse_param_list, positive, SimFlags};
use super::{compile_model, load_model, usage_error, ModelArg, EXIT_GOAL_NOT_MET, EXIT_SIM_STOPPED};
use crate::fit::Bounds;
use crate::optimize::report::OptimizeReport;
use crate::optimize::{self, OptimizeOptions, SolverChoice, Verdict};
use crate::sema::ParamIdx;
use crate::sim::{SimOptions, TrajectoryRequest};
use crate::{Error, Model, OptimizeFailure, OptimizeRequest};

#[derive(Debug, Clone, Copy, ValueEnum)]
enum Format {
    Table,
    Json,
}

/// `--solver`: the library's `SolverChoice` words.
#[derive(Debug, Clone, Copy, ValueEnum)]
enum SolverArg {
    Auto,
    Slsqp,
    Lbfgsb,
}

impl From<SolverArg> for SolverChoice {
    fn from(arg: SolverArg) -> SolverChoice {
        match arg {
            SolverArg::Auto => SolverChoice::Auto,
            SolverArg::Slsqp => SolverChoice::Slsqp,
            SolverArg::Lbfgsb => SolverChoice::Lbfgsb,
        }
    }
}

#[derive(Debug, clap::Args)]
#[command(after_help = "Exit codes: 0 converged (KKT conditions hold); 1 the model has errors; 2 a usage \
                        error; 3 no start can be evaluated (its run stops early or a quantity does not \
                        exist there); 4 did not converge (iterations, infeasible, stalled at a cusp, \
                        runs failing).")]
pub struct OptimizeArgs {
    #[command(flatten)]
    model: ModelArg,
    /// The parameters to optimise: `P1,P2,...` (a vector's name for all its elements), bounded by
    /// their declared ranges and --bounds.
    #[arg(long, value_name = "P1,P2")]
    free: String,
    /// The objective: an output or a state at the final time, `EVENT#K`, `EVENT#last`,
    /// `NAME@TIME`, or a parameter.
    #[arg(long, value_name = "QUANTITY")]
    minimize: String,
    /// A constraint (repeatable): `QUANTITY = V`, `QUANTITY <= V`, `QUANTITY >= V`; a path
    /// constraint `NAME@LO:HI:N >= V` holds at N evenly spaced times.
    #[arg(long = "subject-to", value_name = "\"Q OP V\"")]
    subject_to: Vec<String>,
    /// Bounds of a free parameter (repeatable), within its declared range: `P=LO:HI` (a vector's
    /// name for every element).
    #[arg(long = "bounds", value_name = "P=LO:HI")]
    bounds: Vec<String>,
    /// Start value of a parameter, or a fixed value of one not optimised (repeatable).
    #[arg(long = "set", value_name = "P=VALUE")]
    set: Vec<String>,
    #[command(flatten)]
    sim: SimFlags,
    /// Most evaluations of one local solve (each a run; at most this many runs).
    #[arg(long, default_value_t = OptimizeOptions::default().max_iter)]
    max_iter: usize,
    /// Converged when the projected Lagrangian gradient, relative to its largest term, is at most this.
    #[arg(long, default_value_t = OptimizeOptions::default().kkt_tol)]
    kkt_tol: f64,
    /// The optimiser may stop when a step moves every parameter by less than this, relatively.
    #[arg(long, default_value_t = OptimizeOptions::default().xtol)]
    xtol: f64,
    /// The optimiser may stop when a step changes the objective by less than this, relatively.
    #[arg(long, default_value_t = OptimizeOptions::default().ftol)]
    ftol: f64,
    /// The local solver: `slsqp` (general constraints, at most 1000 free parameters), `lbfgsb`
    /// (bounds only, at most 100000), `auto` (L-BFGS-B for bounds only above 20 free parameters,
    /// else SLSQP).
    #[arg(long, value_enum, default_value = "auto")]
    solver: SolverArg,
    /// Starting points: the given one, then N - 1 drawn uniformly within the bounds.
    #[arg(long, default_value_t = 1)]
    starts: usize,
    /// Seed of the drawn starts.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Worker threads for the starts (0: one per core).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Output format.
    #[arg(long, value_enum, default_value = "table")]
    format: Format,
    /// Plot the optimum's trajectory (states and outputs, inputs among them) into this file.
    #[arg(long, value_name = "FILE.svg|.png")]
    plot: Option<std::path::PathBuf>,
    /// No progress lines on stderr.
    #[arg(long)]
    quiet: bool,
}

pub fn run(args: &OptimizeArgs) -> ExitCode {
    let model = match load_model(&args.model.file) {
        Ok(model) => model,
        Err(code) => return code,
    };
    match optimize_model(&model, args) {
        Ok(code) => code,
        Err(message) => usage_error(&message),
    }
}

fn options(args: &OptimizeArgs) -> Result<OptimizeOptions, String> {
    crate::limits::count("--max-iter", args.max_iter, 1, crate::limits::MAX_OPTIMIZE_RUNS)
        .map_err(|e| e.to_string())?;
    crate::limits::count("--starts", args.starts, 1, crate::limits::MAX_STARTS).map_err(|e| e.to_string())?;
    at_most("--threads", args.threads, crate::limits::MAX_THREADS)?;
    Ok(OptimizeOptions {
        max_iter: args.max_iter,
        kkt_tol: positive("--kkt-tol", args.kkt_tol)?,
        xtol: positive("--xtol", args.xtol)?,
        ftol: positive("--ftol", args.ftol)?,
        starts: args.starts,
        seed: args.seed,
        threads: args.threads,
        shard: None,
    })
}

/// The box of every free parameter: its declared range, narrowed by `--bounds P=LO:HI`.
fn bounds(model: &Model, free: &[ParamIdx], flags: &[String]) -> Result<Vec<Bounds>, String> {
    let mut narrow = Vec::with_capacity(flags.len());
    for flag in flags {
        let bad = || format!("--bounds: expected P=LO:HI with finite LO < HI, found `{flag}`");
        let (name, range) = flag.split_once('=').ok_or_else(bad)?;
        let (lo, hi) = range.split_once(':').ok_or_else(bad)?;
        let lo = crate::number::parse_number(lo.trim()).map_err(|_| bad())?;
        let hi = crate::number::parse_number(hi.trim()).map_err(|_| bad())?;
        if lo >= hi {
            return Err(bad());
        }
        narrow.push((name.trim().to_string(), lo, hi));
    }
    OptimizeRequest::bounds(model, free, &narrow).map_err(|e| format!("--bounds: {e}"))
}

fn optimize_model(model: &Model, args: &OptimizeArgs) -> Result<ExitCode, String> {
    let free = parse_param_list(model, &args.free, "--free")?;
    if free.is_empty() {
        return Err("--free: name at least one parameter to optimise".to_string());
    }
    // Checked before compiling: a count above the cap of the solver that would run is refused at once.
    let choice = SolverChoice::from(args.solver);
    let (cap, solver) = choice.cap(!args.subject_to.is_empty());
    at_most(&format!("--free (parameters, vector elements counted; the cap of {solver})"), free.len(), cap)?;
    choice.pick(free.len(), args.subject_to.len()).map_err(|e| format!("--solver: {e}"))?;
    let start = parameter_values(model, &args.set)?.values().to_vec();
    let sim = analysis_sim_options(model, &args.sim)?;
    let options = options(args)?;
    let bounds = bounds(model, &free, &args.bounds)?;
    if let Some(path) = &args.plot {
        crate::plot::ImageFormat::from_path(path).map_err(|e| format!("--plot: {e}"))?;
    }
    let compiled = match compile_model(model, &free) {
        Ok(c) => c,
        Err(code) => return Ok(code),
    };
    let info = compiled.info().clone();
    let starts = options.starts;
    let progress = |start: usize, t: &optimize::Trial| {
        eprintln!("{}", OptimizeReport::progress_line(&info, starts, start, t));
    };
    let progress: Option<&optimize::Progress<'_>> = if args.quiet { None } else { Some(&progress) };
    let request = OptimizeRequest {
        minimize: &args.minimize,
        subject_to: &args.subject_to,
        bounds,
        start,
        sim: sim.clone(),
        options,
        solver: choice,
    };
    let report = match request.run(&compiled, progress) {
        Ok(report) => report,
        Err(Error::Optimize(OptimizeFailure::Objective(e))) => return Err(format!("--minimize: {e}")),
        Err(Error::Optimize(OptimizeFailure::Constraint(e))) => return Err(format!("--subject-to: {e}")),
        Err(Error::Optimize(OptimizeFailure::Solver(e))) => return Err(format!("--solver: {e}")),
        Err(e) => return Err(super::error_chain(&e)),
    };
    if report.result.locals.iter().all(|l| matches!(l.verdict, Verdict::StartFailed { .. })) {
        eprintln!("error: {}", report.reason());
        return Ok(ExitCode::from(EXIT_SIM_STOPPED));
    }
    match args.format {
        Format::Table => super::print_out(&report.to_table()),
        Format::Json => super::print_out(&format!("{}\n", report.to_json())),
    }
    if let Some(path) = &args.plot {
        plot(&compiled, &sim, &report.result.reported().params, path)?;
    }
    Ok(if report.converged() {
        ExitCode::SUCCESS
    } else {
        eprintln!("error: {}", report.reason());
        ExitCode::from(EXIT_GOAL_NOT_MET)
    })
}

/// Runs the optimum once more with 1000 samples of the dense output and plots them.
fn plot(
    compiled: &crate::Compiled,
    sim: &SimOptions,
    params: &[f64],
    path: &std::path::Path,
) -> Result<(), String> {
    let opts = SimOptions {
        trajectory: TrajectoryRequest::Every((sim.t_end - sim.t_start) / 1000.0),
        ..sim.clone()
    };
    let run = compiled
        .simulator(&opts)
        .and_then(|mut s| s.run_values(params))
        .map_err(|e| format!("--plot: {e}"))?;
    crate::plot::plot_run(&run.into_report(), path).map_err(|e| format!("--plot: {e}"))
}
