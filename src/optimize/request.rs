//! A whole optimisation as a user asks for it (`hybc optimize` and Python's `Model.optimize`):
//! the objective and constraints as text, bounds by name, the start and the options, against a
//! model compiled with the free parameters as its gradient parameters. Parses, solves and builds
//! the report, so that both front ends say the same things about the same problem.

use std::time::Instant;

use super::report::OptimizeReport;
use super::{
    optimize, parse_constraint, OptimizeError, OptimizeOptions, OptimizeProblem, Progress, Quantity, Slsqp,
};
use crate::fit::Bounds;
use crate::sema::ParamIdx;
use crate::sim::SimOptions;

/// What to solve, as text where the user wrote text.
pub struct Request<'a> {
    /// The objective (`--minimize`).
    pub minimize: &'a str,
    /// The constraints (`--subject-to`), each `Q OP V` or a path grid.
    pub subject_to: &'a [String],
    /// One box per free parameter (from [`bounds`]).
    pub bounds: Vec<Bounds>,
    /// Every parameter's value: the free ones start there, the others stay there.
    pub start: Vec<f64>,
    pub sim: SimOptions,
    pub options: OptimizeOptions,
}

/// Why an optimisation gave no report.
#[derive(Debug)]
pub enum Failure {
    /// The objective does not parse against the model.
    Objective(String),
    /// A constraint does not parse, or there are more than the cap.
    Constraint(String),
    /// The solver refused the problem (a start outside its bounds, ...).
    Refused(OptimizeError),
}

/// The box of every free parameter: its declared range, narrowed by `narrow` (a parameter or a
/// vector's name, with `lo < hi` within the declared range). Errors name the offending entry.
pub fn bounds(
    model: &crate::Model,
    free: &[ParamIdx],
    narrow: &[(String, f64, f64)],
) -> Result<Vec<Bounds>, String> {
    let params = &model.checked().params;
    let mut out: Vec<Bounds> = free.iter().map(|p| Bounds::from_range(params[p.0 as usize].range)).collect();
    for (name, lo, hi) in narrow {
        let (lo, hi) = (*lo, *hi);
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(format!("`{name}`: expected finite LO < HI, found [{lo}, {hi}]"));
        }
        for p in model.param_list(&[name]).map_err(|e| e.to_string())? {
            let k = free.iter().position(|f| *f == p).ok_or_else(|| {
                format!(
                    "`{}` is not a free parameter (name it in the free parameters)",
                    params[p.0 as usize].name
                )
            })?;
            let declared = out[k];
            if lo < declared.lower || hi > declared.upper {
                return Err(format!(
                    "[{lo}, {hi}] for `{}` leaves its declared range [{}, {}]",
                    params[p.0 as usize].name, declared.lower, declared.upper
                ));
            }
            out[k] = Bounds { lower: lo, upper: hi };
        }
    }
    Ok(out)
}

/// Solves `request` on `compiled` (compiled with the free parameters as gradient parameters),
/// telling `progress` about every trial.
pub fn run(
    model: &crate::Model,
    compiled: &crate::Compiled,
    request: Request<'_>,
    progress: Option<&Progress<'_>>,
) -> Result<OptimizeReport, Failure> {
    let info = compiled.info().clone();
    let objective =
        Quantity::parse(request.minimize, &info).map_err(|e| Failure::Objective(e.to_string()))?;
    let mut constraints = Vec::new();
    for text in request.subject_to {
        constraints.extend(parse_constraint(text, &info).map_err(|e| Failure::Constraint(e.to_string()))?);
        crate::limits::count("constraints in all", constraints.len(), 0, crate::limits::MAX_CONSTRAINTS)
            .map_err(|e| Failure::Constraint(e.to_string()))?;
    }
    let problem = OptimizeProblem {
        system: compiled.system(),
        start: request.start,
        bounds: request.bounds,
        objective,
        constraints,
        sim: request.sim,
    };
    let started = Instant::now();
    let result = optimize(&problem, &request.options, &Slsqp, progress).map_err(Failure::Refused)?;
    Ok(OptimizeReport {
        model: model.name().to_string(),
        info,
        objective: problem.objective,
        options: request.options,
        result,
        compile_seconds: compiled.compile_seconds(),
        optimize_seconds: started.elapsed().as_secs_f64(),
    })
}

