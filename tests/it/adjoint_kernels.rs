//! The flow's vector-Jacobian products, `HybridSystem::flow_vjp` (`gx = f_x^T w`,
//! `gp = f_p^T w`), the adjoint's backward pass reads at every stage:
//!
//! - the compiled kernel `mode{k}_flow_vjp` against the reference `Interpreter`, for every shipped
//!   model, mode and a set of differentiated parameters (all, a reordered subset, none), whole and
//!   cut into parts: equal (`==`, NaN with NaN), which is tighter than the 1e-13 relative the
//!   issue asks, because both sum the same products in the same order (rows ascending); only
//!   the sign of a zero may differ (the interpreter starts its sums from `+0.0`);
//! - the transpose relations against the compiled `flow_sens` (`ds_j = f_x s_j + f_p_j`):
//!   `w . (f_x v) == (f_x^T w) . v` and `w . f_p_j == gp_j`, to the round-off bound stated at
//!   [`transpose_bound`]; with no differentiated parameter `flow_sens` carries no `f_x`, so
//!   `f_x v` comes from the compiled `flow_jac` (the stiff kernel's symbolic `f_x`) there;
//! - the trait's default `flow_vjp` on a hand-written system against its closed-form Jacobian.

use hybc::codegen::{CompileOptions, CompiledModel};
use hybc::lower::{lower, system_info, Interpreter};
use hybc::sema::ParamIdx;
use hybc::sim::{HybridSystem, ModeInfo, SystemInfo};

use crate::support::models::shipped_models;

const EPS: f64 = f64::EPSILON;

/// A small deterministic generator (xorshift64*), so failures reproduce.
struct Rng(u64);

impl Rng {
    /// Uniform in [-2, 2).
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let bits = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        (bits >> 11) as f64 / (1u64 << 53) as f64 * 4.0 - 2.0
    }
    fn vec(&mut self, len: usize) -> Vec<f64> {
        (0..len).map(|_| self.next()).collect()
    }
}

fn vjp(sys: &dyn HybridSystem, mode: usize, t: f64, x: &[f64], w: &[f64], p: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let info = sys.info();
    let (mut gx, mut gp) = (vec![f64::NAN; info.n_states()], vec![f64::NAN; info.n_grad()]);
    sys.flow_vjp(mode, t, x, w, p, &mut gx, &mut gp);
    (gx, gp)
}

fn assert_equal(what: &str, jit: &[f64], reference: &[f64]) {
    assert_eq!(jit.len(), reference.len(), "{what}");
    for (i, (a, b)) in jit.iter().zip(reference).enumerate() {
        assert!(a == b || (a.is_nan() && b.is_nan()), "{what}[{i}]: jit {a:e} vs interpreter {b:e}");
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a * b).sum()
}

/// The bound on `|lhs - rhs|` of a transpose relation whose two sides each sum the same
/// products `w_i a_ik v_k` (and, through `flow_sens`, add and take off a bias `f_p`), in
/// different orders: each side is a sum of at most `n^2 + n` rounded terms, grouped in sums of at
/// most `n` and `n` again, so each is within `(2n + 2) eps S` of the exact value, with `S` the
/// sum of the terms' magnitudes (the bias counted once more for its subtraction), hence
/// `|lhs - rhs| <= (4n + 4) eps S`.
fn transpose_bound(n: usize, magnitude: f64) -> f64 {
    (4 * n + 4) as f64 * EPS * magnitude
}

/// Counts of the checks one model made, so that a model whose every point is singular cannot
/// pass vacuously.
#[derive(Default)]
struct Checked {
    compared: usize,
    transposed: usize,
}

