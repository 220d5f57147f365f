//! Many events pending in one step: `n` thresholds `x >= k / n` crossed by `x = t` (the stress
//! test's model at several sizes), compile and run times, to show how event handling scales with
//! the number of guards. A plain bench binary (criterion would repeat a several-second run a
//! hundred times): best of three runs per size.
//! Run: `cargo bench --bench events`.

use std::time::{Duration, Instant};

use hybc::Model;

fn thresholds(n: usize) -> String {
    let mut text = String::from("model many\nstate x = 0\nder(x) = 1\n");
    for k in 1..=n {
        text.push_str(&format!("event e{k} when x >= {k} / {n}\n"));
    }
    text
}

fn main() {
    // `cargo bench` passes `--bench`; `cargo test --benches` would pass nothing: run only when
    // benchmarking.
    if !std::env::args().any(|a| a == "--bench") {
        return;
    }
    println!("{:>8}  {:>12}  {:>12}  {:>14}", "events", "compile", "run", "run per event");
    for n in [1_000, 4_000, 10_000] {
        let model = Model::parse(&thresholds(n)).expect("parses");
        let started = Instant::now();
        let compiled = model.compile::<&str>(&[]).expect("compiles");
        let compile = started.elapsed();
        let mut opts = model.sim_options();
        opts.t_end = 1.5;
        opts.max_events = n + 1;
        let mut best = Duration::MAX;
        for _ in 0..3 {
            let started = Instant::now();
            let run = compiled.simulate(&model.params(), &opts).expect("runs");
            best = best.min(started.elapsed());
            assert_eq!(run.events().len(), n);
        }
        let per_event = best / n as u32;
        println!("{n:>8}  {compile:>12.2?}  {best:>12.2?}  {per_event:>14.2?}");
    }
}
