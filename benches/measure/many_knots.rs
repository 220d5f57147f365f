//! Measures optimisation over many knots (issue #39): the double integrator `p'' = u` under a
//! `pwl(t, 0, 1, u)` control of N knots, minimising `(p(1) - 1)^2 + v(1)^2 + 0.01 int u^2`
//! (`tests/it/support/knots.rs`), each knot in `[-B, B]`, from `u = 0`, at the default options
//! (`--kkt-tol 1e-6`, `--ftol 1e-12`, `--max-iter 200`; the model's rtol 1e-10).
//!
//! Three modes:
//! - `cargo run --release --example many_knots -- solve [SOLVER] [B] N...`: the whole
//!   optimisation (`hybc::optimize::optimize`, what `hybc optimize` runs): compile time,
//!   evaluations (runs the solver asked for), runs in all (with the minimum check's and the
//!   end's), time, time per run, the verdict and its stationarity, and the end checked without
//!   hybc: the KKT conditions by the closed-form gradient (largest entry of the projected
//!   gradient over the start's) and, without bounds (`inf`), the distance to the linear system's
//!   optimum with the most strong convexity allows (in brackets).
//! - `... -- closed [SOLVER] [B] N...`: the solver alone on the closed-form objective (no model,
//!   no runs: the quadratic every run computes to round-off): its evaluations and its own time,
//!   so its cost at counts whose runs are too slow today.
//! - `... -- run N...`: compile time and one run with the gradient of every knot; then the
//!   adjoint's `flow_vjp` (its kernel's compile on the first call, and one call) against one
//!   `flow_sens` call.
//!
//! SOLVER is `lbfgsb` (default) or `slsqp`, B a bound (default 3; `inf` for none). docs/performance.md,
//! "Optimisation over many knots", has the figures.

use std::time::Instant;

use hybc::fit::Bounds;
use hybc::optimize::solver::{LocalSolver, Program, SmoothPoint};
use hybc::optimize::{optimize, Lbfgsb, OptimizeOptions, OptimizeProblem, Quantity, Slsqp};
use hybc::sim::HybridSystem;
use hybc::{Model, Sens, SimOptions};

#[path = "../../tests/it/support/knots.rs"]
mod knots;
use knots::{distance_bound, dot, kkt_by_hand, source, Weights};

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mode = if args.is_empty() { "solve".to_string() } else { args.remove(0) };
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
        Some(Ok(b)) if args.len() > 1 && mode != "run" => {
            args.remove(0);
            b
        }
        _ => 3.0,
    };
    let counts: Vec<usize> = args.iter().map(|a| a.parse().expect("a knot count")).collect();
    match mode.as_str() {
        "solve" => solve(solver, bound, &counts),
        "closed" => closed(solver, bound, &counts),
        "run" => run(&counts),
        other => panic!("mode `{other}`: expected solve, closed or run"),
    }
}

/// The distance to the linear system's optimum and its bound, without bounds; `-` with them.
fn distance(w: &Weights, x: &[f64], bound: f64, norm: f64) -> String {
    if bound.is_finite() {
        return "-".to_string();
    }
    let optimum = w.unconstrained_optimum();
    let miss: Vec<f64> = x.iter().zip(&optimum).map(|(u, o)| u - o).collect();
    format!("{:.1e} ({:.1e})", dot(&miss, &miss).sqrt(), distance_bound(w, norm))
}

fn solve(solver: &dyn LocalSolver, bound: f64, counts: &[usize]) {
    println!(
        "{:>6} {:>9} {:>5} {:>9} {:>6} {:>5} {:>9} {:>8} {:>10} {:>9} {:>5} {:>9}  distance",
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
        "by hand"
    );
    for &n in counts {
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
            // What `hybc optimize` takes: gradients by the cheaper mode (`--sens auto`), the
            // adjoint here (one objective against N knots); `MANY_KNOTS_SENS=forward` for forward.
            sim: SimOptions {
                sens: if std::env::var("MANY_KNOTS_SENS").is_ok_and(|v| v == "forward") {
                    Sens::Forward
                } else {
                    Sens::Auto
                },
                ..model.sim_options()
            },
        };
        let started = Instant::now();
        let result = optimize(&problem, &OptimizeOptions::default(), solver, None).expect("optimises");
        let time = started.elapsed().as_secs_f64();
        let end = &result.locals[0];
        let w = Weights::new(n);
        let by_hand = kkt_by_hand(&w, &end.x, bound);
        println!(
            "{:>6} {:>9} {:>5} {:>8.3}s {:>6} {:>5} {:>8.1}s {:>7.3}s {:>10} {:>9.1e} {:>5} {:>9.1e}  {}",
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
            distance(&w, &end.x, bound, by_hand.norm)
        );
    }
}

