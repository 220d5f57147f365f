//! The front end on generated stress models (the ones `tests/it/stress_frontend.rs` checks):
//! chained `let`s, `let`s that double their predecessor, a long chain of states (also written as a
//! loop over an array, which `expand` flattens into the same model). For each: the
//! time to check, to compile (lowering, every derivative, the JIT) and to run with a gradient,
//! and the peak resident memory of each phase (VmHWM, reset before each through
//! /proc/self/clear_refs). A plain bench binary: one run each, these take from milliseconds to
//! seconds. Run: `cargo bench --bench frontend`.

use std::time::Instant;

use hybc::Model;

#[path = "support/stress_models.rs"]
mod stress_models;
use stress_models::{doubling_lets, let_chain, state_chain, state_chain_loop};

#[path = "support/memory.rs"]
mod memory;
use memory::peak_mib;

fn reset_peak() {
    // Writing 5 resets the peak resident set size to the current one (Linux 4.0 and newer).
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

fn measure<T>(f: impl FnOnce() -> T) -> (T, f64, f64) {
    reset_peak();
    let started = Instant::now();
    let out = f();
    (out, started.elapsed().as_secs_f64(), peak_mib())
}

fn main() {
    if !std::env::args().any(|a| a == "--bench") {
        return;
    }
    let cases: Vec<(&str, String, &str)> = vec![
        ("5,000 chained lets", let_chain(5_000, true), "c"),
        ("30,000 chained lets", let_chain(30_000, true), "c"),
        ("60 doubling lets", doubling_lets(60), "p"),
        ("10,000 states", state_chain(10_000), "k"),
        ("10,000 states, a loop", state_chain_loop(10_000), "k"),
    ];
    println!("{:<22} {:>16} {:>16} {:>16}", "model", "check", "compile", "run (1 gradient)");
    for (name, text, grad) in cases {
        let (model, t_check, m_check) = measure(|| Model::parse(&text).expect("checks"));
        let (compiled, t_compile, m_compile) = measure(|| model.compile(&[grad]).expect("compiles"));
        let (run, t_run, m_run) =
            measure(|| compiled.simulate(&model.params(), &model.sim_options()).expect("runs"));
        assert!(run.is_complete());
        let cell = |t: f64, m: f64| format!("{t:>7.3} s {m:>4.0} MiB");
        println!(
            "{name:<22} {} {} {}",
            cell(t_check, m_check),
            cell(t_compile, m_compile),
            cell(t_run, m_run)
        );
    }
}
