//! Gradient check: every derivative a run reports (event times, final state, outputs) against a
//! central difference of the same system re-simulated at `p +/- h`, one parameter at a time. The
//! library side of `hybc run --check-grad`: it takes any [`HybridSystem`] (the compiled model is
//! reused as it is, never recompiled), returns plain data and does no IO.
//!
//! What is compared, and how:
//! - The step for parameter `p_j` is `h_j = rel_step * max(|p_j|, 1)`.
//! - The discrepancy of a derivative `d` of a quantity `Q` against its central difference `c` is
//!   `|d - c| / max(|d|, |c|, r, 0.01 |Q| / max(|p_j|, 1))`: relative to the derivative's own
//!   size, but never below `r = (atol + rtol |Q|) / h`, the worst-case resolution of the
//!   difference (tolerance-level noise in `Q` over the step), nor below 1% of the derivative's
//!   natural scale. The last floor exists because a derivative that is zero (or tiny) has a
//!   central difference made only of integration noise, which is not a gradient error: the
//!   noise of a perturbed run that takes slightly different steps is measured at up to ~2e-8 of
//!   the natural scale at rtol 1e-10 (dosing: d gut / d ke is exactly 0).
//! - An event sequence that differs between `p - h`, `p` and `p + h` (a different count or different
//!   events) is a cusp, not a failure: the events before the first difference are still checked,
//!   the final state is not (it is not a smooth function of `p` across the cusp).
//! - A grazing event has no gradient (`dtime` is `None` for it and every later event, and the final
//!   state's sensitivities are `None`): those quantities are skipped with a note.
//! - For a run ended by a `stop` event the final state is compared with the total derivatives
//!   (`dstate_total`, `doutputs_total`), since the stopping time moves with `p`; a run that stopped
//!   early (Zeno behaviour or a fault) has its final state skipped.

use std::fmt::Write as _;

use serde::Serialize;

use crate::report::num;

use crate::sim::{
    EventRecord, HybridSystem, SimError, SimOptions, SimResult, Simulator, StopReason, TrajectoryRequest,
};

/// Derivatives smaller than this fraction of their natural scale `|Q| / max(|p_j|, 1)` are
/// compared in absolute terms (see the module documentation).
const NATURAL_FRACTION: f64 = 1e-2;

/// How the check is done.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CheckOptions {
    /// Relative step: `h_j = rel_step * max(|p_j|, 1)`.
    pub rel_step: f64,
    /// Largest accepted discrepancy (see the module documentation).
    pub tol: f64,
}

impl CheckOptions {
    /// Defaults for a run at relative tolerance `rtol`: `rel_step = 1e-5`,
    /// `tol = clamp(1e5 rtol, 1e-4, 1e-2)`.
    ///
    /// Why a step that does not follow the tolerance: the sensitivities are integrated with the
    /// same steps as the state, and a run at `p +/- h` takes nearly the same steps, so the noise of
    /// the difference quotient stays far below the worst case `rtol / h`; what limits it is the
    /// truncation of the difference (`~h^2`). In a one-off sweep over the shipped models (steps
    /// 1e-4, 1e-5 and 1e-6 at rtol 1e-6 to 1e-12), 1e-5 gave the smallest worst discrepancy at
    /// rtol 1e-6, 1e-8 and 1e-10 (1e-4 is dominated by truncation, 1e-6 by noise) and was within
    /// 10x of the best at 1e-12. Its worst discrepancies, printed by `tests/check_grad.rs`: 3e-4 at
    /// rtol 1e-6, 6e-5 at 1e-8, 3e-6 at 1e-10 and 1e-12 (README, Accuracy). The default
    /// tolerance sits well above those (more than 10x) and grows with `rtol`, because both the
    /// reported derivatives and the differences are only as good as the integration.
    pub fn for_rtol(rtol: f64) -> CheckOptions {
        CheckOptions { rel_step: 1e-5, tol: (1e5 * rtol).clamp(1e-4, 1e-2) }
    }
}

/// One reported derivative next to its central difference.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Comparison {
    /// What was differentiated: `time of event #3 (impact)`, `state y`, `output energy`.
    pub quantity: String,
    pub reported: f64,
    pub central: f64,
    pub discrepancy: f64,
}

/// Where the event sequences of the three runs part.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Cusp {
    /// Position of the first event that differs (or is missing) between the runs.
    pub first_difference: usize,
    /// Number of events at `p - h`, `p`, `p + h`.
    pub events: [usize; 3],
    /// Whether the runs also ended differently (one stopped by `t_end`, another by Zeno, ...).
    pub ends_differ: bool,
}

