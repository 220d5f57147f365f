//! Optimisation over many variables (issue #39, section 2): L-BFGS-B behind the solver seam,
//! picked by `auto` for bounds alone above `LBFGSB_ABOVE` free variables or by `--solver`, with the
//! verdict, the minimum check and multi-start as for SLSQP.
//!
//! The independent answer: a double integrator under a `pwl` control of `N` knots whose
//! objective is a quadratic in the knots (`support/knots.rs` has its closed form): the optimum
//! without bounds solves `(lam Q + a a^T + b b^T) u = a`, computed there (a tridiagonal solve and
//! a 2 x 2 one, by Woodbury) without hybc. With bounds the problem is a strictly convex
//! quadratic program: the KKT conditions, checked with the gradient computed there, make a
//! point its unique optimum, and strong convexity bounds its distance from it.

use crate::support::cli::hybc;
use crate::support::knots::{distance_bound, dot, kkt_by_hand, source, Weights};

use hybc::fit::Bounds;
use hybc::optimize::solver::LocalSolver;
use hybc::optimize::{
    optimize, LocalResult, OptimizeOptions, OptimizeProblem, Quantity, Slsqp, SolverChoice, Verdict,
    LBFGSB_ABOVE,
};
use hybc::{Compiled, Model};
use serde_json::Value;

fn compiled(n: usize, bound: f64) -> (Model, Compiled) {
    let model = Model::parse(&source(n, bound)).expect("model");
    let compiled = model.compile(&["u"]).expect("compiles");
    (model, compiled)
}

fn solve((model, compiled): &(Model, Compiled), bound: f64, solver: &dyn LocalSolver) -> LocalResult {
    let n = compiled.info().grad_params.len();
    let problem = OptimizeProblem {
        system: compiled.native(),
        start: model.params().values().to_vec(),
        bounds: vec![Bounds { lower: -bound, upper: bound }; n],
        objective: Quantity::parse("obj", compiled.info()).expect("objective"),
        constraints: Vec::new(),
        sim: model.sim_options(),
    };
    // At the default `--ftol` 1e-12 the objective's relative change stops SLSQP short of
    // stationarity 1e-6 on these problems (L-BFGS-B reads it only once the verdict's tolerance
    // is met): these tests ask for 1e-7, with the objective's test at round-off.
    let opts = OptimizeOptions { kkt_tol: KKT_TOL, ftol: 1e-16, ..OptimizeOptions::default() };
    let mut result = optimize(&problem, &opts, solver, None).expect("optimises");
    assert_eq!(result.solver, solver.name());
    result.locals.remove(0)
}

/// The verdict's tolerance in these tests: the objective's change reaches round-off near
/// stationarity 1e-8, so 1e-7 is met with a margin.
const KKT_TOL: f64 = 1e-7;

/// The run's gradient and the closed form's differ by the integrator's error, far below this.
const BY_HAND: f64 = 2.0 * KKT_TOL;

/// The knots of the tests run by L-BFGS-B: 200 (`auto` picks it above 20); the 1,000- and
/// 10,000-knot solves are measured by `benches/measure/many_knots.rs` (docs/performance.md).
const N: usize = 200;

#[test]
fn auto_picks_lbfgsb_for_the_knots_and_it_reaches_the_optimum_of_the_linear_system() {
    const { assert!(N > LBFGSB_ABOVE) };
    let solver = SolverChoice::Auto.pick(N, 0).expect("bounds only");
    assert_eq!(solver.name(), "L-BFGS-B");
    let model = compiled(N, f64::INFINITY);
    let end = solve(&model, f64::INFINITY, solver);
    assert_eq!(end.verdict, Verdict::Converged, "{} {:?}", end.status, end.kkt);
    let w = Weights::new(N);
    let by_hand = kkt_by_hand(&w, &end.x, f64::INFINITY);
    assert!(by_hand.worst <= BY_HAND, "stationary to {:e} by the closed form", by_hand.worst);
    // The linear system's solution is within the distance strong convexity allows.
    let optimum = w.unconstrained_optimum();
    let miss: Vec<f64> = end.x.iter().zip(&optimum).map(|(u, o)| u - o).collect();
    let distance = dot(&miss, &miss).sqrt();
    assert!(distance <= distance_bound(&w, by_hand.norm), "{distance:e} from the linear system's optimum");
    let largest = optimum.iter().fold(0.0_f64, |m, u| m.max(u.abs()));
    assert!(distance <= 1e-4 * largest, "{distance:e}");
    // The run's objective is the closed form's at the same knots.
    let (f, _) = w.objective(&end.x);
    approx::assert_relative_eq!(end.values[0], f, max_relative = 1e-9);
    // The quasi-Newton model of 10 pairs finds the two strong directions (p and v) early: a
    // few hundred runs at most for 200 variables, each of which alone would take one per
    // coordinate to probe.
    assert!(end.trials.len() < 200, "{} runs", end.trials.len());
    // The minimum check, as for SLSQP: a Krylov sequence of 12 directions, no descent.
    assert_eq!(end.probe_runs, 12);
}

