//! Workload W5 of issue #25: the diffusion chain (`benches/support/chain.rs`,
//! `diffusion_source`: N states, 10 conductances `d[0..9]`, a top-up event on `x0`), the 10
//! conductances differentiated, to T = 10 at rtol 1e-8, atol 1e-10. For each N: the time to
//! check and compile the model, to compile the stiff kernels, and one run (best of a few) with
//! Dormand-Prince, DOP853 and Rodas5P with the dense and with the banded LU (`LinearSolver`);
//! the process's peak memory after each size.
//!
//! Run: `cargo run --release --example w5_chain [N ...]` (default 10 30 100 300 1000); each size
//! in its own process gives a clean peak memory: `for n in 10 100 1000; do ...; done`. The
//! figures are in docs/performance.md. `W5_CASES=banded` runs only the cases whose name holds it;
//! `W5_REPS=k` runs each case k times (for profiles).

use hybc::sim::{LinearSolver, Method, SimOptions};
use hybc::Model;
use std::time::Instant;
#[path = "../support/chain.rs"]
mod chain;
use chain::{best, D_NAMES};

#[path = "../support/memory.rs"]
mod memory;
use memory::peak_mib;

fn main() {
    let sizes: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let sizes = if sizes.is_empty() { vec![10, 30, 100, 300, 1000] } else { sizes };
    for n in sizes {
        let src = chain::diffusion_source(n, true);
        let (parse_ms, model) = best(3, || Model::parse(&src).unwrap());
        let (compile_ms, compiled) = best(3, || model.compile(&D_NAMES).unwrap());
        let stiff_ms = {
            let c = model.compile(&D_NAMES).unwrap();
            let start = Instant::now();
            hybc::sim::HybridSystem::prepare_jacobians(c.native()).unwrap();
            start.elapsed().as_secs_f64() * 1e3
        };
        println!(
            "N = {n}: check {parse_ms:.1} ms, compile {compile_ms:.1} ms, stiff kernels {stiff_ms:.1} ms ({} gradients)",
            compiled.info().n_grad()
        );
        let p = compiled.params();
        let cases = [
            ("dopri5", Method::Dopri5, LinearSolver::Auto),
            ("dop853", Method::Dop853, LinearSolver::Auto),
            ("rodas5p dense", Method::Rodas5p, LinearSolver::Dense),
            ("rodas5p banded", Method::Rodas5p, LinearSolver::Banded),
        ];
        // `W5_CASES=banded` (a substring of the case names) runs only those, for profiles.
        let only = std::env::var("W5_CASES").unwrap_or_default();
        for (name, method, linear_solver) in cases.into_iter().filter(|c| c.0.contains(only.as_str())) {
            let opts = SimOptions {
                t_end: 10.0,
                rtol: 1e-8,
                atol: 1e-10,
                method,
                linear_solver,
                ..SimOptions::default()
            };
            let mut sim = compiled.simulator(&opts).unwrap();
            // `W5_REPS=k` repeats each run k times (profiles), else best of 5 (1 for the dense
            // LU from 300 states).
            let reps = std::env::var("W5_REPS").ok().and_then(|r| r.parse().ok());
            let reps = reps.unwrap_or(if n >= 300 && linear_solver == LinearSolver::Dense { 1 } else { 5 });
            let (ms, r) = best(reps, || sim.run(&p).unwrap());
            let r = r.result();
            println!(
                "  {name:15} {:6} steps ({:4} rejected) {:3} events  {ms:10.3} ms",
                r.stats.steps,
                r.stats.rejected,
                r.events.len()
            );
        }
        println!("  peak memory {:.1} MiB", peak_mib());
    }
}