/// For one compiled system and its reference: at random points, the kernel equals the
/// interpreter and the transpose relations hold against `flow_sens` (or `flow_jac` when m = 0).
fn check_system(
    name: &str,
    jit: &CompiledModel,
    reference: &Interpreter,
    p0: &[f64],
    rng: &mut Rng,
) -> Checked {
    let info = jit.info();
    let (n, m) = (info.n_states(), info.n_grad());
    jit.prepare_jacobians().unwrap_or_else(|e| panic!("{name}: {e}"));
    let mut checked = Checked::default();
    for trial in 0..12 {
        // Parameters near the model's values (their signs kept, so that the runs' region is
        // probed), states and times at random; `t` covers the input windows of the shipped models.
        let p: Vec<f64> = p0.iter().map(|&v| v + 0.25 * rng.next() * v.abs().max(1.0)).collect();
        let t = 2.0 + 2.0 * rng.next();
        let x = rng.vec(n);
        let w = rng.vec(n);
        let v = rng.vec(n);
        for mode in 0..info.modes.len() {
            let what = |f: &str| format!("{name} (m = {m}) trial {trial} mode {mode} {f}");
            let (gx, gp) = vjp(jit, mode, t, &x, &w, &p);
            let (rx, rp) = vjp(reference, mode, t, &x, &w, &p);
            assert_equal(&what("gx"), &gx, &rx);
            assert_equal(&what("gp"), &gp, &rp);
            checked.compared += 1;

            // f_x as a dense matrix from the stiff kernel (for the magnitudes, and for `f_x v`
            // when no sensitivity column carries it).
            let (mut fx, mut ft, mut st) = (vec![0.0; n * n], vec![0.0; n], vec![0.0; n * m]);
            jit.flow_jac(mode, t, &x, &vec![0.0; n * m], &p, &mut fx, &mut ft, &mut st);
            let (mut dx, mut fp) = (vec![0.0; n], vec![0.0; n * m]);
            jit.flow_sens(mode, t, &x, &vec![0.0; n * m], &p, &mut dx, &mut fp);
            let fxv: Vec<f64> = if m == 0 {
                (0..n).map(|i| dot(&fx[i * n..(i + 1) * n], &v)).collect()
            } else {
                // Column 0 holds `v`, the others nothing: `ds_0 - f_p_0 = f_x v`.
                let mut s = vec![0.0; n * m];
                s[..n].copy_from_slice(&v);
                let mut ds = vec![0.0; n * m];
                jit.flow_sens(mode, t, &x, &s, &p, &mut dx, &mut ds);
                (0..n).map(|i| ds[i] - fp[i]).collect()
            };
            let magnitude: f64 = (0..n)
                .map(|i| {
                    let row: f64 = (0..n).map(|k| (fx[i * n + k] * v[k]).abs()).sum();
                    let bias = if m == 0 { 0.0 } else { 2.0 * fp[i].abs() };
                    w[i].abs() * (row + bias)
                })
                .sum();
            let (lhs, rhs) = (dot(&w, &fxv), dot(&gx, &v));
            if !(magnitude.is_finite() && gp.iter().chain(&fp).all(|g| g.is_finite())) {
                // A Jacobian entry singular at this point (a 0/0 the flow's value does not
                // have): the relation has no finite sides to compare.
                continue;
            }
            let bound = transpose_bound(n, magnitude);
            assert!(
                (lhs - rhs).abs() <= bound,
                "{}: w.(f_x v) = {lhs:e}, (f_x^T w).v = {rhs:e}, |diff| {:e} > {bound:e}",
                what("transpose"),
                (lhs - rhs).abs()
            );
            for (j, &g) in gp.iter().enumerate() {
                let col = &fp[j * n..(j + 1) * n];
                let want = dot(&w, col);
                let mag: f64 = w.iter().zip(col).map(|(a, b)| (a * b).abs()).sum();
                let bound = transpose_bound(n, mag);
                assert!(
                    (want - g).abs() <= bound,
                    "{}: w.f_p_{j} = {want:e}, gp = {g:e}, |diff| {:e} > {bound:e}",
                    what("gp transpose"),
                    (want - g).abs()
                );
            }
            checked.transposed += 1;
        }
    }
    checked
}

