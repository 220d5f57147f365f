//! Every shipped model (`models/*.hyb`) through the whole front end, compiled by the JIT and
//! compared with the reference `Interpreter` on every `HybridSystem` method at pseudo-random
//! states, sensitivities and parameters.
//!
//! Tolerance: bit for bit, because each kernel evaluates the same DAG in the same order as the
//! evaluator and the host wrappers call the evaluator's own `apply_*`. The one exception is the
//! sign of zero in `flow_sens` and `flow_vjp`: the interpreter accumulates their sums onto
//! `+0.0`, the JIT starts from the first product, so `-0.0` there may come out as `+0.0`; those
//! entries are compared with `==`.

use crate::support::chain::link_chain_source;
use crate::support::hand_functions::same;
use crate::support::models::shipped_models;
use hybc::codegen::{CompileOptions, CompiledModel};
use hybc::lower::{lower, system_info, Interpreter};
use hybc::sema::ParamIdx;
use hybc::sim::HybridSystem;
use proptest::prelude::*;

/// A small deterministic generator (xorshift64*), so failures reproduce.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let bits = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        // Uniform in [-2, 2).
        (bits >> 11) as f64 / (1u64 << 53) as f64 * 4.0 - 2.0
    }
    fn vec(&mut self, len: usize) -> Vec<f64> {
        (0..len).map(|_| self.next()).collect()
    }
}

fn assert_bits(what: &str, jit: &[f64], reference: &[f64]) {
    assert_eq!(jit.len(), reference.len(), "{what}");
    for (i, (a, b)) in jit.iter().zip(reference).enumerate() {
        assert!(
            same(*a, *b),
            "{what}[{i}]: jit {a:e} ({:#x}) vs evaluator {b:e} ({:#x})",
            a.to_bits(),
            b.to_bits()
        );
    }
}

fn assert_values(what: &str, jit: &[f64], reference: &[f64]) {
    assert_eq!(jit.len(), reference.len(), "{what}");
    for (i, (a, b)) in jit.iter().zip(reference).enumerate() {
        assert!(a == b || (a.is_nan() && b.is_nan()), "{what}[{i}]: jit {a:e} vs evaluator {b:e}");
    }
}

