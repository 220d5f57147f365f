//! Gradient check: every derivative a run reports (event times, final state, outputs) against
//! finite differences of the same system re-simulated near `p`, one parameter at a time, and the
//! run's sequence of events against a re-run with other steps. The library side of
//! `hybc run --check-grad`: it takes any [`HybridSystem`] (the compiled model is reused as it is,
//! never recompiled), returns plain data and does no IO.
//!
//! The rules:
//! - **Step** (`stencil.rs`): `h = rel_step |p|` (`rel_step = 1e-5` by default), relative to the
//!   parameter, so that a capacitance of 1e-6 F is stepped by 1e-11 F. For `p = 0` the scale is
//!   the width of the declared range `in [lo, hi]`; without a range it is 1, so `h = rel_step` in
//!   the parameter's own units, and a note says so. The step is at most a quarter of the range,
//!   and the points stay inside it: where `p - h` or `p + h` would leave it, the one-sided
//!   second-order difference `(-3 Q(p) + 4 Q(p + h) - Q(p + 2h)) / 2h` (at the lower bound) or its
//!   mirror `(3 Q(p) - 4 Q(p - h) + Q(p - 2h)) / 2h` (at the upper) replaces the central
//!   `(Q(p + h) - Q(p - h)) / 2h`. All three have a truncation error `~h^2 Q'''` and cost two runs.
//! - **Resolution** (`compare.rs`): each value `Q` a run computes carries noise
//!   `floor + 16 eps |Q| + jump`. The floor is `atol` for a state or an output and `atol / |d|`
//!   for an event time (the time its guard, crossing at speed `d`, takes to move by `atol`): what
//!   the tolerances say is zero. `16 eps |Q|` is the round-off of its own magnitude. The jump is
//!   what another sequence of steps can change `Q` by: 0 when the three runs of a difference took
//!   the same steps (the same numbers of steps, rejections and right-hand-side calls: each step
//!   size is then a smooth function of `p`, and so is each run's error, which cancels in the
//!   difference); the tolerance `rtol |Q|` (`rtol |t - t_start|` for a time) when all three took
//!   different steps; and when one run took other steps, the second difference
//!   `|Q_0 - 2 Q_1 + Q_2|` of the three values (that jump plus `h^2 Q''`), or the tolerance if
//!   smaller. A difference `sum_i w_i Q_i` (the weights above, over `h`) then resolves a
//!   derivative only to `r = sum_i |w_i| noise_i + drift`, about `noise / h`, where the drift
//!   `(floor + rtol |Q|) / scale` is the derivative of the run's own error, which moves with `p`
//!   on the parameter's scale (`|p|`, [`Stencil::scale`]) even where the steps are the same. A reported derivative `d`
//!   whose difference `c` is within `r` of it never fails, `|d - c| <= r` says nothing about `d`;
//!   when its relative discrepancy is above the tolerance it is listed as within noise. Example: a
//!   projectile's height at the stop event where it lands is ~1e-15 (round-off), its difference
//!   ~1e-10 (round-off over `h`), its total derivative exactly 0, and `r ~ atol / h`. Why not the
//!   worst case `(atol + rtol |Q|) / h` everywhere: runs that take the same steps have errors that
//!   cancel in a difference, and at a small parameter the worst case hides real errors (for the
//!   tilted ball's slope `s = 0.1` at rtol 1e-10, `rtol t / h` is 1.2e-3 of `dt/ds`).
//! - **Discrepancy**: `|d - c| / max(|d|, |c|)`. A derivative fails when its discrepancy is above
//!   the tolerance and `|d - c| > r`, unless the truncation rule below clears it; a non-finite
//!   difference of a finite derivative always fails.
//! - **Halving** ([`Truncated`], [`Unjudged`]): a derivative that would fail at step `h` is not
//!   failed yet: its parameter is differenced again at `h / 2`, `h / 4`, .. (two runs each, at
//!   most [`MAX_HALVINGS`] times, only while something is undecided), and each such derivative is
//!   judged by the sequence (`compare::judge`). An estimate of the derivative is the finest
//!   difference once two successive ones agree within their noise, or Richardson's
//!   `c_k + (c_k - c_(k-1)) / 3` once the last three change by the ratios of an `h^2` error (3 to
//!   5.5: the stencils are second order), uncertain by its own change from the level before. It
//!   agrees when it is within the tolerance of the reported value with that uncertainty added
//!   (near grazing, or with a fast wiggle in a guard, `h^2 Q''' / 6` is large although the
//!   derivative is exact: listed as truncation); it disagrees when it is farther with the
//!   uncertainty taken off (a failure). When the sequence decides neither before the step would
//!   cross a cusp, round-off wins (the resolution, growing as `1 / h`, exceeds the tolerance), or
//!   the halvings run out, the check **cannot judge** the derivative: a third verdict, never
//!   FAILED for a gradient the differences could not check, never PASSED for one they could not
//!   confirm.
//! - **Tolerance** ([`Tightened`]): the run's error is a smooth function of `p` where the steps
//!   are the same, so it has a derivative, and every difference contains it; halving `h` does not
//!   remove it. Where it is all there is (a derivative exactly 0 whose parameter moves only where
//!   the steps fall: `d(gut)/dke` in the dosing model, a constant torque's window `Tu` in the
//!   compass gait, differenced to 1e-6 at rtol 1e-6), the halvings find a disagreement that is
//!   the integration's. So what they leave disagreeing or undecided is differenced once more at
//!   `h` with tolerances [`TOLERANCE_TEST`] times tighter (three runs), and the estimate moves by
//!   what that changed. A disagreement that shrinks to a tenth or less of itself, or to within
//!   the tolerance, is the integration's (listed as integration error, not failed); one that keeps
//!   half or more of itself is a wrong derivative (a wrong derivative's disagreement does not
//!   depend on the tolerances); in between, or without an estimate, the check cannot judge it.
//! - **Naming**: a failure names the derivative, `dt(touchdown#2)/de` (the second firing of
//!   `touchdown`) or `d(energy)/dh0`, with the reported and the differenced values.
//! - **Event sequence** (`sequence.rs`): the system is re-run at `p` with a tenth of `rtol` and
//!   `atol` and steps of at most `span / 10_000`, and both runs must have the same events in the same
//!   order, the same count and the same end, with times within `sqrt(rtol) span` (far above the
//!   integration error of a crossing, far below the shift of a missed or invented one). A
//!   difference fails the check: the events change with the step size, so a crossing may be
//!   missed or invented, which differences of runs with the same detector and nearly the same
//!   steps cannot see. Not compared: events from the first grazing crossing on, the tail of a run
//!   that ended early, and an extra event within the time tolerance of the end.
//! - An event sequence that differs between the three points of a difference (a different count
//!   or different events) is a cusp, not a failure: the events before the first difference are
//!   still checked, the final state is not (it is not a smooth function of `p` across the cusp).
//! - A grazing event has no gradient (`dtime` is `None` for it and every later event, and the final
//!   state's sensitivities are `None`): those quantities are skipped with a note, and so is a
//!   single derivative that does not exist (NaN).
//! - For a run ended by a `stop` event the final state is compared with the total derivatives
//!   (`dstate_total`, `doutputs_total`), since the stopping time moves with `p`; a run that stopped
//!   early (Zeno behaviour or a fault) has its final state skipped.

