//! Criterion benchmarks of the JIT (`codegen`): compile time, parse to callable kernels, of every
//! shipped model; nanoseconds per call of the flow and fused sensitivity kernels for the JIT, the
//! reference `Interpreter` and the same model written by hand in Rust (the ball and a 100-state
//! chain); compile time of generated chain models with 10, 100 and 1000 states.
//!
//! The hand-written functions are `#[inline(never)]` and take the mode like
//! `HybridSystem::flow` (a bad mode poisons the output with NaN, as the compiled model does): the
//! integrator always calls a model out of line through that interface, so the fair comparison is
//! an out-of-line call to the same math behind the same contract. The JIT side is called through
//! `HybridSystem` (slice lengths checked, then the native kernel).
//!
//! Run with `cargo bench --bench jit` on an otherwise idle machine.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use hybc::codegen::{CompileOptions, CompiledModel};
use hybc::expr::ModelFunctions;
use hybc::lower::{lower, system_info, Interpreter};
use hybc::sema::ParamIdx;
use hybc::sim::{HybridSystem, SystemInfo};

#[path = "support/chain.rs"]
mod chain;
use chain::chain_source;

// The shipped-model list the tests use (`tests/it/support/models.rs`: `models/*.hyb`, sorted).
#[path = "../tests/it/support/models.rs"]
mod models;
use models::shipped_models;

const BALL: &str = include_str!("../models/ball.hyb");

/// Parses, checks and lowers a model, differentiating every parameter.
fn front_end(source: &str) -> (ModelFunctions, SystemInfo) {
    let model = hybc::check_source(source).expect("a valid model");
    let grad: Vec<ParamIdx> = (0..model.n_params() as u32).map(ParamIdx).collect();
    (lower(&model), system_info(&model, &grad))
}

/// The ball's flow by hand: `der(y) = v, der(v) = -g`.
#[inline(never)]
fn ball_flow(mode: usize, _t: f64, x: &[f64], p: &[f64], dx: &mut [f64]) {
    if mode != 0 {
        return dx.fill(f64::NAN);
    }
    dx[0] = x[1];
    dx[1] = -p[0];
}

/// The ball's fused sensitivity right-hand side by hand, parameters `(g, e, h0)` all
/// differentiated: `f_x = [[0, 1], [0, 0]]`, `f_p` has the single entry `df_v/dg = -1`.
#[inline(never)]
fn ball_flow_sens(mode: usize, _t: f64, x: &[f64], s: &[f64], p: &[f64], dx: &mut [f64], ds: &mut [f64]) {
    if mode != 0 {
        dx.fill(f64::NAN);
        return ds.fill(f64::NAN);
    }
    dx[0] = x[1];
    dx[1] = -p[0];
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
    flow.bench_function("rust", |b| b.iter(|| ball_flow(0, 0.0, black_box(&x), black_box(&p), &mut dx)));
    flow.finish();

    let mut sens = c.benchmark_group("ball/flow_sens");
    sens.bench_function("jit", |b| {
        b.iter(|| jit.flow_sens(0, 0.0, black_box(&x), black_box(&s), &p, &mut dx, &mut ds))
    });
    sens.bench_function("interpreter", |b| {
        b.iter(|| interp.flow_sens(0, 0.0, black_box(&x), black_box(&s), &p, &mut dx, &mut ds))
    });
    sens.bench_function("rust", |b| {
        b.iter(|| ball_flow_sens(0, 0.0, black_box(&x), black_box(&s), &p, &mut dx, &mut ds))
    });
    sens.finish();
}

/// The chain's flow by hand (see `chain_source`), parameters `(k, c, a)`.
#[inline(never)]
fn chain_flow(mode: usize, x: &[f64], p: &[f64], dx: &mut [f64]) {
    if mode != 0 {
        return dx.fill(f64::NAN);
    }
    chain_flow_body(x, p, dx);
}

#[inline(always)]
fn chain_flow_body(x: &[f64], p: &[f64], dx: &mut [f64]) {
    let (k, c) = (p[0], p[1]);
    dx[0] = -k * x[0];
    for i in 1..x.len() {
        dx[i] = k * (x[i - 1] - x[i]) - c * x[i] * x[i];
    }
}