/// Runs every method of both systems at the same inputs and compares the results.
fn compare(name: &str, jit: &dyn HybridSystem, reference: &dyn HybridSystem, p: &[f64], rng: &mut Rng) {
    let info = jit.info();
    let (n, m, k) = (info.n_states(), info.n_grad(), info.n_outputs());
    let run2 = |f: &dyn Fn(&dyn HybridSystem, &mut [f64]), len: usize| {
        let mut a = vec![f64::NAN; len];
        let mut b = vec![f64::NAN; len];
        f(jit, &mut a);
        f(reference, &mut b);
        (a, b)
    };

    let (a, b) = run2(&|s, o| s.initial_state(p, o), n);
    assert_bits(&format!("{name} initial_state"), &a, &b);
    let (a, b) = run2(&|s, o| s.initial_sens(p, o), n * m);
    assert_bits(&format!("{name} initial_sens"), &a, &b);

    for trial in 0..20 {
        let t = rng.next() * 5.0;
        let x = rng.vec(n);
        let sens = rng.vec(n * m);
        let weights = rng.vec(n);
        let what = |f: &str| format!("{name} trial {trial} {f}");
        for (mode, mode_info) in info.modes.iter().enumerate() {
            let (a, b) = run2(&|s, o| s.flow(mode, t, &x, p, o), n);
            assert_bits(&what("flow"), &a, &b);
            let (a, b) = run2(&|s, o| s.guards(mode, t, &x, p, o), mode_info.events.len());
            assert_bits(&what("guards"), &a, &b);
            let fs = |s: &dyn HybridSystem| {
                let (mut dx, mut ds) = (vec![f64::NAN; n], vec![f64::NAN; n * m]);
                s.flow_sens(mode, t, &x, &sens, p, &mut dx, &mut ds);
                (dx, ds)
            };
            let ((dxa, dsa), (dxb, dsb)) = (fs(jit), fs(reference));
            assert_bits(&what("flow_sens dx"), &dxa, &dxb);
            assert_values(&what("flow_sens ds"), &dsa, &dsb);
            // The adjoint's products at random weights: sums as
            // `flow_sens`'s, so equal but for the sign of a zero.
            let vjp = |s: &dyn HybridSystem| {
                let (mut gx, mut gp) = (vec![f64::NAN; n], vec![f64::NAN; m]);
                s.flow_vjp(mode, t, &x, &weights, p, &mut gx, &mut gp);
                [gx, gp].concat()
            };
            assert_values(&what("flow_vjp"), &vjp(jit), &vjp(reference));
        }
        for event in 0..info.events.len() {
            let gg = |s: &dyn HybridSystem| {
                let (mut gx, mut gp) = (vec![f64::NAN; n], vec![f64::NAN; m]);
                let gt = s.guard_grad(event, t, &x, p, &mut gx, &mut gp);
                [gx, gp, vec![gt]].concat()
            };
            assert_bits(&what("guard_grad"), &gg(jit), &gg(reference));
            assert_eq!(
                jit.condition(event, t, &x, p),
                reference.condition(event, t, &x, p),
                "{}",
                what("condition")
            );
            let (a, b) = run2(&|s, o| s.reset(event, t, &x, p, o), n);
            assert_bits(&what("reset"), &a, &b);
            let rj = |s: &dyn HybridSystem| {
                let (mut rx, mut rp, mut rt) =
                    (vec![f64::NAN; n * n], vec![f64::NAN; n * m], vec![f64::NAN; n]);
                s.reset_jac(event, t, &x, p, &mut rx, &mut rp, &mut rt);
                [rx, rp, rt].concat()
            };
            assert_bits(&what("reset_jac"), &rj(jit), &rj(reference));
            // The entries the integrator asks for: the pattern's values, scattered, are the
            // same matrix (the reference has no pattern: only the dense form).
            assert!(reference.reset_jac_pattern(event).is_none());
            let pattern = jit.reset_jac_pattern(event).expect("a compiled model gives R_x's pattern");
            let (mut vals, mut rp, mut rt) =
                (vec![f64::NAN; pattern.len()], vec![f64::NAN; n * m], vec![f64::NAN; n]);
            jit.reset_jac_values(event, t, &x, p, &mut vals, &mut rp, &mut rt);
            let mut rx = vec![0.0; n * n];
            for (&(r, c), v) in pattern.iter().zip(vals) {
                rx[r as usize * n + c as usize] = v;
            }
            assert_bits(&what("reset_jac_values"), &[rx, rp, rt].concat(), &rj(reference));
        }
        let (a, b) = run2(&|s, o| s.outputs(t, &x, p, o), k);
        assert_bits(&what("outputs"), &a, &b);
        let oj = |s: &dyn HybridSystem| {
            let (mut yx, mut yp, mut yt) = (vec![f64::NAN; k * n], vec![f64::NAN; k * m], vec![f64::NAN; k]);
            s.output_jac(t, &x, p, &mut yx, &mut yp, &mut yt);
            [yx, yp, yt].concat()
        };
        assert_bits(&what("output_jac"), &oj(jit), &oj(reference));
    }
}

/// Compiles `source` with all parameters and with a reordered subset differentiated, and compares
/// the JIT with the interpreter on every method.
fn compare_model_text(name: &str, source: &str, rng: &mut Rng) {
    let model = hybc::check_source(source).unwrap_or_else(|e| panic!("{name}: {e}\n{source}"));
    let funcs = lower(&model);
    let p: Vec<f64> = model.params.iter().map(|p| p.default).collect();
    // All parameters, and then every other one in reverse order, so the column mapping of a
    // strict, reordered subset is exercised too.
    let all: Vec<ParamIdx> = (0..model.n_params() as u32).map(ParamIdx).collect();
    let some: Vec<ParamIdx> = all.iter().rev().step_by(2).copied().collect();
    for grad in [all, some] {
        let info = system_info(&model, &grad);
        let reference = Interpreter::new(funcs.clone(), info.clone());
        // Also with every kernel cut into parts of at most two operations (separate native
        // functions called in order), as big models' kernels are.
        for max_part_size in [CompileOptions::default().max_part_size, 2] {
            let opts = CompileOptions { max_part_size, ..CompileOptions::default() };
            let jit =
                CompiledModel::compile(&funcs, info.clone(), &opts).unwrap_or_else(|e| panic!("{name}: {e}"));
            compare(name, &jit, &reference, &p, rng);
        }
    }
}

