//! A finished optimisation with names attached: the table `hybc optimize` prints, its JSON object
//! (field names are a contract, docs/optimize.md), the progress line per run and the `--set`
//! list of the optimum. No IO.

use std::fmt::Write as _;

use serde_json::{json, Map, Value};

use super::{LocalResult, OptimizeOptions, OptimizeResult, Quantity, Trial, Verdict};
use crate::report::{num, number_json};
use crate::sim::{short, SystemInfo};

/// An optimisation's result with the names and settings needed to report it.
#[derive(Clone, Debug)]
pub struct OptimizeReport {
    /// The model's name.
    pub model: String,
    /// The model's shape (names, gradient columns).
    pub info: SystemInfo,
    /// What was minimised.
    pub objective: Quantity,
    /// The options the solve ran with.
    pub options: OptimizeOptions,
    /// Every start's outcome.
    pub result: OptimizeResult,
    /// Seconds spent compiling the model.
    pub compile_seconds: f64,
    /// Seconds spent optimising.
    pub optimize_seconds: f64,
}

impl OptimizeReport {
    fn free_names(&self) -> Vec<&str> {
        self.info.grad_params.iter().map(|&j| self.info.param_names[j].as_str()).collect()
    }

    fn free_object(&self, free: &[f64]) -> Value {
        Value::Object(
            self.free_names().iter().zip(free).map(|(n, v)| (n.to_string(), number_json(*v))).collect(),
        )
    }

    fn event_names(&self, events: &[usize]) -> Vec<String> {
        events.iter().map(|&e| self.info.events[e].name.to_string()).collect()
    }

    /// Whether the reported end converged (the KKT conditions hold there).
    pub fn converged(&self) -> bool {
        self.result.best().is_some()
    }

    /// The optimum as `hybc run --set` values (`h0=1.2`, `u[3]=0.5`), shortest round-trip form.
    pub fn set_list(&self, local: &LocalResult) -> Vec<String> {
        self.free_names().iter().zip(&local.x).map(|(n, v)| format!("{n}={}", round_trip(*v))).collect()
    }

    /// The same as shell arguments: `--set h0=1.2 --set 'u[3]=0.5'`.
    pub fn set_arguments(&self, local: &LocalResult) -> String {
        let quote = |s: String| if s.contains('[') { format!("'{s}'") } else { s };
        self.set_list(local).into_iter().map(|s| format!("--set {}", quote(s))).collect::<Vec<_>>().join(" ")
    }

    /// One sentence: converged, or why not.
    pub fn reason(&self) -> String {
        let r = self.result.reported();
        let k = r.kkt.as_ref();
        let measures = k
            .map(|k| {
                format!(
                    "KKT stationarity {:.1e} (tolerance {:.0e}, of the gradient scale {}), largest constraint violation {} ({:.2} of its tolerance)",
                    k.stationarity,
                    self.options.kkt_tol,
                    short(k.scale),
                    short(k.violation),
                    k.violation_ratio
                )
            })
            .unwrap_or_default();
        let runs = r.trials.len();
        // The optimiser asked for a non-finite point: its search broke down there.
        let broke_down = if r.non_finite > 0 {
            format!(
                "; the optimiser's search broke down: after {runs} run(s) it asked {} time(s) for a point with a non-finite coordinate, where no run is made",
                r.non_finite
            )
        } else {
            String::new()
        };
        match &r.verdict {
            Verdict::Converged => {
                format!("converged after {runs} evaluations ({}: {}): {measures}", self.result.solver, r.status)
            },
            Verdict::MaxIterations => format!("did not converge: the optimiser used up its --max-iter evaluations ({runs} runs){broke_down}; {measures}"),
            Verdict::StalledAtCusp { run } => format!(
                "did not converge: stalled at a cusp: run {run} nearby has another event sequence ({} events at the end), so the problem is not smooth where the optimiser stopped{broke_down}; {measures}; try another start or --starts",
                r.events().len()
            ),
            Verdict::RunsFailing { message } => {
                format!("did not converge: runs near the end failed ({message}){broke_down}; {measures}")
            }
            Verdict::Infeasible => {
                let why = match k {
                    Some(k) if k.violation_stationary => {
                        "; no move within the bounds lowers the violation (its gradient is held by the bounds or vanishes): the constraints cannot be met near here"
                    }
                    _ => "",
                };
                format!(
                    "did not converge: infeasible: a constraint is not met to its tolerance where the optimiser stopped ({}){why}{broke_down}; {measures}",
                    r.status
                )
            }
            Verdict::NotAMinimum { curvature, drop } => format!(
                "did not converge: not a minimum: the KKT conditions hold, but the curvature along a direction the bounds and constraints leave free is negative ({}, in the variables' scales), and a step of 1e-3 of the scales along it lowers the objective (its Lagrangian) by {}: a maximum or a saddle; {measures}; try another start or --starts",
                short(*curvature),
                short(*drop)
            ),
            Verdict::Stalled => format!(
                "did not converge: stalled: the optimiser stopped ({}) where the KKT conditions do not hold{broke_down}; {measures}",
                r.status
            ),
            Verdict::StartFailed { message } => format!("cannot evaluate the start: {message}"),
        }
    }