mod compare;
mod report;
mod sequence;
mod stencil;

use serde::Serialize;

use crate::sim::{HybridSystem, Runner, SimError, SimOptions, SimResult, TrajectoryRequest};

use compare::Judgement;
pub use sequence::{rerun_options, EventCheck, STEPS_PER_SPAN, TIGHTER};
pub use stencil::{stencil, Difference, Stencil};

use stencil::stencil as stencil_fn;

/// How the check is done.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CheckOptions {
    /// Relative step: `h_j = rel_step |p_j|` (see the module documentation for `p_j = 0`).
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
    /// 10x of the best at 1e-12. The default tolerance sits well above the worst discrepancies
    /// of the shipped models (docs/accuracy.md) and grows with `rtol`, because both the reported
    /// derivatives and the differences are only as good as the integration.
    pub fn for_rtol(rtol: f64) -> CheckOptions {
        CheckOptions { rel_step: 1e-5, tol: (1e5 * rtol).clamp(1e-4, 1e-2) }
    }
}

/// One reported derivative next to its finite difference.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Comparison {
    /// What was differentiated: `time of event #3 (impact)`, `state y`, `output energy`.
    pub quantity: String,
    /// The derivative compared, as a failure names it: `dt(touchdown#2)/de` (the time of the
    /// second firing of `touchdown`), `d(energy)/dh0` (a final output or state).
    pub derivative: String,
    /// The derivative the run reported.
    pub reported: f64,
    /// The finite difference (central, or one-sided at a bound: [`ParamCheck::difference`]).
    pub central: f64,
    /// `|reported - central| / max(|reported|, |central|)`.
    pub discrepancy: f64,
    /// What the difference can resolve: a disagreement `|reported - central|` up to this is noise.
    pub resolution: f64,
}

