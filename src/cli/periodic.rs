//! `hybc periodic FILE --section EVENT --free P1,P2`: a periodic orbit through events and its
//! Floquet multipliers (`crate::periodic`), as a table or JSON.

use std::fmt::Write as _;
use std::process::ExitCode;

use clap::ValueEnum;
use serde_json::json;

use super::options::{at_most, parameter_values, parse_param_list, positive, sim_options, SimFlags};
use super::{load_model, usage_error, ModelArg, EXIT_GOAL_NOT_MET, EXIT_SIM_STOPPED};
use crate::periodic::{self, PeriodicError, PeriodicProblem, PeriodicResult, TRIVIAL_MULTIPLIER};
use crate::report::num;
use crate::Model;

#[derive(Debug, Clone, Copy, ValueEnum)]
enum Format {
    Table,
    Json,
}

#[derive(Debug, clap::Args)]
#[command(after_help = "Exit codes: 0 a fixed point found; 1 the model has errors; 2 a usage error; 3 a \
                        run did not reach the section; 4 no fixed point found (Newton did not converge).")]
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

/// The section as the user wrote it: `EVENT`, or `EVENT#K` for a later firing.
fn section_label(problem: &PeriodicProblem<'_>) -> String {
    match problem.firing {
        1 => problem.section.clone(),
        k => format!("{}#{k}", problem.section),
    }
}

/// `EVENT` (its first firing) or `EVENT#K` (its K-th), the spelling of `hybc fit --target`.
fn section_firing(text: &str) -> Result<(String, usize), String> {
    match text.split_once('#') {
        None => Ok((text.trim().to_string(), 1)),
        Some((event, k)) => {
            let max = periodic::MAX_FIRING;
            let firing =
                k.trim().parse::<usize>().ok().filter(|k| (1..=max).contains(k)).ok_or_else(|| {
                    format!("--section: `{text}`: expected EVENT or EVENT#K with K from 1 to {max}")
                })?;
            Ok((event.trim().to_string(), firing))
        }
    }
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
    let (section, firing) = section_firing(&args.section)?;
    let problem = PeriodicProblem {
        model: model.checked(),
        section,
        firing,
        free,
        params: parameter_values(model, &args.set)?.values().to_vec(),
        sim: sim_options(model, &args.sim)?,
        max_iter: args.max_iter,
        tol: positive("--tol", args.tol)?,
    };
    match periodic::find(&problem) {
        Ok(result) => {
            let text = match args.format {
                Format::Table => table(model, &problem, &result),
                Format::Json => format!("{}\n", json(model, &problem, &result)),
            };
            super::print_out(&text);
            Ok(ExitCode::SUCCESS)
        }
        Err(
            e @ (PeriodicError::NoSection { .. } | PeriodicError::NoFree | PeriodicError::BadFiring { .. }),
        ) => Err(format!("--section/--free: {e}")),
        Err(e @ PeriodicError::NotConverged { .. }) => {
            eprintln!("error: {e}");
            Ok(ExitCode::from(EXIT_GOAL_NOT_MET))
        }
        Err(e) => {
            eprintln!("error: {e}");
            Ok(ExitCode::from(EXIT_SIM_STOPPED))
        }
    }
}

fn trivial((re, im): (f64, f64)) -> bool {
    re.hypot(im) <= TRIVIAL_MULTIPLIER
}

fn json(model: &Model, problem: &PeriodicProblem<'_>, r: &PeriodicResult) -> serde_json::Value {
    let m = model.checked();
    let states: serde_json::Map<_, _> =
        m.states.iter().zip(&r.fixed_point).map(|(s, v)| (s.name.clone(), json!(v))).collect();
    let free: serde_json::Map<_, _> = problem
        .free
        .iter()
        .map(|p| (m.params[p.0 as usize].name.clone(), json!(r.params[p.0 as usize])))
        .collect();
    let n = r.orbit.len();
    let rows: Vec<Vec<f64>> = (0..n).map(|i| (0..n).map(|j| r.monodromy[(i, j)]).collect()).collect();
    let orbit: Vec<&str> = r.orbit.iter().map(|&i| m.states[i].name.as_str()).collect();
    json!({
        "model": m.name,
        "section": problem.section,
        "firing": problem.firing,
        "fixed_point": states,
        "params": free,
        "period": r.period,
        "multipliers": r.multipliers.iter().map(|&(re, im)| [re, im]).collect::<Vec<_>>(),
        "trivial": r.multipliers.iter().filter(|&&z| trivial(z)).count(),
        "stable": r.stable,
        "orbit": orbit,
        "monodromy": rows,
        "iterations": r.residuals.len() - 1,
        "residuals": r.residuals,
        "events": r.events,
    })
}

fn table(model: &Model, problem: &PeriodicProblem<'_>, r: &PeriodicResult) -> String {
    let m = model.checked();
    let mut out = String::new();
    let _ = writeln!(
        out,
        "model {}   section {}   fixed point after {} Newton iterations (residual {:.1e})",
        m.name,
        section_label(problem),
        r.residuals.len() - 1,
        r.residuals.last().copied().unwrap_or(f64::NAN)
    );
    let _ = writeln!(out, "\nfree parameters:");
    for p in &problem.free {
        let _ = writeln!(out, "  {:<14}  {:>20}", m.params[p.0 as usize].name, num(r.params[p.0 as usize]));
    }
    let _ = writeln!(out, "\ninitial state (= the state right after {}):", section_label(problem));
    for (i, (s, v)) in m.states.iter().zip(&r.fixed_point).enumerate() {
        let note = if r.orbit.contains(&i) { "" } else { "  (a running cost: not part of the orbit)" };
        let _ = writeln!(out, "  {:<14}  {:>20}{note}", s.name, num(*v));
    }
    let _ = writeln!(out, "\nperiod: {}   events per period: {}", num(r.period), r.events);
    let _ = writeln!(out, "\nFloquet multipliers (eigenvalues of the monodromy matrix, saltation included):");
    for &(re, im) in &r.multipliers {
        let z = if im == 0.0 {
            num(re)
        } else {
            format!("{} {} {}i", num(re), if im < 0.0 { "-" } else { "+" }, num(im.abs()))
        };
        let note = if trivial((re, im)) { "  (trivial: the section's)" } else { "" };
        let _ = writeln!(out, "  {z:<40}  |z| = {}{note}", num(re.hypot(im)));
    }
    let _ = writeln!(
        out,
        "\n{}",
        if r.stable {
            "stable: every non-trivial multiplier lies inside the unit circle"
        } else {
            "unstable: a non-trivial multiplier lies on or outside the unit circle"
        }
    );
    out
}
