//! Measures what `--sens auto` weighs (issue #40, section 2: "a measured cost rule"): a forward
//! sensitivity column's cost and a backward row's, each over a plain run of the same model, on
//! models of different sizes and sparsity. For each model and parameter count `m`: a plain run
//! (compiled without gradients), forward sensitivities of `m` columns (`sens_error_control` off:
//! the same steps), and the adjoint (the recording run and one backward pass) of `r` rows, for
//! several `r`. Medians of `--repeat` runs (default 7), the modes interleaved. It then fits
//! `forward / plain = 1 + a m` and `adjoint / plain = b + c r` by least squares per model and
//! prints `a`, `b` and `c`: the adjoint pays where `b + c r < 1 + a m`.
//!
//! `cargo run --release --example sens_rule`
//! docs/performance.md, "Gradients by the adjoint", has the figures; docs/design.md, "`--sens
//! auto`", the rule taken from them.

use std::time::Instant;

use hybc::sim::adjoint::{record, Seed};
use hybc::sim::{run, HybridSystem, Method, SimOptions};
use hybc::Model;

#[path = "../support/pushed_ball.rs"]
mod pushed_ball;
use pushed_ball::pushed_ball_source;

#[path = "../support/chain.rs"]
mod chain;
use chain::link_chain_source;

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

/// Least squares `y = b + c x`.
fn fit(points: &[(f64, f64)]) -> (f64, f64) {
    let n = points.len() as f64;
    let (sx, sy) = points.iter().fold((0.0, 0.0), |(a, b), &(x, y)| (a + x, b + y));
    let (mx, my) = (sx / n, sy / n);
    let (sxy, sxx) =
        points.iter().fold((0.0, 0.0), |(a, b), &(x, y)| (a + (x - mx) * (y - my), b + (x - mx) * (x - mx)));
    let c = sxy / sxx;
    (my - c * mx, c)
}

struct Case {
    name: String,
    source: String,
    /// The vector parameter differentiated (every element).
    grad: &'static str,
    opts: SimOptions,
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let repeat = match args.iter().position(|a| a == "--repeat") {
        Some(i) => {
            let v = args[i + 1].parse().expect("a count");
            args.drain(i..i + 2);
            v
        }
        None => 7,
    };
    let ball_opts = SimOptions {
        t_end: 2.5,
        rtol: 1e-10,
        atol: 1e-12,
        sens_error_control: false,
        ..SimOptions::default()
    };
    let chain_opts = SimOptions {
        t_end: 10.0,
        method: Method::Dopri5,
        sens_error_control: false,
        ..SimOptions::default()
    };
    let mut families: Vec<Vec<Case>> = Vec::new();
    families.push(
        [8, 32, 128]
            .into_iter()
            .map(|k| Case {
                name: format!("ball, pwl of {k} knots"),
                source: pushed_ball_source(k),
                grad: "u",
                opts: ball_opts.clone(),
            })
            .collect(),
    );
    for n in [20, 60] {
        // The W5 chain with a conductance per link: `n` states, `n - 1` parameters.
        families.push(vec![Case {
            name: format!("chain of {n} cells"),
            source: link_chain_source(n, 50.0, false),
            grad: "d",
            opts: chain_opts.clone(),
        }]);
    }
    // The chain under a Rosenbrock method: each backward row pays a transposed solve and the
    // second-order term per stage (docs/design.md, "The transpose of a Rosenbrock step").
    let stiff_opts = SimOptions { method: Method::Rodas5p, ..chain_opts.clone() };
    families.push(vec![Case {
        name: "chain of 20 cells, Rodas5P".into(),
        source: link_chain_source(20, 50.0, false),
        grad: "d",
        opts: stiff_opts,
    }]);
    let rows = [1usize, 4, 16];
    println!("| model | states | m | plain (ms) | forward / plain | adjoint / plain, r = 1, 4, 16 |");
    println!("| --- | --- | --- | --- | --- | --- |");
    let mut fits = Vec::new();
    for family in &families {
        let (mut fwd_points, mut adj_points) = (Vec::new(), Vec::new());
        let mut label = String::new();
        for case in family {
            let model = Model::parse(&case.source).expect("checks");
            let plain_model = model.compile::<&str>(&[]).expect("compiles");
            let with_grad = model.compile(&[case.grad]).expect("compiles");
            with_grad.system().prepare_sensitivities().expect("compiles");
            let p = with_grad.params().values().to_vec();
            let (n, m) = (with_grad.info().n_states(), with_grad.info().n_grad());
            // `r` rows: the final states in turn, each weighted differently (the backward pass
            // carries a block of `r` cotangents whatever they are).
            let seeds = |r: usize| -> Vec<Seed> {
                (0..r)
                    .map(|i| {
                        let mut state = vec![0.0; n];
                        state[i % n] = 1.0 + i as f64;
                        Seed { state, ..Seed::default() }
                    })
                    .collect()
            };
            let (mut plain, mut forward) = (Vec::new(), Vec::new());
            let mut adjoint = vec![Vec::new(); rows.len()];
            for _ in 0..repeat {
                let t = Instant::now();
                run(plain_model.system(), &p, &case.opts).expect("runs");
                plain.push(t.elapsed().as_secs_f64());
                let t = Instant::now();
                run(with_grad.system(), &p, &case.opts).expect("runs");
                forward.push(t.elapsed().as_secs_f64());
                for (slot, &r) in adjoint.iter_mut().zip(&rows) {
                    let t = Instant::now();
                    let recorded = record(with_grad.system(), &p, &case.opts).expect("records");
                    recorded.gradients(with_grad.system(), &p, &seeds(r)).expect("carried");
                    slot.push(t.elapsed().as_secs_f64());
                }
            }
            let plain = median(plain);
            let forward = median(forward) / plain;
            let adjoint: Vec<f64> = adjoint.into_iter().map(|a| median(a) / plain).collect();
            fwd_points.push((m as f64, forward - 1.0));
            adj_points.extend(rows.iter().zip(&adjoint).map(|(&r, &a)| (r as f64, a)));
            println!(
                "| {} | {n} | {m} | {:.3} | {forward:.2} | {} |",
                case.name,
                plain * 1e3,
                adjoint.iter().map(|a| format!("{a:.2}")).collect::<Vec<_>>().join(", ")
            );
            label =
                if family.len() > 1 { case.name.split(',').next().unwrap_or(&case.name) } else { &case.name }
                    .to_string();
        }
        // `forward / plain - 1 = a m` through the origin: a column's cost.
        let a = fwd_points.iter().map(|(m, y)| m * y).sum::<f64>()
            / fwd_points.iter().map(|(m, _)| m * m).sum::<f64>();
        let (b, c) = fit(&adj_points);
        fits.push((label, a, b, c));
    }
    println!();
    println!("| model | a: a forward column / plain run | b: the adjoint's fixed cost / plain run | c: a backward row / plain run |");
    println!("| --- | --- | --- | --- |");
    for (label, a, b, c) in fits {
        println!("| {label} | {a:.3} | {b:.2} | {c:.3} |");
    }
}
