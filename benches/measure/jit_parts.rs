//! Measures what cutting big kernels into parts (`CompileOptions::max_part_size`) costs and
//! buys: compile time of generated chain models with 10, 100 and 1000 states and ns per call of
//! their flow and fused sensitivity kernels. Used to choose `codegen::MAX_PART_SIZE`.
//!
//! Run: `PART=500 RA=auto cargo run --release --example jit_parts` (`PART`: largest part,
//! default unlimited; `RA`: `bt` backtracking (default), `sp` single-pass, `auto`). The figures
//! are in the doc comment of `MAX_PART_SIZE`.

use hybc::codegen::{CompileOptions, CompiledModel, RegAlloc};
use hybc::lower::{lower, system_info};
use hybc::sema::ParamIdx;
use hybc::sim::HybridSystem;
use std::time::Instant;
#[path = "../support/chain.rs"]
mod chain;
fn main() {
    let ra = match std::env::var("RA").as_deref() {
        Ok("sp") => RegAlloc::SinglePass,
        Ok("auto") => RegAlloc::Auto,
        _ => RegAlloc::Backtracking,
    };
    let part: usize = std::env::var("PART").ok().and_then(|v| v.parse().ok()).unwrap_or(usize::MAX);
    let opts =
        CompileOptions { regalloc: ra, max_part_size: part, verifier: false, ..CompileOptions::default() };
    for n in [10usize, 100, 1000] {
        let model = hybc::check_source(&chain::chain_source(n)).unwrap();
        let grad: Vec<ParamIdx> = (0..model.n_params() as u32).map(ParamIdx).collect();
        let (funcs, info) = (lower(&model), system_info(&model, &grad));
        let mut ts = vec![];
        let reps = if n == 1000 { 3 } else { 9 };
        let mut m = None;
        for _ in 0..reps {
            let t0 = Instant::now();
            m = Some(CompiledModel::compile(&funcs, info.clone(), &opts).unwrap());
            ts.push(t0.elapsed().as_secs_f64());
        }
        ts.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let m = m.unwrap();
        let x: Vec<f64> = (0..n).map(|i| 0.5 + 0.01 * i as f64).collect();
        let s: Vec<f64> = (0..3 * n).map(|i| 0.001 * i as f64).collect();
        let p = [0.5, 0.1, 1.0];
        let (mut dx, mut ds) = (vec![0.0; n], vec![0.0; 3 * n]);
        let calls = 2_000_000 / n;
        let t0 = Instant::now();
        for _ in 0..calls {
            m.flow_sens(0, 0.0, std::hint::black_box(&x), &s, &p, &mut dx, &mut ds);
        }
        let sens = t0.elapsed().as_secs_f64() / calls as f64;
        let t0 = Instant::now();
        for _ in 0..calls {
            m.flow(0, 0.0, std::hint::black_box(&x), &p, &mut dx);
        }
        let flow = t0.elapsed().as_secs_f64() / calls as f64;
        println!(
            "chain{n}: compile {:.2} ms, flow {:.1} ns, flow_sens {:.1} ns, functions {}",
            ts[ts.len() / 2] * 1e3,
            flow * 1e9,
            sens * 1e9,
            m.n_kernels()
        );
    }
}
