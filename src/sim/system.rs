//! What the integrator needs from a model: its shape ([`SystemInfo`]) and its functions
//! ([`HybridSystem`]). `sim` depends only on this trait, not on Cranelift, so integrator tests can
//! implement it with plain closures.
//!
//! Array layouts (n = states, m = differentiated parameters, k = outputs):
//! - state-like vectors `x`, `dx`, `r`: length n.
//! - sensitivities and every `_p` array are column-per-parameter: `s[j * n + i] = dx_i/dp_j`
//!   (length n * m; for outputs `yp[j * k + i]`, length k * m; for guards `gp[j]`, length m).
//! - `_x` Jacobians are row-major: `rx[i * n + c] = dR_i/dx_c` (n * n; outputs k * n).
//!
//! Implementations may assume the lengths above; callers must guarantee them (the JIT-backed
//! implementation checks them before entering native code).

use std::sync::Arc;

use crate::interval::{Dual, Interval};

/// Relative step of the default central differences (`HybridSystem::flow_jac`): the cube root
/// of the machine epsilon balances truncation (h^2) against round-off (eps / h).
const FD_STEP: f64 = 6.0554544523933395e-6;

/// Crossing direction of a guard `g`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Direction {
    /// From positive to non-positive.
    Falling,
    /// From negative to non-negative.
    Rising,
    /// Either way.
    Either,
}

/// A mode, as the integrator sees it.
#[derive(Clone, Debug, PartialEq)]
pub struct ModeInfo {
    /// Its name.
    pub name: String,
    /// Events that can fire in this mode, ascending (declaration order = firing order).
    pub events: Vec<usize>,
}

/// An event, as the integrator sees it.
#[derive(Clone, Debug, PartialEq)]
pub struct EventInfo {
    /// Shared, so that every fired event's record names it without an allocation.
    pub name: Arc<str>,
    /// Which way its guard must cross zero.
    pub direction: Direction,
    /// Mode after the event; `None` keeps the current one.
    pub target_mode: Option<usize>,
    /// Whether the run stops after it.
    pub is_stop: bool,
    /// Whether an enabling condition is judged before it fires.
    pub has_condition: bool,
    /// A flow switch (`sema::switches`): where the mode's flow jumps. Located like an event; at
    /// it the state is kept, the sensitivities jump by `(f- - f+) dt/dp` with the flow evaluated
    /// on each side, and nothing is recorded as an event.
    pub implicit: bool,
    /// A flow switch where the flow is continuous (a `min`, `max` or `abs` kink): steps land on it
    /// as on any switch, and nothing jumps there, the sensitivities included (docs/language.md,
    /// "Expressions"), so no crossing of it voids a gradient.
    pub kink: bool,
    /// How the guard depends on time and the state, which decides how its crossings are searched.
    pub guard: GuardShape,
    /// Whether the reset acts on the guard's motion: it assigns a state that the guard or its
    /// speed `g_x f + g_t` reads (a bounce, a stop). Such an event that leaves the state on its
    /// guard with the flow carrying it through again is stuck, not a fresh crossing.
    pub contact: bool,
}

/// The knots of an input (`pwl`, `pwc`) a mode's flows read: times known when a run starts (the
/// first floating-point times where the knot position `HybridSystem::knot_position`, affine in
/// `t`, has reached each knot), which the integrator keeps as a queue of breakpoints
/// (`sim/breakpoints.rs`): a step ends exactly on the next one, with the input read on its
/// earlier side at the step's end, and the next step starts on its later side.
#[derive(Clone, Debug, PartialEq)]
pub struct KnotSet {
    /// The input as messages name it: `pwc(t, .., u)`.
    pub name: Arc<str>,
    /// The mode whose flows read it.
    pub mode: usize,
    /// Whether the flow jumps at each knot (`pwc`: the sensitivities jump by `(f- - f+) dt_k/dp`
    /// where a knot moves with a parameter); otherwise it only kinks (`pwl`) and nothing jumps.
    pub jumps: bool,
    /// The knots' numbers: knot `k` is where the position is `k`.
    pub knots: std::ops::Range<u32>,
}

/// The shape of a guard along a trajectory, from its symbolic derivatives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum GuardShape {
    /// Anything else: enclosed over pieces of every step by interval code
    /// (`HybridSystem::guard_enclosure`; see `docs/language.md`, when events fire).
    Nonlinear,
    /// `g_x` and `g_t` are constants: along a step's dense output the guard is a polynomial,
    /// bounded piece by piece by its Bernstein coefficients.
    Affine,
    /// `g = c t + d(p)`: a time event, landed on exactly as a breakpoint.
    Time,
}