/// A random real expression over `names` using the whole language (operators, every function,
/// `if` with `and`/`or`/`not`, `t` where `with_time`, `pi`), as .hyb text.
/// A random expression of `names` (and `t` when `with_time`); with `jumps`, also `sign` and
/// `if` (a guard may not have them where they move with the time or the state).
fn expr_text(names: Vec<String>, with_time: bool) -> impl Strategy<Value = String> {
    expr_text_with(names, with_time, true)
}

fn expr_text_with(names: Vec<String>, with_time: bool, jumps: bool) -> impl Strategy<Value = String> {
    let time = if with_time { "t" } else { "pi" };
    let leaf = prop_oneof![
        (-30i32..30).prop_map(|k| format!("{}", k as f64 / 4.0)),
        prop::sample::select(names),
        Just(time.to_string()),
        Just("pi".to_string()),
    ];
    leaf.prop_recursive(4, 24, 3, move |inner| {
        let mut unaries = vec![
            "sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh", "exp", "log", "sqrt", "abs",
        ];
        if jumps {
            unaries.push("sign");
        }
        let unary = prop::sample::select(unaries);
        let binary = prop::sample::select(vec!["atan2", "min", "max", "pow", "hypot"]);
        let op = prop::sample::select(vec!["+", "-", "*", "/", "^"]);
        let cmp = prop::sample::select(vec!["<", "<=", ">", ">="]);
        let mut arms: Vec<BoxedStrategy<String>> = vec![
            (op, inner.clone(), inner.clone()).prop_map(|(o, a, b)| format!("({a} {o} {b})")).boxed(),
            inner.clone().prop_map(|a| format!("(-{a})")).boxed(),
            (unary, inner.clone()).prop_map(|(f, a)| format!("{f}({a})")).boxed(),
            (binary, inner.clone(), inner.clone()).prop_map(|(f, a, b)| format!("{f}({a}, {b})")).boxed(),
        ];
        if jumps {
            arms.push(
                (cmp.clone(), cmp, inner.clone(), inner.clone(), inner.clone(), inner.clone(), any::<u8>())
                    .prop_map(|(c1, c2, a, b, x, y, shape)| {
                        let cond = match shape % 3 {
                            0 => format!("{a} {c1} {b}"),
                            1 => format!("{a} {c1} {b} and not ({x} {c2} {y})"),
                            _ => format!("{a} {c1} {b} or {x} {c2} {y}"),
                        };
                        format!("(if {cond} then {x} else {y})")
                    })
                    .boxed(),
            );
        }
        prop::strategy::Union::new(arms)
    })
}

