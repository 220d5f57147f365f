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
//!   derivative only to `r = sum_i |w_i| noise_i`, about `noise / h`. A reported derivative `d`
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
//! - **Truncation** ([`Truncated`]): a parameter with a derivative that would fail is differenced
//!   again at `h / 2`. A derivative whose difference error shrank to at most 0.4 of its error at
//!   `h` (same side; `h^2` gives 0.25) and whose Richardson extrapolation `c2 + (c2 - c1) / 3` is
//!   within the tolerance of it disagrees only by the difference's truncation: near grazing or
//!   with a fast wiggle in a guard, `h^2 Q''' / 6` is large although `d` is exact. A wrong
//!   derivative is as far from both differences, and still fails.
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
/// the reported derivative is exact. Halving the step (two more runs) tells the cases apart: a
/// truncation error shrinks about fourfold and Richardson's `c2 + (c2 - c1) / 3` removes it, a
/// wrong derivative stays as far from either difference.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Truncated {
    /// The comparison at step `h`.
    pub comparison: Comparison,
    /// The difference at step `h / 2`.
    pub half_step: f64,
    /// `half_step + (half_step - central) / 3`: the difference with its `h^2` term removed.
    pub extrapolated: f64,
}

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
    /// Comparisons above the tolerance at step `h` whose difference at `h / 2` moved towards the
    /// reported value as a truncation error does (`~h^2`), and whose extrapolation agrees with
    /// it: they do not fail ([`Truncated`]).
    pub truncated: Vec<Truncated>,
    /// Every comparison made at step `h` (for the refinement at `h / 2`; not reported).
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
        self.failures().next().is_none() && self.events.is_consistent()
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
            // A failure at h: the same differences at h / 2 tell a truncation error from a wrong
            // derivative ([`Truncated`]).
            if let Ok(half) = stencil_fn(p[param], range, check.rel_step / 2.0) {
                let mut perturbed: [Option<SimResult>; 3] = [None, None, None];
                for (i, slot) in perturbed.iter_mut().enumerate() {
                    if i != half.nominal {
                        let mut q = p.to_vec();
                        q[param] = half.points[i];
                        *slot = Some(simulator.run(&q)?);
                    }
                }
                let runs: [&SimResult; 3] = std::array::from_fn(|i| perturbed[i].as_ref().unwrap_or(nominal));
                let mut refined = ParamCheck { all: Vec::new(), ..param_check.clone() };
                compare::Differences {
                    info,
                    j,
                    stencil: &half,
                    opts: &opts,
                    tol: check.tol,
                    out: &mut refined,
                }
                .compare(runs);
                if refined.cusp.is_none() {
                    compare::refine(&mut param_check, &refined.all, check.tol);
                }
            }
        }
        params.push(param_check);
    }
    Ok(GradCheck { options: *check, params, events })
}
