//! Gradient check: one parameter's reported derivatives against its finite differences, each
//! judged against what the differences can resolve (the rule is in the module documentation of
//! `gradcheck`). Knows `sim` results; runs nothing.

use super::sequence::same_end;
use super::stencil::Stencil;
use super::{Comparison, Cusp, ParamCheck, Truncated};
use crate::sim::{SimOptions, SimResult, StopReason, SystemInfo};

/// Round-off of a quantity's own magnitude, in units of its size: a few operations' worth.
const ROUNDOFF: f64 = 16.0 * f64::EPSILON;

/// The comparisons of one parameter (column `j` of every derivative array).
pub(super) struct Differences<'a> {
    pub info: &'a SystemInfo,
    pub j: usize,
    pub stencil: &'a Stencil,
    pub opts: &'a SimOptions,
    pub tol: f64,
    pub out: &'a mut ParamCheck,
}

/// What the noise of a value is made of: `floor + ROUNDOFF |value| + jump`, where the jump is
/// what another sequence of steps can change it by (module documentation of `gradcheck`).
struct Noise {
    floor: f64,
    /// Where the value's relative tolerance counts from (`t_start` for a time, else 0).
    origin: f64,
    rtol: f64,
    steps: Steps,
}

/// How the steps of the three runs of a difference compare.
#[derive(Clone, Copy, PartialEq)]
enum Steps {
    /// All three took the same steps: their errors are smooth in `p` and cancel.
    Same,
    /// One took other steps: its value jumps, by the second difference of the three values (the
    /// jump plus `h^2 Q''`), or by the tolerance if that is smaller.
    OneDiffers,
    /// All three took different steps: each jumps, by up to the tolerance.
    AllDiffer,
}

impl Differences<'_> {
    /// `runs`: the results at the stencil's three points, ascending (one is the nominal run).
    pub fn compare(&mut self, runs: [&SimResult; 3]) {
        let nominal = runs[self.stencil.nominal];
        let agree = common_events(runs);
        let same_end = runs.iter().all(|r| same_end(&nominal.stopped_by, &r.stopped_by));
        let whole = runs.iter().all(|r| r.events.len() == agree);
        if !whole || !same_end {
            self.out.cusp = Some(Cusp {
                first_difference: agree,
                events: runs.map(|r| r.events.len()),
                ends_differ: !same_end,
            });
        }
        // Runs with the same numbers of steps, rejections and right-hand-side calls took the same
        // sequence of steps, each step a smooth function of p.
        let key = |r: &SimResult| (r.stats.steps, r.stats.rejected, r.stats.rhs_calls);
        let [a, b, c] = runs.map(key);
        let steps = match (a == b, b == c, a == c) {
            (true, true, _) => Steps::Same,
            (false, false, false) => Steps::AllDiffer,
            _ => Steps::OneDiffers,
        };
        self.out.steps = runs.map(|r| r.stats.steps + r.stats.rejected);
        let rtol = self.opts.rtol;
        let atol = self.opts.atol;
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
            // Named as `hybc fit` targets count firings: the m-th firing of this event's name.
            let firing = 1 + nominal.events[..k].iter().filter(|x| x.name == e.name).count();
            let derivative = format!("dt({}#{firing})/d{}", e.name, self.out.name);
            let values = runs.map(|r| r.events[k].time);
            // An event time's absolute tolerance is the time its guard takes to move by atol; its
            // relative one applies to the time elapsed.
            let noise = Noise { floor: atol / e.denominator.abs(), origin: self.opts.t_start, rtol, steps };
            self.compare_one(label, derivative, dtime[self.j], values, &noise);
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
        let (n, k) = (self.info.n_states(), self.info.n_outputs());
        let noise = Noise { floor: atol, origin: 0.0, rtol, steps };
        for i in 0..n {
            let label = format!("state {}", self.info.state_names[i]);
            let derivative = format!("d({})/d{}", self.info.state_names[i], self.out.name);
            let values = runs.map(|r| r.final_state.state[i]);
            self.compare_one(label, derivative, dstate[self.j * n + i], values, &noise);
        }
        for i in 0..k {
            let label = format!("output {}", self.info.output_names[i]);
            let derivative = format!("d({})/d{}", self.info.output_names[i], self.out.name);
            let values = runs.map(|r| r.final_state.outputs[i]);
            self.compare_one(label, derivative, doutputs[self.j * k + i], values, &noise);
        }
    }

    /// One derivative against the finite difference of `values` (at the stencil's points); the
    /// difference resolves what the noises of the values, weighted as they are, add up to.
    fn compare_one(
        &mut self,
        quantity: String,
        derivative: String,
        reported: f64,
        values: [f64; 3],
        noise: &Noise,
    ) {
        if reported.is_nan() {
            // The derivative does not exist (it depends on a grazing crossing): nothing to compare.
            self.out.notes.push(format!("{quantity}: its derivative does not exist; not checked"));
            return;
        }
        let w = self.stencil.weights;
        let difference: f64 = values.iter().zip(w).map(|(v, w)| w * v).sum();
        let tolerance = |v: f64| noise.rtol * (v - noise.origin).abs();
        let jump = |v: f64| match noise.steps {
            Steps::Same => 0.0,
            Steps::OneDiffers => (values[0] - 2.0 * values[1] + values[2]).abs().min(tolerance(v)),
            Steps::AllDiffer => tolerance(v),
        };
        let resolution: f64 = values
            .iter()
            .zip(w)
            .filter(|&(_, w)| w != 0.0)
            .map(|(&v, w)| w.abs() * (noise.floor + ROUNDOFF * v.abs() + jump(v)))
            .sum();
        let gap = (reported - difference).abs();
        // NaN (a non-finite derivative or difference) counts as the worst possible.
        let discrepancy = match gap / reported.abs().max(difference.abs()) {
            _ if gap == 0.0 => 0.0,
            d if d.is_nan() => f64::INFINITY,
            d => d,
        };
        self.out.checked += 1;
        let c = Comparison { quantity, derivative, reported, central: difference, discrepancy, resolution };
        self.out.all.push(c.clone());
        if discrepancy > self.tol && gap <= resolution {
            self.out.within_noise.push(c);
        } else if self.out.worst.as_ref().is_none_or(|w| discrepancy > w.discrepancy) {
            self.out.worst = Some(c);
        }
    }
}

