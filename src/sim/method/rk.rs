//! Stage 5 (sim): the adaptive explicit Runge-Kutta pairs (Dormand-Prince 5(4), DOP853) as a
//! [`Stepper`]: error norm, step-size controller, initial step estimate and dense output. Knows
//! nothing of modes, events or sensitivities: the integrator hands it a right-hand side and says
//! which leading components enter the error norm.
//!
//! Error norm: `err = sqrt(mean_i (e_i / sc_i)^2)` over the controlled components with
//! `sc_i = atol + rtol * max(|z_i|, |z_new_i|)`; a step is accepted when `err <= 1`. DOP853
//! combines its 5th- and 3rd-order estimates as Hairer does,
//! `err = err5^2 / sqrt(err5^2 + 0.01 err3^2)`, which behaves like an 8th-order estimate.
//!
//! Step-size controller (PI, Gustafsson's form as used in Hairer's codes): after an accepted step
//! `h_new = h * safety * err^(-alpha) * err_prev^beta` with `alpha = 1 / q - 0.75 beta`, `q` the
//! order, `safety = 0.9`, and `beta` and the factor bounds from the pair's [`Control`]
//! (`beta = 0.2 / q`, factors in [0.2, 10]); after a rejection only the I-part
//! `h * safety * err^(-1/q)` is used and growth is forbidden.
//!
//! Initial step (Hairer, Norsett & Wanner, ODEs I, II.4): with `d0 = |z0|`, `d1 = |f0|` in the
//! scaled norm, `h0 = 0.01 d0 / d1`; one explicit Euler step gives `d2 = |f(z0 + h0 f0) - f0| / h0`
//! and `h1 = (0.01 / max(d1, d2))^(1/q)`; the estimate is `min(100 h0, h1)`.

use super::dense::Dense;
use super::errnorm::{controlled, plain_block_norm, BlockNorm};
use super::stepper::{Rhs, Stepper, TapePair};
use super::sums::{centred_sum, stage_sum};
#[cfg(doc)]
use super::tableau::Control;
use super::tableau::{DenseKind, Tableau};

const SAFETY: f64 = 0.9;
/// `|y1 - y^|` below this many round-offs of `|y1|` leaves the stiffness estimate that decides
/// landing on events at 0 (`Rk::stiffness_with_floor`).
const ROUNDOFF_FLOOR: f64 = 64.0;

/// An explicit Runge-Kutta pair with its controller and dense output (a [`Stepper`]).
pub struct Rk {
    pub(crate) tab: &'static Tableau,
    /// Length of the integrated vector.
    pub(crate) nz: usize,
    /// The leading `n_err` components enter the error norm.
    pub(crate) n_err: usize,
    /// The leading `n_states` components are states (the rest sensitivities).
    pub(crate) n_states: usize,
    /// Whether the last attempt's error left out sensitivities that were not finite.
    masked: bool,
    pub(crate) rtol: f64,
    pub(crate) atol: f64,
    /// Stage derivatives, `all_stages` blocks of `nz`; block 0 is `f(t, y)` at the start point,
    /// block `stages - 1` is `f(t + h, y_new)` after an attempt.
    pub(crate) k: Vec<f64>,
    /// The last attempted step and its result.
    pub(crate) h: f64,
    pub(crate) y_new: Vec<f64>,
    pub(crate) ytmp: Vec<f64>,
    pub(crate) dense: Dense,
    /// The dense output was built for the states alone (`Stepper::build_states_interpolant`),
    /// from the attempt numbered so: its extra stages' sensitivity blocks are not computed yet.
    partial: Option<u64>,
    /// The dense output's states were built only for some of them
    /// (`Stepper::build_guard_interpolant`), from the attempt numbered so:
    /// `Stepper::complete_states_interpolant` builds the rest from the same stages.
    states_partial: Option<u64>,
    /// Attempts so far (a dense output is completed from its own attempt's stages only).
    attempts: u64,
    /// Scratch: one stage's whole right-hand side, for completing a dense output.
    k_whole: Vec<f64>,
    /// The states of the last attempt's stages `1..stage_count` (`n_states` each, stage `i` at
    /// `(i - 1) n_states`): `Stepper::visit_stage_states`. Kept only while `keep_stages`
    /// (`Stepper::keep_stage_states`: a mode with flow switches), and `stages_kept` says whether
    /// they were for the last attempt: the copies cost the hopper's sweep 5M instructions.
    stage_x: Vec<f64>,
    stage_count: usize,
    keep_stages: bool,
    stages_kept: bool,
    /// The error estimates of the last attempt (5th- and 3rd-order for DOP853).
    err5: Vec<f64>,
    err3: Vec<f64>,
    /// The controller's memory, kept as `err_prev^beta`.
    err_prev_beta: f64,
    /// `1e-10^(-alpha)` and `1e-4^beta`: the controller's powers at the floors of `err`.
    floors: (f64, f64),
    pub(crate) rhs_calls: usize,
    /// States left out of the error norm (the quadrature states); empty: none.
    excluded: Vec<bool>,
    /// The last attempt's largest scaled error among them, and the state (`BlockNorm::outside`).
    outside: (f64, usize),
}

