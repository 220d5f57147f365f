//! The adjoint's `flow_vjp` under a control of K knots (issue #40 section 4): a two-state model
//! `der(y) = v`, `der(v) = pwl(t, 0, T, u) - c v` with `u` of K = 10, 100, 1000, 10,000
//! elements, every parameter differentiated (K + 2 columns). Per K: the first `flow_vjp` call
//! (which compiles the adjoint's kernel: best of a few fresh models), one call (median of
//! batches, at times spread over the window so every segment is visited), and one `flow_sens`
//! call beside it (the forward sensitivities, whose `f_p` has a column per knot), and the time of
//! zero-filling `gp` (K + 2 entries, which the trait's `flow_vjp` overwrites: every call pays it
//! whatever its kernel does).
//!
//! Run: `cargo run --release --example vjp_knots [K ...]`. Compare builds by running their
//! binaries alternately (the figures in docs/performance.md were taken so).

use hybc::codegen::{CompileOptions, CompiledModel};
use hybc::lower::{lower, system_info};
use hybc::sema::ParamIdx;
use hybc::sim::HybridSystem;
use std::time::Instant;

fn source(k: usize) -> String {
    format!(
        "model control\nparam c = 0.5\nparam T = 10\nparam u[{k}] = 0.1\nstate y = 1\nstate v = 0\n\
         der(y) = v\nder(v) = pwl(t, 0, T, u) - c * v\n"
    )
}

/// Median over `batches` of the time per call of `f` in batches of `per` calls, in microseconds.
fn per_call(batches: usize, per: usize, mut f: impl FnMut(usize)) -> f64 {
    let mut times: Vec<f64> = (0..batches)
        .map(|b| {
            let start = Instant::now();
            for i in 0..per {
                f(b * per + i);
            }
            start.elapsed().as_secs_f64() * 1e6 / per as f64
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[batches / 2]
}

fn main() {
    let ks: Vec<usize> = std::env::args().skip(1).map(|a| a.parse().expect("a knot count")).collect();
    let ks = if ks.is_empty() { vec![10, 100, 1000, 10_000] } else { ks };
    println!(
        "{:>6} {:>14} {:>14} {:>14} {:>14}",
        "K", "first call ms", "vjp call us", "gp fill us", "flow_sens us"
    );
    for k in ks {
        let model = hybc::check_source(&source(k)).expect("checks");
        let grad: Vec<ParamIdx> = (0..model.n_params() as u32).map(ParamIdx).collect();
        let (funcs, info) = (lower(&model), system_info(&model, &grad));
        let p: Vec<f64> = model.params.iter().map(|p| p.default).collect();
        let m = info.n_grad();
        let (x, w) = ([0.5, -0.25], [1.0, 0.75]);
        let reps = if k >= 10_000 { 2 } else { 5 };
        let mut first = f64::INFINITY;
        let mut sys = None;
        for _ in 0..reps {
            let s =
                CompiledModel::compile(&funcs, info.clone(), &CompileOptions::default()).expect("compiles");
            let (mut gx, mut gp) = ([0.0; 2], vec![0.0; m]);
            let start = Instant::now();
            s.flow_vjp(0, 0.3, &x, &w, &p, &mut gx, &mut gp);
            first = first.min(start.elapsed().as_secs_f64() * 1e3);
            assert!(gx.iter().chain(&gp).all(|g| g.is_finite()));
            sys = Some(s);
        }
        let sys = sys.expect("compiled");
        let time = |i: usize| 10.0 * (i % 997) as f64 / 997.0;
        let (mut gx, mut gp) = ([0.0; 2], vec![0.0; m]);
        let per = (200_000 / k).clamp(20, 20_000);
        let vjp = per_call(15, per, |i| sys.flow_vjp(0, time(i), &x, &w, &p, &mut gx, &mut gp));
        let (mut dx, s, mut ds) = ([0.0; 2], vec![0.0; 2 * m], vec![0.0; 2 * m]);
        let sens = per_call(15, per, |i| sys.flow_sens(0, time(i), &x, &s, &p, &mut dx, &mut ds));
        // The zero fill of `gp` alone, which every call pays (the trait overwrites `gp`).
        let fill = per_call(15, per, |i| {
            gp.fill(0.0);
            gp[i % m] = std::hint::black_box(1.0);
        });
        println!("{k:>6} {first:>14.3} {vjp:>14.3} {fill:>14.3} {sens:>14.3}");
    }
}
