//! The report of a multi-start run in shards (`OptimizeOptions::shard`, one Dask task each, as
//! `hybc.dask.optimize` runs them), merged from the shards' JSON reports into the report of one
//! process running every start. Knows the report's JSON; runs nothing.

use crate::fit::Bounds;

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
