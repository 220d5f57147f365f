//! The sparse LU (`sim::linsolve`, `sim::sparse_lu`) against the dense and the banded LU:
//! Rodas5P runs with 10 gradients (the conductances `d[0..9]`, to T = 10 at rtol 1e-8, atol
//! 1e-10) on generated models (`benches/support/chain.rs`): a hub of N states (`hub_source`, an
//! arrowhead `f_x`), a `side x side` grid (`grid_source`) and the W5 diffusion chain
//! (`diffusion_source`), each with its top-up event. For each model: the multiply-adds of one
//! factorisation by path (`FactorCosts`, and the time of the band's and the sparse symbolic
//! analyses together), `Auto`'s choice, and the run time of each path, best of a few runs.
//!
//! Run: `cargo run --release --example sparse_hub [hub:N | grid:SIDE | chain:N ...]` (default
//! hub:100 hub:300 hub:1000 grid:32). `SPARSE_REPS=k`: best of k (default 5; 1 for the dense LU
//! from 300 states). `SPARSE_CASES=banded,sparse` runs only the paths whose name holds one of them. The figures
//! are in docs/performance.md.

use hybc::sim::{FactorCosts, HybridSystem, LinearSolver, Method, SimOptions};
use hybc::Model;
use std::time::Instant;

#[path = "../support/chain.rs"]
mod chain;
use chain::{best, D_NAMES};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let args = if args.is_empty() {
        ["hub:100", "hub:300", "hub:1000", "grid:32"].map(String::from).to_vec()
    } else {
        args
    };
    let only = std::env::var("SPARSE_CASES").unwrap_or_default();
    let reps: Option<usize> = std::env::var("SPARSE_REPS").ok().and_then(|r| r.parse().ok());
    for arg in args {
        let (kind, size) = arg.split_once(':').expect("hub:N, grid:SIDE or chain:N");
        let size: usize = size.parse().expect("a size");
        let (src, n) = match kind {
            "hub" => (chain::hub_source(size, true), size),
            "grid" => (chain::grid_source(size, true), size * size),
            "chain" => (chain::diffusion_source(size, true), size),
            _ => panic!("hub:N, grid:SIDE or chain:N"),
        };
        let model = Model::parse(&src).unwrap();
        let compiled = model.compile(&D_NAMES).unwrap();
        compiled.native().prepare_jacobians().unwrap();
        let pattern = compiled.native().jac_pattern(0).expect("a pattern").to_vec();
        let start = Instant::now();
        let costs = FactorCosts::of(n, &pattern);
        let analysis_ms = start.elapsed().as_secs_f64() * 1e3;
        let show = |c: Option<f64>| c.map_or("-".to_string(), |c| format!("{c:.3e}"));
        println!(
            "{arg} ({n} states, {} entries): multiply-adds dense {:.3e}, banded {}, sparse {} (both analyses {analysis_ms:.1} ms); auto picks {:?}",
            pattern.len(),
            costs.dense,
            show(costs.banded),
            show(costs.sparse),
            LinearSolver::Auto.resolve(n, &pattern)
        );
        let p = compiled.params();
        let mut cases = vec![("dense", LinearSolver::Dense)];
        if costs.banded.is_some() {
            cases.push(("banded", LinearSolver::Banded));
        }
        cases.extend([("sparse", LinearSolver::Sparse), ("auto", LinearSolver::Auto)]);
        for (name, linear_solver) in cases.into_iter().filter(|c| only.split(',').any(|o| c.0.contains(o))) {
            let opts = SimOptions {
                t_end: 10.0,
                rtol: 1e-8,
                atol: 1e-10,
                method: Method::Rodas5p,
                linear_solver,
                ..SimOptions::default()
            };
            let mut sim = compiled.simulator(&opts).unwrap();
            let reps = reps.unwrap_or(if n >= 300 && linear_solver == LinearSolver::Dense { 1 } else { 5 });
            let (ms, r) = best(reps, || sim.run(&p).unwrap());
            let r = r.result();
            println!(
                "  {name:7} {:6} steps ({:4} rejected) {:3} events  {ms:10.3} ms",
                r.stats.steps,
                r.stats.rejected,
                r.events.len()
            );
        }
    }
}