impl Rk {
    /// Leaves the states `excluded` marks out of the error norm (empty: none).
    pub(crate) fn with_excluded(mut self, excluded: Vec<bool>) -> Rk {
        self.excluded = excluded;
        self
    }

    pub(crate) fn new(
        tab: &'static Tableau,
        nz: usize,
        n_states: usize,
        n_err: usize,
        rtol: f64,
        atol: f64,
    ) -> Rk {
        Rk {
            tab,
            nz,
            n_err,
            n_states,
            masked: false,
            rtol,
            atol,
            k: vec![0.0; tab.all_stages * nz],
            h: 0.0,
            y_new: vec![0.0; nz],
            ytmp: vec![0.0; nz],
            dense: Dense::new(nz),
            partial: None,
            states_partial: None,
            attempts: 0,
            k_whole: vec![0.0; nz],
            stage_x: vec![0.0; tab.all_stages * n_states],
            keep_stages: true,
            stages_kept: false,
            stage_count: 0,
            err5: vec![0.0; n_err],
            err3: vec![0.0; n_err],
            err_prev_beta: 0.0,
            floors: {
                let (alpha, beta) = controller_exponents(tab);
                (1e-10f64.powf(-alpha), 1e-4f64.powf(beta))
            },
            rhs_calls: 0,
            excluded: Vec::new(),
            outside: (0.0, 0),
        }
    }

    /// Hairer's stiffness estimate (Solving ODEs II, IV.2; DOPRI5's and DOP853's tests) after an
    /// accepted attempt of size `h` from `y`: `h |lambda|` with
    /// `|lambda| ~ |f(y1) - f(y^)| / |y1 - y^|` over the `n` states, where `y^` is the input of
    /// the last stage before the end that is also evaluated at `t + h` (DOPRI5's 6th stage), so
    /// the quotient is a Rayleigh-like estimate of the dominant eigenvalue along the step. 0 for
    /// a tableau without such a stage. Overwrites the stage-input scratch (free after `attempt`).
    pub(crate) fn stiffness(&mut self, y: &[f64], n: usize) -> f64 {
        self.stiffness_with_floor(y, n, 0.0)
    }

    /// [`Self::stiffness`], but 0 unless `|y1 - y^|` exceeds `floor` round-offs of `|y1|`: two
    /// evaluations that agree to round-off (a flow the pair integrates exactly, as a ball's
    /// parabola) make a quotient of noise over noise. (The switching test of `auto` keeps no
    /// floor: near a stiff equilibrium the differences are that small while stability holds the
    /// step.)
    fn stiffness_with_floor(&mut self, y: &[f64], n: usize, floor: f64) -> f64 {
        let s = self.tab.stages;
        let Some(i) = (1..s - 1).rev().find(|&i| self.tab.c[i] == 1.0) else { return 0.0 };
        self.stage_input(y, i, self.h);
        let nz = self.nz;
        let (f_hat, f_end) = (&self.k[i * nz..i * nz + n], &self.k[(s - 1) * nz..(s - 1) * nz + n]);
        let num: f64 = f_end.iter().zip(f_hat).map(|(a, b)| (a - b) * (a - b)).sum();
        let den: f64 = self.y_new[..n].iter().zip(&self.ytmp[..n]).map(|(a, b)| (a - b) * (a - b)).sum();
        let size: f64 = self.y_new[..n].iter().map(|a| a * a).sum();
        if den > 0.0 && den > (floor * f64::EPSILON).powi(2) * size {
            self.h.abs() * (num / den).sqrt()
        } else {
            0.0
        }
    }

    /// Takes `f0` as the derivative at a new start point (another method's end derivative
    /// there: `auto::Auto` switching) and forgets the controller's memory, as `restart` does.
    pub(crate) fn restart_from(&mut self, f0: &[f64]) {
        self.k[..self.nz].copy_from_slice(f0);
        self.err_prev_beta = self.floors.1;
    }

    /// Stage `i`'s input `ytmp = y + h sum_j a_ij k_j`.
    fn stage_input(&mut self, y: &[f64], i: usize, h: f64) {
        stage_sum(&self.k, self.nz, &self.tab.a[i], h, |c| y[c], &mut self.ytmp);
    }

    /// Evaluates stages `from..to` with step `h` from `(t, y)`.
    pub(crate) fn eval_stages<R: Rhs>(
        &mut self,
        t: f64,
        y: &[f64],
        from: usize,
        to: usize,
        h: f64,
        rhs: &mut R,
    ) {
        let nz = self.nz;
        for i in from..to {
            self.stage_input(y, i, h);
            self.keep_stage(i);
            let ti = t + self.tab.c[i] * h;
            rhs.eval(ti, &self.ytmp, &mut self.k[i * nz..(i + 1) * nz]);
            self.rhs_calls += 1;
        }
    }

