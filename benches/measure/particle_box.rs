//! The 1,000-particle box of issue #41 (`benches/support/particle_box.rs`: equal masses, elastic
//! walls, a velocity swap at each contact, written with arrays, loops and event families): the
//! time to check, compile and run it, and its events against the closed form (free particles
//! passing through each other, relabelled): the count of every element's firings, and every time.
//!
//! Run: `cargo run --release --example particle_box [N] [T_END]` (default 1000 and 0.1). The
//! figures are in docs/performance.md.

use std::collections::BTreeMap;
use std::time::Instant;

use hybc::{Model, SimOptions};

#[path = "../support/particle_box.rs"]
mod particle_box;
use particle_box::{box_closed_form, box_source};

fn counts<'a>(names: impl Iterator<Item = &'a str>) -> BTreeMap<&'a str, usize> {
    let mut out = BTreeMap::new();
    for n in names {
        *out.entry(n).or_insert(0) += 1;
    }
    out
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).filter(|a| a != "--bench").collect();
    let n: usize = args.first().map_or(1000, |a| a.parse().expect("N, an integer"));
    let t_end: f64 = args.get(1).map_or(0.1, |a| a.parse().expect("T_END, a number"));
    let source = box_source(n);

    let started = Instant::now();
    let model = Model::parse(&source).expect("the box checks");
    let t_check = started.elapsed().as_secs_f64();
    let started = Instant::now();
    let compiled = model.compile::<&str>(&[]).expect("compiles");
    let t_compile = started.elapsed().as_secs_f64();
    let opts =
        SimOptions { t_end, rtol: 1e-10, atol: 1e-12, max_events: 10_000_000, ..SimOptions::default() };
    let started = Instant::now();
    let run = compiled.simulate(&model.params(), &opts).expect("runs");
    let t_run = started.elapsed().as_secs_f64();
    assert!(run.is_complete(), "the run stopped early");

    let started = Instant::now();
    let (want, last) = box_closed_form(n, t_end);
    let t_closed = started.elapsed().as_secs_f64();
    let got: Vec<(f64, &str)> = run.events().iter().map(|e| (e.time, &*e.name)).collect();
    let pairs = want.iter().filter(|e| e.1.starts_with("hit")).count();
    println!(
        "N = {n}, t_end = {t_end}: {} states, {} guards; {} events ({} pair, {} wall), {} steps",
        2 * n,
        3 * n - 1,
        got.len(),
        pairs,
        want.len() - pairs,
        run.result().stats.steps
    );
    println!(
        "check {t_check:.3} s, compile {t_compile:.3} s, run {t_run:.3} s ({:.1} us an event); closed form {t_closed:.3} s",
        1e6 * t_run / got.len().max(1) as f64
    );
    assert_eq!(
        counts(got.iter().map(|e| e.1)),
        counts(want.iter().map(|e| e.1.as_str())),
        "every element's firings, against the closed form"
    );
    let worst_t = got.iter().zip(&want).map(|(g, w)| (g.0 - w.0).abs()).fold(0.0, f64::max);
    let mut worst_x: f64 = 0.0;
    for (i, (x, v)) in last.iter().enumerate() {
        let gx = run.state(&format!("x[{i}]")).expect("x[i]");
        let gv = run.state(&format!("v[{i}]")).expect("v[i]");
        worst_x = worst_x.max((gx - x).abs());
        assert!((gv - v).abs() < 1e-12, "v[{i}] = {gv} vs {v}");
    }
    println!("largest error: event time {worst_t:.1e}, final position {worst_x:.1e}");
    assert!(worst_t < 1e-9 && worst_x < 1e-9, "event times and positions to 1e-9");
    println!("every element's event count equals the closed form's");
}