/// A derivative whose difference at step `h` disagrees only by the difference's own truncation
/// error. Near a grazing crossing (a ceiling the apex comes near) or with a fast wiggle in a guard,
/// the quantity's higher derivatives are large, so `h^2 Q''' / 6` exceeds the tolerance although
/// the reported derivative is exact. Halving the step tells the cases apart: a truncation error
/// shrinks about fourfold per halving and Richardson's `c2 + (c2 - c1) / 3` removes it, a wrong
/// derivative stays as far from the differences (module documentation, Halving).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Truncated {
    /// The comparison at step `h`.
    pub comparison: Comparison,
    /// The difference at step `h / 2`.
    pub half_step: f64,
    /// The estimate the agreement rests on: the extrapolation of the last differences, or the
    /// finest difference itself once successive ones agree within their noise.
    pub extrapolated: f64,
    /// The differences at `h, h / 2, h / 4, ..` up to the one that decided.
    pub differences: Vec<f64>,
}

/// A derivative whose disagreement with its differences is the integration error's: the
/// difference moves towards it when the tolerances are tightened (module documentation,
/// Tolerance). A derivative that is exactly 0 (a parameter that only moves where the steps fall,
/// such as the window of a constant input) differences to the drift of the run's error with `p`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Tightened {
    /// The comparison at step `h`.
    pub comparison: Comparison,
    /// The differences at `h, h / 2, ..` at the run's tolerances.
    pub differences: Vec<f64>,
    /// The difference at `h` at the tighter tolerances.
    pub tight: f64,
    /// The estimate of the derivative moved by what tightening changed.
    pub estimate: f64,
    /// The tighter relative tolerance (the absolute one in proportion).
    pub rtol: f64,
}

/// A derivative the differences could not judge: above the tolerance at step `h`, and neither
/// confirmed nor refuted by the differences at smaller steps (module documentation, Halving).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Unjudged {
    /// The comparison at step `h`.
    pub comparison: Comparison,
    /// The differences at `h, h / 2, h / 4, ..` that were taken.
    pub differences: Vec<f64>,
    /// Why the sequence stopped: a cusp, round-off, or the halvings ran out.
    pub reason: String,
}

/// The outcome of a gradient check, in one word.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Every compared derivative agrees with its differences (or within their noise), and the
    /// events do not change with the step size.
    Passed,
    /// A derivative disagrees by more than the tolerance and what the differences resolve, or
    /// the events change with the step size.
    Failed,
    /// Nothing failed, but some derivative could be neither confirmed nor refuted
    /// ([`Unjudged`]).
    CannotJudge,
}

impl Verdict {
    /// The word in tables and messages: `passed`, `FAILED`, `cannot judge`.
    pub fn word(self) -> &'static str {
        match self {
            Verdict::Passed => "passed",
            Verdict::Failed => "FAILED",
            Verdict::CannotJudge => "cannot judge",
        }
    }
}

/// The most halvings of a parameter's step the check takes to judge a derivative that would fail
/// at `h` (two runs each): at `h / 64` an `h^2` error has shrunk 4096-fold, and round-off
/// (`~1 / h`) usually wins before.
pub const MAX_HALVINGS: usize = 6;