    /// Notes stage `i`'s input (in `ytmp`) as evaluated, and keeps its states if asked.
    #[inline(always)]
    fn keep_stage(&mut self, i: usize) {
        self.stage_count = i + 1;
        if self.keep_stages {
            let n = self.n_states;
            self.stage_x[(i - 1) * n..i * n].copy_from_slice(&self.ytmp[..n]);
        }
    }

    /// DOP853's three extra stages of the last attempt (from `(t0, y)`) for the states alone
    /// (`Rhs::eval_states`); returns how many leading components their sums covered.
    fn extra_state_stages<R: Rhs>(&mut self, t0: f64, y: &[f64], rhs: &mut R) -> usize {
        let (tab, n, nz, h) = (self.tab, self.n_states, self.nz, self.h);
        // The sums run over whole blocks of four components (`sums.rs`: a block costs about what
        // one component does alone); what they give past the states is not read.
        let upto = n.div_ceil(4).saturating_mul(4).min(nz);
        for i in tab.stages..tab.all_stages {
            stage_sum(&self.k, nz, &tab.a[i], h, |c| y[c], &mut self.ytmp[..upto]);
            self.keep_stage(i);
            rhs.eval_states(t0 + tab.c[i] * h, &self.ytmp, &mut self.k[i * nz..(i + 1) * nz]);
            self.rhs_calls += 1;
        }
        upto
    }

    /// The scaled error of the last attempt from `y`. `MASKED` leaves out the sensitivities (the
    /// components after the first `n_states`) that are not finite at either end or in the
    /// estimate: derivatives that do not exist, which carry no error to control.
    fn error<const MASKED: bool>(&mut self, y: &[f64], h: f64) -> f64 {
        let ne = self.n_err;
        let n_states = self.n_states;
        centred_sum(&self.k, self.nz, &self.tab.e, &mut self.err5[..ne]);
        let with3 = self.tab.e3.is_some();
        if !MASKED && self.excluded.is_empty() {
            // Every component counts: the scaled errors first, in one pass over the components
            // with nothing carried from one to the next (so the compiler gives it vector
            // divisions: a division per component, one block at a time, was most of the norm's
            // time with one state and many parameters), then the blocks' sums of their squares
            // in component order (`errnorm::plain_block_norm`): `BlockNorm`'s norm to the bit.
            let (atol, rtol) = (self.atol, self.rtol);
            self.outside = (0.0, 0);
            let (y, y1) = (&y[..ne], &self.y_new[..ne]);
            let squares = |r: &[f64]| r.iter().fold(0.0, |sum, r| sum + r * r);
            return match &self.tab.e3 {
                Some(e3) => {
                    centred_sum(&self.k, self.nz, e3, &mut self.err3[..ne]);
                    let (r5, r3) = (&mut self.err5[..ne], &mut self.err3[..ne]);
                    let ends = y.iter().zip(y1);
                    for ((y0, y1), (e5, e3)) in ends.zip(r5.iter_mut().zip(r3.iter_mut())) {
                        let h_sc = h / (atol + rtol * y0.abs().max(y1.abs()));
                        *e5 *= h_sc;
                        *e3 *= h_sc;
                    }
                    let (r5, r3) = (&self.err5[..ne], &self.err3[..ne]);
                    plain_block_norm(n_states, ne, true, |range| {
                        (squares(&r5[range.clone()]), squares(&r3[range]))
                    })
                }
                None => {
                    for ((y0, y1), e5) in y.iter().zip(y1).zip(&mut self.err5[..ne]) {
                        let sc = atol + rtol * y0.abs().max(y1.abs());
                        *e5 = h * *e5 / sc;
                    }
                    let r5 = &self.err5[..ne];
                    plain_block_norm(n_states, ne, false, |range| (squares(&r5[range]), 0.0))
                }
            };
        }
        let mut norm = BlockNorm::new(n_states, &self.excluded);
        let scales = y[..ne].iter().zip(&self.y_new[..ne]);
        let skip =
            |i: usize, values: [f64; 4]| MASKED && i >= n_states && values.iter().any(|v| !v.is_finite());
        match &self.tab.e3 {
            Some(e3) => {
                centred_sum(&self.k, self.nz, e3, &mut self.err3[..ne]);
                for (i, ((y0, y1), (e5, e3))) in scales.zip(self.err5.iter().zip(&self.err3)).enumerate() {
                    let h_sc = h / (self.atol + self.rtol * y0.abs().max(y1.abs()));
                    let r = (!skip(i, [*y0, *y1, *e5, *e3])).then(|| (e5 * h_sc, e3 * h_sc));
                    norm.add(i, r, true);
                }
            }
            None => {
                for (i, ((y0, y1), e5)) in scales.zip(&self.err5).enumerate() {
                    let sc = self.atol + self.rtol * y0.abs().max(y1.abs());
                    let r = (!skip(i, [*y0, *y1, *e5, 0.0])).then(|| (h * e5 / sc, 0.0));
                    norm.add(i, r, false);
                }
            }
        }
        self.outside = norm.outside();
        norm.finish(with3)
    }
}

