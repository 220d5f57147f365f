//! Measures optimisation over many knots (issue #39): the double integrator `p'' = u` under a
//! `pwl(t, 0, 1, u)` control of N knots, minimising `(p(1) - 1)^2 + v(1)^2 + 0.01 int u^2`
//! (`tests/it/support/knots.rs`), each knot in `[-B, B]`, from `u = 0` at the default options
//! (`--kkt-tol 1e-6`, `--ftol 1e-12`, `--max-iter 200`, the model's rtol 1e-10). Per solve:
//! compile time, evaluations (runs the solver asked for), runs in all (with the minimum check's
//! and the end's), time, time per run, the verdict, and the end checked without hybc: the KKT
//! conditions by the closed-form gradient and, without bounds, the distance to the linear
//! system's optimum.
//!
//! Run: `cargo run --release --example many_knots -- [SOLVER] [B] N...` with SOLVER `lbfgsb`
//! (default) or `slsqp`, B a bound (default 3; `inf` for none), e.g.
//! `cargo run --release --example many_knots -- lbfgsb 3 1000 10000`. docs/performance.md has the
//! figures.

use std::time::Instant;

use hybc::fit::Bounds;
use hybc::optimize::solver::LocalSolver;
use hybc::optimize::{optimize, Lbfgsb, OptimizeOptions, OptimizeProblem, Quantity, Slsqp};
use hybc::Model;

#[path = "../../tests/it/support/knots.rs"]
mod knots;
use knots::{distance_bound, dot, kkt_by_hand, source, Weights};

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let solver: &dyn LocalSolver = match args.first().map(String::as_str) {
        Some("slsqp") => {
            args.remove(0);
            &Slsqp
        }
        Some("lbfgsb") => {
            args.remove(0);
            &Lbfgsb
        }
        _ => &Lbfgsb,
    };
    let bound: f64 = match args.first().map(|a| a.parse::<f64>()) {
        Some(Ok(b)) if args.len() > 1 => {
            args.remove(0);
            b
        }
        _ => 3.0,
    };
    let counts: Vec<usize> = if args.is_empty() {
        vec![1000]
    } else {
        args.iter().map(|a| a.parse().expect("a knot count")).collect()
    };
    println!(
        "{:>6} {:>9} {:>5} {:>9} {:>6} {:>5} {:>9} {:>8} {:>10} {:>9} {:>5} {:>9} {:>9}",
        "knots",
        "solver",
        "bound",
        "compile",
        "evals",
        "runs",
        "time",
        "per run",
        "verdict",
        "stat",
        "held",
        "by hand",
        "distance"
    );
    for n in counts {
        let started = Instant::now();
        let model = Model::parse(&source(n, bound)).expect("model");
        let compiled = model.compile(&["u"]).expect("compiles");
        let compile = started.elapsed().as_secs_f64();
        let problem = OptimizeProblem {
            system: compiled.native(),
            start: model.params().values().to_vec(),
            bounds: vec![Bounds { lower: -bound, upper: bound }; n],
            objective: Quantity::parse("obj", compiled.info()).expect("objective"),
            constraints: Vec::new(),
            sim: model.sim_options(),
        };
        let started = Instant::now();
        let result = optimize(&problem, &OptimizeOptions::default(), solver, None).expect("optimises");
        let time = started.elapsed().as_secs_f64();
        let end = &result.locals[0];
        let w = Weights::new(n);
        let by_hand = kkt_by_hand(&w, &end.x, bound);
        // Without bounds, the distance to the linear system's optimum, and the most strong
        // convexity allows for the end's projected gradient (in brackets).
        let distance = if bound.is_finite() {
            "-".to_string()
        } else {
            let optimum = w.unconstrained_optimum();
            let miss: Vec<f64> = end.x.iter().zip(&optimum).map(|(u, o)| u - o).collect();
            format!("{:.1e} ({:.1e})", dot(&miss, &miss).sqrt(), distance_bound(&w, by_hand.norm))
        };
        println!(
            "{:>6} {:>9} {:>5} {:>8.3}s {:>6} {:>5} {:>8.1}s {:>7.3}s {:>10} {:>9.1e} {:>5} {:>9.1e} {}",
            n,
            result.solver,
            bound,
            compile,
            end.trials.len(),
            end.runs,
            time,
            time / end.runs as f64,
            end.verdict.word(),
            end.kkt.as_ref().map_or(f64::NAN, |k| k.stationarity),
            by_hand.multipliers.len(),
            by_hand.worst,
            distance
        );
    }
}
