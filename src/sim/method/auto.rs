//! Stage 5 (sim): `--method auto`, a [`Stepper`] that switches between an explicit pair (DOPRI5,
//! or DOP853 below rtol 1e-7) and Rodas5P as the flow becomes stiff and stops being so. Both
//! steppers are kept; one is active. A switch happens only where a step was accepted, from that
//! step's end (`accept`), and the other method restarts there from the same derivative: no
//! state, event or sensitivity is touched, so the integrator (events, resets, saltation) sees one
//! stepper throughout.
//!
//! Detection, with hysteresis (the counters persist across events and restarts: a bounce does
//! not reset them):
//! - explicit -> Rodas5P: Hairer's test (Solving ODEs II, IV.2, as in his DOPRI5 and DOP853
//!   codes): after an accepted step, `h |lambda|` estimated from two stages at `t + h`
//!   (`Rk::stiffness`) beyond [`EXPLICIT_LIMIT`] of the pair (3.25 for DOPRI5, 6.1 for DOP853:
//!   near the edge of its stability region, so the step size is held by stability, not accuracy).
//!   [`TO_STIFF`] positive tests in a row switch; [`TO_STIFF_RESET`] negative ones in a row
//!   forget the positives. The test runs every [`TEST_EVERY`] accepted steps, and at every step
//!   while a positive one is pending (Hairer's `NSTIFF` logic, so a non-stiff run pays almost
//!   nothing).
//! - Rodas5P -> explicit: after an accepted step, `h ||f_x||_inf` (a bound of `h` times the
//!   spectral radius, from the Jacobian the step used) below half the explicit limit means the
//!   explicit pair would be stable at the step Rodas5P takes for accuracy: [`TO_EXPLICIT`] such
//!   steps in a row switch back.
//!
//! The Jacobian kernels are compiled on the first switch to Rodas5P (`Rhs::prepare`), never for a
//! run that stays explicit; if they cannot be had, the run stays explicit.

use super::dense::Dense;
use super::poly::CAP;
use super::rk::Rk;
use super::rosenbrock::{Rosenbrock, RowDense};
use super::stepper::{Interpolant, Rhs, Stepper, TapePair};
use super::tableau::{DOP853, DOPRI5};
use crate::sim::options::Method;
use crate::sim::result::MethodSegment;

/// Positive stiffness tests in a row that switch to Rodas5P (Hairer's 15).
pub const TO_STIFF: usize = 15;
/// Negative tests in a row that forget pending positive ones (Hairer's 6).
pub const TO_STIFF_RESET: usize = 6;
/// Accepted explicit steps between two stiffness tests while none is pending.
pub const TEST_EVERY: usize = 50;
/// Accepted Rodas5P steps in a row inside the explicit stability region that switch back.
pub const TO_EXPLICIT: usize = 15;

/// `h |lambda|` beyond which the explicit pair's step is held by stability (Hairer's values).
fn explicit_limit(method: Method) -> f64 {
    if method == Method::Dop853 {
        DOP853.stability_limit
    } else {
        DOPRI5.stability_limit
    }
}

/// The explicit pair and Rodas5P with the switching logic (a [`Stepper`]).
pub struct Auto {
    rk: Rk,
    row: Rosenbrock,
    explicit: Method,
    n: usize,
    /// Rodas5P is active.
    stiff: bool,
    dense: AutoDense,
    /// Hysteresis counters (see the module documentation).
    positive: usize,
    negative: usize,
    calm: usize,
    since_test: usize,
    /// The Jacobian kernels could not be had: stay explicit.
    no_jacobians: bool,
    /// A switch decided at the last `accept`, done at the next `attempt`'s start point.
    switch_pending: bool,
    /// The last attempt's start and size.
    t_attempt: f64,
    h: f64,
    /// Closed segments, and the open one's start, accepted steps and attempts.
    closed: Vec<MethodSegment>,
    from: f64,
    steps: usize,
    attempts: usize,
    /// The end derivative at the last accepted step (the new method's start derivative).
    f_end: Vec<f64>,
}

impl Auto {
    pub(crate) fn new(explicit: Method, rk: Rk, row: Rosenbrock, nz: usize, n: usize) -> Auto {
        Auto {
            rk,
            row,
            explicit,
            n,
            stiff: false,
            dense: AutoDense { rk: Dense::new(nz), row: RowDense::new(nz), stiff: false },
            positive: 0,
            negative: 0,
            calm: 0,
            since_test: 0,
            no_jacobians: false,
            switch_pending: false,
            t_attempt: 0.0,
            h: 0.0,
            closed: Vec::new(),
            from: f64::NAN,
            steps: 0,
            attempts: 0,
            f_end: vec![0.0; nz],
        }
    }