#[test]
fn with_bounds_active_on_some_knots_the_end_meets_the_kkt_conditions_computed_here() {
    // Unbounded, the control runs from 5.27 down to -5.17 (accelerate, then brake); within
    // [-3, 3] the first and last knots are held at the bounds.
    let bound = 3.0;
    let w = Weights::new(N);
    let free = w.unconstrained_optimum();
    assert!(free[0] > bound && free[N - 1] < -bound && free[N / 2].abs() < bound);
    let model = compiled(N, bound);
    let end = solve(&model, bound, SolverChoice::Lbfgsb.pick(N, 0).expect("bounds only"));
    assert_eq!(end.verdict, Verdict::Converged, "{} {:?}", end.status, end.kkt);
    let by_hand = kkt_by_hand(&w, &end.x, bound);
    assert!(by_hand.worst <= BY_HAND, "KKT violated by {:e} of the start's gradient", by_hand.worst);
    // Some knots held, on both bounds, and most of them held firmly (a multiplier well above 0).
    let held = by_hand.multipliers.len();
    assert!((10..=N - 10).contains(&held), "{held} knots at a bound");
    assert!(end.x.contains(&bound) && end.x.contains(&-bound));
    let firm = by_hand.multipliers.iter().filter(|&&m| m > 1e-3).count();
    assert!(firm >= held / 2, "{firm} of {held} held firmly: {:?}", by_hand.multipliers);
    // The verdict's own bookkeeping agrees: the same knots at a bound.
    let at_bound = end.kkt.as_ref().expect("measured").at_bound.iter().filter(|&&b| b != 0).count();
    assert_eq!(at_bound, held);
}

#[test]
fn both_solvers_agree_where_both_apply() {
    let n = 40;
    let bound = 3.0;
    let model = compiled(n, bound);
    let w = Weights::new(n);
    let solvers: [&dyn LocalSolver; 2] = [&Slsqp, &hybc::optimize::Lbfgsb];
    let ends: Vec<LocalResult> = solvers.iter().map(|s| solve(&model, bound, *s)).collect();
    let mut bounds = Vec::new();
    for end in &ends {
        assert_eq!(end.verdict, Verdict::Converged, "{} {:?}", end.status, end.kkt);
        let by_hand = kkt_by_hand(&w, &end.x, bound);
        assert!(by_hand.worst <= BY_HAND, "{}: KKT violated by {:e}", end.status, by_hand.worst);
        assert!(!by_hand.multipliers.is_empty());
        bounds.push(distance_bound(&w, by_hand.norm));
    }
    // Both within their distance of the one optimum, so within the sum of each other.
    let gap: Vec<f64> = ends[0].x.iter().zip(&ends[1].x).map(|(a, b)| a - b).collect();
    let gap = dot(&gap, &gap).sqrt();
    assert!(gap <= bounds[0] + bounds[1], "SLSQP and L-BFGS-B {gap:e} apart");
    assert!(gap <= 1e-4 * bound, "{gap:e}");
    approx::assert_relative_eq!(ends[0].values[0], ends[1].values[0], max_relative = 1e-10);
}