/// The chain's fused sensitivity right-hand side by hand: `ds_j = f_x s_j + f_p[:, j]` with
/// `f_x` lower bidiagonal and `f_p = [x_{i-1} - x_i, -x_i^2, 0]` (`-x_0`, 0, 0 in row 0).
#[inline(never)]
fn chain_flow_sens(mode: usize, x: &[f64], s: &[f64], p: &[f64], dx: &mut [f64], ds: &mut [f64]) {
    if mode != 0 {
        dx.fill(f64::NAN);
        return ds.fill(f64::NAN);
    }
    chain_flow_body(x, p, dx);
    let (k, c, n) = (p[0], p[1], x.len());
    for j in 0..3 {
        let (sj, dsj) = (&s[j * n..(j + 1) * n], &mut ds[j * n..(j + 1) * n]);
        dsj[0] = -k * sj[0] + if j == 0 { -x[0] } else { 0.0 };
        for i in 1..n {
            let fp = match j {
                0 => x[i - 1] - x[i],
                1 => -x[i] * x[i],
                _ => 0.0,
            };
            dsj[i] = k * sj[i - 1] + (-k - 2.0 * c * x[i]) * sj[i] + fp;
        }
    }
}

fn bench_chain_calls(c: &mut Criterion) {
    const N: usize = 100;
    let (funcs, info) = front_end(&chain_source(N));
    let jit = CompiledModel::compile(&funcs, info.clone(), &CompileOptions::default()).expect("compiles");
    let interp = Interpreter::new(funcs, info);
    let x: Vec<f64> = (0..N).map(|i| 0.5 + 0.01 * i as f64).collect();
    let s: Vec<f64> = (0..3 * N).map(|i| 0.001 * i as f64).collect();
    let p = [0.5, 0.1, 1.0];
    let (mut dx, mut ds) = (vec![0.0; N], vec![0.0; 3 * N]);
    // The hand-written version must compute what the JIT computes, or the comparison is void.
    let (mut dx_ref, mut ds_ref) = (vec![0.0; N], vec![0.0; 3 * N]);
    jit.flow_sens(0, 0.0, &x, &s, &p, &mut dx, &mut ds);
    chain_flow_sens(0, &x, &s, &p, &mut dx_ref, &mut ds_ref);
    for (a, b) in dx.iter().chain(&ds).zip(dx_ref.iter().chain(&ds_ref)) {
        assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0), "hand-written chain differs: {a} vs {b}");
    }
    let mut flow = c.benchmark_group("chain100/flow");
    flow.bench_function("jit", |b| b.iter(|| jit.flow(0, 0.0, black_box(&x), black_box(&p), &mut dx)));
    flow.bench_function("interpreter", |b| {
        b.iter(|| interp.flow(0, 0.0, black_box(&x), black_box(&p), &mut dx))
    });
    flow.bench_function("rust", |b| b.iter(|| chain_flow(0, black_box(&x), black_box(&p), &mut dx)));
    flow.finish();
    let mut sens = c.benchmark_group("chain100/flow_sens");
    sens.bench_function("jit", |b| {
        b.iter(|| jit.flow_sens(0, 0.0, black_box(&x), black_box(&s), &p, &mut dx, &mut ds))
    });
    sens.bench_function("interpreter", |b| {
        b.iter(|| interp.flow_sens(0, 0.0, black_box(&x), black_box(&s), &p, &mut dx, &mut ds))
    });
    sens.bench_function("rust", |b| {
        b.iter(|| chain_flow_sens(0, black_box(&x), black_box(&s), &p, &mut dx, &mut ds))
    });
    sens.finish();
}

/// Parse, check, lower and compile (all parameters differentiated): what `hybc run` pays once.
fn bench_model_compile(c: &mut Criterion) {
    let mut group = c.benchmark_group("compile/model");
    for models::ShippedModel { name, source, .. } in shipped_models() {
        group.bench_function(name, |b| {
            b.iter(|| {
                let (funcs, info) = front_end(black_box(&source));
                CompiledModel::compile(&funcs, info, &CompileOptions::default()).expect("compiles")
            })
        });
    }
    group.finish();
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

criterion_group!(benches, bench_model_compile, bench_ball, bench_chain_calls, bench_chain_compile);
criterion_main!(benches);