impl Stepper for Rk {
    type Interpolant = Dense;

    /// Forgets everything of an earlier run (the buffers are overwritten before they are read):
    /// a run on a reused stepper is bit-for-bit a run on a new one.
    fn reset(&mut self) {
        self.h = 0.0;
        self.rhs_calls = 0;
        self.err_prev_beta = self.floors.1;
    }

    /// Sets `k[0] = f(t, y)` and forgets the controller's memory.
    fn restart<R: Rhs>(&mut self, t: f64, y: &[f64], rhs: &mut R) {
        let nz = self.nz;
        rhs.eval(t, y, &mut self.k[..nz]);
        self.rhs_calls += 1;
        self.err_prev_beta = self.floors.1;
    }

    fn start_derivative(&self) -> &[f64] {
        &self.k[..self.nz]
    }

    /// Fills `y_new` and the FSAL stage and returns the scaled error (infinite when anything is
    /// not finite, so the step is rejected).
    fn attempt<R: Rhs>(&mut self, t: f64, y: &[f64], h: f64, rhs: &mut R) -> f64 {
        let s = self.tab.stages;
        self.h = h;
        self.attempts += 1;
        self.stages_kept = self.keep_stages;
        // The last stage's input is y + h sum b_j k_j = y_new (its row equals b).
        self.eval_stages(t, y, 1, s - 1, h, rhs);
        self.stage_input(y, s - 1, h);
        self.y_new.copy_from_slice(&self.ytmp);
        self.keep_stage(s - 1);
        let nz = self.nz;
        rhs.eval(t + h, &self.y_new, &mut self.k[(s - 1) * nz..s * nz]);
        self.rhs_calls += 1;
        let err = self.error::<false>(y, h);
        self.masked = false;
        if err.is_finite() && all_finite(&self.y_new) {
            return err;
        }
        // A state that is not finite rejects the step; a sensitivity that is not finite at a
        // finite state is a derivative that does not exist (NaN from here on, see `sim::jump`),
        // and the step is judged without it.
        if !all_finite(&self.y_new[..self.n_states]) {
            return f64::INFINITY;
        }
        self.masked = true;
        let err = self.error::<true>(y, h);
        if err.is_finite() {
            err
        } else {
            f64::INFINITY
        }
    }

    /// DOP853 evaluates its three extra stages here.
    fn build_interpolant<R: Rhs>(&mut self, t0: f64, y: &[f64], rhs: &mut R) {
        let tab = self.tab;
        if tab.all_stages > tab.stages {
            self.eval_stages(t0, y, tab.stages, tab.all_stages, self.h, rhs);
        }
        self.dense.build(tab, t0, self.h, y, &self.y_new, &self.k, self.nz);
        self.partial = None;
        self.states_partial = None;
    }

    /// DOP853's three extra stages for the states alone (`Rhs::eval_states`), and the dense
    /// output of the states: the event detector reads nothing else, and with sensitivities the
    /// extra stages' sensitivity blocks were most of the cost of a dense output built on every
    /// step (the pendulum's sweep with every gradient: 170M of 582M instructions).
    fn build_states_interpolant<R: Rhs>(&mut self, t0: f64, y: &[f64], rhs: &mut R) {
        let (tab, n, nz) = (self.tab, self.n_states, self.nz);
        if n == nz || tab.all_stages == tab.stages {
            return self.build_interpolant(t0, y, rhs);
        }
        let upto = self.extra_state_stages(t0, y, rhs);
        self.dense.build(tab, t0, self.h, y, &self.y_new, &self.k, upto);
        self.dense.restrict(n);
        self.partial = Some(self.attempts);
        self.states_partial = None;
    }

    /// The extra stages for the states, as [`Self::build_states_interpolant`], and the
    /// polynomials of the states `states` alone: on the hopper's sweep the states' dense output
    /// was built on 16,000 steps for a walk that reads one state's.
    fn build_guard_interpolant<R: Rhs>(&mut self, t0: f64, y: &[f64], rhs: &mut R, states: &[u32]) {
        let (tab, n, nz) = (self.tab, self.n_states, self.nz);
        if n == nz || tab.all_stages == tab.stages {
            // Without sensitivities or extra stages: the states' polynomials of the whole.
            if tab.all_stages > tab.stages {
                self.eval_stages(t0, y, tab.stages, tab.all_stages, self.h, rhs);
            }
            self.dense.build_some(tab, t0, self.h, &y[..n], &self.y_new[..n], &self.k, states);
            self.partial = (n < nz).then_some(self.attempts);
            self.states_partial = Some(self.attempts);
            return;
        }
        self.extra_state_stages(t0, y, rhs);
        self.dense.build_some(tab, t0, self.h, &y[..n], &self.y_new[..n], &self.k, states);
        self.partial = Some(self.attempts);
        self.states_partial = Some(self.attempts);
    }