/// Runs `hybc optimize` on the model `text` (written to a temporary file) with `args`: exit
/// code, stdout and stderr.
fn hybc_on(text: &str, args: &[&str]) -> (Option<i32>, String, String) {
    let dir = tempfile::tempdir().expect("temporary directory");
    let path = dir.path().join("model.hyb");
    std::fs::write(&path, text).expect("writes");
    let mut all = vec!["optimize", path.to_str().expect("utf-8")];
    all.extend(args);
    let out = hybc(&all);
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn json(out: &str) -> Value {
    serde_json::from_str(out).unwrap_or_else(|e| panic!("{e}: {out}"))
}

#[test]
fn the_solver_flag_picks_and_the_report_names_the_solver_that_ran() {
    let ball = |extra: &[&str]| {
        let mut args = vec!["optimize", "models/ball.hyb", "--quiet", "--format", "json"];
        args.extend(extra);
        let out = hybc(&args);
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    // Bounds alone, few variables: auto runs SLSQP; --solver lbfgsb runs L-BFGS-B to the same
    // end (h0 held at its lower bound, where the objective's gradient 1 points out of the box).
    let bounded = ["--free", "h0", "--minimize", "h0", "--bounds", "h0=0.5:2"];
    for (flag, name) in [(None, "SLSQP"), (Some("lbfgsb"), "L-BFGS-B"), (Some("slsqp"), "SLSQP")] {
        let mut args = bounded.to_vec();
        if let Some(flag) = flag {
            args.extend(["--solver", flag]);
        }
        let (code, out, err) = ball(&args);
        assert_eq!(code, Some(0), "{err}");
        let v = json(&out);
        assert_eq!(v["solver"], name);
        assert_eq!((v["reason"].as_str(), v["optimum"]["h0"].as_f64()), (Some("converged"), Some(0.5)));
        assert_eq!(v["at_bound"]["h0"], "lower");
    }
    // General constraints: auto runs SLSQP, and lbfgsb is a usage error naming the flag.
    let constrained =
        ["--free", "h0,e", "--minimize", "h0", "--subject-to", "energy = 2", "--bounds", "h0=0.5:2"];
    let (code, out, _) = ball(&constrained);
    assert_eq!((code, json(&out)["solver"].as_str()), (Some(0), Some("SLSQP")));
    let mut refused = constrained.to_vec();
    refused.extend(["--solver", "lbfgsb"]);
    let (code, out, err) = ball(&refused);
    assert_eq!(code, Some(2), "{out}");
    assert!(
        err.contains(
            "--solver: lbfgsb takes bounds only, not general constraints: use slsqp (or auto, which picks it for constraints)"
        ),
        "{err}"
    );
    // The usage text states the count `auto` switches at.
    let help = String::from_utf8_lossy(&hybc(&["optimize", "--help"]).stdout).into_owned();
    assert!(
        help.contains(&format!("L-BFGS-B for bounds only above {LBFGSB_ABOVE} free parameters")),
        "{help}"
    );
    // The table says which solver ran, as its JSON does.
    let out = hybc(
        &["optimize", "models/ball.hyb", "--quiet", "--solver", "lbfgsb"]
            .iter()
            .chain(&bounded)
            .copied()
            .collect::<Vec<_>>(),
    );
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(table.contains("solver L-BFGS-B") && table.contains("(L-BFGS-B: GtolReached)"), "{table}");
}

#[test]
fn the_free_parameter_cap_is_the_running_solvers_and_the_error_names_both() {
    // Checked before anything is compiled: the model only declares the vector.
    let declare = |n: usize| {
        format!("model big\nparam u[{n}] = 0 in [-1, 1]\nstate x = 0\nder(x) = u[0]\noutput y = x\n")
    };
    let slsqp = declare(1001);
    for extra in [&["--subject-to", "y <= 1"][..], &["--solver", "slsqp"][..]] {
        let mut args = vec!["--free", "u", "--minimize", "y"];
        args.extend(extra);
        let (code, _, err) = hybc_on(&slsqp, &args);
        assert_eq!(code, Some(2), "{err}");
        assert!(
            err.contains(
                "--free (parameters, vector elements counted; the cap of SLSQP): at most 1000, found 1001"
            ),
            "{err}"
        );
    }
    // L-BFGS-B takes as many as a model can declare (`sema::MAX_PARAMS`, 100,000): the model's
    // own limit refuses more first.
    let (code, _, err) =
        hybc_on(&declare(100_001), &["--free", "u", "--minimize", "y", "--solver", "lbfgsb"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("expected a length from 1 to 100000"), "{err}");
}

#[test]
fn with_lbfgsb_a_maximum_is_not_a_minimum_and_a_multi_start_lists_the_minima() {
    // -(p - 1)^2 on [0, 2] from p = 1: the gradient is 0, so L-BFGS-B stops at once; the verdict's
    // minimum check finds the curvature -2 there, and a multi-start lists both ends (objective
    // -1) and not the start, as with SLSQP (tests/it/optimize_verdicts.rs).
    let peak = "model peak\nparam p = 1 in [0, 2]\nstate x = 0\nder(x) = 1\noutput f = -(p - 1)^2\nsimulate t_end = 1\n";
    let (code, out, err) = hybc_on(
        peak,
        &[
            "--free",
            "p",
            "--minimize",
            "f",
            "--solver",
            "lbfgsb",
            "--starts",
            "4",
            "--seed",
            "1",
            "--quiet",
            "--format",
            "json",
        ],
    );
    assert_eq!(code, Some(0), "{err}");
    let v = json(&out);
    assert_eq!(v["solver"], "L-BFGS-B");
    assert_eq!(v["starts"][0]["reason"], "not_a_minimum");
    assert_eq!(v["starts"][0]["status"], "GtolReached");
    let optima = v["optima"].as_array().expect("optima");
    let mut ends: Vec<f64> = optima.iter().map(|o| o["params"]["p"].as_f64().expect("p")).collect();
    ends.sort_by(f64::total_cmp);
    assert_eq!(ends, vec![0.0, 2.0]);
    assert!(optima.iter().all(|o| o["objective"] == -1.0));
}
