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
//!   `f_x v` comes from the compiled `flow_jac` (the stiff kernel's symbolic `f_x`) there; for
//!   an element of a control read through lookups only, whose `gp` entry is the host's scatter
//!   of `c_L = sum_i w_i df_i/dL` (`ModeFunctions::lookups`), to the bound at [`scatter_bound`];
//! - at random times, exact knots, before the first knot and after the last;
//! - the scatter's weights (`expr::lookup_weights`) against `diff`'s element weights, bit for bit,
//!   and a derivative with respect to a node (`Var::Node`) against its closed form;
//! - the trait's default `flow_vjp` on a hand-written system against its closed-form Jacobian.

use std::collections::HashSet;

use hybc::codegen::{CompileOptions, CompiledModel};
use hybc::expr::eval::reachable;
use hybc::expr::{
    apply_binary, apply_lookup, apply_select, apply_unary, lookup_weights, ExprId, ExprStore, Lookup,
    LookupKind, ModelFunctions, Node, UnaryOp,
};
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

/// `gamma_k = k eps / (1 - k eps)`, the classic bound on `k` rounded operations' relative error.
fn gamma(k: usize) -> f64 {
    let k = k as f64 * EPS;
    k / (1.0 - k)
}

/// A derivative expression's value, its magnitude `M` and its depth `D` (Higham's running error
/// analysis): the float value is within `gamma(D) M` of the value in exact arithmetic from the
/// same leaves. Leaves (`D = 0`, `M = |value|`): the flow's own nodes (`exact`; both sides of a
/// relation read the same floats there, hash-consing), constants, and every operation other than
/// `+`, `*`, `/`, negation and `select`: the chain rule applies those to primal nodes only, which
/// it builds the same way for every variable, so both sides share them too. Then `M(a + b) =
/// M(a) + M(b)`, `M(a b) = M(a) M(b)`, `M(a / b) = (M(a) + |a/b| M(b)) / |b|`, `select` takes its
/// branch's; `D` adds one per rounding, as relative errors add in products.
fn magnitude(
    store: &ExprStore,
    root: ExprId,
    exact: &HashSet<ExprId>,
    t: f64,
    x: &[f64],
    p: &[f64],
) -> (f64, usize) {
    let nodes = reachable(store, &[root]);
    let mut at: std::collections::HashMap<ExprId, (f64, f64, usize)> = Default::default();
    for id in nodes {
        let get = |c: ExprId| at[&c];
        let node = *store.node(id);
        let value = match node {
            Node::Const(bits) => f64::from_bits(bits),
            Node::State(i) => x[i as usize],
            Node::Param(i) => p[i as usize],
            Node::Time => t,
            Node::Unary(op, a) => apply_unary(op, get(a).0),
            Node::Binary(op, a, b) => apply_binary(op, get(a).0, get(b).0),
            Node::Select(c, a, b) => apply_select(get(c).0, get(a).0, get(b).0),
            Node::Lookup(l, pos) => {
                apply_lookup(l.kind, get(pos).0, &p[l.base as usize..(l.base + l.len) as usize])
            }
        };
        let leaf = (value, value.abs(), 0);
        let entry = if exact.contains(&id) {
            leaf
        } else {
            match node {
                Node::Unary(UnaryOp::Neg, a) => (value, get(a).1, get(a).2),
                Node::Binary(hybc::expr::BinaryOp::Add, a, b) => {
                    (value, get(a).1 + get(b).1, get(a).2.max(get(b).2) + 1)
                }
                Node::Binary(hybc::expr::BinaryOp::Mul, a, b) => {
                    (value, get(a).1 * get(b).1, get(a).2 + get(b).2 + 1)
                }
                Node::Binary(hybc::expr::BinaryOp::Div, a, b) => {
                    let (vb, mb) = (get(b).0.abs(), get(b).1);
                    (value, (get(a).1 + value.abs() * mb) / vb, get(a).2 + get(b).2 + 1)
                }
                Node::Select(c, a, b) => {
                    let taken = if get(c).0 != 0.0 { get(a) } else { get(b) };
                    (value, taken.1, taken.2)
                }
                _ => leaf,
            }
        };
        at.insert(id, entry);
    }
    let (_, m, d) = at[&root];
    (m, d)
}

