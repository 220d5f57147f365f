//! The ball energy fit of docs/fit.md: free e, one target energy = 2 at T = 2.5 (rtol 1e-10), from
//! the model's e = 0.8 (same bounce count as the solution) and from e = 0.9 (one bounce fewer, so
//! the fit crosses a cusp). Only the iterations are timed: the model is compiled once outside the
//! loop; its compile time is the separate `fit_ball_compile_grad_e`.
//! Run: `cargo bench --bench fit`.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use hybc::codegen::{compile, CompileOptions};
use hybc::fit::{fit, Bounds, FitOptions, FitProblem, Target};
use hybc::lower::{lower, system_info};
use hybc::sim::{HybridSystem, SimOptions};

const BALL: &str = include_str!("../models/ball.hyb");

fn ball_energy_fit(c: &mut Criterion) {
    let model = hybc::check_source(BALL).expect("ball checks");
    let e = model.param_index("e").expect("e");
    let compiled =
        compile(&lower(&model), system_info(&model, &[e]), &CompileOptions::default()).expect("compiles");
    let target = Target::parse("energy=2.0", compiled.info()).expect("target");
    for start in [0.8, 0.9] {
        let mut p: Vec<f64> = model.params.iter().map(|p| p.default).collect();
        p[e.0 as usize] = start;
        let problem = FitProblem {
            system: &compiled,
            start: p,
            bounds: vec![Bounds::from_range(model.params[e.0 as usize].range)],
            targets: vec![target.clone()],
            sim: SimOptions { t_end: 2.5, rtol: 1e-10, atol: 1e-12, ..SimOptions::default() },
        };
        let result = fit(&problem, &FitOptions::default()).expect("fit starts");
        assert!(result.is_converged(), "{:?}", result.stop);
        let runs = result.iterations.len();
        c.bench_function(&format!("fit_ball_energy_from_e{start}_{runs}_runs"), |b| {
            b.iter(|| fit(black_box(&problem), &FitOptions::default()).expect("fit starts"))
        });
    }
}

fn ball_compile(c: &mut Criterion) {
    c.bench_function("fit_ball_compile_grad_e", |b| {
        b.iter(|| {
            let model = hybc::check_source(black_box(BALL)).expect("ball checks");
            let e = model.param_index("e").expect("e");
            compile(&lower(&model), system_info(&model, &[e]), &CompileOptions::default()).expect("compiles")
        })
    });
}

criterion_group!(benches, ball_energy_fit, ball_compile);
criterion_main!(benches);