/// Every check of [`check_system`] on `source` with every parameter differentiated, with every
/// other one in reverse order (a strict, reordered subset of columns), and with none (m = 0);
/// each compiled whole and with every kernel cut into parts of at most two operations.
fn check_model_text(name: &str, source: &str, rng: &mut Rng) {
    let model = hybc::check_source(source).unwrap_or_else(|e| panic!("{name}: {e}\n{source}"));
    let funcs = lower(&model);
    let p: Vec<f64> = model.params.iter().map(|p| p.default).collect();
    let all: Vec<ParamIdx> = (0..model.n_params() as u32).map(ParamIdx).collect();
    let some: Vec<ParamIdx> = all.iter().rev().step_by(2).copied().collect();
    for grad in [all, some, Vec::new()] {
        let info = system_info(&model, &grad);
        let reference = Interpreter::new(funcs.clone(), info.clone());
        for max_part_size in [CompileOptions::default().max_part_size, 2] {
            let opts = CompileOptions { max_part_size, ..CompileOptions::default() };
            let jit =
                CompiledModel::compile(&funcs, info.clone(), &opts).unwrap_or_else(|e| panic!("{name}: {e}"));
            let checked = check_system(name, &jit, &reference, &p, rng);
            let modes = info.modes.len();
            assert_eq!(checked.compared, 12 * modes, "{name}");
            // At least half the random points are regular enough for the relation.
            assert!(
                2 * checked.transposed >= checked.compared,
                "{name} (m = {}): only {} of {} points had finite sides",
                grad.len(),
                checked.transposed,
                checked.compared
            );
        }
    }
}

#[test]
fn every_shipped_model_has_the_transposed_products() {
    let models = shipped_models();
    assert!(models.len() >= 5, "expected the shipped models, found {}", models.len());
    // The cases the issue names are among them: a vector parameter read by `pwl` (hopper_thrust,
    // juggler) and an `if` in a flow, a flow switch (soft_ball).
    for wanted in ["hopper_thrust", "juggler", "soft_ball"] {
        assert!(models.iter().any(|m| m.name == wanted), "{wanted} is no longer shipped");
    }
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for model in models {
        check_model_text(&model.name, &model.source, &mut rng);
    }
}

#[test]
fn inputs_switches_and_a_model_without_parameters_have_the_transposed_products() {
    let mut rng = Rng(0x2545_F491_4F6C_DD1D);
    // A 40-knot `pwl` and a 5-knot `pwc` in one flow, an `if` and a `sign` that switch it, a
    // second mode reading the same vector: every element one `f_p` entry.
    let inputs = "model inputs
param k = 2
param u[40] = 1 in [-5, 5]
param d[5] = 0.5
state x = 1
state y = 0
state z = 0.5
initial mode a {
    der(x) = pwl(t, 0, 4, u) * y - k * x
    der(y) = -pwc(t, 0, 4, d) * y + (if x > 0 then x * z else -z) + sign(z - y)
    der(z) = sin(x) * u[3] - z
    event flip when x crosses 0.5 -> b
}
mode b {
    der(x) = -k * pwl(t, 1, 3, u)
    der(y) = x^2 * z
    der(z) = 0
    event back when y crosses 0 -> a
}
";
    check_model_text("inputs", inputs, &mut rng);
    // No parameter at all: m = 0 in every compile, `gp` empty, `gx` still wanted.
    let bare = "model bare
state x = 1
state v = 0
der(x) = v
der(v) = -sin(x) - 0.1 * v * abs(v)
";
    check_model_text("bare", bare, &mut rng);
}

