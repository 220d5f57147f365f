//! `hybc fit FILE`: compile a model once with the free parameters as gradient parameters, then fit
//! them to targets on final outputs, final states and event times (`crate::fit`).

use std::process::ExitCode;
use std::time::Instant;

use clap::ValueEnum;

use super::run::{parameter_values, positive, sim_options, SimFlags};
use super::{
    compile_model, load_model, parse_param_list, usage_error, ModelArg, EXIT_GOAL_NOT_MET, EXIT_SIM_STOPPED,
};
use crate::fit::{self, Bounds, FitError, FitOptions, FitProblem, FitReport, Rejection, Target};
use crate::Model;

/// The most trials `--max-iter` allows.
pub(crate) use crate::limits::MAX_FIT_ITER as MAX_ITER;

#[derive(Debug, Clone, Copy, ValueEnum)]
enum Format {
    Table,
    Json,
}

#[derive(Debug, clap::Args)]
pub struct FitArgs {
    #[command(flatten)]
    model: ModelArg,
    /// The parameters to fit: `P1,P2,...` (bounded by their declared ranges).
    #[arg(long, value_name = "P1,P2")]
    free: String,
    /// A target (repeatable): `OUTPUT=VALUE`, `STATE=VALUE` (at the final time), `NAME@TIME=VALUE`
    /// (at a time), `EVENT#K=TIME` (the K-th firing, 1-based) or `EVENT#last=TIME`; append
    /// `@WEIGHT` to weight its residual.
    #[arg(long = "target", value_name = "NAME=VALUE[@W]", required_unless_present = "data")]
    targets: Vec<String>,
    /// Measurements to fit (least squares): a CSV with a `time` column, a column per observed
    /// output or state, optional `sigma_NAME` columns (standard deviations, weights 1/sigma);
    /// an empty cell is a missing value. The report adds the residuals per name and the
    /// parameters' standard errors.
    #[arg(long, value_name = "FILE.csv")]
    data: Option<std::path::PathBuf>,
    /// Start value of a parameter, or a fixed value of a parameter not fitted (repeatable).
    #[arg(long = "set", value_name = "P=VALUE")]
    set: Vec<String>,
    #[command(flatten)]
    sim: SimFlags,
    /// Largest number of trial points (one run each).
    #[arg(long, default_value_t = FitOptions::default().max_iter)]
    max_iter: usize,
    /// Converged when the Gauss-Newton step is below this, relative to the parameters.
    #[arg(long, default_value_t = FitOptions::default().xtol)]
    xtol: f64,
    /// Converged when the residuals' cosine with every Jacobian column is below this.
    #[arg(long, default_value_t = FitOptions::default().gtol)]
    gtol: f64,
    /// Converged when an accepted step lowers the objective by less than this fraction.
    #[arg(long, default_value_t = FitOptions::default().ftol)]
    ftol: f64,
    /// Output format.
    #[arg(long, value_enum, default_value = "table")]
    format: Format,
}

pub fn run(args: &FitArgs) -> ExitCode {
    let model = match load_model(&args.model.file) {
        Ok(model) => model,
        Err(code) => return code,
    };
    match fit_model(&model, args) {
        Ok(code) => code,
        Err(message) => usage_error(&message),
    }
}

fn fit_options(args: &FitArgs) -> Result<FitOptions, String> {
    if args.max_iter == 0 {
        return Err("--max-iter: expected at least 1".to_string());
    }
    // Every trial is kept for the report (a few hundred bytes each).
    super::run::at_most("--max-iter", args.max_iter, MAX_ITER)?;
    Ok(FitOptions {
        max_iter: args.max_iter,
        xtol: positive("--xtol", args.xtol)?,
        gtol: positive("--gtol", args.gtol)?,
        ftol: positive("--ftol", args.ftol)?,
    })
}

fn fit_model(model: &Model, args: &FitArgs) -> Result<ExitCode, String> {
    let free = parse_param_list(model, &args.free, "--free")?;
    if free.is_empty() {
        return Err("--free: name at least one parameter to fit".to_string());
    }
    let start = parameter_values(model, &args.set)?.values().to_vec();
    let sim = sim_options(model, &args.sim)?;
    let options = fit_options(args)?;
    let compiled = match compile_model(model, &free) {
        Ok(c) => c,
        Err(code) => return Ok(code),
    };
    let info = compiled.info().clone();
    let mut targets = args
        .targets
        .iter()
        .map(|t| Target::parse(t, &info).map_err(|e| format!("--target: {e}")))
        .collect::<Result<Vec<_>, _>>()?;
    let mut sigma_known = false;
    if let Some(path) = &args.data {
        let shown = path.display().to_string();
        let text = read_data(path).map_err(|e| format!("--data: cannot read `{shown}`: {e}"))?;
        let data = fit::data::parse_data(&text, &shown, &info).map_err(|e| format!("--data: {e}"))?;
        sigma_known = data.sigma_known;
        targets.extend(data.targets);
    }
    if targets.len() < free.len() {
        eprintln!(
            "warning: {} free parameters but {} target(s): the fit is underdetermined; the damped steps \
             stay near the start and the condition number is infinite",
            free.len(),
            targets.len()
        );
    }
    let bounds =
        free.iter().map(|p| Bounds::from_range(model.checked().params[p.0 as usize].range)).collect();

    let problem = FitProblem { system: compiled.native(), start, bounds, targets, sim };
    let started = Instant::now();
    let result = match fit::fit(&problem, &options) {
        Ok(result) => result,
        // The run works, but the fit's goal cannot be stated in doubles: the goal is not met.
        Err(e @ FitError::Start(Rejection::ObjectiveOverflow { .. } | Rejection::NonFinite { .. })) => {
            eprintln!("error: {e}");
            return Ok(ExitCode::from(EXIT_GOAL_NOT_MET));
        }
        Err(e @ FitError::Start(_)) => {
            eprintln!("error: {e}");
            return Ok(ExitCode::from(EXIT_SIM_STOPPED));
        }
        Err(e) => return Err(e.to_string()),
    };
    let report = FitReport {
        model: model.name().to_string(),
        info,
        targets: problem.targets,
        options,
        result,
        compile_seconds: compiled.compile_seconds(),
        fit_seconds: started.elapsed().as_secs_f64(),
        sigma_known,
    };
    match args.format {
        Format::Table => super::print_out(&report.to_table()),
        Format::Json => super::print_out(&format!("{}\n", report.to_json())),
    }
    Ok(if report.result.is_converged() {
        ExitCode::SUCCESS
    } else {
        eprintln!("error: {}", report.reason());
        ExitCode::from(EXIT_GOAL_NOT_MET)
    })
}

/// A data file's text, refused beyond `MAX_DATA_BYTES` before it is read whole.
fn read_data(path: &std::path::Path) -> std::io::Result<String> {
    /// 10^6 measurements of a few columns are some 50 MB.
    const MAX_DATA_BYTES: u64 = 256 << 20;
    let len = std::fs::metadata(path)?.len();
    if len > MAX_DATA_BYTES {
        return Err(std::io::Error::other(format!(
            "{len} bytes, more than the {MAX_DATA_BYTES} a data file may have"
        )));
    }
    std::fs::read_to_string(path)
}