/// A random well-formed model: 1-4 states, 1-3 parameters, one or two modes, an event per mode
/// with a random guard, condition and resets, and a random output.
fn model_text() -> impl Strategy<Value = String> {
    (1usize..=4, 1usize..=3, any::<bool>()).prop_flat_map(|(n, m, two_modes)| {
        let states: Vec<String> = (0..n).map(|i| format!("x{i}")).collect();
        let params: Vec<String> = (0..m).map(|j| format!("p{j}")).collect();
        let all: Vec<String> = states.iter().chain(&params).cloned().collect();
        let modes = if two_modes { 2 } else { 1 };
        (
            prop::collection::vec(expr_text(params.clone(), false), n),
            prop::collection::vec(expr_text(all.clone(), true), n * modes),
            prop::collection::vec(expr_text_with(all.clone(), true, false), modes),
            prop::collection::vec(expr_text(all.clone(), true), modes),
            prop::collection::vec(expr_text(all.clone(), true), n),
            expr_text(all, true),
            prop::collection::vec(-20i32..20, m),
        )
            .prop_map(move |(inits, flows, guards, conditions, resets, output, defaults)| {
                let mut s = String::from("model generated\n");
                for (j, d) in defaults.iter().enumerate() {
                    s.push_str(&format!("param p{j} = {}\n", *d as f64 / 8.0));
                }
                for (i, init) in inits.iter().enumerate() {
                    s.push_str(&format!("state x{i} = {init}\n"));
                }
                for mode in 0..modes {
                    let (open, close) = match (modes, mode) {
                        (1, _) => (String::new(), String::new()),
                        (_, 0) => ("initial mode a {\n".to_string(), "}\n".to_string()),
                        _ => ("mode b {\n".to_string(), "}\n".to_string()),
                    };
                    s.push_str(&open);
                    for i in 0..n {
                        s.push_str(&format!("der(x{i}) = {}\n", flows[mode * n + i]));
                    }
                    let target = match (modes, mode) {
                        (1, _) => "",
                        (_, 0) => " -> b",
                        _ => " -> a",
                    };
                    let (g, c) = (&guards[mode], &conditions[mode]);
                    s.push_str(&format!("event e{mode} when {g} crosses x0 if {c} > 0{target} {{\n"));
                    s.push_str(&format!("    x{} := {}\n", mode % n, resets[mode % n]));
                    s.push_str("}\n");
                    s.push_str(&close);
                }
                s.push_str(&format!("output y = {output}\n"));
                s
            })
    })
}

proptest! {
    #![proptest_config(crate::support::proptest_config(48))]

    /// Random well-formed models of random sizes through the whole pipeline: the JIT agrees with
    /// the interpreter on every method, bit for bit.
    #[test]
    fn generated_models_match_the_interpreter(source in model_text(), seed in any::<u64>()) {
        compare_model_text("generated", &source, &mut Rng(seed | 1));
    }
}

#[test]
fn every_shipped_model_matches_the_interpreter() {
    let models = shipped_models();
    assert!(models.len() >= 5, "expected the shipped models, found {}", models.len());
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for model in models {
        compare_model_text(&model.name, &model.source, &mut rng);
    }
}

#[test]
fn a_large_forward_sensitivity_kernel_is_compiled_on_first_use_and_matches_the_interpreter() {
    // 40 cells, the 40 parameters differentiated: `flow_sens` has 40 * (40 + 118) = 6,320 in size,
    // over the limit of 5,000 (`plan::EAGER_FLOW_SENS_LIMIT`), so it is not among the kernels
    // compiled with the model: flow, guards, guard speeds, the event's guard gradient and
    // reset and reset Jacobian, init, init_sens, outputs, output_jac.
    let source = link_chain_source(40, 2.0, true);
    let model = hybc::check_source(&source).expect("checks");
    let funcs = lower(&model);
    let all: Vec<ParamIdx> = (0..model.n_params() as u32).map(ParamIdx).collect();
    let opts = CompileOptions::default();
    let deferred = CompiledModel::compile(&funcs, system_info(&model, &all), &opts).expect("compiles");
    assert_eq!(deferred.n_kernels(), 10, "without flow_sens");
    // The other side: with a few parameters differentiated (2 * 158 in size) it is compiled with
    // the model, one kernel more.
    let few = CompiledModel::compile(&funcs, system_info(&model, &all[..2]), &opts).expect("compiles");
    assert_eq!(few.n_kernels(), 11, "with flow_sens");
    // On first use, the same values as the interpreter's (every method, bit for bit but the
    // sign of a zero in the sums, as for the shipped models).
    let mut rng = Rng(0x2545_F491_4F6C_DD1D);
    compare_model_text("link chain", &source, &mut rng);
}
