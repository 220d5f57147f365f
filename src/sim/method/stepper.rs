//! Stage 5 (sim): the seam between the integrator and a time-stepping method. A [`Stepper`]
//! attempts steps under its own error control, gives the dense interpolant of its last attempt and
//! restarts after a jump; the integrator (`sim/integrator.rs`) owns the state `(t, z, mode)` and does
//! everything hybrid: event detection, location, resets, saltation, Zeno, recording. So a new
//! method (an implicit Rosenbrock method for stiff models, say) implements this trait and nothing
//! of event handling changes.
//!
//! The integrated vector is `z = [x, S]`: the states and their sensitivities, column per
//! parameter. Which leading components enter the error norm is the stepper's construction
//! argument.

use super::poly::{chebyshev_node, Poly, CAP};

/// The right-hand side `dz = F(t, z)` a stepper integrates: the current mode's flow with its
/// sensitivity equations, `z = [x, S]` with `n` states. Any `FnMut(f64, &[f64], &mut [f64])` is
/// one.
///
/// An implicit (Rosenbrock) method also needs the Jacobian of `F`, which is block lower
/// triangular, `[[f_x, 0], [B, I (x) f_x]]` with `B v = d/dx (f_x s_j + f_p_j) v` per
/// sensitivity column: [`Self::jacobian`] gives `f_x` and `F_t`, [`Self::sens_coupling`] the
/// product `B v`. Explicit methods never call them. The integrator's right-hand side takes them
/// from the model (`HybridSystem::flow_jac`, `sens_dir`: symbolic derivatives for a compiled
/// model); the provided defaults take central differences of [`Self::eval`], for closures in
/// tests.
pub trait Rhs {
    /// The right-hand side `dz = F(t, z)`: the flow and, for the sensitivity columns, their rates.
    fn eval(&mut self, t: f64, z: &[f64], dz: &mut [f64]);

    /// The state block's Jacobian `fx = f_x` (n * n, row-major; `n` from its length) and the
    /// time derivative `ft = F_t` of the whole right-hand side (`z.len()`), at `(t, z)`.
    fn jacobian(&mut self, t: f64, z: &[f64], fx: &mut [f64], ft: &mut [f64]) {
        let nz = z.len();
        let n = (fx.len() as f64).sqrt().round() as usize;
        let (mut zp, mut zm) = (z.to_vec(), z.to_vec());
        let (mut fp, mut fm) = (vec![0.0; nz], vec![0.0; nz]);
        for c in 0..n {
            let h = FD_STEP * z[c].abs().max(1.0);
            zp[c] = z[c] + h;
            zm[c] = z[c] - h;
            self.eval(t, &zp, &mut fp);
            self.eval(t, &zm, &mut fm);
            for i in 0..n {
                fx[i * n + c] = (fp[i] - fm[i]) / (zp[c] - zm[c]);
            }
            zp[c] = z[c];
            zm[c] = z[c];
        }
        let h = FD_STEP * t.abs().max(1.0);
        self.eval(t + h, z, &mut fp);
        self.eval(t - h, z, &mut fm);
        for (out, (a, b)) in ft.iter_mut().zip(fp.iter().zip(&fm)) {
            *out = (a - b) / ((t + h) - (t - h));
        }
    }

    /// The structurally nonzero entries of `f_x`, `(row, column)`, in the order
    /// [`Self::jacobian_values`] writes their values, with a key naming the structure (the
    /// mode): what a sparse factorisation analyses once per key. `None` (the default): only the
    /// dense [`Self::jacobian`].
    fn jac_pattern(&self) -> Option<(usize, &[(u32, u32)])> {
        None
    }

    /// `f_x`'s values in the order of [`Self::jac_pattern`] and `ft = F_t` (`z.len()`), at
    /// `(t, z)`. Called only when [`Self::jac_pattern`] gives a pattern.
    fn jacobian_values(&mut self, t: f64, z: &[f64], vals: &mut [f64], ft: &mut [f64]) {
        let _ = (t, z, vals, ft);
        unreachable!("jacobian_values without a jac_pattern");
    }