/// Where the event sequences of the three runs of a difference part.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Cusp {
    /// Position of the first event that differs (or is missing) between the runs.
    pub first_difference: usize,
    /// Number of events at the difference's three points, ascending (`p - h`, `p`, `p + h` for a
    /// central difference).
    pub events: [usize; 3],
    /// Whether the runs also ended differently (one stopped by `t_end`, another by Zeno, ...).
    pub ends_differ: bool,
}

/// The check of one gradient parameter.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ParamCheck {
    /// The parameter's name.
    pub name: String,
    /// Index into all parameters.
    pub param: usize,
    /// The step `h` (0 when the parameter could not be varied).
    pub step: f64,
    /// Which difference was taken.
    pub difference: Difference,
    /// Steps (accepted and rejected) of the runs at the difference's three points, ascending.
    pub steps: [usize; 3],
    /// Number of derivatives compared.
    pub checked: usize,
    /// The comparison with the largest discrepancy, of those not within noise.
    pub worst: Option<Comparison>,
    /// Comparisons whose discrepancy is above the tolerance but within what the differences
    /// resolve: they do not fail.
    pub within_noise: Vec<Comparison>,
    /// Comparisons above the tolerance at step `h` whose differences at smaller steps converge
    /// to the reported value as a truncation error does (`~h^2`): they do not fail
    /// ([`Truncated`]).
    pub truncated: Vec<Truncated>,
    /// Comparisons whose disagreement shrinks with the tolerances: the integration's error, not
    /// the derivative's ([`Tightened`]); they do not fail.
    pub tightened: Vec<Tightened>,
    /// Comparisons above the tolerance at step `h` that neither the differences at smaller steps
    /// nor the tolerance test could confirm or refute: they do not fail, and the check cannot
    /// judge them ([`Unjudged`]).
    pub cannot_judge: Vec<Unjudged>,
    /// Every comparison made at step `h` (for the halvings; not reported).
    #[serde(skip)]
    pub(crate) all: Vec<Comparison>,
    /// Where the event sequences of the difference's runs part, if they do.
    pub cusp: Option<Cusp>,
    /// Why some quantities were not compared (grazing, a run that stopped early), and how the step
    /// was chosen where that needs saying.
    pub notes: Vec<String>,
}

impl ParamCheck {
    /// The largest discrepancy of this parameter's comparisons that are not within noise.
    pub fn worst_discrepancy(&self) -> f64 {
        self.worst.as_ref().map_or(0.0, |w| w.discrepancy)
    }
}

/// The outcome of a gradient check.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GradCheck {
    /// The step and the tolerance.
    pub options: CheckOptions,
    /// One check per gradient parameter.
    pub params: Vec<ParamCheck>,
    /// The run's events against a re-run at tighter tolerances and capped steps.
    pub events: EventCheck,
}

impl GradCheck {
    /// Whether every compared derivative is within the tolerance or within noise, and the events
    /// do not change with the step size (cusps and skipped quantities do not fail a check).
    pub fn passed(&self) -> bool {
        self.verdict() == Verdict::Passed
    }

    /// Failed when a derivative disagrees or the events change with the step size; else cannot
    /// judge when some derivative could not be judged; else passed.
    pub fn verdict(&self) -> Verdict {
        if self.failures().next().is_some() || !self.events.is_consistent() {
            Verdict::Failed
        } else if self.params.iter().any(|c| !c.cannot_judge.is_empty()) {
            Verdict::CannotJudge
        } else {
            Verdict::Passed
        }
    }

    /// The parameters whose worst discrepancy exceeds the tolerance.
    pub fn failures(&self) -> impl Iterator<Item = &ParamCheck> {
        self.params.iter().filter(|c| c.worst_discrepancy() > self.options.tol)
    }
}

/// Checks every derivative in `nominal` (the result of `sim::run(sys, p, opts)`) against finite
/// differences of `sys` re-simulated near `p` with the same options (without a trajectory), and
/// its events against a re-run (module documentation). No parameter has a declared range: see
/// [`check_within`]. Errors only when a run is rejected as input, which the nominal run was not.
pub fn check(
    sys: &(impl HybridSystem + ?Sized),
    p: &[f64],
    opts: &SimOptions,
    nominal: &SimResult,
    check: &CheckOptions,
) -> Result<GradCheck, SimError> {
    check_within(sys, p, &[], opts, nominal, check)
}

