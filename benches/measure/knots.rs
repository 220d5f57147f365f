//! What controls of many knots cost (issue #39): the bouncing ball under a piecewise-linear force,
//! `der(v) = -g + pwl(t, 0, 2.5, u)`, to `t_end = 2.5` at rtol 1e-10 (three bounces), with 10,
//! 100, 1,000 and 10,000 knots. For each: the time to check the model (parse and sema) and to
//! compile it (lower and codegen), best of a few; one run without gradients and one with the
//! gradient of the restitution `e` (steps, rejected attempts, run time best of a few, and per
//! knot); beside them the same ball with a constant force (the steps its accuracy needs). The
//! force `u[k] = 0.5 + 0.3 sin(k)` wiggles at every knot.
//!
//! Run: `cargo run --release --example knots`. The figures are in docs/performance.md.

use hybc::{Model, SimOptions};
#[path = "../support/chain.rs"]
mod chain;
use chain::best;

fn ball(force: &str, n: usize) -> String {
    format!(
        "model ball\nparam g = 9.81\nparam e = 0.8 in [0, 1]\nparam h0 = 1\nparam c = 0.5\n\
         param u[{n}] = 0.5 in [-50, 50]\nstate y = h0\nstate v = 0\nder(y) = v\nder(v) = -g + {force}\n\
         event touchdown when y <= 0 {{\n    v := -e * v\n}}\nsimulate t_end = 2.5, rtol = 1e-10, atol = 1e-12\n"
    )
}

fn main() {
    let plain = Model::parse(&ball("c", 2)).unwrap();
    let compiled = plain.compile::<&str>(&[]).unwrap();
    let plain_run = compiled.simulate(&compiled.params(), &plain.sim_options()).unwrap();
    let stats = &plain_run.result().stats;
    println!(
        "constant force: {} steps ({} rejected), {} events",
        stats.steps,
        stats.rejected,
        plain_run.events().len()
    );
    for n in [10usize, 100, 1000, 10_000] {
        let src = ball("pwl(t, 0, 2.5, u)", n);
        let reps = if n == 10_000 { 5 } else { 11 };
        let (check_ms, model) = best(reps, || Model::parse(&src).unwrap());
        let (compile_ms, compiled) = best(reps, || model.compile::<&str>(&[]).unwrap());
        let u: Vec<f64> = (0..n).map(|k| 0.5 + 0.3 * (k as f64).sin()).collect();
        let params = model.params().with_vector("u", &u).unwrap();
        let opts: SimOptions = model.sim_options();
        let mut sim = compiled.simulator(&opts).unwrap();
        let (run_ms, run) = best(reps, || sim.run(&params).unwrap());
        let graded = model.compile(&["e"]).unwrap();
        let mut sim = graded.simulator(&opts).unwrap();
        let (grad_ms, grad_run) = best(reps, || sim.run(&params).unwrap());
        let (s, g) = (&run.result().stats, &grad_run.result().stats);
        println!(
            "{n} knots: check {check_ms:.2} ms, compile {compile_ms:.2} ms; run {} steps ({} rejected), \
             {} events, {run_ms:.3} ms ({:.3} us a knot); with d/de {} steps ({} rejected), {grad_ms:.3} ms \
             ({:.3} us a knot)",
            s.steps,
            s.rejected,
            run.events().len(),
            1e3 * run_ms / n as f64,
            g.steps,
            g.rejected,
            1e3 * grad_ms / n as f64,
        );
    }
}