    /// The progress line of one run (stderr), with its start when there are several.
    pub fn progress_line(info: &SystemInfo, starts: usize, start: usize, t: &Trial) -> String {
        let mut line = if starts > 1 { format!("start {start:>3}  ") } else { String::new() };
        let _ = write!(
            line,
            "run {:>4}  objective {:>14}  violation {:>9}  events {:>4} ",
            t.run,
            t.objective.map_or("-".into(), |v| format!("{v:.8e}")),
            t.violation.map_or("-".into(), |v| format!("{v:.1e}")),
            t.events.map_or("-".into(), |n| n.to_string()),
        );
        for (&j, v) in info.grad_params.iter().zip(&t.free).take(8) {
            let _ = write!(line, " {}={}", info.param_names[j], short(*v));
        }
        if t.free.len() > 8 {
            line.push_str(" ...");
        }
        if t.new_sequence {
            line.push_str("  (event sequence changed)");
        }
        if let Some(f) = &t.failure {
            let _ = write!(line, "  failed: {f}");
        }
        line
    }

    /// The table `hybc optimize` prints.
    pub fn to_table(&self) -> String {
        let mut out = String::new();
        let r = self.result.reported();
        let _ = writeln!(
            out,
            "model {}   free {}   minimize {}   solver {}",
            self.model,
            self.free_names().join(","),
            self.objective.label(&self.info),
            self.result.solver
        );
        let _ = writeln!(out, "\n{}", self.reason());
        let _ = writeln!(
            out,
            "  objective {} = {}",
            self.objective.label(&self.info),
            r.values.first().map_or("-".into(), |v| num(*v))
        );
        for (name, (v, &b)) in self
            .free_names()
            .iter()
            .zip(r.x.iter().zip(r.kkt.as_ref().map_or(&vec![0; r.x.len()], |k| &k.at_bound)))
        {
            let held = match b {
                -1 => "  (at its lower bound)",
                1 => "  (at its upper bound)",
                _ => "",
            };
            let _ = writeln!(out, "  {name:<14} = {:>20}{held}", num(*v));
        }
        if !self.result.constraints.is_empty() {
            let _ = writeln!(
                out,
                "\n  {:<28} {:>20} {:>12} {:>10} {:>14}  active",
                "constraint", "value", "violation", "tolerance", "multiplier"
            );
            for (i, c) in self.result.constraints.iter().enumerate() {
                let value = r.values.get(i + 1).copied();
                let k = r.kkt.as_ref();
                let _ = writeln!(
                    out,
                    "  {:<28} {:>20} {:>12} {:>10.1e} {:>14}  {}",
                    c.label(&self.info),
                    value.map_or("-".into(), num),
                    value.map_or("-".into(), |v| format!("{:.1e}", c.violation(v))),
                    self.result.tolerances[i],
                    k.map_or("-".into(), |k| short(k.multipliers[i])),
                    k.map_or("-", |k| if k.active[i] { "yes" } else { "no" })
                );
            }
        }
        let events = self.event_names(&r.events());
        let _ = writeln!(out, "\nevents at the end: {} ({})", events.len(), summarize(&events));
        match (&r.verdict, r.cusp_notes.is_empty()) {
            // The end's own run is smooth, but a run next to it is on another piece.
            (Verdict::StalledAtCusp { run }, true) => {
                let _ = writeln!(
                    out,
                    "no event at a breakpoint, at t_end or near grazing in the end's own run, but run {run} next to it has another event sequence: the end lies at the edge of its smooth piece"
                );
            }
            (_, true) => {
                let _ = writeln!(
                    out,
                    "no event at a breakpoint, at t_end or near grazing: the end lies inside one smooth piece"
                );
            }
            _ => {}
        }
        for note in &r.cusp_notes {
            let _ = writeln!(out, "cusp: {note}");
        }
        if !r.changes.is_empty() {
            let shown: Vec<String> = r
                .changes
                .iter()
                .take(10)
                .map(|c| format!("run {} ({} -> {} events)", c.run, c.before.len(), c.after.len()))
                .collect();
            let more = if r.changes.len() > 10 {
                format!(", and {} more", r.changes.len() - 10)
            } else {
                String::new()
            };
            let _ = writeln!(out, "event sequence changed at: {}{more}", shown.join(", "));
        }
        if self.result.locals.len() > 1 {
            let _ = writeln!(
                out,
                "\n{} starts (seed {}); distinct optima, best first:",
                self.result.locals.len(),
                self.options.seed
            );
            for group in &self.result.optima {
                let l = &self.result.locals[group[0]];
                let params: Vec<String> =
                    self.free_names().iter().zip(&l.x).map(|(n, v)| format!("{n}={}", short(*v))).collect();
                let _ = writeln!(
                    out,
                    "  objective {:>20}  {}  events {} ({})  from {} start(s)",
                    num(l.values[0]),
                    params.join(" "),
                    l.events().len(),
                    summarize(&self.event_names(&l.events())),
                    group.len()
                );
            }
            let mut failed: Vec<(&str, usize)> = Vec::new();
            for l in self.result.locals.iter().filter(|l| !l.converged()) {
                match failed.iter_mut().find(|(w, _)| *w == l.verdict.word()) {
                    Some((_, n)) => *n += 1,
                    None => failed.push((l.verdict.word(), 1)),
                }
            }
            for (word, n) in failed {
                let _ = writeln!(out, "  {n} start(s) did not converge: {word}");
            }
        }
        let _ = writeln!(out, "\nset: {}", self.set_arguments(r));
        let evaluations: usize = self.result.locals.iter().map(|l| l.trials.len()).sum();
        let probes: usize = self.result.locals.iter().map(|l| l.probe_runs).sum();
        let rest = if probes > 0 {
            format!("{probes} to check the curvature at stationary ends, the rest to report the ends")
        } else {
            "the rest to report the ends".to_string()
        };
        let _ = writeln!(
            out,
            "{} runs ({evaluations} evaluations, {rest}), compile {:.2} ms, optimize {:.2} ms",
            self.result.runs(),
            self.compile_seconds * 1e3,
            self.optimize_seconds * 1e3
        );
        out
    }