/// [`check`] with the parameters' declared ranges (`ranges[i]` for parameter `i`, `None` or
/// missing for none): the finite differences stay inside them.
pub fn check_within(
    sys: &(impl HybridSystem + ?Sized),
    p: &[f64],
    ranges: &[Option<(f64, f64)>],
    opts: &SimOptions,
    nominal: &SimResult,
    check: &CheckOptions,
) -> Result<GradCheck, SimError> {
    let info = sys.info();
    let opts = SimOptions { trajectory: TrajectoryRequest::None, ..opts.clone() };
    let rerun_opts = sequence::rerun_options(&opts);
    let rerun = Runner::new(sys, &rerun_opts)?.run(p)?;
    let events = sequence::compare(info, nominal, &rerun, &opts, &rerun_opts);
    let mut simulator = Runner::new(sys, &opts)?;
    let mut params = Vec::with_capacity(info.n_grad());
    for (j, &param) in info.grad_params.iter().enumerate() {
        let mut param_check = ParamCheck {
            name: info.param_names[param].clone(),
            param,
            step: 0.0,
            difference: Difference::Central,
            steps: [0; 3],
            checked: 0,
            worst: None,
            within_noise: Vec::new(),
            truncated: Vec::new(),
            tightened: Vec::new(),
            cannot_judge: Vec::new(),
            all: Vec::new(),
            cusp: None,
            notes: Vec::new(),
        };
        let range = ranges.get(param).copied().flatten();
        let stencil = match stencil(p[param], range, check.rel_step) {
            Ok(s) => s,
            Err(reason) => {
                param_check.notes.push(format!("not checked: {reason}"));
                params.push(param_check);
                continue;
            }
        };
        param_check.step = stencil.step;
        param_check.difference = stencil.difference;
        param_check.notes.extend(stencil.note.clone());
        let mut perturbed: [Option<SimResult>; 3] = [None, None, None];
        for (i, slot) in perturbed.iter_mut().enumerate() {
            if i != stencil.nominal {
                let mut q = p.to_vec();
                q[param] = stencil.points[i];
                *slot = Some(simulator.run(&q)?);
            }
        }
        let runs: [&SimResult; 3] = std::array::from_fn(|i| perturbed[i].as_ref().unwrap_or(nominal));
        compare::Differences {
            info,
            j,
            stencil: &stencil,
            opts: &opts,
            tol: check.tol,
            out: &mut param_check,
        }
        .compare(runs);
        if param_check.worst_discrepancy() > check.tol && param_check.cusp.is_none() {
            // A failure at h: the differences at h / 2, h / 4, .. tell a truncation error from a
            // wrong derivative, or say they cannot.
            let setup = Halving { sys, info, j, p, param, range, opts: &opts, check, nominal };
            setup.judge(&mut param_check, &mut simulator)?;
        }
        params.push(param_check);
    }
    Ok(GradCheck { options: *check, params, events })
}

/// How much tighter the tolerances of the tolerance test are (module documentation, Tolerance).
pub const TOLERANCE_TEST: f64 = 100.0;

/// One parameter's halvings and tolerance test (module documentation, Halving and Tolerance):
/// what they need besides the runs.
struct Halving<'a, S: HybridSystem + ?Sized> {
    sys: &'a S,
    info: &'a crate::sim::SystemInfo,
    /// Column of the parameter among the gradient parameters, and its index among all.
    j: usize,
    param: usize,
    p: &'a [f64],
    range: Option<(f64, f64)>,
    opts: &'a SimOptions,
    check: &'a CheckOptions,
    nominal: &'a SimResult,
}

/// A comparison the halvings left undecided or found disagreeing, before the tolerance test.
struct Undecided {
    comparison: Comparison,
    /// (difference, resolution) at `h, h / 2, ..`.
    seq: Vec<(f64, f64)>,
    /// The halvings' estimate, if they reached one (then it disagrees).
    estimate: Option<f64>,
}