    /// Switches the active method at `t` (a switch decided at the last `accept`): closes the
    /// current segment and resets the counters. To Rodas5P only if the Jacobians can be had
    /// (compiled here on the first switch of a model); else the run stays explicit for good.
    fn switch<R: Rhs>(&mut self, t: f64, rhs: &mut R) {
        self.switch_pending = false;
        if !self.stiff && !rhs.prepare() {
            self.no_jacobians = true;
            return;
        }
        let rejected = self.attempts - self.steps;
        let (from, method, steps) = (self.from, self.method(), self.steps);
        self.closed.push(MethodSegment { from, to: t, method, steps, rejected });
        (self.from, self.steps, self.attempts) = (t, 0, 0);
        (self.positive, self.negative, self.calm, self.since_test) = (0, 0, 0, 0);
        self.stiff = !self.stiff;
        self.dense.stiff = self.stiff;
    }

    fn method(&self) -> Method {
        if self.stiff {
            Method::Rodas5p
        } else {
            self.explicit
        }
    }

    /// The stiffness test after an accepted step from `z`: updates the counters and says whether
    /// to switch.
    fn wants_switch(&mut self, z: &[f64]) -> bool {
        let limit = explicit_limit(self.explicit);
        if self.stiff {
            if self.row.stiffness() <= 0.5 * limit {
                self.calm += 1;
            } else {
                self.calm = 0;
            }
            return self.calm >= TO_EXPLICIT;
        }
        if self.no_jacobians {
            return false;
        }
        self.since_test += 1;
        if self.positive == 0 && self.since_test < TEST_EVERY {
            return false;
        }
        self.since_test = 0;
        if self.rk.stiffness(z, self.n) > limit {
            self.positive += 1;
            self.negative = 0;
        } else {
            self.negative += 1;
            if self.negative >= TO_STIFF_RESET {
                self.positive = 0;
            }
        }
        self.positive >= TO_STIFF
    }
}

impl Stepper for Auto {
    type Interpolant = AutoDense;

    fn reset(&mut self) {
        self.rk.reset();
        self.row.reset();
        self.stiff = false;
        self.dense.stiff = false;
        (self.positive, self.negative, self.calm, self.since_test) = (0, 0, 0, 0);
        self.switch_pending = false;
        self.closed.clear();
        (self.steps, self.attempts) = (0, 0);
        self.from = f64::NAN;
    }

    fn restart<R: Rhs>(&mut self, t: f64, z: &[f64], rhs: &mut R) {
        if self.from.is_nan() {
            self.from = t;
        }
        if self.switch_pending {
            self.switch(t, rhs);
        }
        if self.stiff {
            self.row.restart(t, z, rhs)
        } else {
            self.rk.restart(t, z, rhs)
        }
    }

    fn start_derivative(&self) -> &[f64] {
        if self.switch_pending {
            &self.f_end
        } else if self.stiff {
            self.row.start_derivative()
        } else {
            self.rk.start_derivative()
        }
    }

    fn initial_step<R: Rhs>(&mut self, t: f64, z: &[f64], h_max: f64, rhs: &mut R) -> f64 {
        if self.stiff {
            self.row.initial_step(t, z, h_max, rhs)
        } else {
            self.rk.initial_step(t, z, h_max, rhs)
        }
    }

    fn attempt<R: Rhs>(&mut self, t: f64, z: &[f64], h: f64, rhs: &mut R) -> f64 {
        if self.switch_pending {
            self.switch(t, rhs);
            if self.stiff {
                self.row.restart_from(&self.f_end);
            } else {
                self.rk.restart_from(&self.f_end);
            }
        }
        self.attempts += 1;
        self.t_attempt = t;
        self.h = h;
        if self.stiff {
            let err = self.row.attempt(t, z, h, rhs);
            std::mem::swap(&mut self.row.dense, &mut self.dense.row);
            err
        } else {
            self.rk.attempt(t, z, h, rhs)
        }
    }

    /// As the active method.
    fn lands_on_events(&mut self, z: &[f64]) -> bool {
        if self.stiff {
            self.row.lands_on_events(z)
        } else {
            self.rk.lands_on_events(z)
        }
    }

    /// The active method lands; the stiffness tests and statistics see only attempts.
    fn land<R: Rhs>(&mut self, t: f64, z: &[f64], h: f64, rhs: &mut R) -> f64 {
        if self.stiff {
            self.row.land(t, z, h, rhs)
        } else {
            self.rk.land(t, z, h, rhs)
        }
    }

    fn end_state(&self) -> &[f64] {
        if self.stiff {
            self.row.end_state()
        } else {
            self.rk.end_state()
        }
    }

    fn end_derivative(&self) -> &[f64] {
        if self.stiff {
            self.row.end_derivative()
        } else {
            self.rk.end_derivative()
        }
    }

    fn grow(&mut self, err: f64) -> f64 {
        self.steps += 1;
        if self.stiff {
            self.row.grow(err)
        } else {
            self.rk.grow(err)
        }
    }

    fn shrink(&self, err: f64) -> f64 {
        if self.stiff {
            self.row.shrink(err)
        } else {
            self.rk.shrink(err)
        }
    }

    fn build_interpolant<R: Rhs>(&mut self, t0: f64, z: &[f64], rhs: &mut R) {
        if !self.stiff {
            self.rk.build_interpolant(t0, z, rhs);
            std::mem::swap(&mut self.rk.dense, &mut self.dense.rk);
        }
    }