/// The static shape of a compiled hybrid model.
#[derive(Clone, Debug, PartialEq)]
pub struct SystemInfo {
    /// State names, in order.
    pub state_names: Vec<String>,
    /// Output names, in order.
    pub output_names: Vec<String>,
    /// Names of all parameters, in declaration order (the `p` slices have this length).
    pub param_names: Vec<String>,
    /// Indices into `param_names` of the differentiated parameters, in sensitivity column order.
    pub grad_params: Vec<usize>,
    /// The modes, in order.
    pub modes: Vec<ModeInfo>,
    /// The events, declared ones first, then the implicit ones.
    pub events: Vec<EventInfo>,
    /// The modes' input knots ([`HybridSystem::knot_position`] takes an index into this).
    pub knots: Vec<KnotSet>,
    /// The mode the run starts in.
    pub initial_mode: usize,
    /// `quadrature[i]`: state `i` is a running cost that no flow, guard, condition or other
    /// state's reset reads (`sema::quadrature_states`); such states stay out of the step-size
    /// error test, as CVODES' quadratures do by default. Empty: none.
    pub quadrature: Vec<bool>,
}

impl SystemInfo {
    /// How many states.
    pub fn n_states(&self) -> usize {
        self.state_names.len()
    }
    /// How many outputs.
    pub fn n_outputs(&self) -> usize {
        self.output_names.len()
    }
    /// How many parameters.
    pub fn n_params(&self) -> usize {
        self.param_names.len()
    }
    /// Number of differentiated parameters (sensitivity columns).
    pub fn n_grad(&self) -> usize {
        self.grad_params.len()
    }
}

/// The functions of a hybrid model. `p` always holds all parameters (length `n_params`);
/// derivatives `_p` are taken only with respect to `grad_params`.
pub trait HybridSystem: Sync {
    /// The system's shape: names, modes, events, gradient parameters.
    fn info(&self) -> &SystemInfo;

    /// Initial state `x0(p)`.
    fn initial_state(&self, p: &[f64], x0: &mut [f64]);
    /// Initial sensitivities `dx0/dp` (n * m).
    fn initial_sens(&self, p: &[f64], s0: &mut [f64]);