/// The bound on `|w . f_p_j - gp_j|` for an element `u_j` of a control read through lookups
/// only. The two sides are equal in exact arithmetic from the same leaves: `f_p_ij` is the chain
/// rule from the leaf derivative `wt_jL` (the element's weight at lookup `L`'s position, the same
/// float on both sides), `c_L` from the leaf derivative 1, so `f_p_ij = sum_L df_i/dL wt_jL`.
/// The left side is `f_p_ij` evaluated (within `gamma(D_f) M_f`) and dotted with `w` (`n`
/// roundings); the right `df_i/dL` evaluated (`gamma(D_a) M_a`), dotted with `w` (`n`), times the
/// weight (1) and added into `gp_j` lookup by lookup (`lookups`). Hence, to first order,
/// `gamma(D_f + n + 1) S_f + gamma(D_a + n + 2 + lookups) S_a`, with `S_f = sum_i |w_i| M_f(i)`
/// and `S_a = sum_L |wt_jL| sum_i |w_i| M_a(i, L)`.
fn scatter_bound(n: usize, m: &ScatterMagnitudes) -> f64 {
    gamma(m.d_f + n + 1) * m.s_f + gamma(m.d_a + n + 2 + m.lookups) * m.s_a
}

/// The sums and depths of [`scatter_bound`] for one element, and how many lookups read it.
struct ScatterMagnitudes {
    s_f: f64,
    d_f: usize,
    s_a: f64,
    d_a: usize,
    lookups: usize,
}

/// The magnitudes of [`scatter_bound`] for the sensitivity column of parameter `param` in `mode`, when a
/// lookup of the mode's `lookups` reads it; `None` otherwise (the kernel's own product).
#[allow(clippy::too_many_arguments)]
fn scatter_magnitudes(
    funcs: &ModelFunctions,
    mode: usize,
    param: u32,
    t: f64,
    x: &[f64],
    w: &[f64],
    p: &[f64],
) -> Option<ScatterMagnitudes> {
    let mf = &funcs.modes[mode];
    let reading: Vec<_> = mf.lookups.iter().filter(|fl| fl.lookup.reads(param)).collect();
    if reading.is_empty() {
        return None;
    }
    let store = &funcs.store;
    let exact: HashSet<ExprId> = reachable(store, &mf.flow).into_iter().collect();
    let (mut s_f, mut d_f) = (0.0, 0);
    for &(i, _, e) in mf.flow_p.entries.iter().filter(|e| e.1 == param) {
        let (m, d) = magnitude(store, e, &exact, t, x, p);
        s_f += w[i as usize].abs() * m;
        d_f = d_f.max(d);
    }
    let (mut s_a, mut d_a) = (0.0, 0);
    for fl in &reading {
        // The element's weight at this lookup's position, from the value's own definition:
        // `apply_lookup` of the unit vector (it is linear in the vector).
        let pos_value = hybc::expr::eval_one(store, fl.position, t, x, p);
        let mut unit = vec![0.0; fl.lookup.len as usize];
        unit[(param - fl.lookup.base) as usize] = 1.0;
        let weight = apply_lookup(fl.lookup.kind, pos_value, &unit);
        for &(i, e) in &fl.flow_l.entries {
            let (m, d) = magnitude(store, e, &exact, t, x, p);
            s_a += weight.abs() * w[i as usize].abs() * m;
            d_a = d_a.max(d);
        }
    }
    Some(ScatterMagnitudes { s_f, d_f, s_a, d_a, lookups: reading.len() })
}

