//! A finished fit with names attached: the table `hybc fit` prints and its JSON object (field
//! names are a contract, docs/fit.md). No IO.

use std::fmt::Write as _;

use serde_json::{json, Map, Value};

use super::{FitOptions, FitResult, FitStop, Outcome, StallCause, Target};
use crate::report::num;
use crate::sim::short;
use crate::sim::SystemInfo;

/// A fit's result with the names and settings needed to report it.
#[derive(Clone, Debug)]
pub struct FitReport {
    /// The model's name.
    pub model: String,
    /// The model's shape (names, gradient columns).
    pub info: SystemInfo,
    /// What was fitted to.
    pub targets: Vec<Target>,
    /// The options the fit ran with.
    pub options: FitOptions,
    /// The outcome.
    pub result: FitResult,
    /// Seconds spent compiling the model.
    pub compile_seconds: f64,
    /// Seconds spent fitting.
    pub fit_seconds: f64,
    /// Whether every measurement (`--data`) came with its standard deviation: the parameters'
    /// standard errors are then not rescaled by the residual variance.
    pub sigma_known: bool,
}

/// What a fit to measurements adds to the report: per observed name, how many values and the
/// root mean square of `model - measured`; the free parameters' standard errors.
struct DataSummary {
    observations: usize,
    by_name: Vec<(String, usize, f64)>,
    standard_errors: Option<Vec<f64>>,
}

impl FitReport {
    fn free_names(&self) -> Vec<&str> {
        self.info.grad_params.iter().map(|&j| self.info.param_names[j].as_str()).collect()
    }

    fn free_object(&self, free: &[f64]) -> Value {
        Value::Object(self.free_names().iter().zip(free).map(|(n, v)| (n.to_string(), json!(v))).collect())
    }

    /// One sentence: whether the fit converged and why it stopped.
    pub fn reason(&self) -> String {
        let solver = self.solver_reason();
        if self.result.stop.is_converged() && !self.result.targets_met() {
            return format!("targets not met: {}", self.unmet_reason(&solver));
        }
        solver
    }

    /// Why a least-squares minimum is not a solution: each unmet target with its value, goal and
    /// tolerance, the parameters held at a bound, and a cusp the final point sits on.
    fn unmet_reason(&self, solver: &str) -> String {
        let r = &self.result;
        let unmet: Vec<String> = self
            .targets
            .iter()
            .enumerate()
            .filter(|&(i, _)| !r.met[i])
            .map(|(i, t)| {
                let value = r.evaluation.values[i];
                format!(
                    "{} = {} against the goal {} (off by {}, tolerance {:.1e})",
                    t.label(&self.info),
                    num(value),
                    num(t.value),
                    short(value - t.value),
                    r.tolerances[i]
                )
            })
            .collect();
        // The solver's own sentence says how it stopped; "converged" would mislead here.
        let how = solver.split_once(": ").map_or(solver, |(_, why)| why);
        let mut out =
            format!("the fit stopped at a least-squares minimum ({how}) that leaves {}", unmet.join("; "));
        let held: Vec<String> = self
            .free_names()
            .iter()
            .zip(&self.info.grad_params)
            .zip(&r.bounds)
            .filter(|((_, &j), b)| r.params[j] <= b.lower || r.params[j] >= b.upper)
            .map(|((name, &j), _)| format!("{name} = {}", num(r.params[j])))
            .collect();
        if !held.is_empty() {
            let _ = write!(out, "; held at a bound: {}", held.join(", "));
        }
        // The final point sits on a cusp when trials after it (none of them accepted) lay on
        // another event sequence: the targets may be in the jump between the two.
        let last_accepted =
            r.iterations.iter().rev().find(|it| matches!(it.outcome, Outcome::Start | Outcome::Accepted));
        let after = last_accepted.map_or(0, |it| it.iteration);
        if let Some(c) = r.cusps.iter().rev().find(|c| c.iteration > after && !c.accepted) {
            let _ = write!(
                out,
                "; it sits on a cusp: steps from it change the number of events ({} -> {} at iteration {})",
                c.events_before, c.events_after, c.iteration
            );
        }
        out.push_str(
            "; the targets are unreachable from this start (try another start, or other free parameters)",
        );
        out
    }

    /// The solver's sentence: how it stopped, before the targets are checked.
    fn solver_reason(&self) -> String {
        let o = &self.options;
        let trials = self.result.iterations.len() - 1;
        match &self.result.stop {
            FitStop::Gradient => format!(
                "converged after {trials} trials: the gradient vanishes (every free column's cosine \
                 with the residuals is below gtol {:e}, or the free parameters are held at their bounds)",
                o.gtol
            ),
            FitStop::Step => {
                format!("converged after {trials} trials: the Gauss-Newton step is below xtol {:e}", o.xtol)
            }
            FitStop::Objective => format!(
                "converged after {trials} trials: the residuals vanish or the objective stopped \
                 decreasing (relative decrease, or the Gauss-Newton step's predicted one, below ftol {:e})",
                o.ftol
            ),
            FitStop::MaxIterations => format!("did not converge in {trials} trials (--max-iter)"),
            FitStop::Stalled(cause) => format!("did not converge: {}", stall(cause)),
        }
    }