/// Moves the comparisons of `out` that fail at step `h` but whose differences at `h / 2` (`half`,
/// the same quantities) converge to the reported value as `h^2` into `out.truncated`, and sets
/// `out.worst` to the worst of the rest. Converging: the error at `h / 2` is at most 0.4 of the
/// error at `h`, on the same side (a truncation error `~h^2` shrinks to 0.25; noise and a wrong
/// derivative do not shrink), and the extrapolation `c2 + (c2 - c1) / 3` is within the tolerance
/// of the reported value.
pub(super) fn refine(out: &mut ParamCheck, half: &[Comparison], tol: f64) {
    let mut worst: Option<Comparison> = None;
    for c in &out.all {
        let failing = c.discrepancy > tol && !out.within_noise.iter().any(|n| n.derivative == c.derivative);
        if failing {
            if let Some(h) = half.iter().find(|h| h.derivative == c.derivative) {
                let (e1, e2) = (c.central - c.reported, h.central - c.reported);
                let extrapolated = h.central + (h.central - c.central) / 3.0;
                let off = (extrapolated - c.reported).abs() / c.reported.abs().max(extrapolated.abs());
                if e1 * e2 > 0.0 && e2.abs() <= 0.4 * e1.abs() && off <= tol {
                    out.truncated.push(Truncated {
                        comparison: c.clone(),
                        half_step: h.central,
                        extrapolated,
                    });
                    continue;
                }
            }
        } else if out.within_noise.iter().any(|n| n.derivative == c.derivative) {
            continue;
        }
        if worst.as_ref().is_none_or(|w| c.discrepancy > w.discrepancy) {
            worst = Some(c.clone());
        }
    }
    out.worst = worst;
}

/// Length of the common prefix of the event sequences (same event at each position).
fn common_events(runs: [&SimResult; 3]) -> usize {
    let [a, b, c] = runs.map(|r| &r.events);
    a.iter().zip(b).zip(c).take_while(|((x, y), z)| x.event == y.event && x.event == z.event).count()
}