/// The check of one gradient parameter.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ParamCheck {
    pub name: String,
    /// Index into all parameters.
    pub param: usize,
    /// The step `h`.
    pub step: f64,
    /// Number of derivatives compared.
    pub checked: usize,
    /// The comparison with the largest discrepancy, if any was made.
    pub worst: Option<Comparison>,
    pub cusp: Option<Cusp>,
    /// Why some quantities were not compared (grazing, a run that stopped early).
    pub notes: Vec<String>,
}

impl ParamCheck {
    pub fn worst_discrepancy(&self) -> f64 {
        self.worst.as_ref().map_or(0.0, |w| w.discrepancy)
    }
}

/// The outcome of a gradient check.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GradCheck {
    pub options: CheckOptions,
    pub params: Vec<ParamCheck>,
}

impl GradCheck {
    /// Whether every compared derivative is within the tolerance (cusps and skipped quantities do
    /// not fail a check).
    pub fn passed(&self) -> bool {
        self.params.iter().all(|c| c.worst_discrepancy() <= self.options.tol)
    }

    /// The parameters whose worst discrepancy exceeds the tolerance.
    pub fn failures(&self) -> impl Iterator<Item = &ParamCheck> {
        self.params.iter().filter(|c| c.worst_discrepancy() > self.options.tol)
    }

    /// The table `hybc run --check-grad` prints: one row per parameter with its worst discrepancy
    /// and where it occurred, then cusps and notes, then the verdict.
    pub fn to_table(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "gradient check: central differences at p +/- h, h = {:.0e} max(|p|, 1), tolerance {:.0e}",
            self.options.rel_step, self.options.tol
        );
        let _ = writeln!(
            out,
            "  {:<12}  {:>8}  {:>7}  {:>11}  {:>18}  {:>18}  worst at",
            "parameter", "h", "checked", "discrepancy", "reported", "central"
        );
        for c in &self.params {
            let flag = if c.worst_discrepancy() > self.options.tol { "  FAILED" } else { "" };
            match &c.worst {
                Some(w) => {
                    let _ = writeln!(
                        out,
                        "  {:<12}  {:>8.1e}  {:>7}  {:>11.1e}  {:>18}  {:>18}  {}{flag}",
                        c.name,
                        c.step,
                        c.checked,
                        w.discrepancy,
                        num(w.reported),
                        num(w.central),
                        w.quantity
                    );
                }
                None => {
                    let _ = writeln!(out, "  {:<12}  {:>8.1e}  {:>7}  {:>11}", c.name, c.step, 0, "-");
                }
            }
        }
        for c in &self.params {
            if let Some(cusp) = &c.cusp {
                let [m, n, p] = cusp.events;
                let _ = writeln!(
                    out,
                    "  cusp in {}: {m}, {n}, {p} events at p - h, p, p + h; the sequences part at event \
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
        let failed: Vec<&str> = self.failures().map(|c| c.name.as_str()).collect();
        if failed.is_empty() {
            let _ = writeln!(out, "gradient check passed");
        } else {
            let _ = writeln!(
                out,
                "gradient check FAILED: {} above the tolerance {:.0e}",
                failed.join(", "),
                self.options.tol
            );
        }
        out
    }
}

/// Checks every derivative in `nominal` (the result of `sim::run(sys, p, opts)`) against central
/// differences of `sys` re-simulated at `p +/- h` with the same options (without a trajectory).
/// Errors only when a perturbed run is rejected as input, which the nominal run was not.
pub fn check(
    sys: &(impl HybridSystem + ?Sized),
    p: &[f64],
    opts: &SimOptions,
    nominal: &SimResult,
    check: &CheckOptions,
) -> Result<GradCheck, SimError> {
    let info = sys.info();
    let opts = SimOptions { trajectory: TrajectoryRequest::None, ..opts.clone() };
    let mut simulator = Simulator::new(sys, &opts)?;
    let mut params = Vec::with_capacity(info.n_grad());
    for (j, &param) in info.grad_params.iter().enumerate() {
        let step = check.rel_step * p[param].abs().max(1.0);
        let mut perturbed = |sign: f64| {
            let mut q = p.to_vec();
            q[param] += sign * step;
            simulator.run(&q)
        };
        let (minus, plus) = (perturbed(-1.0)?, perturbed(1.0)?);
        let mut param_check = ParamCheck {
            name: info.param_names[param].clone(),
            param,
            step,
            checked: 0,
            worst: None,
            cusp: None,
            notes: Vec::new(),
        };
        Differences {
            sys,
            opts: &opts,
            j,
            step,
            param_scale: p[param].abs().max(1.0),
            out: &mut param_check,
        }
        .compare(nominal, &minus, &plus);
        params.push(param_check);
    }
    Ok(GradCheck { options: *check, params })
}

/// The comparisons for one parameter (column `j` of every derivative array).
struct Differences<'a, S: HybridSystem + ?Sized> {
    sys: &'a S,
    opts: &'a SimOptions,
    j: usize,
    step: f64,
    /// `max(|p_j|, 1)`.
    param_scale: f64,
    out: &'a mut ParamCheck,
}

impl<S: HybridSystem + ?Sized> Differences<'_, S> {
    fn compare(&mut self, nominal: &SimResult, minus: &SimResult, plus: &SimResult) {
        let agree = common_events(&nominal.events, &minus.events, &plus.events);
        let same_end = same_end(&nominal.stopped_by, &minus.stopped_by)
            && same_end(&nominal.stopped_by, &plus.stopped_by);
        let whole =
            agree == nominal.events.len() && agree == minus.events.len() && agree == plus.events.len();
        if !whole || !same_end {
            self.out.cusp = Some(Cusp {
                first_difference: agree,
                events: [minus.events.len(), nominal.events.len(), plus.events.len()],
                ends_differ: !same_end,
            });
        }
        for k in 0..agree {
            let e = &nominal.events[k];
            let Some(dtime) = &e.dtime else {
                self.out.notes.push(format!(
                    "event #{k} ({}) grazes at t = {}: its gradient and all later ones do not exist; not checked",
                    e.name, e.time
                ));
                break;
            };
            if dtime[self.j].is_nan() {
                self.out.notes.push(format!(
                    "event #{k} ({}) at t = {}: its time gradient does not exist (a grazing crossing before or at it); not checked",
                    e.name, e.time
                ));
                continue;
            }
            let label = format!("time of event #{k} ({})", e.name);
            self.compare_one(label, dtime[self.j], minus.events[k].time, plus.events[k].time);
        }
        if !whole || !same_end {
            return;
        }
        let f = &nominal.final_state;
        let (dstate, doutputs) = match &nominal.stopped_by {
            StopReason::TEnd => (&f.dstate, &f.doutputs),
            StopReason::Event { .. } => (&f.dstate_total, &f.doutputs_total),
            _ => {
                self.out.notes.push("the run stopped early: final state not checked".to_string());
                return;
            }
        };
        // After a grazing event the sensitivities are `None` (already noted above).
        let (Some(dstate), Some(doutputs), true) = (dstate, doutputs, f.dstate.is_some()) else {
            return;
        };
        let info = self.sys.info();
        let (n, k) = (info.n_states(), info.n_outputs());
        for i in 0..n {
            let label = format!("state {}", info.state_names[i]);
            let (a, b) = (minus.final_state.state[i], plus.final_state.state[i]);
            self.compare_one(label, dstate[self.j * n + i], a, b);
        }
        for i in 0..k {
            let label = format!("output {}", info.output_names[i]);
            let (a, b) = (minus.final_state.outputs[i], plus.final_state.outputs[i]);
            self.compare_one(label, doutputs[self.j * k + i], a, b);
        }
    }

