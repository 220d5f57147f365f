//! Measures the adjoint tape's memory on a long run (issue #40: "memory stays bounded"): `k`
//! damped oscillators driven by `sin(t)` (2k states, a stiffness and a damping parameter each),
//! Dormand-Prince at rtol 1e-10 to `t_end`, about 34 steps a unit of time (10^6 steps at
//! `t_end = 30000`). For the gradient of the sum of the final positions: a plain run (the model
//! compiled without gradients), the adjoint (recording run and one backward pass), the tape's
//! bytes, the start states it kept, and the process's peak memory.
//!
//! `cargo run --release --example adjoint_long -- [--full-tape] [--only plain] K T_END`; one
//! choice per process for a clean peak memory (`/usr/bin/time -v` confirms it from outside).
//! `--full-tape` keeps every step's start state (`Checkpoints::Every(1)`, the tape before
//! checkpoints), else the default checkpoints. docs/performance.md, "Gradients by the adjoint",
//! has the figures.

use std::time::Instant;

use hybc::sim::adjoint::{record_with, Checkpoints, Seed};
use hybc::sim::{run, Method, SimOptions};
use hybc::Model;

fn source(k: usize) -> String {
    let mut s = format!("model oscillators\nparam w[{k}] = 1\nparam c[{k}] = 0.01\n");
    for i in 0..k {
        s.push_str(&format!("state x{i} = {}\nstate v{i} = 0\n", 1.0 / (i + 1) as f64));
        s.push_str(&format!("der(x{i}) = v{i}\n"));
        s.push_str(&format!(
            "der(v{i}) = -w[{i}] * {} * x{i} - c[{i}] * v{i} + sin(t)\n",
            1.0 + 0.1 * i as f64
        ));
    }
    let sum: Vec<String> = (0..k).map(|i| format!("x{i}")).collect();
    s.push_str(&format!("output y = {}\n", sum.join(" + ")));
    s
}

#[path = "../support/memory.rs"]
mod memory;
use memory::peak_mib;

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut flag = |name: &str| match args.iter().position(|a| a == name) {
        Some(i) => {
            args.remove(i);
            true
        }
        None => false,
    };
    let full = flag("--full-tape");
    let only_plain = flag("--only");
    if only_plain {
        assert_eq!(args.first().map(String::as_str), Some("plain"), "--only plain");
        args.remove(0);
    }
    let k: usize = args.first().map_or(5, |a| a.parse().expect("a count of oscillators"));
    let t_end: f64 = args.get(1).map_or(30000.0, |a| a.parse().expect("an end time"));
    let checkpoints = if full { Checkpoints::Every(1) } else { Checkpoints::default() };
    let opts = SimOptions {
        t_end,
        rtol: 1e-10,
        atol: 1e-12,
        method: Method::Dopri5,
        max_steps: 100_000_000,
        sens_error_control: false,
        ..SimOptions::default()
    };
    let model = Model::parse(&source(k)).expect("checks");
    let plain_model = model.compile::<&str>(&[]).expect("compiles");
    let t = Instant::now();
    let r = run(plain_model.system(), plain_model.params().values(), &opts).expect("runs");
    let plain = t.elapsed().as_secs_f64();
    if only_plain {
        println!("{} states, {} steps: plain {plain:.2} s, peak {:.0} MiB", 2 * k, r.stats.steps, peak_mib());
        return;
    }
    let with_grad = model.compile(&["w", "c"]).expect("compiles");
    let p = with_grad.params().values().to_vec();
    let seed = Seed { outputs: vec![1.0], ..Seed::default() };
    let t = Instant::now();
    let recorded = record_with(with_grad.system(), &p, &opts, checkpoints).expect("records");
    let recording = t.elapsed().as_secs_f64();
    let grad = recorded.gradient(with_grad.system(), &p, &seed).expect("carried");
    let adjoint = t.elapsed().as_secs_f64();
    let tape = &recorded.tape;
    println!(
        "{} states, {} steps, {checkpoints:?}: plain {plain:.2} s, adjoint {adjoint:.2} s ({:.1}x plain; recording \
         {recording:.2} s), tape {:.1} MiB ({} start states kept, {} numbers stored), peak {:.0} MiB; dy/dw0 {:.6e}",
        2 * k,
        tape.steps(),
        adjoint / plain,
        tape.bytes() as f64 / (1024.0 * 1024.0),
        tape.kept_states(),
        tape.stored_numbers(),
        peak_mib(),
        grad[0],
    );
}