/// The report of a whole multi-start from the reports (`OptimizeReport::to_json`) of its shards
/// (`OptimizeOptions::shard`), given in start order and covering the starts from 0 without a gap:
/// the same report as one process running every start. The optima are grouped again over all
/// the starts, by the rule of one process (`group_optima`); everything about the reported end
/// (the best optimum, else start 0) comes from the shard that ran it; `stats.runs` and
/// `stats.optimize_seconds` add up over the shards (work, not wall time).
pub fn merge_shards(shards: &[serde_json::Value], bounds: &[Bounds]) -> Result<serde_json::Value, String> {
    use serde_json::{json, Value};
    let first = shards.first().ok_or("no shard reports to merge")?;
    let free: Vec<String> = first["free"]
        .as_array()
        .ok_or("a shard report without `free`")?
        .iter()
        .map(|v| v.as_str().unwrap_or_default().to_string())
        .collect();
    if free.len() != bounds.len() {
        return Err(format!("{} bounds for {} free parameters", bounds.len(), free.len()));
    }
    // Every start, in order, with the shard that ran it.
    let mut entries: Vec<(usize, &Value)> = Vec::new();
    for (k, shard) in shards.iter().enumerate() {
        if shard["free"] != first["free"] || shard["objective"] != first["objective"] {
            return Err(format!("shard {k} solved another problem"));
        }
        let starts = shard["starts"].as_array().ok_or_else(|| format!("shard {k} has no `starts`"))?;
        entries.extend(starts.iter().map(|e| (k, e)));
    }
    let xs: Vec<Vec<f64>> = entries
        .iter()
        .map(|(_, e)| free.iter().map(|n| e["params"][n].as_f64().unwrap_or(f64::NAN)).collect())
        .collect();
    let ends: Vec<super::End<'_, &Value>> = entries
        .iter()
        .zip(&xs)
        .map(|((_, e), x)| super::End {
            converged: e["converged"].as_bool().unwrap_or(false),
            objective: e["objective"].as_f64(),
            events: e["events"].as_array().map(|a| a.iter().collect()).unwrap_or_default(),
            x,
        })
        .collect();
    let groups = super::group_optima(&ends, bounds);
    // The shards must hold the starts 0, 1, 2, ... in order: the indices of the groups are theirs.
    for (position, (k, e)) in entries.iter().enumerate() {
        if e["index"].as_u64() != Some(position as u64) {
            return Err(format!("shard {k} holds start {} where start {position} belongs", e["index"]));
        }
    }
    let reported = groups.first().map_or(0, |g| g[0]);
    let mut merged = shards[entries[reported].0].clone();
    merged["starts"] = Value::Array(entries.iter().map(|(_, e)| (*e).clone()).collect());
    merged["optima"] = Value::Array(
        groups
            .iter()
            .map(|g| {
                let e = entries[g[0]].1;
                let set: Vec<String> = free
                    .iter()
                    .zip(&xs[g[0]])
                    .map(|(n, v)| format!("{n}={}", super::report::round_trip(*v)))
                    .collect();
                json!({
                    "params": e["params"],
                    "objective": e["objective"],
                    "events": e["events"],
                    "starts": g,
                    "set": set,
                })
            })
            .collect(),
    );
    let sum = |key: &str| shards.iter().map(|s| s["stats"][key].as_f64().unwrap_or(0.0)).sum::<f64>();
    merged["stats"]["runs"] = json!(sum("runs") as u64);
    merged["stats"]["optimize_seconds"] = json!(sum("optimize_seconds"));
    Ok(merged)
}
