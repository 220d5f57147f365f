//! What the Rosenbrock methods cost at compile time (issue #25), on the generated chain models
//! (10, 100, 1000 states, all three parameters differentiated): the time to compile the model
//! (which now keeps a copy of its functions for the stiff kernels: `ModelFunctions::clone`,
//! timed alone too) and the time to compile the stiff kernels on the first Rosenbrock run
//! (`HybridSystem::prepare_jacobians`: second derivatives, a second JIT module) and the adjoint's
//! kernels on the first `HybridSystem::flow_vjp` call (a third module, issue #40); then one run to
//! T = 10 with Dormand-Prince and with Rodas5P (steps, run time). Best of a few repetitions.
//!
//! Run: `cargo run --release --example stiff_compile`. The figures are in docs/performance.md.

use hybc::codegen::{CompileOptions, CompiledModel};
use hybc::lower::{lower, system_info};
use hybc::sema::ParamIdx;
use hybc::sim::{HybridSystem, Method, Runner, SimOptions};
use std::time::Instant;
#[path = "../support/chain.rs"]
mod chain;
use chain::best;

fn main() {
    for n in [10usize, 100, 1000] {
        let model = hybc::check_source(&chain::chain_source(n)).unwrap();
        let grad: Vec<ParamIdx> = (0..model.n_params() as u32).map(ParamIdx).collect();
        let (funcs, info) = (lower(&model), system_info(&model, &grad));
        let reps = if n == 1000 { 3 } else { 9 };
        let (clone_ms, _) = best(reps, || funcs.clone());
        let (compile_ms, _) =
            best(reps, || CompiledModel::compile(&funcs, info.clone(), &CompileOptions::default()).unwrap());
        let stiff = (0..reps)
            .map(|_| {
                let m = CompiledModel::compile(&funcs, info.clone(), &CompileOptions::default()).unwrap();
                let start = Instant::now();
                m.prepare_jacobians().unwrap();
                start.elapsed().as_secs_f64() * 1e3
            })
            .fold(f64::INFINITY, f64::min);
        let p: Vec<f64> = model.params.iter().map(|p| p.default).collect();
        // The adjoint's kernels, compiled on the first `flow_vjp` call (issue #40).
        let vjp = (0..reps)
            .map(|_| {
                let m = CompiledModel::compile(&funcs, info.clone(), &CompileOptions::default()).unwrap();
                let (x, w) = (vec![0.5; n], vec![1.0; n]);
                let (mut gx, mut gp) = (vec![0.0; n], vec![0.0; info.n_grad()]);
                let start = Instant::now();
                m.flow_vjp(0, 0.0, &x, &w, &p, &mut gx, &mut gp);
                assert!(gx.iter().chain(&gp).all(|g| g.is_finite()));
                start.elapsed().as_secs_f64() * 1e3
            })
            .fold(f64::INFINITY, f64::min);
        let m = CompiledModel::compile(&funcs, info.clone(), &CompileOptions::default()).unwrap();
        let mut runs = Vec::new();
        for method in [Method::Dopri5, Method::Rodas5p] {
            let opts = SimOptions { t_end: 10.0, rtol: 1e-8, atol: 1e-10, method, ..SimOptions::default() };
            let mut sim = Runner::new(&m, &opts).unwrap();
            let (ms, r) = best(reps, || sim.run(&p).unwrap());
            runs.push(format!(
                "{method:?} {} steps ({} rejected) {ms:.3} ms",
                r.stats.steps, r.stats.rejected
            ));
        }
        println!(
            "n = {n}: compile {compile_ms:.2} ms (of which clone {clone_ms:.3} ms), stiff kernels {stiff:.2} ms, \
             adjoint kernels {vjp:.2} ms; {}",
            runs.join("; ")
        );
    }
}