#[test]
fn a_zero_weight_annihilates_a_singular_entry_as_a_zero_sensitivity_does() {
    // The drag `c hypot(vx, vy) vx` has the derivative 0/0 in `vx` at rest; a row with weight 0
    // must not turn the products of the other rows into NaN, one with weight 1 reads it.
    let source = "model drag
param c = 0.1
state x = 0
state vx = 0
state vy = 0
der(x) = vx
der(vx) = -c * hypot(vx, vy) * vx
der(vy) = -9.81 - c * hypot(vx, vy) * vy
";
    let model = hybc::check_source(source).expect("checks");
    let funcs = lower(&model);
    let info = system_info(&model, &[ParamIdx(0)]);
    let reference = Interpreter::new(funcs.clone(), info.clone());
    let jit = CompiledModel::compile(&funcs, info, &CompileOptions::default()).expect("compiles");
    let (x, p) = ([0.0; 3], [0.1]);
    for sys in [&jit as &dyn HybridSystem, &reference] {
        let (gx, gp) = vjp(sys, 0, 0.0, &x, &[1.0, 0.0, 0.0], &p);
        assert_eq!(gx, [0.0, 1.0, 0.0]);
        assert_eq!(gp, [0.0]);
        let (gx, _) = vjp(sys, 0, 0.0, &x, &[0.0, 1.0, 0.0], &p);
        assert!(gx[1].is_nan(), "the singular entry is read where its row has weight: {gx:?}");
    }
    // Ordinary points are untouched: at vx = 3, vy = 4, d/dvx (hypot vx) = vx^2/5 + 5.
    let (x, w) = ([0.0, 3.0, 4.0], [0.0, 1.0, 0.0]);
    let (gx, gp) = vjp(&jit, 0, 0.0, &x, &w, &p);
    let want_vx = -0.1 * (9.0 / 5.0 + 5.0);
    assert!((gx[1] - want_vx).abs() <= 4.0 * EPS * want_vx.abs(), "{gx:?}");
    assert!((gp[0] + 5.0 * 3.0).abs() <= 4.0 * EPS * 15.0, "{gp:?}");
}

/// A hand-written system with a closed-form Jacobian: states `x0, x1, x2`, parameters `a, b`,
/// `f0 = a x0 x1 + sin x2`, `f1 = x0^2 - b x2 + t`, `f2 = exp(a x1) - b x2 x0`. Only `flow_sens`
/// is written (and, with `exact_jac`, `flow_jac`): `flow_vjp` is the trait's default.
struct Hand {
    info: SystemInfo,
    exact_jac: bool,
}

impl Hand {
    fn new(grad_params: Vec<usize>, exact_jac: bool) -> Hand {
        let info = SystemInfo {
            state_names: vec!["x0".into(), "x1".into(), "x2".into()],
            output_names: Vec::new(),
            param_names: vec!["a".into(), "b".into()],
            grad_params,
            modes: vec![ModeInfo { name: "only".into(), events: Vec::new() }],
            events: Vec::new(),
            knots: Vec::new(),
            initial_mode: 0,
            quadrature: Vec::new(),
        };
        Hand { info, exact_jac }
    }

    /// `f_x` row-major and `f_p` (3 x 2, row-major: `[df_i/da, df_i/db]`), closed form.
    fn jacobians(x: &[f64], p: &[f64]) -> ([f64; 9], [f64; 6]) {
        let (a, b) = (p[0], p[1]);
        let e = (a * x[1]).exp();
        let fx = [a * x[1], a * x[0], x[2].cos(), 2.0 * x[0], 0.0, -b, -b * x[2], a * e, -b * x[0]];
        let fp = [x[0] * x[1], 0.0, 0.0, -x[2], x[1] * e, -x[2] * x[0]];
        (fx, fp)
    }
}