    /// The statistics of the measurements among the targets, if any.
    fn data_summary(&self) -> Option<DataSummary> {
        let r = &self.result;
        let observed: Vec<usize> = (0..self.targets.len()).filter(|&i| self.targets[i].observed).collect();
        if observed.is_empty() {
            return None;
        }
        let mut by_name: Vec<(String, usize, f64)> = Vec::new();
        for &i in &observed {
            let label = self.targets[i].label(&self.info);
            let name = label.split_once('@').map_or(label.as_str(), |(n, _)| n).to_string();
            let miss = r.evaluation.values[i] - self.targets[i].value;
            match by_name.iter_mut().find(|(n, _, _)| *n == name) {
                Some(entry) => {
                    entry.1 += 1;
                    entry.2 += miss * miss;
                }
                None => by_name.push((name, 1, miss * miss)),
            }
        }
        for entry in &mut by_name {
            entry.2 = (entry.2 / entry.1 as f64).sqrt();
        }
        let standard_errors =
            super::data::standard_errors(&r.evaluation.jacobian, &r.evaluation.residuals, self.sigma_known);
        Some(DataSummary { observations: observed.len(), by_name, standard_errors })
    }

    /// The JSON object documented in docs/fit.md.
    pub fn to_json(&self) -> Value {
        let r = &self.result;
        let params: Map<String, Value> =
            self.info.param_names.iter().zip(&r.params).map(|(n, v)| (n.clone(), json!(v))).collect();
        let residuals: Vec<Value> = self
            .targets
            .iter()
            .enumerate()
            .map(|(i, t)| {
                json!({
                    "target": t.label(&self.info),
                    "goal": t.value,
                    "value": r.evaluation.values[i],
                    "weight": t.weight,
                    "residual": r.evaluation.residuals[i],
                    "tolerance": r.tolerances[i],
                    "met": r.met[i],
                })
            })
            .collect();
        let iterations: Vec<Value> = r
            .iterations
            .iter()
            .map(|it| {
                let (outcome, rejection) = match &it.outcome {
                    Outcome::Start => ("start", Value::Null),
                    Outcome::Accepted => ("accepted", Value::Null),
                    Outcome::Rejected => ("rejected", Value::Null),
                    Outcome::Failed(why) => ("failed", json!(why.to_string())),
                };
                json!({
                    "iteration": it.iteration,
                    "params": self.free_object(&it.free),
                    "objective": it.objective,
                    "step_norm": it.step_norm,
                    "events": it.events,
                    "damping": it.damping,
                    "cusp": it.cusp,
                    "outcome": outcome,
                    "rejection": rejection,
                })
            })
            .collect();
        let cusps: Vec<Value> = r
            .cusps
            .iter()
            .map(|c| {
                json!({"iteration": c.iteration, "events_before": c.events_before,
                       "events_after": c.events_after, "accepted": c.accepted})
            })
            .collect();
        let reason = match &r.stop {
            stop if stop.is_converged() && !r.targets_met() => "targets_not_met",
            FitStop::Gradient => "gradient",
            FitStop::Step => "step",
            FitStop::Objective => "objective",
            FitStop::MaxIterations => "max_iterations",
            FitStop::Stalled(_) => "stalled",
        };
        let data = self.data_summary().map(|d| {
            let by_name: Vec<Value> =
                d.by_name.iter().map(|(n, c, rms)| json!({"name": n, "count": c, "rms": rms})).collect();
            json!({
                "observations": d.observations,
                "by_name": by_name,
                "sigma_known": self.sigma_known,
                "standard_errors": d.standard_errors.map(|se| self.free_object(&se)),
            })
        });
        json!({
            "model": self.model,
            "free": self.free_names(),
            "data": data,
            "params": params,
            "residuals": residuals,
            "objective": r.evaluation.objective(),
            "iterations": iterations,
            "converged": r.is_converged(),
            "reason": reason,
            "message": self.reason(),
            // JSON has no infinity: a rank-deficient Jacobian's condition number is null.
            "condition": r.condition.is_finite().then_some(r.condition),
            "cusps": cusps,
            "stats": {
                "runs": r.iterations.len(),
                "compile_seconds": self.compile_seconds,
                "fit_seconds": self.fit_seconds,
            },
        })
    }