    /// The polynomials of the states [`Self::build_guard_interpolant`] left out, from the same
    /// stages: the states' dense output whole, to the bit as if built at once.
    fn complete_states_interpolant(&mut self, t0: f64, y: &[f64]) {
        let Some(attempt) = self.states_partial.take() else { return };
        assert_eq!(attempt, self.attempts, "a dense output completed from another attempt's stages");
        let (tab, n) = (self.tab, self.n_states);
        if self.partial.is_none() {
            // The whole dense output is the states': built as `build_interpolant` builds it.
            self.dense.build(tab, t0, self.h, y, &self.y_new, &self.k, self.nz);
            return;
        }
        let upto = n.div_ceil(4).saturating_mul(4).min(self.nz);
        self.dense.build(tab, t0, self.h, y, &self.y_new, &self.k, upto);
        self.dense.restrict(n);
    }

    /// The extra stages' sensitivity blocks, from the states' stage inputs already computed
    /// (the states' blocks of `k` stay as they were, so the states' dense output does not move
    /// by a rounding), then the whole dense output.
    fn complete_interpolant<R: Rhs>(&mut self, t0: f64, y: &[f64], rhs: &mut R) {
        if self.partial.is_none() {
            // The states alone are the whole (no sensitivities, or no extra stages).
            return self.complete_states_interpolant(t0, y);
        }
        self.states_partial = None;
        let Some(attempt) = self.partial.take() else { return };
        assert_eq!(attempt, self.attempts, "a dense output completed from another attempt's stages");
        let (tab, n, nz, h) = (self.tab, self.n_states, self.nz, self.h);
        for i in tab.stages..tab.all_stages {
            stage_sum(&self.k, nz, &tab.a[i], h, |c| y[c], &mut self.ytmp);
            rhs.eval(t0 + tab.c[i] * h, &self.ytmp, &mut self.k_whole);
            self.rhs_calls += 1;
            self.k[i * nz + n..(i + 1) * nz].copy_from_slice(&self.k_whole[n..]);
        }
        self.dense.build(tab, t0, h, y, &self.y_new, &self.k, nz);
    }

    fn interpolant(&self) -> &Dense {
        &self.dense
    }

    fn rhs_calls(&self) -> usize {
        self.rhs_calls
    }

    fn masked(&self) -> bool {
        self.masked
    }

    fn outside_error(&self) -> (f64, usize) {
        self.outside
    }

    fn keep_stage_states(&mut self, keep: bool) {
        self.keep_stages = keep;
    }

    fn visit_stage_states<V: FnMut(f64, &[f64])>(&self, mut visit: V) {
        assert!(self.stages_kept, "the stages' states read from an attempt that did not keep them");
        let n = self.n_states;
        for i in 1..self.stage_count {
            visit(self.tab.c[i], &self.stage_x[(i - 1) * n..i * n]);
        }
    }

    /// Next step size after an accepted step with error `err`; updates the controller memory.
    fn grow(&mut self, err: f64) -> f64 {
        let (alpha, beta) = controller_exponents(self.tab);
        // Both powers are often at their floors (tiny errors), which are computed once; otherwise
        // they share the error's logarithm: one `ln` and two `exp` cost less than two `powf`
        // (which took 6% of a bouncing-ball run).
        let err = err.max(1e-10);
        let ln_err = if err == 1e-10 { 0.0 } else { err.ln() };
        let err_alpha = if err == 1e-10 { self.floors.0 } else { (-alpha * ln_err).exp() };
        let fac = SAFETY * err_alpha * self.err_prev_beta;
        self.err_prev_beta = if beta == 0.0 {
            1.0
        } else if err <= 1e-4 {
            self.floors.1
        } else {
            (beta * ln_err).exp()
        };
        self.h * fac.clamp(self.tab.control.fac_min, self.tab.control.fac_max)
    }

    /// Smaller step size after a rejected step with error `err` (infinite: by the smallest factor).
    fn shrink(&self, err: f64) -> f64 {
        let q = self.tab.order as f64;
        let fac_min = self.tab.control.fac_min;
        let fac = if err.is_finite() { SAFETY * err.powf(-1.0 / q) } else { fac_min };
        self.h * fac.clamp(fac_min, 1.0)
    }

