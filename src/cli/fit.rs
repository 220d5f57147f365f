//! `hybc fit FILE`: compile a model once with the free parameters as gradient parameters, then fit
//! them to targets on final outputs, final states and event times (`crate::fit`).

use clap::ValueEnum;
use std::process::ExitCode;

use super::options::{analysis_sim_options, at_most, parameter_values, parse_param_list, positive, SimFlags};
use super::{compile_model, load_model, usage_error, ModelArg, EXIT_GOAL_NOT_MET, EXIT_SIM_STOPPED};
use crate::fit::FitOptions;
use crate::{Error, FitFailure, FitRequest, Model};

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
    at_most("--max-iter", args.max_iter, MAX_ITER)?;
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
    let sim = analysis_sim_options(model, &args.sim)?;
    let options = fit_options(args)?;
    let compiled = match compile_model(model, &free) {
        Ok(c) => c,
        Err(code) => return Ok(code),
    };
    let data = match &args.data {
        Some(path) => {
            let shown = path.display().to_string();
            let text = read_data(path).map_err(|e| format!("--data: cannot read `{shown}`: {e}"))?;
            Some((text, shown))
        }
        None => None,
    };
    let request = FitRequest {
        targets: &args.targets,
        data: data.as_ref().map(|(text, file)| (text.as_str(), file.as_str())),
        start,
        sim,
        options,
    };
    let report = match request.run(&compiled, &mut |w| eprintln!("warning: {w}")) {
        Ok(report) => report,
        Err(Error::Fit(FitFailure::Target(e))) => return Err(format!("--target: {e}")),
        Err(Error::Fit(FitFailure::Data(e))) => return Err(format!("--data: {e}")),
        // The run works, but the fit's goal cannot be stated in doubles: the goal is not met.
        Err(Error::Fit(FitFailure::StartObjective(e))) => {
            eprintln!("error: {e}");
            return Ok(ExitCode::from(EXIT_GOAL_NOT_MET));
        }
        Err(Error::Fit(FitFailure::StartRun(e))) => {
            eprintln!("error: {e}");
            return Ok(ExitCode::from(EXIT_SIM_STOPPED));
        }
        Err(e) => return Err(super::error_chain(&e)),
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