impl HybridSystem for Hand {
    fn info(&self) -> &SystemInfo {
        &self.info
    }
    fn initial_state(&self, _p: &[f64], x0: &mut [f64]) {
        x0.fill(0.0);
    }
    fn initial_sens(&self, _p: &[f64], s0: &mut [f64]) {
        s0.fill(0.0);
    }
    fn flow(&self, _mode: usize, t: f64, x: &[f64], p: &[f64], dx: &mut [f64]) {
        let (a, b) = (p[0], p[1]);
        dx[0] = a * x[0] * x[1] + x[2].sin();
        dx[1] = x[0] * x[0] - b * x[2] + t;
        dx[2] = (a * x[1]).exp() - b * x[2] * x[0];
    }
    fn flow_sens(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        s: &[f64],
        p: &[f64],
        dx: &mut [f64],
        ds: &mut [f64],
    ) {
        self.flow(mode, t, x, p, dx);
        let (fx, fp) = Hand::jacobians(x, p);
        for (j, &param) in self.info.grad_params.iter().enumerate() {
            for i in 0..3 {
                ds[j * 3 + i] = (0..3).map(|k| fx[i * 3 + k] * s[j * 3 + k]).sum::<f64>() + fp[i * 2 + param];
            }
        }
    }
    fn flow_jac(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        _s: &[f64],
        p: &[f64],
        fx: &mut [f64],
        ft: &mut [f64],
        st: &mut [f64],
    ) {
        if self.exact_jac {
            fx.copy_from_slice(&Hand::jacobians(x, p).0);
            ft.copy_from_slice(&[0.0, 1.0, 0.0]);
            st.fill(0.0);
        } else {
            // The trait's central differences, written out (a default cannot be called from
            // an override): the step of `HybridSystem::flow_jac`.
            let h_of = |u: f64| 6.0554544523933395e-6 * u.abs().max(1.0);
            let (mut fp, mut fm) = ([0.0; 3], [0.0; 3]);
            for c in 0..3 {
                let (mut xp, mut xm) = (x.to_vec(), x.to_vec());
                xp[c] += h_of(x[c]);
                xm[c] -= h_of(x[c]);
                self.flow(mode, t, &xp, p, &mut fp);
                self.flow(mode, t, &xm, p, &mut fm);
                for i in 0..3 {
                    fx[i * 3 + c] = (fp[i] - fm[i]) / (xp[c] - xm[c]);
                }
            }
            ft.copy_from_slice(&[0.0, 1.0, 0.0]);
            st.fill(0.0);
        }
    }
    fn guards(&self, _mode: usize, _t: f64, _x: &[f64], _p: &[f64], _g: &mut [f64]) {}
    fn guard_grad(
        &self,
        _e: usize,
        _t: f64,
        _x: &[f64],
        _p: &[f64],
        _gx: &mut [f64],
        _gp: &mut [f64],
    ) -> f64 {
        0.0
    }
    fn condition(&self, _e: usize, _t: f64, _x: &[f64], _p: &[f64]) -> bool {
        true
    }
    fn reset(&self, _e: usize, _t: f64, x: &[f64], _p: &[f64], r: &mut [f64]) {
        r.copy_from_slice(x);
    }
    fn reset_jac(
        &self,
        _e: usize,
        _t: f64,
        _x: &[f64],
        _p: &[f64],
        rx: &mut [f64],
        rp: &mut [f64],
        rt: &mut [f64],
    ) {
        rx.fill(0.0);
        rp.fill(0.0);
        rt.fill(0.0);
    }
    fn outputs(&self, _t: f64, _x: &[f64], _p: &[f64], _y: &mut [f64]) {}
    fn output_jac(&self, _t: f64, _x: &[f64], _p: &[f64], _yx: &mut [f64], _yp: &mut [f64], _yt: &mut [f64]) {
    }
}

/// The default `flow_vjp` of [`Hand`] against `F^T w` and `F_p^T w` from the closed form, at
/// random points. `rel` scales the bound on `gx`: the default's error per entry of `f_x` is
/// `eps (|F_ic| + min_j |f_p_ji|)` (read off `flow_sens`) or the central differences' (m = 0
/// without an exact `flow_jac`), and the sums add `n eps` of their terms' magnitudes.
fn check_default(sys: &Hand, rel: f64, rng: &mut Rng) {
    let m = sys.info.n_grad();
    for trial in 0..50 {
        let x = rng.vec(3);
        let p = [1.0 + 0.25 * rng.next(), 1.0 + 0.25 * rng.next()];
        let w = rng.vec(3);
        let t = rng.next();
        let (gx, gp) = vjp(sys, 0, t, &x, &w, &p);
        let (fx, fp) = Hand::jacobians(&x, &p);
        let cols: Vec<usize> = sys.info.grad_params.clone();
        // The magnitude of the `f_p` entry each row's `f_x` is read against (none when m = 0).
        let bias = |i: usize| cols.iter().map(|&q| fp[i * 2 + q].abs()).fold(f64::INFINITY, f64::min);
        for c in 0..3 {
            let want: f64 = (0..3).map(|i| w[i] * fx[i * 3 + c]).sum();
            let mag: f64 =
                (0..3).map(|i| w[i].abs() * (fx[i * 3 + c].abs() + if m == 0 { 1.0 } else { bias(i) })).sum();
            let bound = rel * mag;
            assert!(
                (gx[c] - want).abs() <= bound,
                "m = {m} trial {trial}: gx[{c}] = {:e}, closed form {want:e}, |diff| {:e} > {bound:e}",
                gx[c],
                (gx[c] - want).abs()
            );
        }
        assert_eq!(gp.len(), m);
        for (j, &q) in cols.iter().enumerate() {
            let want: f64 = (0..3).map(|i| w[i] * fp[i * 2 + q]).sum();
            let mag: f64 = (0..3).map(|i| (w[i] * fp[i * 2 + q]).abs()).sum();
            assert!(
                (gp[j] - want).abs() <= 4.0 * EPS * mag,
                "m = {m} trial {trial}: gp[{j}] = {:e} vs {want:e}",
                gp[j]
            );
        }
    }
}

