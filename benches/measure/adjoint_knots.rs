//! Measures the adjoint's cost against the number of parameters (issue #40, section 4): the
//! bouncing ball pushed by a `pwl(t, 0, 2.5, u)` force of K knots, the gradient of one scalar
//! (the final energy) with respect to every knot. For each K: the compile time (every knot
//! differentiated), a plain run (the model compiled without gradients), the adjoint (the
//! recording run and one backward pass: `hybc::sim::adjoint::record` + `Recorded::gradient`),
//! and forward sensitivities (K columns, `sens_error_control` off: the same steps) up to the
//! largest K given to `--forward-upto` (default 2000; they grow as K). Times are medians of
//! `--repeat` runs (default 7), interleaved per K so the machine's drift hits every mode alike.
//!
//! `--svg PATH` also draws both modes' cost over a plain run's against K on log-log axes.
//!
//! `cargo run --release --example adjoint_knots -- 10 100 1000 10000`
//! docs/performance.md, "Gradients by the adjoint", has the figures.

use std::time::Instant;

use hybc::plot::{plot_curves, CurveFigure, CurveSeries};
use hybc::sim::adjoint::{record, Seed};
use hybc::sim::{run, SimOptions};
use hybc::Model;

#[path = "../support/pushed_ball.rs"]
mod pushed_ball;
use pushed_ball::pushed_ball_source;

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let svg = args.iter().position(|a| a == "--svg").map(|i| {
        let path = std::path::PathBuf::from(&args[i + 1]);
        args.drain(i..i + 2);
        path
    });
    let mut take = |flag: &str, default: usize| -> usize {
        match args.iter().position(|a| a == flag) {
            Some(i) => {
                let v = args[i + 1].parse().expect("a count");
                args.drain(i..i + 2);
                v
            }
            None => default,
        }
    };
    let repeat = take("--repeat", 7);
    let forward_upto = take("--forward-upto", 2000);
    let counts: Vec<usize> = args.iter().map(|a| a.parse().expect("a knot count")).collect();
    let opts = SimOptions {
        t_end: 2.5,
        rtol: 1e-10,
        atol: 1e-12,
        sens_error_control: false,
        ..SimOptions::default()
    };
    println!("| K | compile (s) | plain run (ms) | adjoint (ms) | adjoint / plain | forward (ms) | forward / plain | events | gap |");
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    let (mut adjoint_curve, mut forward_curve) = (Vec::new(), Vec::new());
    for &k in &counts {
        let model = Model::parse(&pushed_ball_source(k)).expect("checks");
        let plain_model = model.compile::<&str>(&[]).expect("compiles");
        let started = Instant::now();
        let with_grad = model.compile(&["u"]).expect("compiles");
        let compile = started.elapsed().as_secs_f64();
        let p = with_grad.params().values().to_vec();
        let out = with_grad.info().output_names.iter().position(|n| n == "energy").expect("energy");
        let seed =
            Seed { outputs: (0..1).map(|i| if i == out { 1.0 } else { 0.0 }).collect(), ..Seed::default() };
        let (mut plain, mut adjoint, mut forward) = (Vec::new(), Vec::new(), Vec::new());
        let (mut grad_adj, mut grad_fwd, mut events) = (Vec::new(), Vec::new(), 0);
        for _ in 0..repeat {
            let t = Instant::now();
            let r = run(plain_model.system(), &p, &opts).expect("runs");
            plain.push(t.elapsed().as_secs_f64());
            events = r.events.len();
            let t = Instant::now();
            let recorded = record(with_grad.system(), &p, &opts).expect("records");
            grad_adj = recorded.gradient(with_grad.system(), &p, &seed).expect("carried");
            adjoint.push(t.elapsed().as_secs_f64());
            if k <= forward_upto {
                let t = Instant::now();
                let r = run(with_grad.system(), &p, &opts).expect("runs");
                forward.push(t.elapsed().as_secs_f64());
                let dy = r.final_state.doutputs.expect("doutputs");
                let n_out = with_grad.info().n_outputs();
                grad_fwd = (0..k).map(|j| dy[j * n_out + out]).collect();
            }
        }
        let (plain, adjoint) = (median(plain), median(adjoint));
        adjoint_curve.push((k as f64, adjoint / plain));
        let (fwd, ratio, gap) = if forward.is_empty() {
            ("-".to_string(), "-".to_string(), "-".to_string())
        } else {
            let f = median(forward);
            forward_curve.push((k as f64, f / plain));
            let scale = grad_fwd.iter().fold(0.0f64, |a, b| a.max(b.abs()));
            let gap = grad_adj.iter().zip(&grad_fwd).fold(0.0f64, |a, (x, y)| a.max((x - y).abs())) / scale;
            (format!("{:.2}", f * 1e3), format!("{:.1}", f / plain), format!("{gap:.0e}"))
        };
        println!(
            "| {k} | {compile:.2} | {:.3} | {:.3} | {:.1} | {fwd} | {ratio} | {events} | {gap} |",
            plain * 1e3,
            adjoint * 1e3,
            adjoint / plain
        );
    }
    if let Some(path) = svg {
        let figure = CurveFigure {
            title: "The ball under a pwl control of K knots: one gradient's cost".into(),
            x_desc: "knots K (parameters)".into(),
            y_desc: "time over a plain run".into(),
            series: vec![
                CurveSeries { name: "adjoint (--sens adjoint)".into(), points: adjoint_curve },
                CurveSeries { name: "forward sensitivities".into(), points: forward_curve },
            ],
        };
        plot_curves(&figure, &path).expect("draws");
    }
}