/// Counts of the checks one model made, so that a model whose every point is singular cannot
/// pass vacuously.
#[derive(Default)]
struct Checked {
    compared: usize,
    transposed: usize,
    /// Points exactly on a knot of an input the mode's flow reads.
    on_knots: usize,
}

/// For one compiled system and its reference: at random points, the kernel equals the
/// interpreter and the transpose relations hold against `flow_sens` (or `flow_jac` when m = 0).
fn check_system(
    name: &str,
    funcs: &ModelFunctions,
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
        let x = rng.vec(n);
        let w = rng.vec(n);
        let v = rng.vec(n);
        for mode in 0..info.modes.len() {
            let (t, on_knot) = trial_time(jit, mode, trial, &p, rng);
            checked.on_knots += usize::from(on_knot);
            let what = |f: &str| format!("{name} (m = {m}) trial {trial} mode {mode} t = {t:e} {f}");
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
                let param = info.grad_params[j] as u32;
                let bound = match scatter_magnitudes(funcs, mode, param, t, &x, &w, &p) {
                    Some(magnitudes) => scatter_bound(n, &magnitudes),
                    None => transpose_bound(n, w.iter().zip(col).map(|(a, b)| (a * b).abs()).sum()),
                };
                if !bound.is_finite() {
                    continue;
                }
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

/// The time of `trial` in `mode`: at random in `[0, 4)` (the shipped models' input windows), or,
/// where the mode's flow reads an input, in turn exactly on one of its knots (the position, as
/// the compiled model computes it, equal to the knot's number: the time searched ulp by ulp
/// near the affine position's root; whether it was found is returned), before its first knot,
/// and after its last.
fn trial_time(sys: &CompiledModel, mode: usize, trial: usize, p: &[f64], rng: &mut Rng) -> (f64, bool) {
    let random = 2.0 + 2.0 * rng.next();
    let sets: Vec<usize> =
        (0..sys.info().knots.len()).filter(|&k| sys.info().knots[k].mode == mode).collect();
    if sets.is_empty() || trial.is_multiple_of(4) {
        return (random, false);
    }
    let set = sets[trial / 4 % sets.len()];
    let knots = sys.info().knots[set].knots.clone();
    let last = f64::from(knots.end - 1);
    let pos = |t: f64| sys.knot_position(set, t, p);
    let (b, a) = (pos(0.0), pos(1.0) - pos(0.0));
    let at = |s: f64| (s - b) / a;
    match trial % 4 {
        1 => {
            // A few knots, until one is hit exactly (a step of one ulp in `t` can move the
            // position by more than one ulp, past the knot).
            for _ in 0..8 {
                let span = last - f64::from(knots.start);
                let k = f64::from(knots.start) + ((rng.next() + 2.0) / 4.0 * span).round();
                let mut t = at(k);
                // Ulp by ulp towards the knot: the position is monotone in `t`.
                for _ in 0..16 {
                    let s = pos(t);
                    if s == k {
                        return (t, true);
                    }
                    t = if (s < k) == (a > 0.0) { t.next_up() } else { t.next_down() };
                }
            }
            (random, false)
        }
        2 => (at(-0.5 - (rng.next() + 2.0)), false),
        _ => (at(last + 0.5 + (rng.next() + 2.0)), false),
    }
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
            let checked = check_system(name, &funcs, &jit, &reference, &p, rng);
            let modes = info.modes.len();
            assert_eq!(checked.compared, 12 * modes, "{name}");
            if !info.knots.is_empty() {
                assert!(checked.on_knots > 0, "{name}: no point on a knot");
            }
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

#[test]
fn controls_read_through_lookups_have_the_transposed_products() {
    // Mode a: `u` read by three lookups (one shared by two rows, two at other positions, one
    // squared), `d` by a `pwc` whose window ends at the parameter `T` (whose own entry stays a
    // normal one), `v` by a lookup and by `sum(v)` (today's path: an `f_p` product per element).
    // Mode b: `u` by a `pwc`, `d` by a `pwl`. Every time of `check_system`: random, on knots,
    // before the first and after the last.
    let source = "model controls
param T = 3 in [1, 5]
param u[12] = 0.5
param v[6] = 1
param d[5] = 0.25
state x = 1
state y = 0.5
initial mode a {
    der(x) = pwl(t, 0, 1, u)^2 + pwl(t, 0, 2, u) - x * pwc(t, 0, T, d)
    der(y) = y * pwl(t, 0, T, v) + sum(v) * x - pwl(t, 0, 1, u) * y + sin(pwl(t, 0.5, 3.5, u))
    event flip when x crosses 2 -> b
}
mode b {
    der(x) = -pwc(t, 0.5, 3, u) * x
    der(y) = pwl(t, 1, 4, d) * x
    event back when y crosses 0 -> a
}
";
    let model = hybc::check_source(source).expect("checks");
    let funcs = lower(&model);
    // What the kernel scatters: mode a, `u`'s four lookups and `d`'s; mode b, `u`'s and `d`'s.
    let vectors = |mode: usize| -> Vec<(LookupKind, u32)> {
        funcs.modes[mode].lookups.iter().map(|fl| (fl.lookup.kind, fl.lookup.len)).collect()
    };
    let mut a = vectors(0);
    a.sort();
    assert_eq!(
        a,
        [(LookupKind::Pwl, 12), (LookupKind::Pwl, 12), (LookupKind::Pwl, 12), (LookupKind::Pwc, 5)]
    );
    let mut b = vectors(1);
    b.sort();
    assert_eq!(b, [(LookupKind::Pwl, 5), (LookupKind::Pwc, 12)]);
    let shared = funcs.modes[0].lookups.iter().find(|fl| fl.flow_l.entries.len() == 2);
    assert!(shared.is_some(), "pwl(t, 0, 1, u) is one node read by both rows");
    check_model_text("controls", source, &mut Rng(0x5DEE_CE66_D1CE_4E5B));
}

#[test]
fn a_control_of_many_knots_is_scattered_onto_the_elements_its_position_reads() {
    // 1000 knots: at a time inside segment k, the gradient of `der(x) = pwl(t, 0, 999, u)` with
    // weight 1 is `1 - s` on u[k], `s` on u[k+1] and exactly 0 elsewhere (s = pos - k), the same
    // from the compiled model and the interpreter; before the window all on u[0], after it on
    // u[999], on a knot all on it.
    let source = "model many\nparam u[1000] = 1\nstate x = 0\nder(x) = pwl(t, 0, 999, u)\n";
    let model = hybc::check_source(source).expect("checks");
    let funcs = lower(&model);
    let grad: Vec<ParamIdx> = (0..1000).map(ParamIdx).collect();
    let info = system_info(&model, &grad);
    let reference = Interpreter::new(funcs.clone(), info.clone());
    let jit = CompiledModel::compile(&funcs, info, &CompileOptions::default()).expect("compiles");
    let p = vec![1.0; 1000];
    for (t, want) in [
        (417.25, vec![(417, 0.75), (418, 0.25)]),
        (3.0, vec![(3, 1.0)]),
        (-2.0, vec![(0, 1.0)]),
        (1e6, vec![(999, 1.0)]),
        (998.5, vec![(998, 0.5), (999, 0.5)]),
    ] {
        for sys in [&jit as &dyn HybridSystem, &reference] {
            let (gx, gp) = vjp(sys, 0, t, &[0.0], &[1.0], &p);
            assert_eq!(gx, [0.0]);
            let mut expected = vec![0.0; 1000];
            for &(j, w) in &want {
                expected[j] = w;
            }
            assert_eq!(gp, expected, "t = {t}");
        }
    }
}

#[test]
fn the_scatter_weights_are_the_element_weights() {
    // `lookup_weights` (the adjoint's scatter) against `diff`'s weight of each element (the
    // forward sensitivities' `f_p`), bit for bit, and against the value's own definition
    // (`apply_lookup` of a unit vector, linear in the vector): every kind, short and longer
    // vectors, at knots, between them, before the first, after the last, at infinities.
    let mut rng = Rng(0x0123_4567_89AB_CDEF);
    for kind in [LookupKind::Pwl, LookupKind::Pwc, LookupKind::PwlSlope] {
        for len in [2u32, 3, 7] {
            let mut store = ExprStore::new();
            let pos = store.param(len);
            let l = Lookup { kind, base: 0, len };
            let node = store.lookup(l, pos);
            let weights: Vec<ExprId> =
                (0..len).map(|j| hybc::expr::diff(&mut store, node, hybc::expr::Var::Param(j))).collect();
            let mut positions: Vec<f64> = (-2..=len as i32 + 1).map(f64::from).collect();
            positions.extend([-0.0, 0.5, f64::from(len) - 1.5, f64::INFINITY, f64::NEG_INFINITY, 1e300]);
            positions.extend((0..40).map(|_| (rng.next() + 2.0) / 4.0 * (f64::from(len) + 2.0) - 1.0));
            for s in positions {
                let mut p = vec![0.0; len as usize + 1];
                p[len as usize] = s;
                let mut scatter = vec![0.0; len as usize];
                for (j, w) in lookup_weights(kind, s, len as usize) {
                    assert_ne!(w, 0.0, "{kind:?} len {len} at {s}: a zero weight listed");
                    scatter[j] += w;
                }
                for j in 0..len as usize {
                    let by_diff = hybc::expr::eval_one(&store, weights[j], 0.0, &[], &p);
                    let mut unit = vec![0.0; len as usize];
                    unit[j] = 1.0;
                    let by_value = apply_lookup(kind, s, &unit);
                    assert_eq!(scatter[j], by_diff, "{kind:?} len {len} u[{j}] at {s}: diff");
                    assert_eq!(scatter[j], by_value, "{kind:?} len {len} u[{j}] at {s}: value");
                }
            }
            // A NaN position shows: NaN on the element the value's clamped index reads.
            let nan: Vec<(usize, f64)> = lookup_weights(kind, f64::NAN, len as usize).collect();
            assert!(!nan.is_empty() && nan.iter().all(|(_, w)| w.is_nan()), "{kind:?} len {len}: {nan:?}");
        }
    }
}

#[test]
fn a_derivative_with_respect_to_a_node_holds_its_operands_fixed() {
    // d/dL of `L^2 x + sin(L) + L s` with L = pwl(s, u) and s read beside it: `2 L x + cos(L) + s`
    // (the position s held fixed), while d/ds keeps the path through L (its slope).
    let mut store = ExprStore::new();
    let (x, s) = (store.state(0), store.param(3));
    let l = store.lookup(Lookup { kind: LookupKind::Pwl, base: 0, len: 3 }, s);
    let two = store.constant(2.0);
    let sq = store.pow(l, two);
    let a = store.mul(sq, x);
    let sn = store.unary(UnaryOp::Sin, l);
    let b = store.mul(l, s);
    let ab = store.add(a, sn);
    let f = store.add(ab, b);
    let by_node = hybc::expr::diff(&mut store, f, hybc::expr::Var::Node(l));
    let other = store.constant(1.0);
    let constant = hybc::expr::diff(&mut store, other, hybc::expr::Var::Node(l));
    assert!(store.is_zero(constant));
    let by_s = hybc::expr::diff(&mut store, f, hybc::expr::Var::Param(3));
    let u = [1.5, -0.5, 2.0];
    for &(pos, xv) in &[(0.25, 0.7), (1.0, -1.25), (1.8, 3.0)] {
        let p = [u[0], u[1], u[2], pos];
        let lv = apply_lookup(LookupKind::Pwl, pos, &u);
        let want = 2.0 * lv * xv + lv.cos() + pos;
        let got = hybc::expr::eval_one(&store, by_node, 0.0, &[xv], &p);
        assert!(
            (got - want).abs() <= 8.0 * EPS * (2.0 * (lv * xv).abs() + 1.0 + pos.abs()),
            "{got} vs {want}"
        );
        // d/ds = (df/dL) slope + L: the slope of the segment `pos` is in.
        let k = (pos as usize).min(1);
        let slope = u[k + 1] - u[k];
        let want_s = want * slope + lv;
        let got_s = hybc::expr::eval_one(&store, by_s, 0.0, &[xv], &p);
        assert!(
            (got_s - want_s).abs() <= 16.0 * EPS * (want.abs() * slope.abs() + lv.abs()),
            "{got_s} vs {want_s}"
        );
    }
}

/// `HybridSystem::flow_vjp_dir` (`xbar += (w^T f_xx) v + a f_tx^T w`, `pbar += (w^T f_xp) v +
/// a f_tp^T w`), what the adjoint of a Rosenbrock step reads for its `J` and `F_t`.
#[allow(clippy::too_many_arguments)]
fn vjp_dir(
    sys: &dyn HybridSystem,
    mode: usize,
    t: f64,
    x: &[f64],
    v: &[f64],
    a: f64,
    w: &[f64],
    p: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let info = sys.info();
    let (mut xbar, mut pbar) = (vec![0.0; info.n_states()], vec![0.0; info.n_grad()]);
    sys.flow_vjp_dir(mode, t, x, v, a, w, p, &mut xbar, &mut pbar);
    (xbar, pbar)
}

/// `|a - b| <= rel * scale`, NaN with NaN.
fn within(what: &str, a: f64, b: f64, rel: f64, scale: f64) {
    assert!(
        (a - b).abs() <= rel * scale || (a.is_nan() && b.is_nan()),
        "{what}: {a:e} vs {b:e} (|diff| {:e}, scale {scale:e})",
        (a - b).abs()
    );
}

/// Every shipped model, every mode, every parameter differentiated and none: the compiled
/// `flow_vjp_dir` equals the interpreter's (the same expressions, `expr::flow_vjp_dir_terms`)
/// to 1e-13 of the largest entry, and both are the transposes of the forward coupling
/// `sens_dir` and of `flow_jac`'s `st`:
/// - `pbar_j(v, a) = w . sens_dir(v; S = 0)_j + a w . st(S = 0)_j` (`f_xp_j v`, `f_pt_j`);
/// - `xbar(v, 0) . s_j = w . (sens_dir(v; S)_j - sens_dir(v; 0)_j)` (`f_xx[s_j, v]`) and
///   `xbar(0, 1) . s_j = w . (st(S)_j - st(0)_j)` (`f_xt s_j`),
///
/// each to 1e-12 of the sum of its terms' magnitudes (round-off of sums in different orders,
/// with cancellations, far below it).
#[test]
fn the_second_order_products_are_the_transposes_of_the_forward_coupling() {
    let mut rng = Rng(0x5DEE_CE66_D1CE_4E5B);
    let mut compared = 0;
    for shipped in shipped_models() {
        let model = hybc::check_source(&shipped.source).unwrap_or_else(|e| panic!("{}: {e}", shipped.name));
        let funcs = lower(&model);
        let p0: Vec<f64> = model.params.iter().map(|p| p.default).collect();
        let all: Vec<ParamIdx> = (0..model.n_params() as u32).map(ParamIdx).collect();
        for grad in [all, Vec::new()] {
            let info = system_info(&model, &grad);
            let reference = Interpreter::new(funcs.clone(), info.clone());
            let jit =
                CompiledModel::compile(&funcs, info.clone(), &CompileOptions::default()).expect("compiles");
            jit.prepare_jacobians().expect("stiff kernels");
            let (n, m) = (info.n_states(), info.n_grad());
            for trial in 0..6 {
                let p: Vec<f64> = p0.iter().map(|&v| v + 0.25 * rng.next() * v.abs().max(1.0)).collect();
                let (x, w, v, s) = (rng.vec(n), rng.vec(n), rng.vec(n), rng.vec(n * m));
                let a = rng.next();
                for mode in 0..info.modes.len() {
                    let t = 2.0 + 2.0 * rng.next();
                    let what = |f: &str| format!("{} (m = {m}) trial {trial} mode {mode} {f}", shipped.name);
                    let (xb, pb) = vjp_dir(&jit, mode, t, &x, &v, a, &w, &p);
                    let (rxb, rpb) = vjp_dir(&reference, mode, t, &x, &v, a, &w, &p);
                    if !xb.iter().chain(&pb).all(|g| g.is_finite()) {
                        continue;
                    }
                    let top = xb.iter().chain(&pb).fold(f64::MIN_POSITIVE, |m, g| m.max(g.abs()));
                    for (i, (g, r)) in xb.iter().zip(&rxb).enumerate() {
                        within(&what(&format!("xbar[{i}] jit vs interpreter")), *g, *r, 1e-13, top);
                    }
                    for (j, (g, r)) in pb.iter().zip(&rpb).enumerate() {
                        within(&what(&format!("pbar[{j}] jit vs interpreter")), *g, *r, 1e-13, top);
                    }
                    let zero = vec![0.0; n * m];
                    let dir = |s: &[f64]| {
                        let mut xv = x.clone();
                        xv.extend_from_slice(&v);
                        let mut out = vec![0.0; n * m];
                        jit.sens_dir(mode, t, &xv, s, &p, &mut out);
                        out
                    };
                    let st = |s: &[f64]| {
                        let (mut fx, mut ft, mut out) = (vec![0.0; n * n], vec![0.0; n], vec![0.0; n * m]);
                        jit.flow_jac(mode, t, &x, s, &p, &mut fx, &mut ft, &mut out);
                        out
                    };
                    let (dir0, dirs, st0, sts) = (dir(&zero), dir(&s), st(&zero), st(&s));
                    let absdot =
                        |u: &[f64], v: &[f64]| u.iter().zip(v).map(|(a, b)| (a * b).abs()).sum::<f64>();
                    let (xv0, _) = vjp_dir(&jit, mode, t, &x, &v, 0.0, &w, &p);
                    let (xt, _) = vjp_dir(&jit, mode, t, &x, &vec![0.0; n], 1.0, &w, &p);
                    for j in 0..m {
                        let col = |u: &[f64]| u[j * n..(j + 1) * n].to_vec();
                        let want = dot(&w, &col(&dir0)) + a * dot(&w, &col(&st0));
                        let scale =
                            absdot(&w, &col(&dir0)) + (a * absdot(&w, &col(&st0))).abs() + pb[j].abs();
                        within(&what(&format!("pbar[{j}] vs sens_dir")), pb[j], want, 1e-12, scale);
                        let sj = col(&s);
                        let want = dot(&w, &col(&dirs)) - dot(&w, &col(&dir0));
                        let scale = absdot(&w, &col(&dirs)) + absdot(&w, &col(&dir0)) + absdot(&xv0, &sj);
                        within(
                            &what(&format!("xbar . s_{j} vs sens_dir")),
                            dot(&xv0, &sj),
                            want,
                            1e-12,
                            scale,
                        );
                        let want = dot(&w, &col(&sts)) - dot(&w, &col(&st0));
                        let scale = absdot(&w, &col(&sts)) + absdot(&w, &col(&st0)) + absdot(&xt, &sj);
                        within(&what(&format!("xbar_t . s_{j} vs st")), dot(&xt, &sj), want, 1e-12, scale);
                    }
                    compared += 1;
                }
            }
        }
    }
    assert!(compared >= 100, "only {compared} points compared");
}

/// The trait's default (a central difference of `flow_vjp` along `(v, a)`) on the hand-written
/// system against the compiled model of the same flow: 1e-7 of the largest entry.
#[test]
fn the_default_second_order_products_are_central_differences_of_the_vjp() {
    let src = "model nl\nparam a = 0.7\nparam b = 1.3\nstate x = 1\nstate y = 0.5\n\
               der(x) = a * x * y + sin(t) * b\nder(y) = -b * y^2 + a * x * t\n";
    let model = hybc::check_source(src).expect("checks");
    let funcs = lower(&model);
    let grad: Vec<ParamIdx> = (0..2).map(ParamIdx).collect();
    let info = system_info(&model, &grad);
    let jit = CompiledModel::compile(&funcs, info.clone(), &CompileOptions::default()).expect("compiles");
    /// Only the flow's own products: every other method is the trait's default.
    struct Defaults<'a>(&'a CompiledModel);
    impl HybridSystem for Defaults<'_> {
        fn info(&self) -> &SystemInfo {
            self.0.info()
        }
        fn initial_state(&self, p: &[f64], x0: &mut [f64]) {
            self.0.initial_state(p, x0)
        }
        fn initial_sens(&self, p: &[f64], s0: &mut [f64]) {
            self.0.initial_sens(p, s0)
        }
        fn flow(&self, mode: usize, t: f64, x: &[f64], p: &[f64], dx: &mut [f64]) {
            self.0.flow(mode, t, x, p, dx)
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
            self.0.flow_sens(mode, t, x, s, p, dx, ds)
        }
        fn flow_vjp(
            &self,
            mode: usize,
            t: f64,
            x: &[f64],
            w: &[f64],
            p: &[f64],
            gx: &mut [f64],
            gp: &mut [f64],
        ) {
            self.0.flow_vjp(mode, t, x, w, p, gx, gp)
        }
        fn guards(&self, mode: usize, t: f64, x: &[f64], p: &[f64], g: &mut [f64]) {
            self.0.guards(mode, t, x, p, g)
        }
        fn guard_grad(
            &self,
            event: usize,
            t: f64,
            x: &[f64],
            p: &[f64],
            gx: &mut [f64],
            gp: &mut [f64],
        ) -> f64 {
            self.0.guard_grad(event, t, x, p, gx, gp)
        }
        fn condition(&self, event: usize, t: f64, x: &[f64], p: &[f64]) -> bool {
            self.0.condition(event, t, x, p)
        }
        fn reset(&self, event: usize, t: f64, x: &[f64], p: &[f64], r: &mut [f64]) {
            self.0.reset(event, t, x, p, r)
        }
        fn reset_jac(
            &self,
            event: usize,
            t: f64,
            x: &[f64],
            p: &[f64],
            rx: &mut [f64],
            rp: &mut [f64],
            rt: &mut [f64],
        ) {
            self.0.reset_jac(event, t, x, p, rx, rp, rt)
        }
        fn outputs(&self, t: f64, x: &[f64], p: &[f64], y: &mut [f64]) {
            self.0.outputs(t, x, p, y)
        }
        fn output_jac(&self, t: f64, x: &[f64], p: &[f64], yx: &mut [f64], yp: &mut [f64], yt: &mut [f64]) {
            self.0.output_jac(t, x, p, yx, yp, yt)
        }
    }
    let hand = Defaults(&jit);
    let mut rng = Rng(77);
    for _ in 0..20 {
        let (x, w, v, p) = (rng.vec(2), rng.vec(2), rng.vec(2), rng.vec(2));
        let (a, t) = (rng.next(), 1.0 + rng.next());
        let (xb, pb) = vjp_dir(&jit, 0, t, &x, &v, a, &w, &p);
        let (hx, hp) = vjp_dir(&hand, 0, t, &x, &v, a, &w, &p);
        let top = xb.iter().chain(&pb).fold(1e-300, |m: f64, g| m.max(g.abs()));
        for (g, h) in xb.iter().chain(&pb).zip(hx.iter().chain(&hp)) {
            within("default vs compiled", *h, *g, 1e-7, top);
        }
    }
}
