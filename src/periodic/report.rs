//! A periodic orbit with names attached: the table `hybc periodic` prints and its JSON object,
//! and the JSON object of a search that found none (field names are a contract,
//! docs/periodic.md). No IO.

use std::fmt::Write as _;

use serde_json::{json, Value};

use super::{PeriodicError, PeriodicResult, Stability, TRIVIAL_MULTIPLIER};
use crate::report::num;
use crate::sema::ParamIdx;

/// A fixed point of the return map with the names and the question that found it.
#[derive(Clone, Debug)]
pub struct PeriodicReport {
    /// The model's name.
    pub model: String,
    /// The section event's name.
    pub section: String,
    /// Which of its firings closes the orbit (1-based).
    pub firing: usize,
    /// Every parameter's name, in declaration order.
    pub params: Vec<String>,
    /// The parameters solved for.
    pub free: Vec<ParamIdx>,
    /// The model's states, in declaration order.
    pub states: Vec<String>,
    /// The fixed point, its monodromy matrix and its multipliers.
    pub result: PeriodicResult,
}

fn trivial((re, im): (f64, f64)) -> bool {
    re.hypot(im) <= TRIVIAL_MULTIPLIER
}

impl PeriodicReport {
    /// The section as the user wrote it: `EVENT`, or `EVENT#K` for a later firing.
    fn section_label(&self) -> String {
        match self.firing {
            1 => self.section.clone(),
            k => format!("{}#{k}", self.section),
        }
    }

    /// The JSON object `hybc periodic --format json` prints (docs/periodic.md).
    pub fn to_json(&self) -> Value {
        let r = &self.result;
        let states: serde_json::Map<_, _> =
            self.states.iter().zip(&r.fixed_point).map(|(s, v)| (s.clone(), json!(v))).collect();
        let free: serde_json::Map<_, _> = self
            .free
            .iter()
            .map(|p| (self.params[p.0 as usize].clone(), json!(r.params[p.0 as usize])))
            .collect();
        let n = r.orbit.len();
        let rows: Vec<Vec<f64>> = (0..n).map(|i| (0..n).map(|j| r.monodromy[(i, j)]).collect()).collect();
        let orbit: Vec<&str> = r.orbit.iter().map(|&i| self.states[i].as_str()).collect();
        json!({
            "model": self.model,
            "section": self.section,
            "firing": self.firing,
            "found": true,
            "fixed_point": states,
            "params": free,
            "period": r.period,
            "multipliers": r.multipliers.iter().map(|&(re, im)| [re, im]).collect::<Vec<_>>(),
            "trivial": r.multipliers.iter().filter(|&&z| trivial(z)).count(),
            "stable": r.stable,
            "stability": r.stability.name(),
            "neutral_band": r.neutral_band,
            "orbit": orbit,
            "monodromy": rows,
            "iterations": r.residuals.len() - 1,
            "residuals": r.residuals,
            "events": r.events,
            "verification": {"residual": r.verification.residual, "period": r.verification.period},
        })
    }

    /// The table `hybc periodic` prints.
    pub fn to_table(&self) -> String {
        let r = &self.result;
        let mut out = String::new();
        let _ = writeln!(
            out,
            "model {}   section {}   fixed point after {} Newton iterations (residual {:.1e})",
            self.model,
            self.section_label(),
            r.residuals.len() - 1,
            r.residuals.last().copied().unwrap_or(f64::NAN)
        );
        let _ = writeln!(out, "\nfree parameters:");
        for p in &self.free {
            let _ = writeln!(out, "  {:<14}  {:>20}", self.params[p.0 as usize], num(r.params[p.0 as usize]));
        }
        let _ = writeln!(out, "\ninitial state (= the state right after {}):", self.section_label());
        for (i, (s, v)) in self.states.iter().zip(&r.fixed_point).enumerate() {
            let note = if r.orbit.contains(&i) { "" } else { "  (a running cost: not part of the orbit)" };
            let _ = writeln!(out, "  {:<14}  {:>20}{note}", s, num(*v));
        }
        let _ = writeln!(out, "\nperiod: {}   events per period: {}", num(r.period), r.events);
        let _ = writeln!(
            out,
            "verified: a run of the model from it is back after {} (residual {:.1e})",
            self.section_label(),
            r.verification.residual
        );
        let _ =
            writeln!(out, "\nFloquet multipliers (eigenvalues of the monodromy matrix, saltation included):");
        for &(re, im) in &r.multipliers {
            let z = if im == 0.0 {
                num(re)
            } else {
                format!("{} {} {}i", num(re), if im < 0.0 { "-" } else { "+" }, num(im.abs()))
            };
            let note = if trivial((re, im)) { "  (trivial: the section's)" } else { "" };
            let _ = writeln!(out, "  {z:<40}  |z| = {}{note}", num(re.hypot(im)));
        }
        let verdict = match r.stability {
            Stability::Stable => "stable: every non-trivial multiplier lies inside the unit circle".to_string(),
            Stability::Unstable => "unstable: a non-trivial multiplier lies outside the unit circle".to_string(),
            Stability::Borderline => format!(
                "borderline: a non-trivial multiplier lies on the unit circle (|z| within {:.0e} of 1, 1000 rtol); \
                 the multipliers cannot decide stability",
                r.neutral_band
            ),
        };
        let _ = writeln!(out, "\n{verdict}");
        out
    }
}

/// The JSON object `hybc periodic --format json` prints when the search found no orbit (`None`
/// for a refusal of the question, which is a usage error): `found: false`, the `reason`, the
/// `message`, and where the search ended (the free parameters of its last iterate, the Newton
/// iterations made, the residuals so far).
pub fn failure_json(
    model: &str,
    section: &str,
    firing: usize,
    params: &[String],
    free: &[ParamIdx],
    error: &PeriodicError,
) -> Option<Value> {
    let (reason, attempt) = (error.reason()?, error.attempt()?);
    let values: serde_json::Map<_, _> = free
        .iter()
        .filter_map(|p| {
            let i = p.0 as usize;
            Some((params.get(i)?.clone(), json!(attempt.params.get(i)?)))
        })
        .collect();
    let mut out = json!({
        "model": model,
        "section": section,
        "firing": firing,
        "found": false,
        "reason": reason,
        "message": error.to_string(),
        "params": values,
        "iterations": attempt.iterations,
        "residuals": attempt.residuals,
    });
    if let PeriodicError::NotVerified { residual, .. } = error {
        out["verification"] = json!({ "residual": residual });
    }
    Some(out)
}