    fn local_json(&self, l: &LocalResult) -> Value {
        json!({
            "index": l.index,
            "start": self.free_object(&l.start),
            "params": self.free_object(&l.x),
            "objective": l.values.first().map(|v| number_json(*v)),
            "converged": l.converged(),
            "reason": l.verdict.word(),
            "status": l.status,
            "evaluations": l.trials.len(),
            "runs": l.runs,
            "probe_runs": l.probe_runs,
            "non_finite_requests": l.non_finite,
            "events": self.event_names(&l.events()),
            "stationarity": l.kkt.as_ref().map(|k| number_json(k.stationarity)),
            "violation": l.kkt.as_ref().map(|k| number_json(k.violation)),
        })
    }

    /// The JSON object `hybc optimize --format json` prints (docs/optimize.md).
    pub fn to_json(&self) -> Value {
        let r = self.result.reported();
        let params: Map<String, Value> =
            self.info.param_names.iter().zip(&r.params).map(|(n, v)| (n.clone(), number_json(*v))).collect();
        let constraints: Vec<Value> = self
            .result
            .constraints
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let value = r.values.get(i + 1).copied();
                json!({
                    "constraint": c.label(&self.info),
                    "quantity": c.quantity.label(&self.info),
                    "sense": c.sense.symbol(),
                    "bound": c.value,
                    "value": value.map(number_json),
                    "violation": value.map(|v| number_json(c.violation(v))),
                    "tolerance": self.result.tolerances[i],
                    "met": value.is_some_and(|v| c.violation(v) <= self.result.tolerances[i]),
                    "multiplier": r.kkt.as_ref().map(|k| number_json(k.multipliers[i])),
                    "active": r.kkt.as_ref().map(|k| k.active[i]),
                })
            })
            .collect();
        let at_bound: Map<String, Value> = r
            .kkt
            .as_ref()
            .map(|k| {
                self.free_names()
                    .iter()
                    .zip(&k.at_bound)
                    .filter(|(_, &b)| b != 0)
                    .map(|(n, &b)| (n.to_string(), json!(if b < 0 { "lower" } else { "upper" })))
                    .collect()
            })
            .unwrap_or_default();
        let iterations: Vec<Value> = r
            .trials
            .iter()
            .map(|t| {
                json!({
                    "run": t.run,
                    "params": self.free_object(&t.free),
                    "objective": t.objective.map(number_json),
                    "violation": t.violation.map(number_json),
                    "events": t.events,
                    "new_sequence": t.new_sequence,
                    "failure": t.failure,
                })
            })
            .collect();
        let changes: Vec<Value> = r
            .changes
            .iter()
            .map(|c| json!({"run": c.run, "events_before": self.event_names(&c.before), "events_after": self.event_names(&c.after)}))
            .collect();
        let optima: Vec<Value> = self
            .result
            .optima
            .iter()
            .map(|g| {
                let l = &self.result.locals[g[0]];
                json!({
                    "params": self.free_object(&l.x),
                    "objective": number_json(l.values[0]),
                    "events": self.event_names(&l.events()),
                    "starts": g.iter().map(|&i| self.result.locals[i].index).collect::<Vec<_>>(),
                    "set": self.set_list(l),
                })
            })
            .collect();
        json!({
            "model": self.model,
            "free": self.free_names(),
            "objective": self.objective.label(&self.info),
            "objective_value": r.values.first().map(|v| number_json(*v)),
            "constraints": constraints,
            "params": params,
            "optimum": self.free_object(&r.x),
            "set": self.set_list(r),
            "at_bound": at_bound,
            "converged": self.converged(),
            "reason": r.verdict.word(),
            "message": self.reason(),
            "solver": self.result.solver,
            "solver_status": r.status,
            "kkt": {
                "stationarity": r.kkt.as_ref().map(|k| number_json(k.stationarity)),
                "scale": r.kkt.as_ref().map(|k| number_json(k.scale)),
                "tolerance": self.options.kkt_tol,
                "violation": r.kkt.as_ref().map(|k| number_json(k.violation)),
                "violation_ratio": r.kkt.as_ref().map(|k| number_json(k.violation_ratio)),
            },
            "events": self.event_names(&r.events()),
            "cusp_notes": r.cusp_notes,
            "sequence_changes": changes,
            "iterations": iterations,
            "starts": self.result.locals.iter().map(|l| self.local_json(l)).collect::<Vec<_>>(),
            "optima": optima,
            "stats": {
                "runs": self.result.runs(),
                "compile_seconds": self.compile_seconds,
                "optimize_seconds": self.optimize_seconds,
            },
        })
    }
}

/// `touchdown x4` for a run of repeated names, `a, b, a` otherwise.
fn summarize(names: &[String]) -> String {
    let mut parts: Vec<(String, usize)> = Vec::new();
    for n in names {
        match parts.last_mut() {
            Some((last, k)) if last == n => *k += 1,
            _ => parts.push((n.clone(), 1)),
        }
    }
    if parts.is_empty() {
        return "none".into();
    }
    parts.into_iter().map(|(n, k)| if k > 1 { format!("{n} x{k}") } else { n }).collect::<Vec<_>>().join(", ")
}

/// The shortest text that reads back as `v`: `{}` (`1.25`), or `{:e}` where that is shorter
/// (`4.4e-15`, which `{}` writes with fifteen zeros).
pub(crate) fn round_trip(v: f64) -> String {
    let plain = format!("{v}");
    let exp = format!("{v:e}");
    if exp.len() < plain.len() {
        exp
    } else {
        plain
    }
}