    /// FSAL: the end derivative becomes `k[0]`, the start derivative of the next step.
    fn accept(&mut self, z: &mut [f64]) {
        let nz = self.nz;
        let s = self.tab.stages;
        z.copy_from_slice(&self.y_new);
        self.k.copy_within((s - 1) * nz..s * nz, 0);
    }

    /// The stages are recomputed (the first, the start's derivative, is kept); the dense output
    /// has stages and coefficients of its own and stays.
    fn land<R: Rhs>(&mut self, t: f64, y: &[f64], h: f64, rhs: &mut R) -> f64 {
        self.attempt(t, y, h, rhs)
    }

    /// Only where the step was held by stability: Hairer's estimate `h |lambda|` of the attempt
    /// above half the pair's stability limit (the bound `auto` switches back below). There the
    /// dense output is poor for the fast components (a chain's event-time gradients 25 times
    /// less accurate than landed, docs/accuracy.md); elsewhere Dormand-Prince's and DOP853's
    /// dense outputs are of order 4 and 7, and landing would cost an attempt per event for
    /// nothing (the ball 36% more evaluations).
    fn lands_on_events(&mut self, z: &[f64]) -> bool {
        self.stiffness_with_floor(z, self.n_states, ROUNDOFF_FLOOR) > 0.5 * self.tab.stability_limit
    }

    fn end_state(&self) -> &[f64] {
        &self.y_new
    }

    fn tape_pair(&self) -> Option<TapePair> {
        Some(match self.tab.dense {
            DenseKind::Dopri5 => TapePair::Dopri5,
            DenseKind::Dop853 => TapePair::Dop853,
        })
    }

    fn end_derivative(&self) -> &[f64] {
        let s = self.tab.stages;
        &self.k[(s - 1) * self.nz..s * self.nz]
    }

    /// Hairer's initial step estimate from `(t, y)` with `k[0] = f(t, y)`, capped by `h_max`.
    /// Uses stage block 1 and `ytmp` as scratch.
    fn initial_step<R: Rhs>(&mut self, t: f64, y: &[f64], h_max: f64, rhs: &mut R) -> f64 {
        let nz = self.nz;
        let mut d0 = 0.0;
        let mut d1 = 0.0;
        // The scales' reciprocals, kept for `d2` in `err5` (scratch: every attempt overwrites it).
        let ne = self.n_err;
        let (excluded, block) = (&self.excluded, self.n_states);
        // A component out of the step-size control (a running cost) gets a zero weight.
        let mut counted = 0usize;
        for (i, ((inv, &y), &f)) in self.err5[..ne].iter_mut().zip(&y[..ne]).zip(&self.k[..ne]).enumerate() {
            if !controlled(excluded, block, i) {
                *inv = 0.0;
                continue;
            }
            counted += 1;
            *inv = 1.0 / (self.atol + self.rtol * y.abs());
            d0 += (y * *inv).powi(2);
            d1 += (f * *inv).powi(2);
        }
        let n = counted.max(1) as f64;
        let (mut d0, mut d1) = ((d0 / n).sqrt(), (d1 / n).sqrt());
        if !(d0.is_finite() && d1.is_finite()) {
            // A tiny atol at a state or derivative of zero overflowed the squares (1e-300 is
            // legal): the same norms, scaled by their largest term first.
            let rms = |v: &[f64], inv: &[f64]| {
                let big = v.iter().zip(inv).map(|(v, i)| (v * i).abs()).fold(0.0, f64::max);
                if big == 0.0 || !big.is_finite() {
                    return big;
                }
                big * (v.iter().zip(inv).map(|(v, i)| (v * i / big).powi(2)).sum::<f64>() / n).sqrt()
            };
            d0 = rms(&y[..ne], &self.err5[..ne]);
            d1 = rms(&self.k[..ne], &self.err5[..ne]);
        }
        // Hairer takes 1e-6 for a state at zero (d0 < 1e-5); a state that is not zero but still
        // within its tolerance of it (d0 < 1: 1e-13 after an event with atol 1e-10) is no better
        // a scale, and 1% of it gave a first step at the resolution of `t` (a relay flipping at
        // x = 0 stopped on a step size underflow), so it gets 1e-6 too.
        let mut h0 = if d0 < 1.0 || d1 < 1e-5 { 1e-6 } else { 0.01 * d0 / d1 };
        h0 = h0.min(h_max);
        for ((tmp, &y), &f) in self.ytmp.iter_mut().zip(&y[..nz]).zip(&self.k[..nz]) {
            *tmp = y + h0 * f;
        }
        let (k0, rest) = self.k.split_at_mut(nz);
        rhs.eval(t + h0, &self.ytmp, &mut rest[..nz]);
        self.rhs_calls += 1;
        let mut d2 = 0.0;
        for ((inv, f1), f0) in self.err5[..ne].iter().zip(&rest[..ne]).zip(&k0[..ne]) {
            d2 += ((f1 - f0) * inv).powi(2);
        }
        let d2 = (d2 / n).sqrt() / h0;
        let dmax = d1.max(d2);
        let h_euler = 100.0 * h0;
        let h = if dmax <= 1e-15 || !dmax.is_finite() {
            h_euler.min((h0 * 1e-3).max(1e-6))
        } else if euler_bound_is_smaller(h_euler, dmax, self.tab.order) {
            h_euler
        } else {
            h_euler.min(root_q(0.01 / dmax, self.tab.order))
        };
        h.min(h_max)
    }
}

