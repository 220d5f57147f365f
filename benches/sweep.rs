//! Sweep throughput: the compiled bouncing ball with gradients for all three parameters, at the
//! model's own settings (T = 2.5, rtol 1e-10, atol 1e-12), over 10 000 points of e in
//! [0.75, 0.95] (every one runs to T without Zeno), on 1 and 2 threads. Criterion reports the
//! time per sweep and the points per second (throughput in elements).
//! Run: `cargo bench --bench sweep`.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use hybc::codegen::{compile, CompileOptions};
use hybc::lower::{lower, system_info};
use hybc::sema::ParamIdx;
use hybc::sim::SimOptions;
use hybc::sweep;

const POINTS: usize = 10_000;

fn ball_sweep(c: &mut Criterion) {
    let model = hybc::check_source(include_str!("../models/ball.hyb")).expect("ball checks");
    let grad = [ParamIdx(0), ParamIdx(1), ParamIdx(2)];
    let compiled =
        compile(&lower(&model), system_info(&model, &grad), &CompileOptions::default()).expect("compiles");
    let opts = SimOptions { t_end: 2.5, rtol: 1e-10, atol: 1e-12, ..SimOptions::default() };
    let base: Vec<f64> = model.params.iter().map(|p| p.default).collect();
    let points = sweep::full_grid(&base, &[(1, sweep::linspace(0.75, 0.95, POINTS))]);
    let mut group = c.benchmark_group("sweep_ball_grad_all_T2.5_rtol1e-10");
    group.throughput(Throughput::Elements(POINTS as u64));
    group.sample_size(20);
    for threads in [1, 2] {
        group.bench_function(format!("{POINTS}_points_{threads}_threads"), |b| {
            b.iter(|| sweep::run_points(&compiled, black_box(&points), &opts, threads, &|| ()).expect("pool"))
        });
    }
    group.finish();
}

criterion_group!(benches, ball_sweep);
criterion_main!(benches);