    /// `out = B v` (n * m) at `(t, z)`, with `xv = [x, v]` (2n, `x` the state part of `z`): the
    /// derivative of the sensitivity right-hand side along the state direction `v`.
    fn sens_coupling(&mut self, t: f64, xv: &[f64], z: &[f64], out: &mut [f64]) {
        let n = xv.len() / 2;
        let nz = z.len();
        let v = &xv[n..];
        let vmax = v.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        if vmax == 0.0 {
            out.fill(0.0);
            return;
        }
        let h = FD_STEP * z[..n].iter().fold(1.0f64, |a, b| a.max(b.abs())) / vmax;
        let (mut zp, mut zm) = (z.to_vec(), z.to_vec());
        for i in 0..n {
            zp[i] = z[i] + h * v[i];
            zm[i] = z[i] - h * v[i];
        }
        let (mut fp, mut fm) = (vec![0.0; nz], vec![0.0; nz]);
        self.eval(t, &zp, &mut fp);
        self.eval(t, &zm, &mut fm);
        for (o, (a, b)) in out.iter_mut().zip(fp[n..].iter().zip(&fm[n..])) {
            *o = (a - b) / (2.0 * h);
        }
    }

    /// The flow alone: `dz[..n] = f(t, z[..n])` for the `n` states (`n` the system's). The
    /// default evaluates the whole right-hand side (what it writes past the states is not
    /// read); a system with a kernel of the flow alone spares the sensitivities' part.
    fn eval_states(&mut self, t: f64, z: &[f64], dz: &mut [f64]) {
        self.eval(t, z, dz)
    }

    /// Makes [`Self::jacobian`] and [`Self::sens_coupling`] ready; `false` when they cannot be
    /// had. A stepper that switches to an implicit method mid-run (`auto::Auto`) calls it first:
    /// the compiled model then compiles its Jacobian kernels on the first switch, not before.
    fn prepare(&mut self) -> bool {
        true
    }
}

/// Relative step of the default central differences: the cube root of the machine epsilon.
const FD_STEP: f64 = 6.0554544523933395e-6;

impl<F: FnMut(f64, &[f64], &mut [f64])> Rhs for F {
    #[inline(always)]
    fn eval(&mut self, t: f64, z: &[f64], dz: &mut [f64]) {
        self(t, z, dz)
    }
}

/// The dense output of one step `[t0, t0 + h]`: values and time derivatives of every component.
pub trait Interpolant {
    /// The step's start.
    fn t0(&self) -> f64;
    /// The step's length.
    fn h(&self) -> f64;
    /// Values of the first `out.len()` components at `t`.
    fn eval(&self, t: f64, out: &mut [f64]);
    /// Time derivatives of the first `out.len()` components at `t`.
    fn eval_deriv(&self, t: f64, out: &mut [f64]);
    /// The degree of the interpolating polynomial in time (an affine guard along it is a
    /// polynomial of that degree, known exactly from that many samples plus one).
    fn degree(&self) -> usize;
    /// The power-basis coefficients, in `s = (t - t0) / h`, of `sum_i w_i (P_i(s) - P_i(0))` over
    /// the first `w.len()` components (an affine guard's motion along the step), written to
    /// `coef[..k]`; returns `k`, the degree plus one (at most `poly::CAP`). The default
    /// interpolates the dense output at `k` Chebyshev points; a method whose interpolant has
    /// coefficients of its own converts them exactly and without evaluating it.
    fn linear_form(&self, w: &[f64], coef: &mut [f64; CAP]) -> usize {
        let count = (self.degree() + 1).min(CAP);
        let (t0, h) = (self.t0(), self.h());
        let mut at = vec![0.0; w.len()];
        self.eval(t0, &mut at);
        let base: f64 = w.iter().zip(&at).map(|(a, b)| a * b).sum();
        let (mut nodes, mut values) = ([0.0; CAP], [0.0; CAP]);
        for k in 0..count {
            nodes[k] = chebyshev_node(k, count);
            self.eval(t0 + nodes[k] * h, &mut at);
            values[k] = w.iter().zip(&at).map(|(a, b)| a * b).sum::<f64>() - base;
        }
        Poly::through(&nodes[..count], &values[..count]).write_to(coef)
    }
    /// A bound `[lo, hi]` of `sum_k w_k (P_k(s) - P_k(0)) + slope s` over all of `s` in `[0, 1]`
    /// for the gradient entries `(k, w_k)`, widened by the rounding of its own computation and
    /// of the polynomial's: a cheaper, coarser [`Self::linear_form`] for a step far from every
    /// guard, which then needs neither the power basis nor its Bernstein pieces. `None` when
    /// the method has no such bound (the detector then walks the polynomial).
    fn affine_motion_hull(&self, _entries: &[(u32, f64)], _slope: f64) -> Option<(f64, f64)> {
        None
    }
    /// [`Self::linear_form`] of the single component `i` (`P_i(s) - P_i(0)`), `i` below the
    /// number of components: what the event detector bounds a nonlinear guard's states with.
    /// The default calls `linear_form` with a unit vector; a method with coefficients of its own
    /// reads component `i`'s alone.
    fn component_form(&self, i: usize, coef: &mut [f64; CAP]) -> usize {
        let mut w = vec![0.0; i + 1];
        w[i] = 1.0;
        self.linear_form(&w, coef)
    }
}