    /// The human-readable report `hybc fit` prints by default.
    pub fn to_table(&self) -> String {
        let r = &self.result;
        let mut out = String::new();
        let free = self.free_names();
        let labels: Vec<String> = self.targets.iter().map(|t| t.label(&self.info)).collect();
        let shown = if labels.len() > 8 {
            format!("{}, ... ({} in all)", labels[..8].join(", "), labels.len())
        } else {
            labels.join(", ")
        };
        let _ = writeln!(out, "model {}   free {}   targets {shown}", self.model, free.join(", "));
        let pcols: String = free.iter().map(|n| format!("  {n:>16}")).collect();
        let _ = writeln!(
            out,
            "\n  {:>4}  {:>16}  {:>12}  {:>6}  {:>9}{pcols}  outcome",
            "iter", "objective", "step", "events", "damping"
        );
        for it in &r.iterations {
            let opt = |v: Option<String>| v.unwrap_or_else(|| "-".to_string());
            let outcome = match &it.outcome {
                Outcome::Start => "start".to_string(),
                Outcome::Accepted if it.cusp => "accepted across a cusp".to_string(),
                Outcome::Accepted => "accepted".to_string(),
                Outcome::Rejected if it.cusp => {
                    "rejected: event sequence changed, objective rose".to_string()
                }
                Outcome::Rejected => "rejected: objective rose".to_string(),
                Outcome::Failed(why) => format!("rejected: {why}"),
            };
            let values: String = it.free.iter().map(|v| format!("  {:>16}", num(*v))).collect();
            let _ = writeln!(
                out,
                "  {:>4}  {:>16}  {:>12}  {:>6}  {:>9}{values}  {outcome}",
                it.iteration,
                opt(it.objective.map(sci)),
                if it.iteration == 0 { "-".to_string() } else { sci(it.step_norm) },
                opt(it.events.map(|e| e.to_string())),
                opt(it.damping.map(|d| format!("{d:.1e}"))),
            );
        }
        let _ = writeln!(out, "\n{}", self.reason());
        for (name, &j) in free.iter().zip(&self.info.grad_params) {
            let _ = writeln!(out, "  {name} = {}", num(r.params[j]));
        }
        let _ = writeln!(
            out,
            "\n  {:<16}  {:>18}  {:>18}  {:>8}  {:>16}  {:>12}",
            "target", "goal", "model", "weight", "residual", "tolerance"
        );
        for (i, (t, label)) in self.targets.iter().zip(&labels).enumerate() {
            let _ = writeln!(
                out,
                "  {label:<16}  {:>18}  {:>18}  {:>8}  {:>16}  {:>12.1e}{}",
                num(t.value),
                num(r.evaluation.values[i]),
                num(t.weight),
                sci(r.evaluation.residuals[i]),
                r.tolerances[i],
                if r.met[i] { "" } else { "  not met" }
            );
        }
        if let Some(d) = self.data_summary() {
            let _ = writeln!(out, "\ndata: {} measurements", d.observations);
            for (name, count, rms) in &d.by_name {
                let _ = writeln!(out, "  {name:<16}  {count:>8} values  residual rms {}", sci(*rms));
            }
            match &d.standard_errors {
                Some(se) => {
                    let scale = if self.sigma_known { "the given sigmas" } else { "the residual variance" };
                    let _ = writeln!(out, "standard errors (from the Jacobian, scaled by {scale}):");
                    for ((name, &j), se) in free.iter().zip(&self.info.grad_params).zip(se) {
                        let _ = writeln!(out, "  {name} = {} +/- {}", num(r.params[j]), short(*se));
                    }
                }
                None => {
                    let _ = writeln!(
                        out,
                        "standard errors: none (J^T J is singular, or no more measurements than parameters)"
                    );
                }
            }
        }
        let condition = if r.condition.is_finite() { num(r.condition) } else { "infinite".to_string() };
        let _ = writeln!(
            out,
            "\nJacobian condition number: {condition} ({}, {})",
            count(self.targets.len(), "target"),
            count(free.len(), "free parameter")
        );
        if let Some(first) = r.cusps.first() {
            // The JSON lists every cusp; near a jump there can be dozens.
            let accepted = r.cusps.iter().filter(|c| c.accepted).count();
            let _ = writeln!(
                out,
                "cusps: {} with another event sequence ({accepted} accepted, {} rejected); the first at \
                 iteration {} ({} -> {} events)",
                count(r.cusps.len(), "trial"),
                r.cusps.len() - accepted,
                first.iteration,
                first.events_before,
                first.events_after
            );
        }
        let _ = writeln!(
            out,
            "{} runs, compile {:.2} ms, fit {:.2} ms",
            r.iterations.len(),
            self.compile_seconds * 1e3,
            self.fit_seconds * 1e3
        );
        out
    }
}

fn count(n: usize, what: &str) -> String {
    format!("{n} {what}{}", if n == 1 { "" } else { "s" })
}

fn sci(v: f64) -> String {
    format!("{v:.6e}")
}

fn stall(cause: &StallCause) -> String {
    match cause {
        StallCause::Cusp(c) => format!(
            "stalled at a cusp: steps towards smaller residuals change the number of events ({} -> {} \
             at iteration {}) and the objective is higher there; the targets may lie in the jump \
             between two event sequences, or be reachable only from another start",
            c.events_before, c.events_after, c.iteration
        ),
        StallCause::Failed { iteration, rejection } => format!(
            "stalled: trial points beyond this one give no residuals (iteration {iteration}: {rejection})"
        ),
        StallCause::NoDecrease => {
            "stalled: the objective does not decrease along the Gauss-Newton direction \
             although the step is not small; the simulation error may exceed it (tighten --rtol/--atol)"
                .to_string()
        }
        StallCause::Singular => {
            "stalled: the singular value decomposition of the Jacobian did not converge".to_string()
        }
    }
}
