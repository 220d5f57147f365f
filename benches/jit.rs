//! Criterion benchmarks of the JIT (`codegen`): compile time of the bouncing ball; nanoseconds per
//! call of its flow and fused sensitivity kernels for the JIT, the reference `Interpreter` and
//! hand-written Rust; compile time of generated chain models with 10, 100 and 1000 states.
//!
//! Run with `cargo bench --bench jit` on an otherwise idle machine.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use hybc::codegen::{CompileOptions, CompiledModel};
use hybc::expr::ModelFunctions;
use hybc::lower::{lower, system_info, Interpreter};
use hybc::sema::ParamIdx;
use hybc::sim::{HybridSystem, SystemInfo};

const BALL: &str = include_str!("../models/ball.hyb");

/// Parses, checks and lowers a model, differentiating every parameter.
fn front_end(source: &str) -> (ModelFunctions, SystemInfo) {
    let model = hybc::check_source(source).expect("a valid model");
    let grad: Vec<ParamIdx> = (0..model.n_params() as u32).map(ParamIdx).collect();
    (lower(&model), system_info(&model, &grad))
}

/// A chain of `n` states: `x0` decays, each later state relaxes towards its predecessor with a
/// quadratic loss; one event resets the last state.
fn chain_source(n: usize) -> String {
    let mut s = String::from("model chain\nparam k = 0.5\nparam c = 0.1\nparam a = 1.0\n");
    s.push_str("state x0 = a\n");
    for i in 1..n {
        s.push_str(&format!("state x{i} = 0\n"));
    }
    s.push_str("der(x0) = -k * x0\n");
    for i in 1..n {
        s.push_str(&format!("der(x{i}) = k * (x{} - x{i}) - c * x{i} * x{i}\n", i - 1));
    }
    let last = n - 1;
    s.push_str(&format!("event full when x{last} >= 0.5 {{\n    x{last} := 0\n}}\n"));
    s.push_str(&format!("output y = x{last}\n"));
    s
}

/// The ball's flow by hand: `der(y) = v, der(v) = -g`.
fn ball_flow(_t: f64, x: &[f64], p: &[f64], dx: &mut [f64]) {
    dx[0] = x[1];
    dx[1] = -p[0];
}

/// The ball's fused sensitivity right-hand side by hand, parameters `(g, e, h0)` all
/// differentiated: `f_x = [[0, 1], [0, 0]]`, `f_p` has the single entry `df_v/dg = -1`.
fn ball_flow_sens(t: f64, x: &[f64], s: &[f64], p: &[f64], dx: &mut [f64], ds: &mut [f64]) {
    ball_flow(t, x, p, dx);
    for j in 0..3 {
        ds[2 * j] = s[2 * j + 1];
        ds[2 * j + 1] = if j == 0 { -1.0 } else { 0.0 };
    }
}

fn bench_ball(c: &mut Criterion) {
    let (funcs, info) = front_end(BALL);
    let opts = CompileOptions::default();
    c.bench_function("compile/ball", |b| {
        b.iter(|| CompiledModel::compile(black_box(&funcs), info.clone(), &opts).expect("compiles"))
    });

    let jit = CompiledModel::compile(&funcs, info.clone(), &opts).expect("compiles");
    let interp = Interpreter::new(funcs.clone(), info);
    let (x, p, s) = ([0.7, -1.3], [9.81, 0.8, 1.0], [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]);
    let (mut dx, mut ds) = ([0.0; 2], [0.0; 6]);

    let mut flow = c.benchmark_group("ball/flow");
    flow.bench_function("jit", |b| b.iter(|| jit.flow(0, 0.0, black_box(&x), black_box(&p), &mut dx)));
    flow.bench_function("interpreter", |b| {
        b.iter(|| interp.flow(0, 0.0, black_box(&x), black_box(&p), &mut dx))
    });
    flow.bench_function("rust", |b| b.iter(|| ball_flow(0.0, black_box(&x), black_box(&p), &mut dx)));
    flow.finish();

    let mut sens = c.benchmark_group("ball/flow_sens");
    sens.bench_function("jit", |b| {
        b.iter(|| jit.flow_sens(0, 0.0, black_box(&x), black_box(&s), &p, &mut dx, &mut ds))
    });
    sens.bench_function("interpreter", |b| {
        b.iter(|| interp.flow_sens(0, 0.0, black_box(&x), black_box(&s), &p, &mut dx, &mut ds))
    });
    sens.bench_function("rust", |b| {
        b.iter(|| ball_flow_sens(0.0, black_box(&x), black_box(&s), &p, &mut dx, &mut ds))
    });
    sens.finish();
}

fn bench_chain_compile(c: &mut Criterion) {
    let mut group = c.benchmark_group("compile/chain");
    group.sample_size(10);
    let opts = CompileOptions::default();
    for n in [10, 100, 1000] {
        let (funcs, info) = front_end(&chain_source(n));
        group.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter(|| CompiledModel::compile(&funcs, info.clone(), &opts).expect("compiles"))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_ball, bench_chain_compile);
criterion_main!(benches);