/// The method of a step, as the adjoint tape (`sim/recorder.rs`, `TapeEntry`) names it: an
/// explicit pair or a Rosenbrock method.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TapePair {
    /// Dormand-Prince 5(4).
    Dopri5,
    /// DOP853.
    Dop853,
    /// The Rosenbrock method Rodas5P.
    Rodas5p,
    /// The Rosenbrock method Rodas4.
    Rodas4,
}

/// A time-stepping method with error control and dense output.
///
/// The protocol, as the integrator drives it: `restart` at the start and after every jump, then
/// `initial_step`; then repeatedly `attempt`, followed by `shrink` (rejected) or `grow` and, once
/// the integrator has looked at the end point and possibly `build_interpolant`, either `accept`
/// (the step stands) or `restart` at a point inside it (an event cut it short).
pub trait Stepper {
    /// The dense output of the stepper's last attempt.
    type Interpolant: Interpolant;

    /// Forgets an earlier run entirely (statistics included).
    fn reset(&mut self);
    /// A new start point `(t, z)`: evaluates what the method keeps of it (the derivative there)
    /// and forgets the step-size controller's memory, which was learnt before a jump.
    fn restart<R: Rhs>(&mut self, t: f64, z: &[f64], rhs: &mut R);
    /// The derivative `F(t, z)` at the current start point.
    fn start_derivative(&self) -> &[f64];
    /// A first step size from the current start point `(t, z)`, at most `h_max`.
    fn initial_step<R: Rhs>(&mut self, t: f64, z: &[f64], h_max: f64, rhs: &mut R) -> f64;
    /// Attempts a step of size `h` from `(t, z)` (`z` is the start point given to `restart` or
    /// the last `accept`). Returns the scaled error: `<= 1` accepts; infinite when anything was
    /// not finite.
    fn attempt<R: Rhs>(&mut self, t: f64, z: &[f64], h: f64, rhs: &mut R) -> f64;
    /// Retakes the last attempt from its start `(t, z)` with the shorter length `h`, to land a
    /// step on an event located at `t + h` on its dense output: the end state, its derivative and
    /// [`Self::masked`] become this step's, under the same error control (the error is returned
    /// as by [`Self::attempt`]), while [`Self::interpolant`] stays the last attempt's, which the
    /// event was located on. Nothing of the controller changes: a restart follows.
    fn land<R: Rhs>(&mut self, t: f64, z: &[f64], h: f64, rhs: &mut R) -> f64;
    /// Whether the event instants inside the last attempt (from `z`) are landed on
    /// ([`Self::land`]) unless the options say (`SimOptions::land_events`): where the dense
    /// output is less accurate than a step end, a method whose dense output is of lower order
    /// than its steps, or a step held by stability.
    fn lands_on_events(&mut self, z: &[f64]) -> bool;
    /// The end state of the last attempt.
    fn end_state(&self) -> &[f64];
    /// The derivative at the end state of the last attempt.
    fn end_derivative(&self) -> &[f64];
    /// After an accepted attempt with error `err`: the next step size; updates the controller.
    fn grow(&mut self, err: f64) -> f64;
    /// After a rejected attempt with error `err`: a smaller step size.
    fn shrink(&self, err: f64) -> f64;
    /// Builds the dense output of the last attempt, which started at `(t0, z)`.
    fn build_interpolant<R: Rhs>(&mut self, t0: f64, z: &[f64], rhs: &mut R);
    /// Builds the dense output of the last attempt for the states alone, what the event
    /// detector reads: [`Self::complete_interpolant`] adds the sensitivities' part before
    /// anything reads it (an evaluation of more components panics until then). By default the
    /// whole of it.
    fn build_states_interpolant<R: Rhs>(&mut self, t0: f64, z: &[f64], rhs: &mut R) {
        self.build_interpolant(t0, z, rhs)
    }
    /// [`Self::build_states_interpolant`] with the polynomials of the states `states` alone
    /// (ascending): what the walk over guards that read only those states needs. The other
    /// states read as their values at the step's start until
    /// [`Self::complete_states_interpolant`] (or [`Self::complete_interpolant`]) builds them, to
    /// the bit what a whole build gives; nothing but a guard that does not read them may read
    /// them before. By default the states' whole dense output.
    fn build_guard_interpolant<R: Rhs>(&mut self, t0: f64, z: &[f64], rhs: &mut R, states: &[u32]) {
        let _ = states;
        self.build_states_interpolant(t0, z, rhs)
    }
    /// Builds the states' polynomials [`Self::build_guard_interpolant`] left out, from the same
    /// attempt's stages (nothing when they are built).
    fn complete_states_interpolant(&mut self, _t0: f64, _z: &[f64]) {}
    /// Completes a dense output [`Self::build_states_interpolant`] built for the states alone,
    /// from the same attempt's stages (nothing when it is whole).
    fn complete_interpolant<R: Rhs>(&mut self, _t0: f64, _z: &[f64], _rhs: &mut R) {}
    /// The dense output built last.
    fn interpolant(&self) -> &Self::Interpolant;
    /// Moves to the end of the last attempt: writes its end state into `z`.
    fn accept(&mut self, z: &mut [f64]);
    /// Right-hand side evaluations since the last `reset`.
    fn rhs_calls(&self) -> usize;
    /// Whether the last attempt found sensitivities that are not finite at its finite end state
    /// (and judged its error without them): derivatives that do not exist from there on.
    fn masked(&self) -> bool;
    /// The last attempt's largest scaled error among the states left out of its error test (the
    /// running costs), and that state's index: above 1, the step would have failed the test
    /// with them in it. `(0, 0)` when none is left out.
    fn outside_error(&self) -> (f64, usize);
    /// Calls `visit` with the position in the step (`c_i`, in `[0, 1]`) and the state (the first
    /// `n` components) of every stage of the last attempt at which the flow was evaluated, the
    /// start point excluded (its state is the step's start), in stage order; with the stages of
    /// its dense output when built. The integrator checks with them that no stage evaluated a
    /// flow switch's other branch (docs/language.md, rule 2). The default visits none.
    fn visit_stage_states<V: FnMut(f64, &[f64])>(&self, visit: V) {
        let _ = visit;
    }
    /// Whether the attempts from now on keep their stages' states for
    /// [`Self::visit_stage_states`] (the integrator asks in modes with flow switches only; a
    /// method may then panic when asked for them after an attempt that did not keep them).
    fn keep_stage_states(&mut self, keep: bool) {
        let _ = keep;
    }
    /// The stretches of the run each method integrated, for a stepper that switches between
    /// methods (`auto::Auto`), up to the current point `t`; `None` for a single method.
    fn segments(&self, _t: f64) -> Option<Vec<crate::sim::result::MethodSegment>> {
        None
    }
    /// The method the last attempt was taken with, for the adjoint's tape; `None` for a method
    /// the backward pass does not recompute.
    fn tape_pair(&self) -> Option<TapePair> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two components, `x0 = t^3 - t` and `x1 = 2 t^2` on a step from `t0 = 1` of size `h = 0.5`,
    /// with nothing but values: the default `linear_form` samples it.
    struct Cubic;

    impl Interpolant for Cubic {
        fn t0(&self) -> f64 {
            1.0
        }
        fn h(&self) -> f64 {
            0.5
        }
        fn eval(&self, t: f64, out: &mut [f64]) {
            out[0] = t * t * t - t;
            out[1] = 2.0 * t * t;
        }
        fn eval_deriv(&self, t: f64, out: &mut [f64]) {
            out[0] = 3.0 * t * t - 1.0;
            out[1] = 4.0 * t;
        }
        fn degree(&self) -> usize {
            3
        }
    }

    #[test]
    fn the_default_linear_form_is_the_sampled_polynomial() {
        // With t = 1 + s / 2: x0 = s + 3 s^2 / 4 + s^3 / 8 and x1 = 2 + 2 s + s^2 / 2, so
        // 3 x0 - x1 less its value at s = 0 is s + 7 s^2 / 4 + 3 s^3 / 8.
        let mut coef = [0.0; CAP];
        let len = Cubic.linear_form(&[3.0, -1.0], &mut coef);
        assert_eq!(len, 4);
        for (got, want) in coef[..4].iter().zip([0.0, 1.0, 1.75, 0.375]) {
            assert!((got - want).abs() < 1e-13, "{coef:?}");
        }
    }
}