    fn build_states_interpolant<R: Rhs>(&mut self, t0: f64, z: &[f64], rhs: &mut R) {
        if !self.stiff {
            self.rk.build_states_interpolant(t0, z, rhs);
            std::mem::swap(&mut self.rk.dense, &mut self.dense.rk);
        }
    }

    fn build_guard_interpolant<R: Rhs>(&mut self, t0: f64, z: &[f64], rhs: &mut R, states: &[u32]) {
        if !self.stiff {
            self.rk.build_guard_interpolant(t0, z, rhs, states);
            std::mem::swap(&mut self.rk.dense, &mut self.dense.rk);
        }
    }

    fn complete_states_interpolant(&mut self, t0: f64, z: &[f64]) {
        if !self.stiff {
            std::mem::swap(&mut self.rk.dense, &mut self.dense.rk);
            self.rk.complete_states_interpolant(t0, z);
            std::mem::swap(&mut self.rk.dense, &mut self.dense.rk);
        }
    }

    fn complete_interpolant<R: Rhs>(&mut self, t0: f64, z: &[f64], rhs: &mut R) {
        if !self.stiff {
            // The explicit pair's dense output lives in `dense.rk` since it was built.
            std::mem::swap(&mut self.rk.dense, &mut self.dense.rk);
            self.rk.complete_interpolant(t0, z, rhs);
            std::mem::swap(&mut self.rk.dense, &mut self.dense.rk);
        }
    }

    fn interpolant(&self) -> &AutoDense {
        &self.dense
    }

    /// Moves to the end of the last attempt, and there decides whether to switch (the switch
    /// itself waits for the next attempt, which has the right-hand side to prepare).
    fn accept(&mut self, z: &mut [f64]) {
        // `z` is still the step's start point, which the explicit test needs.
        let switch = self.wants_switch(z);
        if switch {
            let end = if self.stiff { self.row.end_derivative() } else { self.rk.end_derivative() };
            self.f_end.copy_from_slice(end);
            self.switch_pending = true;
        }
        if self.stiff {
            self.row.accept(z);
        } else {
            self.rk.accept(z);
        }
    }

    fn rhs_calls(&self) -> usize {
        self.rk.rhs_calls() + self.row.rhs_calls()
    }

    fn masked(&self) -> bool {
        if self.stiff {
            self.row.masked()
        } else {
            self.rk.masked()
        }
    }

    fn outside_error(&self) -> (f64, usize) {
        if self.stiff {
            self.row.outside_error()
        } else {
            self.rk.outside_error()
        }
    }

    fn keep_stage_states(&mut self, keep: bool) {
        self.rk.keep_stage_states(keep);
    }

    fn visit_stage_states<V: FnMut(f64, &[f64])>(&self, visit: V) {
        if self.stiff {
            self.row.visit_stage_states(visit)
        } else {
            self.rk.visit_stage_states(visit)
        }
    }

    fn tape_pair(&self) -> Option<TapePair> {
        if self.stiff {
            self.row.tape_pair()
        } else {
            self.rk.tape_pair()
        }
    }

    fn segments(&self, t: f64) -> Option<Vec<MethodSegment>> {
        let mut all = self.closed.clone();
        let (from, method) = (self.from, self.method());
        let rejected = self.attempts - self.steps;
        all.push(MethodSegment { from, to: t, method, steps: self.steps, rejected });
        Some(all)
    }
}

/// The dense output of the active method (an [`Interpolant`]): both kept, swapped in from the
/// steppers as they build them.
pub struct AutoDense {
    rk: Dense,
    row: RowDense,
    stiff: bool,
}

impl Interpolant for AutoDense {
    fn t0(&self) -> f64 {
        if self.stiff {
            self.row.t0()
        } else {
            self.rk.t0()
        }
    }
    fn h(&self) -> f64 {
        if self.stiff {
            self.row.h()
        } else {
            self.rk.h()
        }
    }
    fn eval(&self, t: f64, out: &mut [f64]) {
        if self.stiff {
            self.row.eval(t, out)
        } else {
            self.rk.eval(t, out)
        }
    }
    fn eval_deriv(&self, t: f64, out: &mut [f64]) {
        if self.stiff {
            self.row.eval_deriv(t, out)
        } else {
            self.rk.eval_deriv(t, out)
        }
    }
    fn degree(&self) -> usize {
        if self.stiff {
            self.row.degree()
        } else {
            self.rk.degree()
        }
    }
    fn linear_form(&self, w: &[f64], coef: &mut [f64; CAP]) -> usize {
        if self.stiff {
            self.row.linear_form(w, coef)
        } else {
            self.rk.linear_form(w, coef)
        }
    }
    fn affine_motion_hull(&self, entries: &[(u32, f64)], slope: f64) -> Option<(f64, f64)> {
        if self.stiff {
            self.row.affine_motion_hull(entries, slope)
        } else {
            self.rk.affine_motion_hull(entries, slope)
        }
    }
    fn component_form(&self, i: usize, coef: &mut [f64; CAP]) -> usize {
        if self.stiff {
            self.row.component_form(i, coef)
        } else {
            self.rk.component_form(i, coef)
        }
    }
}
