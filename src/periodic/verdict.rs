//! What is said about a fixed point before it is reported: that it is one (a run of the model as
//! written from it comes back to it, `verify`) and whether the orbit is stable (its Floquet
//! multipliers against the unit circle, [`Stability`]).

use nalgebra::DMatrix;

use super::{Search, Section};
use crate::sim::{HybridSystem, NoRecorder, Runner, StepOutcome};

/// Multipliers of at most this magnitude are the section's trivial ones: a perturbation along
/// the flow reaches the section at another time but at the same point, and the state right after
/// a reset lies on the reset's image; both map to zero exactly, so their multipliers are zero to
/// round-off. They take no part in the stability verdict.
pub const TRIVIAL_MULTIPLIER: f64 = 1e-8;

/// A non-trivial multiplier whose magnitude is within this many times the run's `rtol` of 1
/// lies on the unit circle as far as the monodromy matrix can tell, and the verdict is
/// [`Stability::Borderline`]. The matrix is made of sensitivities integrated under the run's
/// tolerances: on the kicked oscillator (`tests/it/periodic.rs`) the non-trivial multiplier is
/// off its closed form by 0.3 `rtol` from `rtol = 1e-4` to `1e-12`; the factor leaves room for
/// longer orbits, more events and eigenvalues less well conditioned. A neutral direction (a
/// conservative system's family of orbits) computes as 1 to round-off, inside the band at any
/// `rtol` the runs accept (at least `10 eps`).
pub const NEUTRAL_BAND: f64 = 1000.0;

/// The verdict on an orbit's non-trivial multipliers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stability {
    /// Every one lies inside the unit circle by more than the band ([`NEUTRAL_BAND`] `rtol`):
    /// perturbations decay.
    Stable,
    /// One lies outside it by more than the band: a perturbation grows.
    Unstable,
    /// None lies outside, and one lies on it to within the band: the linearisation cannot
    /// decide.
    Borderline,
}

impl Stability {
    /// The verdict on `multipliers` (those above [`TRIVIAL_MULTIPLIER`] count), `band` the
    /// distance from 1 within which a magnitude is 1 ([`NEUTRAL_BAND`] times the runs' `rtol`).
    pub fn of(multipliers: &[(f64, f64)], band: f64) -> Stability {
        let sizes = multipliers.iter().map(|(re, im)| re.hypot(*im)).filter(|&s| s > TRIVIAL_MULTIPLIER);
        let largest = sizes.fold(0.0, f64::max);
        if largest > 1.0 + band {
            Stability::Unstable
        } else if largest >= 1.0 - band {
            Stability::Borderline
        } else {
            Stability::Stable
        }
    }

    /// Its name in the JSON (`stability`).
    pub fn name(self) -> &'static str {
        match self {
            Stability::Stable => "stable",
            Stability::Unstable => "unstable",
            Stability::Borderline => "borderline",
        }
    }
}

/// The eigenvalues of `m` as `(re, im)`, by decreasing magnitude (a complex pair stays together).
pub fn multipliers(m: &DMatrix<f64>) -> Vec<(f64, f64)> {
    let mut values: Vec<(f64, f64)> = m.complex_eigenvalues().iter().map(|c| (c.re, c.im)).collect();
    values.sort_by(|a, b| b.0.hypot(b.1).total_cmp(&a.0.hypot(a.1)).then(b.1.total_cmp(&a.1)));
    values
}

/// The run that verified a fixed point: the model as written from it, to the section's K-th
/// firing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Verification {
    /// The largest `|x - x0|` component of the orbit's states after the instant of the
    /// section's K-th firing (`x0` as the events at the start left it).
    pub residual: f64,
    /// The time from the start to that firing.
    pub period: f64,
}

/// "1st", "2nd", "3rd", "4th", ..., "11th", "12th", "13th", "21st", ...
fn ordinal(k: usize) -> String {
    let suffix = match (k % 10, k % 100) {
        (_, 11..=13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    format!("{k}{suffix}")
}

/// Runs `sys` (the section's verifying model, compiled with the seeds as its gradient
/// parameters) from `x0` at `params` until the section has fired `section.firing` times, and
/// checks that the state after that instant is the state the run had after its start (`x0`, or
/// what the events that fire at the start make of it: an event declared after the section on its
/// guard fires at the start as it fires after the section, and the orbit goes through both),
/// every orbit state within `tol (1 + |x0|)`, at the return map's `period` (within
/// `tol (1 + period)`). `Err`: what the run did instead, and its residual when it got to the
/// firing.
pub(super) fn verify<V: HybridSystem>(
    sys: &V,
    params: &[f64],
    x0: &[f64],
    period: f64,
    section: &Section,
    search: &Search,
) -> Result<Verification, (String, Option<f64>)> {
    let firing = format!("the section's {} firing", ordinal(section.firing));
    let mut p = params.to_vec();
    p.extend_from_slice(x0);
    let cannot = |e: crate::sim::SimError| (format!("a run of the model from it cannot start: {e}"), None);
    let mut runner = Runner::new(sys, &search.sim).map_err(cannot)?;
    let mut recorder = NoRecorder;
    let mut run = runner.integrator(&p, &mut recorder).map_err(cannot)?;
    let t_start = search.sim.t_start;
    let mut start = x0.to_vec();
    let mut fired = 0;
    loop {
        match run.step() {
            StepOutcome::Fired { .. } if run.t() == t_start => start.copy_from_slice(run.state()),
            StepOutcome::Fired { first, count } => {
                fired +=
                    run.events()[first..first + count].iter().filter(|e| e.event == section.event).count();
                if fired < section.firing {
                    continue;
                }
                let x = run.state();
                let residual = section.orbit.iter().map(|&i| (x[i] - start[i]).abs()).fold(0.0, f64::max);
                let back = section
                    .orbit
                    .iter()
                    .all(|&i| (x[i] - start[i]).abs() <= search.tol * (1.0 + x0[i].abs()));
                let t = run.t() - t_start;
                if !back {
                    return Err((
                        format!(
                            "a run of the model from it returns {residual:.2e} away after {firing} (t = {t}), \
                             beyond the tolerance"
                        ),
                        Some(residual),
                    ));
                }
                if (t - period).abs() > search.tol * (1.0 + period.abs()) {
                    return Err((
                        format!(
                            "a run of the model from it comes back after {firing} at t = {t}, not at the return \
                             map's period {period}"
                        ),
                        Some(residual),
                    ));
                }
                return Ok(Verification { residual, period: t });
            }
            StepOutcome::Done(stop) => {
                let how = match &stop {
                    crate::sim::StopReason::TEnd => format!("t_end = {}", search.sim.t_end),
                    crate::sim::StopReason::Event { name, .. } => format!("the stop event `{name}`"),
                    other => other.name().to_string(),
                };
                return Err((format!("a run of the model from it ends ({how}) before {firing}"), None));
            }
            StepOutcome::Accepted | StepOutcome::Rejected => {}
        }
    }
}