    /// Flow of `mode`: `dx = f(t, x, p)`.
    fn flow(&self, mode: usize, t: f64, x: &[f64], p: &[f64], dx: &mut [f64]);
    /// Flow and sensitivity right-hand side in one call: `dx = f`, `ds = f_x s + f_p`.
    // The argument list mirrors the native kernel's ABI; a struct would only add a copy.
    #[allow(clippy::too_many_arguments)]
    fn flow_sens(&self, mode: usize, t: f64, x: &[f64], s: &[f64], p: &[f64], dx: &mut [f64], ds: &mut [f64]);
    /// The flow's vector-Jacobian products at `(t, x)` in `mode`: `gx = f_x^T w` (n) and
    /// `gp = f_p^T w` (m, one entry per differentiated parameter, `grad_params` order), both
    /// overwritten: what the adjoint's backward pass needs at every stage. A compiled model has a
    /// kernel, compiled on the first call, that sums each entry over the structurally nonzero
    /// entries of its column of `f_x` or `f_p`, never forming `f_x`, except for a vector the flow
    /// reads only through `pwl`/`pwc`: the kernel returns each lookup's cotangent and position and
    /// the host adds it into the (at most two) elements read there, so the call's work does not
    /// grow with the knots (`gp` is still overwritten whole); a zero `w_i` annihilates an entry that is infinite or NaN
    /// at a finite state, as a zero sensitivity does in [`Self::flow_sens`] (the default skips the
    /// rows whose `w_i` is zero).
    ///
    /// The default, for hand-written systems in tests, reads the Jacobians off
    /// [`Self::flow_sens`] with `n + 1` calls: `f_p` with `s = 0` (then column `j` of `ds` is
    /// `f_p_j`), and column `c` of `f_x` with every sensitivity column set to the unit vector
    /// `e_c` (then `ds_j - f_p_j = f_x e_c`). That is exact but for the rounding of the sum
    /// `f_x e_c + f_p_j` and its difference; each row takes the column `j` whose `|f_p_j|` is the
    /// smallest (exact where some parameter does not enter the row), so an entry of `f_x` is off
    /// by at most `eps (|f_x| + min_j |f_p_j|)`. With no differentiated parameter (`m = 0`) the
    /// sensitivities carry nothing to read `f_x` from: the default then takes `f_x` from
    /// [`Self::flow_jac`] (after [`Self::prepare_jacobians`]; NaN if that fails), which is
    /// whatever the system gives there: exact if it writes its Jacobian, central differences
    /// (about 1e-10 relative) under the default `flow_jac`.
    #[allow(clippy::too_many_arguments)]
    fn flow_vjp(&self, mode: usize, t: f64, x: &[f64], w: &[f64], p: &[f64], gx: &mut [f64], gp: &mut [f64]) {
        let n = x.len();
        let m = self.info().n_grad();
        let mut fx = vec![0.0; n * n];
        if m == 0 {
            if self.prepare_jacobians().is_err() {
                gx.fill(f64::NAN);
                gp.fill(f64::NAN);
                return;
            }
            let mut ft = vec![0.0; n];
            self.flow_jac(mode, t, x, &[], p, &mut fx, &mut ft, &mut []);
        } else {
            let mut dx = vec![0.0; n];
            let mut fp = vec![0.0; n * m];
            self.flow_sens(mode, t, x, &vec![0.0; n * m], p, &mut dx, &mut fp);
            for (j, g) in gp.iter_mut().enumerate() {
                *g = (0..n).filter(|&i| w[i] != 0.0).map(|i| w[i] * fp[j * n + i]).sum();
            }
            // The column each row reads `f_x` from: the one with the smallest `|f_p_j|`.
            let best: Vec<usize> = (0..n)
                .map(|i| {
                    (0..m).min_by(|&a, &b| fp[a * n + i].abs().total_cmp(&fp[b * n + i].abs())).unwrap_or(0)
                })
                .collect();
            let mut s = vec![0.0; n * m];
            let mut ds = vec![0.0; n * m];
            for c in 0..n {
                for j in 0..m {
                    s[j * n + c] = 1.0;
                }
                self.flow_sens(mode, t, x, &s, p, &mut dx, &mut ds);
                for (i, &j) in best.iter().enumerate() {
                    fx[i * n + c] = ds[j * n + i] - fp[j * n + i];
                }
                for j in 0..m {
                    s[j * n + c] = 0.0;
                }
            }
        }
        for (c, g) in gx.iter_mut().enumerate() {
            *g = (0..n).filter(|&i| w[i] != 0.0).map(|i| w[i] * fx[i * n + c]).sum();
        }
    }
    /// Makes [`Self::flow_sens`] ready (a compiled model with many states and differentiated
    /// parameters compiles its kernels here, once, rather than with the model); called before a
    /// run that carries forward sensitivities (never before the adjoint's). An error says why
    /// they cannot be had. The default needs
    /// nothing.
    fn prepare_sensitivities(&self) -> Result<(), String> {
        Ok(())
    }
    /// Makes [`Self::flow_jac`] and [`Self::sens_dir`] ready (a compiled model compiles their
    /// kernels here, once); called before a run with an implicit method. An error says why
    /// they cannot be had. The default (the central differences below) needs nothing.
    fn prepare_jacobians(&self) -> Result<(), String> {
        Ok(())
    }
    /// The flow's Jacobian `fx = f_x` (n * n, row-major) and `ft = f_t` (n) at `(t, x)`, and the
    /// time derivative of the sensitivity right-hand side, `st = f_xt s + f_pt` (n * m), at
    /// `(t, x, s)`: what a Rosenbrock stepper needs of the flow with its sensitivities.
    ///
    /// A compiled model evaluates symbolic derivatives. The default takes central differences
    /// of [`Self::flow_sens`] (steps `cbrt(eps) max(|u|, 1)`, about 1e-10 relative error): it is
    /// for hand-written systems in tests, never the path of a compiled model.
    #[allow(clippy::too_many_arguments)]
    fn flow_jac(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        s: &[f64],
        p: &[f64],
        fx: &mut [f64],
        ft: &mut [f64],
        st: &mut [f64],
    ) {
        let n = x.len();
        let (mut xp, mut xm) = (x.to_vec(), x.to_vec());
        let (mut fp, mut fm) = (vec![0.0; n], vec![0.0; n]);
        let (mut sp, mut sm) = (vec![0.0; s.len()], vec![0.0; s.len()]);
        for c in 0..n {
            let h = FD_STEP * x[c].abs().max(1.0);
            xp[c] = x[c] + h;
            xm[c] = x[c] - h;
            self.flow(mode, t, &xp, p, &mut fp);
            self.flow(mode, t, &xm, p, &mut fm);
            for i in 0..n {
                fx[i * n + c] = (fp[i] - fm[i]) / (xp[c] - xm[c]);
            }
            xp[c] = x[c];
            xm[c] = x[c];
        }
        let h = FD_STEP * t.abs().max(1.0);
        let (tp, tm) = (t + h, t - h);
        self.flow_sens(mode, tp, x, s, p, &mut fp, &mut sp);
        self.flow_sens(mode, tm, x, s, p, &mut fm, &mut sm);
        for (out, (a, b)) in ft.iter_mut().zip(fp.iter().zip(&fm)) {
            *out = (a - b) / (tp - tm);
        }
        for (out, (a, b)) in st.iter_mut().zip(sp.iter().zip(&sm)) {
            *out = (a - b) / (tp - tm);
        }
    }
    /// The structurally nonzero entries of `f_x` in `mode`, `(row, column)`: the entries
    /// [`Self::flow_jac_values`] writes, in its order. A compiled model knows them from its
    /// symbolic Jacobian (after [`Self::prepare_jacobians`]); `None` (the default) leaves a
    /// Rosenbrock stepper with the dense `flow_jac`.
    fn jac_pattern(&self, mode: usize) -> Option<&[(u32, u32)]> {
        let _ = mode;
        None
    }
    /// As [`Self::flow_jac`], with `f_x` as the values of [`Self::jac_pattern`]'s entries
    /// (`vals`, in its order) instead of an `n x n` matrix. The default gathers them from
    /// `flow_jac`; a compiled model's kernel computes only them.
    #[allow(clippy::too_many_arguments)]
    fn flow_jac_values(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        s: &[f64],
        p: &[f64],
        vals: &mut [f64],
        ft: &mut [f64],
        st: &mut [f64],
    ) {
        let n = x.len();
        let mut fx = vec![0.0; n * n];
        self.flow_jac(mode, t, x, s, p, &mut fx, ft, st);
        for (v, &(r, c)) in vals.iter_mut().zip(self.jac_pattern(mode).unwrap_or(&[])) {
            *v = fx[r as usize * n + c as usize];
        }
    }
    /// The derivative of the sensitivity right-hand side along a direction `v` of the state,
    /// `dir = (d/dx (f_x s_j + f_p_j)) v = f_xx[s_j, v] + f_xp_j v` (n * m, column per parameter),
    /// at `(t, x, s)`, with `xv = [x, v]` (2n): the coupling block of the Jacobian of the flow
    /// with its sensitivities. The default takes a central difference of [`Self::flow_sens`]
    /// along `v` (for hand-written systems in tests, as [`Self::flow_jac`]).
    #[allow(clippy::too_many_arguments)]
    fn sens_dir(&self, mode: usize, t: f64, xv: &[f64], s: &[f64], p: &[f64], dir: &mut [f64]) {
        let n = xv.len() / 2;
        let (x, v) = xv.split_at(n);
        let vmax = v.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        if vmax == 0.0 {
            dir.fill(0.0);
            return;
        }
        let xmax = x.iter().fold(1.0f64, |a, b| a.max(b.abs()));
        let h = FD_STEP * xmax / vmax;
        let xp: Vec<f64> = x.iter().zip(v).map(|(x, v)| x + h * v).collect();
        let xm: Vec<f64> = x.iter().zip(v).map(|(x, v)| x - h * v).collect();
        let mut f = vec![0.0; n];
        let (mut sp, mut sm) = (vec![0.0; s.len()], vec![0.0; s.len()]);
        self.flow_sens(mode, t, &xp, s, p, &mut f, &mut sp);
        self.flow_sens(mode, t, &xm, s, p, &mut f, &mut sm);
        for (out, (a, b)) in dir.iter_mut().zip(sp.iter().zip(&sm)) {
            *out = (a - b) / (2.0 * h);
        }
    }
    /// As [`Self::flow_vjp`], with the parameters' part added into `pbar` (m) rather than
    /// written: the adjoint's backward pass at every stage. A compiled model touches only the
    /// columns its kernel sums and the elements a control's lookups read there, so the call does
    /// not cost `m` (a control of 10,000 knots); the default adds `flow_vjp`'s `gp`.
    #[allow(clippy::too_many_arguments)]
    fn flow_vjp_add(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        w: &[f64],
        p: &[f64],
        gx: &mut [f64],
        pbar: &mut [f64],
    ) {
        let mut gp = vec![0.0; pbar.len()];
        self.flow_vjp(mode, t, x, w, p, gx, &mut gp);
        for (a, b) in pbar.iter_mut().zip(&gp) {
            *a += b;
        }
    }
    /// The transposes of a Rosenbrock step's second-order terms (the adjoint's backward pass
    /// through a stage, docs/design.md "The adjoint"): with `phi = w^T (f_x v + a f_t)` at
    /// `(t, x)` in `mode`, adds `d phi/dx = (w^T f_xx) v + a f_tx^T w` into `xbar` (n) and
    /// `d phi/dp = (w^T f_xp) v + a f_tp^T w` into `pbar` (m, `grad_params` order), never
    /// forming `f_xx`. It is the transpose of [`Self::sens_dir`] (and of `flow_jac`'s `st`):
    /// `w . sens_dir(v)_j = (w^T f_xx)[v, s_j] + (w^T f_xp_j) v`.
    ///
    /// A compiled model has a kernel per mode, compiled on the first call from the symbolic
    /// second derivatives (`expr::flow_vjp_dir_terms`); the interpreter evaluates the same
    /// expressions. The default, for hand-written systems in tests, takes a central difference
    /// of [`Self::flow_vjp`] along `(v, a)` in `(x, t)` (about 1e-10 relative).
    #[allow(clippy::too_many_arguments)]
    fn flow_vjp_dir(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        v: &[f64],
        a: f64,
        w: &[f64],
        p: &[f64],
        xbar: &mut [f64],
        pbar: &mut [f64],
    ) {
        let n = x.len();
        let vmax = v.iter().fold(a.abs(), |m, b| m.max(b.abs()));
        if vmax == 0.0 || w.iter().all(|&c| c == 0.0) {
            return;
        }
        let xmax = x.iter().fold(t.abs().max(1.0), |m, b| m.max(b.abs()));
        let h = FD_STEP * xmax / vmax;
        let xp: Vec<f64> = x.iter().zip(v).map(|(x, v)| x + h * v).collect();
        let xm: Vec<f64> = x.iter().zip(v).map(|(x, v)| x - h * v).collect();
        let (mut gxp, mut gxm) = (vec![0.0; n], vec![0.0; n]);
        let (mut gpp, mut gpm) = (vec![0.0; pbar.len()], vec![0.0; pbar.len()]);
        self.flow_vjp(mode, t + h * a, &xp, w, p, &mut gxp, &mut gpp);
        self.flow_vjp(mode, t - h * a, &xm, w, p, &mut gxm, &mut gpm);
        for (o, (a, b)) in xbar.iter_mut().zip(gxp.iter().zip(&gxm)) {
            *o += (a - b) / (2.0 * h);
        }
        for (o, (a, b)) in pbar.iter_mut().zip(gpp.iter().zip(&gpm)) {
            *o += (a - b) / (2.0 * h);
        }
    }
    /// Guards of every event active in `mode`, in the order of `ModeInfo::events`.
    fn guards(&self, mode: usize, t: f64, x: &[f64], p: &[f64], g: &mut [f64]);
    /// Speeds `g_x f + g_t` of every guard active in `mode` (order of `ModeInfo::events`) along a
    /// flow `f` (n) at `(t, x)`. The default evaluates `guard_grad` event by event; a compiled
    /// model has one kernel for the whole mode.
    #[allow(clippy::too_many_arguments)]
    fn guard_speeds(&self, mode: usize, t: f64, x: &[f64], f: &[f64], p: &[f64], dg: &mut [f64]) {
        let info = self.info();
        let mut gx = vec![0.0; info.n_states()];
        let mut gp = vec![0.0; info.n_grad()];
        for (slot, &ev) in dg.iter_mut().zip(&info.modes[mode].events) {
            let gt = self.guard_grad(ev, t, x, p, &mut gx, &mut gp);
            *slot = gx.iter().zip(f).map(|(a, b)| a * b).sum::<f64>() + gt;
        }
    }
    /// Partial derivatives of one guard: `gx` (n), `gp` (m), returns `g_t`.
    fn guard_grad(&self, event: usize, t: f64, x: &[f64], p: &[f64], gx: &mut [f64], gp: &mut [f64]) -> f64;
    /// Enclosures of event `event`'s guard and of its time derivative along a trajectory:
    /// `g(t, x, p)` in `.v` and `g_x x' + g_t` in `.d` for every time in `t` and states in `x`
    /// moving at rates in `dx` (one interval per state; only [`Self::guard_states`] are read),
    /// with `scratch` for intermediate values. Event detection proves with them where a guard
    /// cannot change sign (`event::enclose`). The default knows nothing (`ENTIRE`): detection is
    /// then left to bisection and point values, correct but slow, fit only for hand-written
    /// systems with affine guards, which never ask. A compiled model evaluates interval code made
    /// from the guard's expression (`expr::Enclosure`).
    fn guard_enclosure(
        &self,
        event: usize,
        t: Interval,
        x: &[Interval],
        dx: &[Interval],
        p: &[f64],
        scratch: &mut Vec<Dual>,
    ) -> Dual {
        let _ = (event, t, x, dx, p, scratch);
        Dual { v: Interval::ENTIRE, d: Interval::ENTIRE }
    }
    /// The states event `event`'s guard reads, ascending; `None` (the default): unknown, all.
    fn guard_states(&self, event: usize) -> Option<&[u32]> {
        let _ = event;
        None
    }
    /// The knot position of knot set `set` (`SystemInfo::knots`) at `t`: affine in `t`, knot `k`
    /// where it is `k`, computed as the input's value computes it (so both agree on the side of
    /// every knot). The default, for a system without knots, is NaN.
    fn knot_position(&self, set: usize, t: f64, p: &[f64]) -> f64 {
        let _ = (set, t, p);
        f64::NAN
    }
    /// The knot position's derivatives: `sp` (m) with respect to the gradient parameters; returns
    /// its rate `s_t`. The default, for a system without knots, is NaN.
    fn knot_position_grad(&self, set: usize, t: f64, p: &[f64], sp: &mut [f64]) -> f64 {
        let _ = (set, t, p);
        sp.fill(f64::NAN);
        f64::NAN
    }
    /// Whether the enabling condition holds (true for events without one).
    fn condition(&self, event: usize, t: f64, x: &[f64], p: &[f64]) -> bool;