impl<S: HybridSystem + ?Sized> Halving<'_, S> {
    /// The comparisons of `stencil`'s runs (`None` where the events differ between them: a cusp).
    fn level(
        &self,
        out: &ParamCheck,
        stencil: &Stencil,
        simulator: &mut Runner<&S>,
        opts: &SimOptions,
    ) -> Result<Option<Vec<Comparison>>, SimError> {
        let mut perturbed: [Option<SimResult>; 3] = [None, None, None];
        let nominal = if opts.rtol == self.opts.rtol { None } else { Some(simulator.run(self.p)?) };
        for (i, slot) in perturbed.iter_mut().enumerate() {
            if i != stencil.nominal {
                let mut q = self.p.to_vec();
                q[self.param] = stencil.points[i];
                *slot = Some(simulator.run(&q)?);
            }
        }
        let nominal = nominal.as_ref().unwrap_or(self.nominal);
        let runs: [&SimResult; 3] = std::array::from_fn(|i| perturbed[i].as_ref().unwrap_or(nominal));
        let mut level = ParamCheck { all: Vec::new(), cusp: None, ..out.clone() };
        compare::Differences {
            info: self.info,
            j: self.j,
            stencil,
            opts,
            tol: self.check.tol,
            out: &mut level,
        }
        .compare(runs);
        Ok(level.cusp.is_none().then_some(level.all))
    }

    /// Judges every comparison of `out` above the tolerance at `h` and not within noise: by its
    /// differences at `h / 2`, `h / 4`, .. until each agrees ([`Truncated`]), disagrees, or
    /// cannot be decided; then what did not agree by the tolerance test
    /// ([`Tightened`] where the disagreement is the integration's, [`Unjudged`] where the test
    /// cannot tell). `out.worst` is then the worst of what agreed at `h` and what disagrees.
    fn judge(&self, out: &mut ParamCheck, simulator: &mut Runner<&S>) -> Result<(), SimError> {
        let tol = self.check.tol;
        let noisy: Vec<String> = out.within_noise.iter().map(|c| c.derivative.clone()).collect();
        let mut open: Vec<Undecided> = out
            .all
            .iter()
            .filter(|c| c.discrepancy > tol && !noisy.contains(&c.derivative))
            .map(|c| Undecided {
                comparison: c.clone(),
                seq: vec![(c.central, c.resolution)],
                estimate: None,
            })
            .collect();
        let mut decided: Vec<Undecided> = Vec::new();
        let mut stopped = format!("{MAX_HALVINGS} halvings of the step did not decide");
        for k in 1..=MAX_HALVINGS {
            let stencil =
                match stencil_fn(self.p[self.param], self.range, self.check.rel_step / 2f64.powi(k as i32)) {
                    Ok(s) => s,
                    Err(reason) => {
                        stopped = format!("at h / 2^{k}: {reason}");
                        break;
                    }
                };
            let Some(level) = self.level(out, &stencil, simulator, self.opts)? else {
                stopped = format!("the difference at h / 2^{k} crosses a cusp (its runs' events differ)");
                break;
            };
            for mut u in std::mem::take(&mut open) {
                if let Some(finer) = level.iter().find(|f| f.derivative == u.comparison.derivative) {
                    u.seq.push((finer.central, finer.resolution));
                }
                match compare::judge(u.comparison.reported, &u.seq, tol) {
                    Judgement::Agrees { estimate } => out.truncated.push(Truncated {
                        comparison: u.comparison,
                        half_step: u.seq[1].0,
                        extrapolated: estimate,
                        differences: u.seq.iter().map(|s| s.0).collect(),
                    }),
                    Judgement::Disagrees { estimate } => {
                        decided.push(Undecided { estimate: Some(estimate), ..u })
                    }
                    Judgement::Open => open.push(u),
                }
            }
            if open.is_empty() {
                break;
            }
            // Round-off wins: every open difference resolves no better than the tolerance, and
            // halving again only doubles its noise.
            let hopeless = |u: &Undecided| {
                let (ck, rk) = u.seq[u.seq.len() - 1];
                rk > tol * u.comparison.reported.abs().max(ck.abs())
            };
            if open.iter().all(hopeless) {
                stopped = format!(
                    "round-off wins at h / 2^{k}: the differences resolve no better than the tolerance"
                );
                break;
            }
        }
        let disagree = self.tolerance_test(out, decided, open, &stopped)?;
        // The worst of what counts: comparisons that agreed at h, and those that disagree.
        out.worst = out
            .all
            .iter()
            .filter(|c| !noisy.contains(&c.derivative))
            .filter(|c| c.discrepancy <= tol || disagree.contains(&c.derivative))
            .max_by(|a, b| a.discrepancy.total_cmp(&b.discrepancy))
            .cloned();
        Ok(())
    }

    /// The tolerance test of what the halvings found disagreeing (`disagreeing`) or left open
    /// (`open`, stopped for `stopped`): the difference at `h` again with tolerances
    /// [`TOLERANCE_TEST`] times tighter. Its change moves the halvings' estimate (or, for an open
    /// one, the difference at `h`) by what the integration error contributed. A disagreement that
    /// shrinks to a tenth or less, or to within the tolerance, is the integration's
    /// ([`Tightened`]); one that keeps at least half of itself confirms a disagreement; anything
    /// else cannot be judged. Returns the derivatives that disagree.
    fn tolerance_test(
        &self,
        out: &mut ParamCheck,
        disagreeing: Vec<Undecided>,
        open: Vec<Undecided>,
        stopped: &str,
    ) -> Result<Vec<String>, SimError> {
        let mut disagree = Vec::new();
        if disagreeing.is_empty() && open.is_empty() {
            return Ok(disagree);
        }
        let tol = self.check.tol;
        let rtol = (self.opts.rtol / TOLERANCE_TEST).max(crate::sim::MIN_RTOL);
        let tight_opts =
            SimOptions { rtol, atol: self.opts.atol * rtol / self.opts.rtol, ..self.opts.clone() };
        let tight = if rtol < self.opts.rtol {
            let stencil = stencil_fn(self.p[self.param], self.range, self.check.rel_step)
                .expect("the stencil at h was made before");
            let mut tight_runner = Runner::new(self.sys, &tight_opts)?;
            self.level(out, &stencil, &mut tight_runner, &tight_opts)?
        } else {
            None
        };
        for u in disagreeing.into_iter().chain(open) {
            let reported = u.comparison.reported;
            let differences: Vec<f64> = u.seq.iter().map(|s| s.0).collect();
            let tight_c =
                tight.as_ref().and_then(|t| t.iter().find(|c| c.derivative == u.comparison.derivative));
            let Some(tight_c) = tight_c else {
                // No tolerance test (a cusp at the tighter tolerances, or none tighter exists): the
                // halvings' judgement stands.
                match u.estimate {
                    Some(_) => disagree.push(u.comparison.derivative.clone()),
                    None => out.cannot_judge.push(Unjudged {
                        comparison: u.comparison,
                        differences,
                        reason: stopped.to_string(),
                    }),
                }
                continue;
            };
            let estimate = u.estimate.unwrap_or(u.comparison.central);
            let shifted = estimate + (tight_c.central - u.comparison.central);
            let (gap, tight_gap) = ((reported - estimate).abs(), (reported - shifted).abs());
            let within = tight_gap <= tol * reported.abs().max(shifted.abs());
            if within || tight_gap <= 0.1 * gap {
                out.tightened.push(Tightened {
                    comparison: u.comparison,
                    differences,
                    tight: tight_c.central,
                    estimate: shifted,
                    rtol,
                });
            } else if u.estimate.is_some() && tight_gap >= 0.5 * gap {
                disagree.push(u.comparison.derivative.clone());
            } else {
                let reason = if u.estimate.is_some() {
                    format!(
                        "the disagreement moves with the tolerance ({} at rtol {rtol:.0e}) but neither vanishes \
                         nor stays",
                        crate::report::num(shifted)
                    )
                } else {
                    format!(
                        "{stopped}; at rtol {rtol:.0e} the difference is {}",
                        crate::report::num(tight_c.central)
                    )
                };
                out.cannot_judge.push(Unjudged { comparison: u.comparison, differences, reason });
            }
        }
        Ok(disagree)
    }
}