/// Whether `h_euler <= (0.01 / dmax)^(1/q)`, tested as `h_euler^q dmax <= 0.01` (`q` dependent
/// multiplications at most) instead of taking the root (a division and, for q = 8, three dependent
/// square roots: the longest chain of the estimate). The Euler bound is the smaller one at every
/// restart of the bouncing ball, whose zero velocity puts its scale at `atol`. Powers that
/// overflow or underflow leave the answer to the root.
fn euler_bound_is_smaller(h_euler: f64, dmax: f64, q: u32) -> bool {
    let power = h_euler.powi(q as i32);
    power > 0.0 && power.is_finite() && power * dmax <= 0.01
}

/// `x^(1/q)`: three square roots for the 8th-order pair, a third of the cost of `powf` (which
/// took 2% of a bouncing-ball run, in the step estimates after its events).
fn root_q(x: f64, q: u32) -> f64 {
    if q == 8 {
        x.sqrt().sqrt().sqrt()
    } else {
        x.powf(1.0 / q as f64)
    }
}

/// The PI controller's `(alpha, beta)` for the tableau's order.
fn controller_exponents(tab: &Tableau) -> (f64, f64) {
    let q = tab.order as f64;
    let beta = tab.control.beta;
    (1.0 / q - 0.75 * beta, beta)
}

/// Whether every value is finite, in independent lanes that the compiler can vectorise
/// (`v * 0` is zero for finite `v`, NaN otherwise).
fn all_finite(v: &[f64]) -> bool {
    let mut lanes = [0.0f64; 8];
    let mut chunks = v.chunks_exact(8);
    for chunk in &mut chunks {
        for (l, x) in lanes.iter_mut().zip(chunk) {
            *l += x * 0.0;
        }
    }
    let rest = chunks.remainder().iter().fold(0.0, |acc, x| acc + x * 0.0);
    lanes.iter().sum::<f64>() + rest == 0.0
}

#[cfg(test)]
mod tests {
    use super::super::poly::CAP;
    use super::super::stepper::Interpolant;
    use super::super::tableau::{DOP853, DOPRI5};
    use super::*;

    /// Integrates y' = -y + cos t from 0 to 2 and compares with the closed form
    /// y = 0.5 (cos t + sin t) + (y0 - 0.5) e^-t.
    fn integrate(tab: &'static Tableau, rtol: f64) -> (f64, usize) {
        let mut rk = Rk::new(tab, 1, 1, 1, rtol, rtol * 1e-2);
        let (mut t, mut y) = (0.0, [2.0]);
        let mut rhs = |t: f64, y: &[f64], dy: &mut [f64]| dy[0] = -y[0] + t.cos();
        rk.restart(t, &y, &mut rhs);
        let mut h = rk.initial_step(t, &y, f64::INFINITY, &mut rhs);
        let mut steps = 0;
        while t < 2.0 {
            let h_try = h.min(2.0 - t);
            let err = rk.attempt(t, &y, h_try, &mut rhs);
            if err <= 1.0 {
                h = rk.grow(err);
                rk.accept(&mut y);
                t += h_try;
                steps += 1;
            } else {
                h = rk.shrink(err);
            }
        }
        let exact = 0.5 * (2f64.cos() + 2f64.sin()) + 1.5 * (-2f64).exp();
        ((y[0] - exact).abs(), steps)
    }

    #[test]
    fn non_finite_stage_with_zero_error_weight_rejects_the_step() {
        // Stage 2 of both pairs has zero weight in `b` and in the error estimators, so `y_new` and
        // the weighted sums stay finite; an infinite derivative there must still reject the step.
        for tab in [&DOPRI5, &DOP853] {
            let mut rk = Rk::new(tab, 1, 1, 1, 1e-8, 1e-10);
            let mut calls = 0;
            let mut rhs = |_t: f64, _y: &[f64], dy: &mut [f64]| {
                calls += 1;
                dy[0] = if calls == 2 { f64::INFINITY } else { 1.0 };
            };
            rk.restart(0.0, &[0.0], &mut rhs);
            assert_eq!(rk.attempt(0.0, &[0.0], 0.1, &mut rhs), f64::INFINITY, "order {}", tab.order);
        }
        assert!(all_finite(&[1.0; 19]) && !all_finite(&[1.0, f64::NAN]) && !all_finite(&[f64::INFINITY; 9]));
    }

