//! Gradient check: one parameter's reported derivatives against its finite differences, each
//! judged against what the differences can resolve (the rule is in the module documentation of
//! `gradcheck`). Knows `sim` results; runs nothing.

use super::sequence::same_end;
use super::stencil::Stencil;
use super::{Comparison, Cusp, ParamCheck};
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
/// what another sequence of steps can change it by, and what the difference of those values
/// resolves besides: the drift of the run's own error with `p` (module documentation of
/// `gradcheck`).
struct Noise {
    floor: f64,
    /// Where the value's relative tolerance counts from (`t_start` for a time, else 0).
    origin: f64,
    rtol: f64,
    steps: Steps,
    /// The parameter's scale ([`Stencil::scale`]): the run's error, of the size of the tolerance,
    /// moves with `p` on it even where every run takes the same number of steps.
    scale: f64,
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
        // The event times whose gradients the run reports (all, unless `SimOptions::of` named
        // others: those are not checked).
        let wanted = nominal.reports_event_gradients(self.info);
        for (k, e) in nominal.events.iter().enumerate().take(agree) {
            if !wanted[k] {
                continue;
            }
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
            let noise = Noise {
                floor: atol / e.denominator.abs(),
                origin: self.opts.t_start,
                rtol,
                steps,
                scale: self.stencil.scale,
            };
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
        let noise = Noise { floor: atol, origin: 0.0, rtol, steps, scale: self.stencil.scale };
        for i in (0..n).filter(|&i| nominal.reports_gradient(false, i)) {
            let label = format!("state {}", self.info.state_names[i]);
            let derivative = format!("d({})/d{}", self.info.state_names[i], self.out.name);
            let values = runs.map(|r| r.final_state.state[i]);
            self.compare_one(label, derivative, dstate[self.j * n + i], values, &noise);
        }
        for i in (0..k).filter(|&i| nominal.reports_gradient(true, i)) {
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
        let nominal = values[self.stencil.nominal];
        // The run's error (`floor + rtol |Q|` at most) is a smooth function of `p` when the steps
        // are the same, but not a constant: the step sizes move with `p`, on its own scale. Its
        // derivative, up to that error over the scale, is in every difference (the whole of it
        // where the reported derivative is exactly 0: `d(gut)/dke` in the dosing model at rtol
        // 1e-6 differences to 1.9e-6, with 9e-6 of drift).
        let drift = (noise.floor + tolerance(nominal)) / noise.scale;
        let resolution: f64 = drift
            + values
                .iter()
                .zip(w)
                .filter(|&(_, w)| w != 0.0)
                .map(|(&v, w)| w.abs() * (noise.floor + ROUNDOFF * v.abs() + jump(v)))
                .sum::<f64>();
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

/// Ratios of successive changes of a second-order difference under halving that show it in its
/// asymptotic regime: `h^2` gives 4 (the next term, `h^3` one-sided or `h^4` central, pulls it
/// towards 8 or 16 only while it still counts, which the extrapolation then does not remove).
const ASYMPTOTIC_RATIO: std::ops::RangeInclusive<f64> = 3.0..=5.5;

/// What a sequence of differences at `h, h/2, h/4, ..` says of a reported derivative.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Judgement {
    /// An estimate of the derivative within the tolerance of the reported value, its own
    /// uncertainty included.
    Agrees {
        /// The difference at the finest step, or its extrapolation.
        estimate: f64,
    },
    /// An estimate farther from the reported value than the tolerance, its uncertainty excluded.
    Disagrees {
        /// As for `Agrees`.
        estimate: f64,
    },
    /// No estimate good enough to tell yet.
    Open,
}

/// Judges `reported` by its differences `seq` (`(difference, resolution)` at `h / 2^k`,
/// `k = 0 ..`, at least two). An estimate is either the finest difference, once two
/// successive differences agree within their noise (the truncation error is below the noise), or
/// Richardson's extrapolation `c_k + (c_k - c_(k-1)) / 3`, once the last three differences change
/// by ratios of an `h^2` error (3 to 5.5; `h^2` gives 4), with the change of the extrapolation
/// between the last two levels as its uncertainty. The derivative agrees when the estimate is
/// within the tolerance of it with the uncertainty added, disagrees when it is farther with the
/// uncertainty taken off, and otherwise the sequence must go on. A wrong derivative cannot agree
/// and a right one cannot disagree, except by an estimate whose uncertainty was underestimated,
/// which both tests need in the same direction.
pub(super) fn judge(reported: f64, seq: &[(f64, f64)], tol: f64) -> Judgement {
    let k = seq.len() - 1;
    assert!(k >= 1, "a judgement needs two differences");
    let within = |estimate: f64, gap: f64| gap <= tol * reported.abs().max(estimate.abs());
    let (ck, rk) = seq[k];
    let change = |i: usize| (seq[i].0 - seq[i - 1].0).abs();
    let noise = |i: usize| seq[i].1 + seq[i - 1].1;
    let richardson = |i: usize| seq[i].0 + (seq[i].0 - seq[i - 1].0) / 3.0;
    let (estimate, uncertainty) = if change(k) <= noise(k) {
        (ck, noise(k))
    } else if k >= 2 && ASYMPTOTIC_RATIO.contains(&(change(k - 1) / change(k))) {
        let r = richardson(k);
        (r, (r - richardson(k - 1)).abs() + 1.5 * rk)
    } else {
        return Judgement::Open;
    };
    let gap = (reported - estimate).abs();
    if within(estimate, gap + uncertainty) {
        Judgement::Agrees { estimate }
    } else if gap > uncertainty && !within(estimate, gap - uncertainty) {
        Judgement::Disagrees { estimate }
    } else {
        Judgement::Open
    }
}

/// Length of the common prefix of the event sequences (same event at each position).
fn common_events(runs: [&SimResult; 3]) -> usize {
    let [a, b, c] = runs.map(|r| &r.events);
    a.iter().zip(b).zip(c).take_while(|((x, y), z)| x.event == y.event && x.event == z.event).count()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Differences of a quantity with derivative `exact` and an `h^2` truncation (`h = 2^-k`),
    /// each resolved to `noise`.
    fn truncating(exact: f64, k: usize, noise: f64) -> Vec<(f64, f64)> {
        (0..=k).map(|i| (exact + 0.3 * exact * 0.25f64.powi(i as i32), noise)).collect()
    }

    #[test]
    fn a_truncation_error_agrees_once_its_ratio_shows_and_a_wrong_derivative_disagrees() {
        let tol = 1e-3;
        // One halving shows no ratio: the sequence goes on.
        assert_eq!(judge(2.0, &truncating(2.0, 1, 1e-12), tol), Judgement::Open);
        // Two show the ratio 4: Richardson's estimate is exact for a pure h^2 error.
        match judge(2.0, &truncating(2.0, 2, 1e-12), tol) {
            Judgement::Agrees { estimate } => assert!((estimate - 2.0).abs() < 1e-12, "{estimate}"),
            j => panic!("{j:?}"),
        }
        // The same differences refute a derivative 1% off ...
        assert!(matches!(judge(2.02, &truncating(2.0, 2, 1e-12), tol), Judgement::Disagrees { .. }));
        // ... and one at 0.5 tol stays undecided only if the estimate's uncertainty covers it.
        assert!(matches!(
            judge(2.0 * (1.0 + 0.5 * tol), &truncating(2.0, 2, 1e-12), tol),
            Judgement::Agrees { .. }
        ));
    }

    #[test]
    fn converged_differences_refute_a_wrong_derivative_at_once_but_noise_decides_nothing() {
        let tol = 1e-3;
        // Differences equal to their noise: the estimate is the finer one.
        let flat = [(1.0, 1e-9), (1.0 + 5e-10, 2e-9)];
        assert!(matches!(judge(1.1, &flat, tol), Judgement::Disagrees { .. }));
        assert!(matches!(judge(1.0, &flat, tol), Judgement::Agrees { .. }));
        // Noise above the tolerance: neither a right nor a wrong derivative is decided.
        let noisy = [(1.0, 0.01), (1.01, 0.02)];
        assert_eq!(judge(1.0, &noisy, tol), Judgement::Open);
        assert_eq!(judge(1.005, &noisy, tol), Judgement::Open);
        // Differences that jump about without an h^2 ratio decide nothing either.
        let erratic = [(1.0, 1e-12), (1.5, 1e-12), (0.7, 1e-12)];
        assert_eq!(judge(1.0, &erratic, tol), Judgement::Open);
        assert_eq!(judge(3.0, &erratic, tol), Judgement::Open);
    }
}
