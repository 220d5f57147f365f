//! Measures what the JIT's `CompileOptions` cost and buy: compile time of the bouncing ball and of
//! a 100-state chain, and time per call of the chain's fused sensitivity kernel, for every
//! combination of optimisation level, register allocator and verifier. Used to choose
//! `CompileOptions::default()`.
//!
//! Run: `cargo run --example jit_options` (a debug build: Cranelift itself is built with
//! opt-level 2 by the workspace profile, and the generated code does not depend on the profile;
//! `JIT_CHAIN=1000` sets the chain size of the option grid).
//!
//! Measured on the shared 2-core VM (load average about 4, so +-30% noise), debug build:
//! - ball: 0.34-0.57 ms to compile under every option set; the verifier adds 10-25%.
//! - 100-state chain: 12-18 ms with `single_pass`, 25-45 ms with `backtracking`; fused
//!   sensitivity kernel 0.7-1.5 us per call under every option set (differences within noise).
//! - 1000-state chain: 108-180 ms with `single_pass`, 1.4-2.4 s with `backtracking` (its cost
//!   grows faster than linearly with one kernel's size); fused sensitivity kernel 5.5-6.7 us per
//!   call with `backtracking`, 6.6-8.9 us with `single_pass`.
//! - growth at the default options (`Auto` allocator): chain10 2 ms, chain100 36 ms,
//!   chain1000 149 ms.

use std::time::{Duration, Instant};

use hybc::codegen::{CompileOptions, CompiledModel, OptLevel, RegAlloc};
use hybc::expr::ModelFunctions;
use hybc::lower::{lower, system_info};
use hybc::sema::ParamIdx;
use hybc::sim::{HybridSystem, SystemInfo};

#[path = "../support/chain.rs"]
mod chain;
use chain::chain_source;

fn front_end(source: &str) -> (ModelFunctions, SystemInfo) {
    let model = hybc::check_source(source).expect("the generated model is valid");
    let grad: Vec<ParamIdx> = (0..model.n_params() as u32).map(ParamIdx).collect();
    (lower(&model), system_info(&model, &grad))
}

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[v.len() / 2]
}

fn compile_time(funcs: &ModelFunctions, info: &SystemInfo, opts: &CompileOptions) -> Duration {
    median(
        (0..7)
            .map(|_| {
                let start = Instant::now();
                let m = CompiledModel::compile(funcs, info.clone(), opts).expect("compiles");
                let d = start.elapsed();
                drop(m);
                d
            })
            .collect(),
    )
}

fn main() {
    let ball = front_end(&std::fs::read_to_string("models/ball.hyb").expect("models/ball.hyb"));
    // The chain size of the option grid: `JIT_CHAIN=1000 cargo run --example jit_options`.
    let size: usize = std::env::var("JIT_CHAIN").ok().and_then(|v| v.parse().ok()).unwrap_or(100);
    let chain = front_end(&chain_source(size));
    let (n, m) = (chain.1.n_states(), chain.1.n_grad());
    let x: Vec<f64> = (0..n).map(|i| 0.01 * i as f64).collect();
    let s: Vec<f64> = (0..n * m).map(|i| 0.001 * i as f64).collect();
    let p = [0.5, 0.1, 1.0];
    let (mut dx, mut ds) = (vec![0.0; n], vec![0.0; n * m]);

    // Growth of compile time with model size: default options against the fastest-compiling.
    let fast = CompileOptions {
        opt_level: OptLevel::None,
        verifier: false,
        regalloc: RegAlloc::SinglePass,
        ..CompileOptions::default()
    };
    for size in [10, 100, 1000] {
        let (funcs, info) = front_end(&chain_source(size));
        let start = Instant::now();
        let jit = CompiledModel::compile(&funcs, info.clone(), &CompileOptions::default()).expect("compiles");
        let default_t = start.elapsed();
        let start = Instant::now();
        drop(CompiledModel::compile(&funcs, info, &fast).expect("compiles"));
        let fast_t = start.elapsed();
        println!(
            "chain{size}: {} nodes, {} kernels; default options {:.1} ms, fastest {:.1} ms",
            funcs.store.len(),
            jit.n_kernels(),
            default_t.as_secs_f64() * 1e3,
            fast_t.as_secs_f64() * 1e3
        );
    }

    println!("opt_level     regalloc      verifier  ball_compile  chain_compile  chain_flow_sens");
    for opt_level in [OptLevel::None, OptLevel::Speed, OptLevel::SpeedAndSize] {
        for regalloc in [RegAlloc::Backtracking, RegAlloc::SinglePass] {
            for verifier in [false, true] {
                let opts = CompileOptions { opt_level, verifier, regalloc, ..CompileOptions::default() };
                let ball_t = compile_time(&ball.0, &ball.1, &opts);
                let chain_t = compile_time(&chain.0, &chain.1, &opts);
                let jit = CompiledModel::compile(&chain.0, chain.1.clone(), &opts).expect("compiles");
                let calls = 20_000;
                let per_call = median(
                    (0..5)
                        .map(|_| {
                            let start = Instant::now();
                            for _ in 0..calls {
                                jit.flow_sens(0, 0.0, std::hint::black_box(&x), &s, &p, &mut dx, &mut ds);
                            }
                            start.elapsed() / calls
                        })
                        .collect(),
                );
                println!(
                    "{:<13} {:<13} {:<9} {:>9.3} ms  {:>13.3} ms  {:>15} ns",
                    format!("{opt_level:?}"),
                    format!("{regalloc:?}"),
                    verifier,
                    ball_t.as_secs_f64() * 1e3,
                    chain_t.as_secs_f64() * 1e3,
                    per_call.as_nanos()
                );
            }
        }
    }
}
