//! Gradient check: the table `hybc run --check-grad` prints and the JSON it adds to the run's
//! (`check_grad`). Text only; no runs.

use std::fmt::Write as _;

use super::GradCheck;
use crate::report::num;

impl GradCheck {
    /// The check as the JSON field `check_grad` of `hybc run --check-grad --format json` (every
    /// field of the check, and `passed`).
    pub fn to_json(&self) -> serde_json::Value {
        let mut value = serde_json::json!(self);
        value["passed"] = self.passed().into();
        value["verdict"] = serde_json::json!(self.verdict());
        value
    }

    /// One row per parameter with its worst discrepancy and where it occurred, then what was
    /// within noise, cusps and notes, then the event-sequence check, then the verdict.
    pub fn to_table(&self) -> String {
        let mut out = String::new();
        let tol = self.options.tol;
        let _ = writeln!(
            out,
            "gradient check: finite differences with h = {:.0e} |p| (one-sided at a declared bound), \
             tolerance {tol:.0e}",
            self.options.rel_step
        );
        let _ = writeln!(
            out,
            "  {:<12}  {:>8}  {:<8}  {:>7}  {:>11}  {:>18}  {:>18}  worst at",
            "parameter", "h", "stencil", "checked", "discrepancy", "reported", "difference"
        );
        for c in &self.params {
            let flag = if c.worst_discrepancy() > tol {
                "  FAILED"
            } else if !c.cannot_judge.is_empty() {
                "  cannot judge"
            } else {
                ""
            };
            let head =
                format!("  {:<12}  {:>8.1e}  {:<8}  {:>7}", c.name, c.step, c.difference.name(), c.checked);
            let _ = match &c.worst {
                Some(w) => writeln!(
                    out,
                    "{head}  {:>11.1e}  {:>18}  {:>18}  {}{flag}",
                    w.discrepancy,
                    num(w.reported),
                    num(w.central),
                    w.quantity
                ),
                None => writeln!(out, "{head}  {:>11}", "-"),
            };
        }
        for c in &self.params {
            if let Some(w) = c.within_noise.iter().max_by(|a, b| a.discrepancy.total_cmp(&b.discrepancy)) {
                let more = c.within_noise.len() - 1;
                let _ = writeln!(
                    out,
                    "  within noise ({}): {}: reported {}, difference {}, apart by {:.1e} <= the resolution \
                     {:.1e} of the difference{}",
                    c.name,
                    w.quantity,
                    num(w.reported),
                    num(w.central),
                    (w.reported - w.central).abs(),
                    w.resolution,
                    if more > 0 { format!(" (and {more} more)") } else { String::new() }
                );
            }
            for t in &c.truncated {
                let w = &t.comparison;
                let _ = writeln!(
                    out,
                    "  truncation ({}): {}: reported {}, differences {}, estimate {}: the difference's own \
                     truncation error (it shrinks as h^2), not a wrong derivative",
                    c.name,
                    w.derivative,
                    num(w.reported),
                    sequence(&t.differences),
                    num(t.extrapolated)
                );
            }
            for t in &c.tightened {
                let w = &t.comparison;
                let _ = writeln!(
                    out,
                    "  integration error ({}): {}: reported {}, differences {}; at rtol {:.0e} the difference \
                     at h is {}, estimate {}: the disagreement shrinks with the tolerances, not a wrong derivative",
                    c.name,
                    w.derivative,
                    num(w.reported),
                    sequence(&t.differences),
                    t.rtol,
                    num(t.tight),
                    num(t.estimate)
                );
            }
            for u in &c.cannot_judge {
                let w = &u.comparison;
                let _ = writeln!(
                    out,
                    "  cannot judge ({}): {}: reported {}, differences {}: {}",
                    c.name,
                    w.derivative,
                    num(w.reported),
                    sequence(&u.differences),
                    u.reason
                );
            }
            if let Some(cusp) = &c.cusp {
                let [a, b, d] = cusp.events;
                let [x, y, z] = c.difference.point_names();
                let _ = writeln!(
                    out,
                    "  cusp in {}: {a}, {b}, {d} events at {x}, {y}, {z}; the sequences part at event \
                     #{}{}: later events and the final state not checked",
                    c.name,
                    cusp.first_difference,
                    if cusp.ends_differ { " and the runs end differently" } else { "" }
                );
            }
            for note in &c.notes {
                let _ = writeln!(out, "  note ({}): {note}", c.name);
            }
        }
        let e = &self.events;
        let rerun =
            format!("re-run at rtol {:.0e}, atol {:.0e}, steps at most {:.2e}", e.rtol, e.atol, e.h_max);
        let _ = match &e.difference {
            None => writeln!(
                out,
                "event sequence: {} of {} events the same when {rerun} (times within {:.1e})",
                e.compared, e.events[0], e.time_tol
            ),
            Some(d) => writeln!(
                out,
                "event sequence FAILED: the events change with the step size: a crossing may be missed \
                 or invented ({rerun}): {d}"
            ),
        };
        for note in &e.notes {
            let _ = writeln!(out, "  note (events): {note}");
        }
        // A failure names the derivative that disagrees (`d(y)/dv0`), not only its parameter, with
        // both numbers: the parameter's other derivatives may well be right.
        let failed: Vec<String> = self
            .failures()
            .filter_map(|c| c.worst.as_ref())
            .map(|w| {
                format!(
                    "{} is {} but the difference gives {} (discrepancy {:.1e})",
                    w.derivative,
                    num(w.reported),
                    num(w.central),
                    w.discrepancy
                )
            })
            .collect();
        let unjudged: Vec<&str> = self
            .params
            .iter()
            .flat_map(|c| &c.cannot_judge)
            .map(|u| u.comparison.derivative.as_str())
            .collect();
        if failed.is_empty() && e.is_consistent() && unjudged.is_empty() {
            let _ = writeln!(out, "gradient check passed");
        } else if failed.is_empty() && e.is_consistent() {
            let _ = writeln!(
                out,
                "gradient check cannot judge {}: the differences neither confirm nor refute {}; nothing \
                 disagrees",
                unjudged.join(", "),
                if unjudged.len() == 1 { "it" } else { "them" }
            );
        } else {
            let mut parts = Vec::new();
            if !e.is_consistent() {
                parts.push("the event sequence changes with the step size".to_string());
            }
            if !failed.is_empty() {
                parts.push(format!("{}; above the tolerance {tol:.0e}", failed.join("; ")));
            }
            let _ = writeln!(out, "gradient check FAILED: {}", parts.join("; "));
        }
        out
    }
}

/// Differences at `h, h/2, ..` as `a (h), b (h/2), c (h/4)`.
fn sequence(values: &[f64]) -> String {
    let step = |k: usize| if k == 0 { "h".to_string() } else { format!("h/{}", 1u64 << k) };
    values
        .iter()
        .enumerate()
        .map(|(k, v)| format!("{} ({})", num(*v), step(k)))
        .collect::<Vec<_>>()
        .join(", ")
}