    /// The values and derivatives of the first `n` components of `rk`'s dense output at eleven
    /// points of its step, as bits.
    fn dense_bits(rk: &Rk, n: usize) -> Vec<u64> {
        let dense = rk.interpolant();
        let (mut v, mut d) = (vec![0.0; n], vec![0.0; n]);
        let mut bits = Vec::new();
        for i in 0..=10 {
            let t = dense.t0() + dense.h() * i as f64 / 10.0;
            dense.eval(t, &mut v);
            dense.eval_deriv(t, &mut d);
            bits.extend(v.iter().chain(&d).map(|x| x.to_bits()));
        }
        bits
    }

    #[test]
    fn a_dense_output_built_for_some_states_is_the_whole_one_to_the_bit() {
        // Three states with two sensitivity columns (nz = 9) and without (nz = 3), both pairs:
        // the states the walk reads (here the second) come out as a whole build's, the others
        // as their start values until completed, then every component as a whole build's.
        let mut rhs = |t: f64, z: &[f64], dz: &mut [f64]| {
            dz[0] = z[1];
            dz[1] = -z[0] * (1.0 + 0.3 * t.sin()) - 0.1 * z[1] * z[2];
            dz[2] = z[0] * z[0] - 0.5 * z[2];
            for c in (3..z.len()).step_by(3) {
                dz[c] = z[c + 1];
                dz[c + 1] = -(1.0 + 0.3 * t.sin()) * z[c] - 0.1 * (z[c + 1] * z[2] + z[1] * z[c + 2]);
                dz[c + 2] = 2.0 * z[0] * z[c] - 0.5 * z[c + 2];
            }
        };
        for tab in [&DOPRI5, &DOP853] {
            for nz in [3, 9] {
                let z: Vec<f64> = (0..nz).map(|i| 0.9 - 0.35 * i as f64).collect();
                let (t0, h) = (0.2, 0.45);
                fn fresh<R: Rhs>(tab: &'static Tableau, z: &[f64], (t0, h): (f64, f64), rhs: &mut R) -> Rk {
                    let mut rk = Rk::new(tab, z.len(), 3, z.len(), 1e-8, 1e-8);
                    rk.restart(t0, z, rhs);
                    rk.attempt(t0, z, h, rhs);
                    rk
                }
                let fresh = |rhs: &mut _| fresh(tab, &z, (t0, h), rhs);
                let mut whole = fresh(&mut rhs);
                whole.build_interpolant(t0, &z, &mut rhs);
                let mut states = fresh(&mut rhs);
                states.build_states_interpolant(t0, &z, &mut rhs);
                let mut some = fresh(&mut rhs);
                some.build_guard_interpolant(t0, &z, &mut rhs, &[1]);
                // The read state: its polynomial and its values, the whole build's.
                let (mut a, mut b) = ([0.0; CAP], [0.0; CAP]);
                let (la, lb) = (
                    some.interpolant().component_form(1, &mut a),
                    whole.interpolant().component_form(1, &mut b),
                );
                assert_eq!(
                    (la, a.map(f64::to_bits)),
                    (lb, b.map(f64::to_bits)),
                    "order {} nz {nz}",
                    tab.order
                );
                let (part, full) = (dense_bits(&some, 3), dense_bits(&whole, 3));
                for (k, (p, f)) in part.iter().zip(&full).enumerate() {
                    let (comp, deriv) = (k % 3, (k / 3) % 2 == 1);
                    if comp == 1 {
                        assert_eq!(p, f, "order {} nz {nz} value {k}", tab.order);
                    } else {
                        // Not built: the start value, at rest.
                        let want = if deriv { 0.0 } else { z[comp] };
                        assert_eq!(f64::from_bits(*p), want, "order {} nz {nz} value {k}", tab.order);
                    }
                }
                some.complete_states_interpolant(t0, &z);
                assert_eq!(dense_bits(&some, 3), dense_bits(&states, 3), "order {} nz {nz}", tab.order);
                some.complete_interpolant(t0, &z, &mut rhs);
                assert_eq!(dense_bits(&some, nz), dense_bits(&whole, nz), "order {} nz {nz}", tab.order);
            }
        }
    }

    #[test]
    fn dopri5_meets_tolerance() {
        let (err, steps) = integrate(&DOPRI5, 1e-8);
        assert!(err < 1e-7, "error {err}");
        assert!(steps < 200, "steps {steps}");
    }

    #[test]
    fn dop853_meets_tight_tolerance_in_few_steps() {
        let (err, steps) = integrate(&DOP853, 1e-12);
        assert!(err < 1e-11, "error {err}");
        // An 8th-order method needs few steps here; a wrong coefficient would either miss the
        // accuracy or blow the step count up.
        assert!(steps < 60, "steps {steps}");
    }
}