#[test]
fn the_default_flow_vjp_is_the_closed_form_transposed() {
    let mut rng = Rng(0x1234_5678_9ABC_DEF1);
    // Read off `flow_sens`: round-off only, with both parameters, one, and both reordered.
    for grad in [vec![0, 1], vec![1], vec![1, 0]] {
        check_default(&Hand::new(grad, false), 8.0 * EPS, &mut rng);
    }
    // m = 0 reads `f_x` off `flow_jac`: exact when the system writes it...
    check_default(&Hand::new(Vec::new(), true), 8.0 * EPS, &mut rng);
    // ... central differences otherwise (truncation h^2 f'''/6 and round-off eps/h: about 1e-10
    // of the entries' scale here, asserted at 1e-8).
    check_default(&Hand::new(Vec::new(), false), 1e-8, &mut rng);
}

#[test]
fn the_default_reads_a_row_against_its_smallest_parameter_entry() {
    // With `b` then `a` differentiated, row 1 (`x0^2 - b x2 + t`) has `f_p = [-x2, 0]`. Read
    // against column 0 (`b`) its `f_x` entry `2 x0 = 0.2` would come back as
    // `(0.2 - 333.3..) + 333.3.. = 0.19999999999998863`; read against column 1 (`a`, no entry)
    // it is exact, so a weight on row 1 alone gives `F^T w` bit for bit.
    let sys = Hand::new(vec![1, 0], false);
    let x2 = 1000.0 / 3.0;
    let (x, p) = ([0.1, -0.75, x2], [1.25, 0.875]);
    let (gx, gp) = vjp(&sys, 0, 0.0, &x, &[0.0, 2.0, 0.0], &p);
    assert_eq!(gx, [2.0 * (2.0 * 0.1), 0.0, 2.0 * -0.875]);
    assert_eq!(gp, [2.0 * -x2, 0.0]);
}

#[test]
fn the_compiled_flow_vjp_checks_its_lengths_and_its_mode() {
    // A caller's bug shows as NaN in its results, never as a read or write out of bounds.
    let source = "model two\nparam a = 1\nstate x = 1\nstate y = 0\nder(x) = a * y\nder(y) = -x\n";
    let model = hybc::check_source(source).expect("checks");
    let funcs = lower(&model);
    let jit = CompiledModel::compile(&funcs, system_info(&model, &[ParamIdx(0)]), &CompileOptions::default())
        .expect("compiles");
    let (x, p) = ([1.0, 2.0], [3.0]);
    let (gx, gp) = vjp(&jit, 0, 0.0, &x, &[1.0, 1.0], &p);
    assert_eq!((gx, gp), (vec![-1.0, 3.0], vec![2.0]), "f_x = [[0, a], [-1, 0]], f_p = [y, 0]");
    for (w, gx_len, gp_len, mode) in [(2, 2, 1, 1), (1, 2, 1, 0), (2, 3, 1, 0), (2, 2, 0, 0)] {
        let (mut gx, mut gp) = (vec![0.0; gx_len], vec![0.0; gp_len]);
        jit.flow_vjp(mode, 0.0, &x, &vec![1.0; w], &p, &mut gx, &mut gp);
        assert!(gx.iter().chain(&gp).all(|g| g.is_nan()), "w {w}, gx {gx_len}, gp {gp_len}, mode {mode}");
    }
}