fn closed(solver: &dyn LocalSolver, bound: f64, counts: &[usize]) {
    println!(
        "{:>7} {:>9} {:>5} {:>6} {:>10} {:>10} {:>15} {:>7} {:>9}  distance",
        "knots", "solver", "bound", "evals", "time", "per eval", "status", "held", "by hand"
    );
    for &n in counts {
        let w = Weights::new(n);
        let options = OptimizeOptions::default();
        let program = Program {
            bounds: vec![(-bound, bound); n],
            n_eq: 0,
            n_ineq: 0,
            tolerances: Vec::new(),
            max_evals: options.max_iter,
            xtol_rel: options.xtol,
            ftol_rel: options.ftol,
            gtol: options.kkt_tol,
        };
        let mut evals = 0;
        let mut evaluate = |x: &[f64]| {
            evals += 1;
            let (objective, gradient) = w.objective(x);
            Some(SmoothPoint { objective, gradient, constraints: Vec::new(), jacobian: Vec::new() })
        };
        let started = Instant::now();
        let end = solver.solve(&program, &vec![0.0; n], &mut evaluate);
        let time = started.elapsed().as_secs_f64();
        let by_hand = kkt_by_hand(&w, &end.x, bound);
        println!(
            "{:>7} {:>9} {:>5} {:>6} {:>9.3}s {:>8.2}ms {:>15} {:>7} {:>9.1e}  {}",
            n,
            solver.name(),
            bound,
            evals,
            time,
            1e3 * time / evals as f64,
            end.status,
            by_hand.multipliers.len(),
            by_hand.worst,
            distance(&w, &end.x, bound, by_hand.norm)
        );
    }
}

fn run(counts: &[usize]) {
    println!(
        "{:>6} {:>9} {:>9} {:>12} {:>10} {:>11}",
        "knots", "compile", "run", "vjp compile", "vjp call", "sens call"
    );
    for &n in counts {
        let started = Instant::now();
        let model = Model::parse(&source(n, 3.0)).expect("model");
        let compiled = model.compile(&["u"]).expect("compiles");
        let compile = started.elapsed().as_secs_f64();
        let started = Instant::now();
        compiled.simulate(&model.params(), &model.sim_options()).expect("runs");
        let run = started.elapsed().as_secs_f64();
        // The adjoint's products (issue #40): the first `flow_vjp` call compiles its kernel; then
        // one call against one `flow_sens` call (every knot's sensitivity column), at t = 0.3.
        let sys = compiled.system();
        let p: Vec<f64> = (0..n).map(|k| (k % 7) as f64 / 7.0).chain([knots::LAM]).collect();
        let (x, w) = ([0.1, 0.2, 0.3], [1.0, -1.0, 0.5]);
        let (mut gx, mut gp) = (vec![0.0; 3], vec![0.0; n]);
        let started = Instant::now();
        sys.flow_vjp(0, 0.3, &x, &w, &p, &mut gx, &mut gp);
        let vjp_compile = started.elapsed().as_secs_f64();
        let per_call = |f: &mut dyn FnMut()| {
            let reps = (200_000 / n).max(10);
            let started = Instant::now();
            for _ in 0..reps {
                f();
            }
            started.elapsed().as_secs_f64() / reps as f64 * 1e6
        };
        let vjp_call = per_call(&mut || sys.flow_vjp(0, 0.3, &x, &w, &p, &mut gx, &mut gp));
        let s = vec![0.0; 3 * n];
        let (mut dx, mut ds) = (vec![0.0; 3], vec![0.0; 3 * n]);
        let sens_call = per_call(&mut || sys.flow_sens(0, 0.3, &x, &s, &p, &mut dx, &mut ds));
        println!(
            "{:>6} {:>8.3}s {:>8.3}s {:>11.3}s {:>8.2}us {:>9.2}us",
            n, compile, run, vjp_compile, vjp_call, sens_call
        );
    }
}