    fn compare_one(&mut self, quantity: String, reported: f64, at_minus: f64, at_plus: f64) {
        if reported.is_nan() {
            // The derivative does not exist (it depends on a grazing crossing): nothing to compare.
            self.out.notes.push(format!("{quantity}: its derivative does not exist; not checked"));
            return;
        }
        let central = (at_plus - at_minus) / (2.0 * self.step);
        let size = at_minus.abs().max(at_plus.abs());
        let resolution = (self.opts.atol + self.opts.rtol * size) / self.step;
        let natural = NATURAL_FRACTION * (size + self.opts.atol) / self.param_scale;
        let scale = reported.abs().max(central.abs()).max(resolution).max(natural);
        // NaN (a non-finite derivative or difference) must count as the worst possible.
        let discrepancy = match (reported - central).abs() / scale {
            d if d.is_nan() => f64::INFINITY,
            d => d,
        };
        self.out.checked += 1;
        if self.out.worst.as_ref().is_none_or(|w| discrepancy > w.discrepancy) {
            self.out.worst = Some(Comparison { quantity, reported, central, discrepancy });
        }
    }
}

/// Length of the common prefix of the three event sequences (same event at each position).
fn common_events(nominal: &[EventRecord], minus: &[EventRecord], plus: &[EventRecord]) -> usize {
    nominal
        .iter()
        .zip(minus)
        .zip(plus)
        .take_while(|((a, b), c)| a.event == b.event && a.event == c.event)
        .count()
}

/// Whether two runs ended the same way (the same kind of stop; the same stop event).
fn same_end(a: &StopReason, b: &StopReason) -> bool {
    match (a, b) {
        (StopReason::Event { event: x, .. }, StopReason::Event { event: y, .. }) => x == y,
        _ => std::mem::discriminant(a) == std::mem::discriminant(b),
    }
}
