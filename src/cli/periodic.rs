//! `hybc periodic FILE --section EVENT --free P1,P2`: a periodic orbit through events and its
//! Floquet multipliers. Flags to a `PeriodicRequest`, its report printed as a table or JSON.

use std::process::ExitCode;

use clap::ValueEnum;

use super::options::{at_most, parameter_values, parse_param_list, positive, sim_options, SimFlags};
use super::{error_chain, load_model, usage_error, ModelArg, EXIT_GOAL_NOT_MET, EXIT_SIM_STOPPED};
use crate::periodic::{self, PeriodicError, Search};
use crate::{Error, Model, PeriodicRequest};

#[derive(Debug, Clone, Copy, ValueEnum)]
enum Format {
    Table,
    Json,
}

#[derive(Debug, clap::Args)]
#[command(
    after_help = "Exit codes: 0 a fixed point found (stable or not); 1 the model has errors; 2 a usage \
                        error; 3 a run did not reach the section, or the return map's Jacobian is not finite; \
                        4 no fixed point found (Newton did not converge, or a run of the model from its point \
                        does not come back to it). With --format json a search that found nothing prints an \
                        object too, with found: false and the reason."
)]
pub struct PeriodicArgs {
    #[command(flatten)]
    model: ModelArg,
    /// The section: an event; the orbit returns to its initial state right after its first
    /// firing (a run of the return map stops there), or its K-th with `EVENT#K`.
    #[arg(long, value_name = "EVENT[#K]")]
    section: String,
    /// The parameters that set the initial state, solved for: `P1,P2,...`.
    #[arg(long, value_name = "P1,P2")]
    free: String,
    /// A starting value of a free parameter, or the value of another one (repeatable).
    #[arg(long = "set", value_name = "P=VALUE")]
    set: Vec<String>,
    #[command(flatten)]
    sim: SimFlags,
    /// Largest number of Newton iterations (one run each).
    #[arg(long, default_value_t = 50)]
    max_iter: usize,
    /// Converged when every state returns within TOL (1 + |x0|) of its initial value.
    #[arg(long, default_value_t = 1e-10)]
    tol: f64,
    /// Output format.
    #[arg(long, value_enum, default_value = "table")]
    format: Format,
}

pub fn run(args: &PeriodicArgs) -> ExitCode {
    let model = match load_model(&args.model.file) {
        Ok(model) => model,
        Err(code) => return code,
    };
    match solve(&model, args) {
        Ok(code) => code,
        Err(message) => usage_error(&message),
    }
}

fn solve(model: &Model, args: &PeriodicArgs) -> Result<ExitCode, String> {
    let free = parse_param_list(model, &args.free, "--free")?;
    at_most("--max-iter", args.max_iter, crate::limits::MAX_FIT_ITER)?;
    let (section, firing) = periodic::parse_section(&args.section).map_err(|e| format!("--section: {e}"))?;
    let search = Search {
        free,
        params: parameter_values(model, &args.set)?.values().to_vec(),
        sim: sim_options(model, &args.sim)?,
        max_iter: args.max_iter,
        tol: positive("--tol", args.tol)?,
    };
    let request = PeriodicRequest { section, firing, search };
    let print = |json: &serde_json::Value| super::print_out(&format!("{json}\n"));
    match request.run(model) {
        Ok(report) => {
            match args.format {
                Format::Table => super::print_out(&report.to_table()),
                Format::Json => print(&report.to_json()),
            }
            Ok(ExitCode::SUCCESS)
        }
        Err(Error::Periodic(
            e @ (PeriodicError::NoSection { .. } | PeriodicError::NoFree | PeriodicError::BadFiring { .. }),
        )) => Err(format!("--section/--free: {e}")),
        Err(e) => {
            eprintln!("error: {}", error_chain(&e));
            if let (Format::Json, Some(json)) = (args.format, request.failure_json(model, &e)) {
                print(&json);
            }
            // No fixed point: Newton did not converge, or its point failed the check by a run of
            // the model; the others are runs that did not get there.
            let goal_not_met = matches!(
                e,
                Error::Periodic(PeriodicError::NotConverged { .. } | PeriodicError::NotVerified { .. })
            );
            Ok(ExitCode::from(if goal_not_met { EXIT_GOAL_NOT_MET } else { EXIT_SIM_STOPPED }))
        }
    }
}