    /// Reset map: the post-event state `r = R(t, x, p)`.
    fn reset(&self, event: usize, t: f64, x: &[f64], p: &[f64], r: &mut [f64]);
    /// Reset Jacobians `rx` (n * n, row-major), `rp` (n * m), `rt` (n).
    #[allow(clippy::too_many_arguments)]
    fn reset_jac(
        &self,
        event: usize,
        t: f64,
        x: &[f64],
        p: &[f64],
        rx: &mut [f64],
        rp: &mut [f64],
        rt: &mut [f64],
    );

    /// The structurally nonzero entries `(row, column)` of event `event`'s `R_x`, in the order
    /// [`Self::reset_jac_values`] writes their values; `None` (the default): only the dense
    /// [`Self::reset_jac`]. A large model's reset touches few states: its saltation then costs
    /// time and memory in these entries, not `n^2`.
    fn reset_jac_pattern(&self, event: usize) -> Option<&[(u32, u32)]> {
        let _ = event;
        None
    }

    /// [`Self::reset_jac`] with `rx` the values of [`Self::reset_jac_pattern`]'s entries. Called
    /// only when it gives a pattern.
    #[allow(clippy::too_many_arguments)]
    fn reset_jac_values(
        &self,
        event: usize,
        t: f64,
        x: &[f64],
        p: &[f64],
        rx: &mut [f64],
        rp: &mut [f64],
        rt: &mut [f64],
    ) {
        let _ = (event, t, x, p, rx, rp, rt);
        unreachable!("reset_jac_values without a reset_jac_pattern");
    }

    /// Outputs `y = h(t, x, p)`.
    fn outputs(&self, t: f64, x: &[f64], p: &[f64], y: &mut [f64]);
    /// Output Jacobians `yx` (k * n, row-major), `yp` (k * m), `yt` (k).
    fn output_jac(&self, t: f64, x: &[f64], p: &[f64], yx: &mut [f64], yp: &mut [f64], yt: &mut [f64]);
}
