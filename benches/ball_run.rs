//! One run of the compiled bouncing ball to T = 2.5 at rtol 1e-10 with gradients with respect to
//! all three parameters (the headline figure of docs/performance.md), plus the same without gradients. Each is
//! timed twice: through `sim::run` (a fresh `Runner` per run: options checked and scratch
//! buffers allocated every time) and through one `Runner` reused for every run, which is what
//! sweeps, fits and gradient checks do. Last, the reused run with gradients and 100 `--at` samples
//! from the dense output, against the same run without (`_at100`); and the same pair on the dosing
//! model (two doses, gradients with respect to ka and ke, 53 steps to t = 12), the shape of a fit
//! to a time series.
//! Run: `cargo bench --bench ball_run`.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use hybc::codegen::{compile, CompileOptions};
use hybc::lower::{lower, system_info};
use hybc::sema::ParamIdx;
use hybc::sim::{run, Runner, SimOptions};

fn ball_run(c: &mut Criterion) {
    let model = hybc::check_source(include_str!("../models/ball.hyb")).expect("ball checks");
    let funcs = lower(&model);
    let opts = SimOptions { t_end: 2.5, rtol: 1e-10, atol: 1e-12, ..SimOptions::default() };
    let p: Vec<f64> = model.params.iter().map(|p| p.default).collect();
    for (label, grad) in [("grad_all", vec![ParamIdx(0), ParamIdx(1), ParamIdx(2)]), ("no_grad", vec![])] {
        let compiled =
            compile(&funcs, system_info(&model, &grad), &CompileOptions::default()).expect("compiles");
        c.bench_function(&format!("ball_run_T2.5_rtol1e-10_{label}"), |b| {
            b.iter(|| run(black_box(&compiled), black_box(&p), &opts).expect("runs"))
        });
        let mut sim = Runner::new(&compiled, &opts).expect("valid options");
        c.bench_function(&format!("ball_run_T2.5_rtol1e-10_{label}_reused_simulator"), |b| {
            b.iter(|| sim.run(black_box(&p)).expect("runs"))
        });
        if label == "grad_all" {
            let at: Vec<f64> = (0..100).map(|k| 2.5 * k as f64 / 99.0).collect();
            let sampled = SimOptions { at, ..opts.clone() };
            let mut sim = Runner::new(&compiled, &sampled).expect("valid options");
            c.bench_function("ball_run_T2.5_rtol1e-10_grad_all_reused_simulator_at100", |b| {
                b.iter(|| sim.run(black_box(&p)).expect("runs"))
            });
        }
    }
}

fn dosing_samples(c: &mut Criterion) {
    let model = hybc::check_source(include_str!("../models/dosing.hyb")).expect("dosing checks");
    let funcs = lower(&model);
    let grad = vec![model.param_index("ka").expect("ka"), model.param_index("ke").expect("ke")];
    let compiled = compile(&funcs, system_info(&model, &grad), &CompileOptions::default()).expect("compiles");
    let p: Vec<f64> = model.params.iter().map(|p| p.default).collect();
    let opts = SimOptions { t_end: 12.0, rtol: 1e-10, atol: 1e-12, ..SimOptions::default() };
    let at: Vec<f64> = (0..100).map(|k| 12.0 * k as f64 / 99.0).collect();
    for (label, opts) in [("", opts.clone()), ("_at100", SimOptions { at, ..opts })] {
        let mut sim = Runner::new(&compiled, &opts).expect("valid options");
        c.bench_function(&format!("dosing_run_T12_grad_ka_ke_reused_simulator{label}"), |b| {
            b.iter(|| sim.run(black_box(&p)).expect("runs"))
        });
    }
}

fn ball_compile(c: &mut Criterion) {
    let source = include_str!("../models/ball.hyb");
    c.bench_function("ball_compile_parse_to_kernels_grad_all", |b| {
        b.iter(|| {
            let model = hybc::check_source(black_box(source)).expect("ball checks");
            let funcs = lower(&model);
            let grad: Vec<ParamIdx> = (0..model.params.len() as u32).map(ParamIdx).collect();
            compile(&funcs, system_info(&model, &grad), &CompileOptions::default()).expect("compiles")
        })
    });
}

criterion_group!(benches, ball_run, dosing_samples, ball_compile);
criterion_main!(benches);
