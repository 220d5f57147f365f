//! Measures the adjoint on a large model with a parameter per link (issue #40, section 4): the W5
//! diffusion chain (`benches/support/chain.rs`) with N cells and one conductance per link,
//! `d[i]` between cells i and i+1 (N - 1 parameters, every one differentiated), integrated with
//! Dormand-Prince to T = 10 at rtol 1e-8 (the top-up event on `x0` included). For each N: a
//! plain run (the model compiled without gradients), the adjoint of the last cell's output `y`
//! (recording run and one backward pass), the process's peak memory after them, then forward
//! sensitivities of all N - 1 columns (their kernel compiled first, timed apart) (`sens_error_control` off: the same steps) and the gap
//! between the two gradients, relative to the largest final sensitivity of any state. Medians of `--repeat` runs (default 3).
//!
//! `cargo run --release --example adjoint_chain -- 100 1000`; one size per process for a clean
//! peak memory. `--only plain` compiles and runs the model without gradients and nothing else,
//! `--only adjoint` adds the adjoint and leaves forward mode out (for the peak memory of each,
//! which `/usr/bin/time -v` confirms from outside). `--full-tape` keeps every step's start state
//! (`Checkpoints::Every(1)`, the tape before checkpoints) rather than the default checkpoints.
//! docs/performance.md, "Gradients by the adjoint", has the figures.

use std::time::Instant;

use hybc::sim::adjoint::{record_with, Checkpoints, Seed};
use hybc::sim::{run, HybridSystem, Method, SimOptions};
use hybc::Model;

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

#[path = "../support/chain.rs"]
mod chain;
use chain::link_chain_source;

#[path = "../support/memory.rs"]
mod memory;
use memory::peak_mib;

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let repeat = match args.iter().position(|a| a == "--repeat") {
        Some(i) => {
            let v = args[i + 1].parse().expect("a count");
            args.drain(i..i + 2);
            v
        }
        None => 3,
    };
    let only = match args.iter().position(|a| a == "--only") {
        Some(i) => {
            let v = args[i + 1].clone();
            assert!(v == "plain" || v == "adjoint", "--only plain or --only adjoint");
            args.drain(i..i + 2);
            Some(v)
        }
        None => None,
    };
    let checkpoints = match args.iter().position(|a| a == "--full-tape") {
        Some(i) => {
            args.remove(i);
            Checkpoints::Every(1)
        }
        None => Checkpoints::default(),
    };
    let sizes: Vec<usize> = args.iter().map(|a| a.parse().expect("a size")).collect();
    let opts = SimOptions {
        t_end: 10.0,
        method: Method::Dopri5,
        sens_error_control: false,
        ..SimOptions::default()
    };
    for n in sizes {
        let model = Model::parse(&link_chain_source(n, 50.0, false)).expect("checks");
        let plain_model = model.compile::<&str>(&[]).expect("compiles");
        if only.as_deref() == Some("plain") {
            let mut plain = Vec::new();
            let mut steps = 0;
            for _ in 0..repeat {
                let t = Instant::now();
                let r = run(plain_model.system(), plain_model.params().values(), &opts).expect("runs");
                plain.push(t.elapsed().as_secs_f64());
                steps = r.stats.steps;
            }
            println!(
                "N = {n}: plain {:.1} ms ({steps} steps), peak {:.0} MiB",
                median(plain) * 1e3,
                peak_mib()
            );
            continue;
        }
        let with_grad = model.compile(&["d"]).expect("compiles");
        let p = with_grad.params().values().to_vec();
        let seed = Seed { outputs: vec![1.0], ..Seed::default() };
        let (mut plain, mut adjoint) = (Vec::new(), Vec::new());
        let (mut steps, mut events, mut grad, mut tape_mib) = (0, 0, Vec::new(), 0.0);
        // The first adjoint compiles the flow's vector-Jacobian kernel: timed apart.
        let started = Instant::now();
        let recorded = record_with(with_grad.system(), &p, &opts, checkpoints).expect("records");
        recorded.gradient(with_grad.system(), &p, &seed).expect("carried");
        let first = started.elapsed().as_secs_f64();
        for _ in 0..repeat {
            let t = Instant::now();
            let r = run(plain_model.system(), &p, &opts).expect("runs");
            plain.push(t.elapsed().as_secs_f64());
            (steps, events) = (r.stats.steps, r.events.len());
            let t = Instant::now();
            let recorded = record_with(with_grad.system(), &p, &opts, checkpoints).expect("records");
            grad = recorded.gradient(with_grad.system(), &p, &seed).expect("carried");
            adjoint.push(t.elapsed().as_secs_f64());
            tape_mib = recorded.tape.bytes() as f64 / (1024.0 * 1024.0);
        }
        let peak = peak_mib();
        let (plain, adjoint) = (median(plain), median(adjoint));
        if only.is_some() {
            println!(
                "N = {n} ({} parameters, {steps} steps, {events} events): plain {:.1} ms, adjoint {:.1} ms \
                 ({:.1}x plain; first call {:.0} ms with the kernel's compile), tape {tape_mib:.1} MiB, \
                 peak {peak:.0} MiB",
                n - 1,
                plain * 1e3,
                adjoint * 1e3,
                adjoint / plain,
                first * 1e3,
            );
            continue;
        }
        // The forward sensitivity kernel is compiled on first use at these sizes: timed apart.
        let t = Instant::now();
        with_grad.system().prepare_sensitivities().expect("the forward kernel compiles");
        let forward_compile = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let r = run(with_grad.system(), &p, &opts).expect("runs");
        let forward = t.elapsed().as_secs_f64();
        let dy = r.final_state.doutputs.expect("doutputs");
        // The far cell's gradient is many orders below the sensitivities of the cells near the
        // source (1e-9 of them at N = 100): the gap is measured against those, the largest
        // final sensitivity of any state, the size the round-off of either mode scales with.
        let ds = r.final_state.dstate.expect("dstate");
        let scale = ds.iter().chain(&dy).fold(0.0f64, |a, b| a.max(b.abs()));
        let gap = grad.iter().zip(&dy).fold(0.0f64, |a, (x, y)| a.max((x - y).abs())) / scale;
        println!(
            "N = {n} ({} parameters, {steps} steps, {events} events): plain {:.1} ms, adjoint {:.1} ms ({:.1}x plain; \
             first call {:.0} ms with the kernel's compile), tape {tape_mib:.1} MiB, peak {peak:.0} MiB; \
             forward {:.0} ms ({:.0}x plain; its kernel's compile {:.1} s before); gap {gap:.0e}",
            n - 1,
            plain * 1e3,
            adjoint * 1e3,
            adjoint / plain,
            first * 1e3,
            forward * 1e3,
            forward / plain,
            forward_compile,
        );
    }
}
