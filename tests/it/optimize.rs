//! `hybc optimize` on the shipped problems: the library API for the numbers (closed forms, KKT
//! residuals, event sequences), the binary for JSON, the `--set` list and exit codes.
//!
//! Problem 1, the reference notebook's two-parameter exercise on the bouncing ball
//! (`models/ball.hyb`, g = 9.81, T = 2.5): choose (h0, e) so that the energy at T is E* = 2 and the
//! height at T is y* = 0.1. Two equations in two unknowns: written as equality constraints, with
//! the drop height as the objective (the lowest drop that ends so). The feasible set is a point per
//! branch: after n bounces the speed is w = sqrt(2 E*) whatever h0 and e are, so y* fixes the time
//! since the n-th bounce, tau = (w -/+ sqrt(w^2 - 2 g y*)) / g (rising / falling at T), and then
//! t_n = T - tau = (w / (g e^n)) (1 + 2 e + ... + 2 e^(n-1)) is a polynomial in e, with
//! h0 = w^2 / (2 g e^(2n)). Each branch (n, rising or falling) is one smooth piece of the problem
//! and has its own solution; a local optimiser ends on the branch its start leads to.

use crate::support::cli::hybc;

use hybc::fit::Bounds;
use hybc::optimize::{
    optimize, parse_constraint, OptimizeOptions, OptimizeProblem, OptimizeResult, Quantity, Slsqp, Verdict,
};
use hybc::{Compiled, Model};
use serde_json::Value;

const G: f64 = 9.81;
const T: f64 = 2.5;
const E_STAR: f64 = 2.0;
const Y_STAR: f64 = 0.1;

/// (e, h0) of the branch with `n` bounces before T, rising or falling at T.
pub(crate) fn branch(n: i32, rising: bool) -> (f64, f64) {
    let w = (2.0 * E_STAR).sqrt();
    let root = (w * w - 2.0 * G * Y_STAR).sqrt();
    let tau = if rising { (w - root) / G } else { (w + root) / G };
    let t_n = T - tau;
    // F(e) = t_n(e) - (T - tau) decreases in e on (0, 1]: bisection to round-off.
    let f = |e: f64| w / (G * e.powi(n)) * (1.0 + 2.0 * (1..n).map(|k| e.powi(k)).sum::<f64>()) - t_n;
    let (mut lo, mut hi) = (1e-3, 1.0);
    assert!(f(lo) > 0.0 && f(hi) < 0.0, "branch n = {n} has no solution with e in (0, 1]");
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let e = 0.5 * (lo + hi);
    (e, w * w / (2.0 * G * e.powi(2 * n)))
}

fn compiled<S: AsRef<str>>(path: &str, free: &[S]) -> (Model, Compiled) {
    let model = Model::from_file(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(path)).expect("model");
    let compiled = model.compile(free).expect("compiles");
    (model, compiled)
}

fn solve(
    model: &Model,
    compiled: &Compiled,
    bounds: Vec<Bounds>,
    objective: &str,
    constraints: &[&str],
    opts: &OptimizeOptions,
) -> OptimizeResult {
    let info = compiled.info();
    let problem = OptimizeProblem {
        system: compiled.native(),
        start: model.params().values().to_vec(),
        bounds,
        objective: Quantity::parse(objective, info).expect("objective"),
        constraints: constraints
            .iter()
            .flat_map(|c| parse_constraint(c, info).expect("constraint"))
            .collect(),
        sim: model.sim_options(),
    };
    optimize(&problem, opts, &Slsqp, None).expect("optimises")
}

fn ball_bounds() -> Vec<Bounds> {
    vec![Bounds { lower: 0.5, upper: 2.0 }, Bounds { lower: 0.75, upper: 0.95 }]
}

/// Relative 1e-8: `hybc run` meets the ball's closed forms to 1e-9 at the model's tolerances
/// (tests/cli_run.rs), the equalities are met to 1e-2 of their tolerance (2e-10 in E), and the
/// 2 x 2 system's condition number (about 10 here) carries both into (h0, e).
const CLOSED_FORM_TOL: f64 = 1e-8;

#[test]
fn ball_exercise_ends_on_the_branch_of_its_start_at_the_closed_form() {
    let (model, compiled) = compiled("models/ball.hyb", &["h0", "e"]);
    let r = solve(
        &model,
        &compiled,
        ball_bounds(),
        "h0",
        &["energy = 2", "y = 0.1"],
        &OptimizeOptions::default(),
    );
    let end = r.best().expect("converged");
    // From h0 = 1, e = 0.8 (4 bounces, falling at T): the 4-bounce falling branch.
    let (e, h0) = branch(4, false);
    approx::assert_relative_eq!(end.x[0], h0, max_relative = CLOSED_FORM_TOL);
    approx::assert_relative_eq!(end.x[1], e, max_relative = CLOSED_FORM_TOL);
    let run = end.run.as_ref().expect("the end's run");
    assert_eq!(run.events.len(), 4);
    assert!(run.events.iter().all(|ev| &*ev.name == "touchdown"));
    assert!(run.final_state.state[1] < 0.0, "falling at T");
    let kkt = end.kkt.as_ref().expect("kkt");
    assert!(kkt.stationarity <= 1e-6, "stationarity {}", kkt.stationarity);
    assert!(kkt.violation_ratio <= 1.0);
    assert_eq!(kkt.active, vec![true, true]);
    // The lowest drop on this branch: a larger E* needs a larger h0 (positive multiplier).
    assert!(kkt.multipliers[0] > 0.0);
    assert!(end.cusp_notes.is_empty(), "{:?}", end.cusp_notes);
    assert_eq!(end.verdict, Verdict::Converged);
}

#[test]
fn ball_starts_find_the_optima_of_three_branches() {
    let (model, compiled) = compiled("models/ball.hyb", &["h0", "e"]);
    // 32 starts: of 16, one found the 5-bounce branch, on a path across three cusps that
    // round-off decides (event times moving by 1e-16 lost it); of 32, two do.
    let opts = OptimizeOptions { starts: 32, seed: 1, ..OptimizeOptions::default() };
    let r = solve(&model, &compiled, ball_bounds(), "h0", &["energy = 2", "y = 0.1"], &opts);
    // Within h0 in [0.5, 2], e in [0.75, 0.95] three branches have a solution: 4 bounces falling
    // (h0 = 0.810), 4 rising (1.216), 5 rising (0.553); 3 falling needs h0 = 2.12.
    let mut found: Vec<(usize, f64, f64)> = r
        .optima
        .iter()
        .map(|g| {
            let l = &r.locals[g[0]];
            (l.events().len(), l.x[0], l.x[1])
        })
        .collect();
    found.sort_by(|a, b| a.1.total_cmp(&b.1));
    let expected = [(5, branch(5, true)), (4, branch(4, false)), (4, branch(4, true))];
    assert_eq!(found.len(), expected.len(), "{found:?}");
    for ((n, h0, e), (n_x, (e_x, h0_x))) in found.iter().zip(expected) {
        assert_eq!(*n, n_x);
        approx::assert_relative_eq!(*h0, h0_x, max_relative = CLOSED_FORM_TOL);
        approx::assert_relative_eq!(*e, e_x, max_relative = CLOSED_FORM_TOL);
    }
    // Each start is computed from its index alone: one thread finds the same, bit for bit.
    let serial = solve(
        &model,
        &compiled,
        ball_bounds(),
        "h0",
        &["energy = 2", "y = 0.1"],
        &OptimizeOptions { threads: 1, ..opts },
    );
    assert_eq!(serial.optima, r.optima);
    assert!(serial.locals.iter().zip(&r.locals).all(|(a, b)| a.x == b.x && a.trials.len() == b.trials.len()));
    // Best first: the 5-bounce branch has the lowest drop.
    assert_eq!(r.best().expect("converged").events().len(), 5);
    // The starts that found none are honest about it: each says why (a start drawn into the
    // infeasible corner may also run out of evaluations there, where SLSQP's steps stall on the
    // bounds; which starts do depends on round-off at the cusps between branches).
    for l in r.locals.iter().filter(|l| !l.converged()) {
        assert!(
            matches!(
                l.verdict,
                Verdict::Infeasible
                    | Verdict::StalledAtCusp { .. }
                    | Verdict::StartFailed { .. }
                    | Verdict::MaxIterations
            ),
            "{:?}",
            l.verdict
        );
    }
}

#[test]
fn path_constraint_on_the_first_fall_holds_at_its_last_time() {
    // Before the first bounce y = h0 - g t^2 / 2: y >= 0.5 on t in [0.2, 0.4] binds at t = 0.4,
    // so the lowest drop is h0 = 0.5 + g 0.4^2 / 2.
    let (model, compiled) = compiled("models/ball.hyb", &["h0"]);
    let bounds = vec![Bounds { lower: 0.5, upper: 3.0 }];
    let r = solve(&model, &compiled, bounds, "h0", &["y@0.2:0.4:5 >= 0.5"], &OptimizeOptions::default());
    let end = r.best().expect("converged");
    approx::assert_relative_eq!(end.x[0], 0.5 + G * 0.16 / 2.0, max_relative = CLOSED_FORM_TOL);
    let kkt = end.kkt.as_ref().expect("kkt");
    assert_eq!(kkt.active, vec![false, false, false, false, true]);
    approx::assert_relative_eq!(kkt.multipliers[4], 1.0, max_relative = 1e-6);
}

#[test]
fn an_optimum_on_t_end_says_so_with_its_margin() {
    // Pin the 4th touchdown on T = t_end: t1 (1 + 2 e + 2 e^2 + 2 e^3) = T with t1 = sqrt(2 / g).
    // The point is a KKT point of its piece, and a cusp of the problem: converged, with a note.
    let (model, compiled) = compiled("models/ball.hyb", &["e"]);
    let bounds = vec![Bounds { lower: 0.75, upper: 0.95 }];
    let r = solve(&model, &compiled, bounds, "e", &["touchdown#4 = 2.5"], &OptimizeOptions::default());
    let end = r.best().expect("converged");
    let t1 = (2.0 / G).sqrt();
    let (mut lo, mut hi) = (0.75_f64, 0.95_f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if t1 * (1.0 + 2.0 * (mid + mid * mid + mid.powi(3))) < T {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    approx::assert_relative_eq!(end.x[0], 0.5 * (lo + hi), max_relative = CLOSED_FORM_TOL);
    assert_eq!(end.cusp_notes.len(), 1, "{:?}", end.cusp_notes);
    assert!(end.cusp_notes[0].contains("before t_end"), "{}", end.cusp_notes[0]);
}

#[test]
fn energies_in_the_jump_between_branches_stall_at_a_cusp() {
    // Between g e_c^8 = 3.12 and g e_c^6 = 4.16 no e gives the energy (docs/fit.md): the
    // optimiser ends at the jump, and says so (exit 4).
    let out = hybc(&[
        "optimize",
        "models/ball.hyb",
        "--free",
        "e",
        "--minimize",
        "e",
        "--subject-to",
        "energy = 3.5",
        "--set",
        "e=0.84",
        "--quiet",
        "--format",
        "json",
    ]);
    assert_eq!(out.status.code(), Some(4));
    let v = json(&out);
    assert_eq!(v["reason"], "stalled_at_cusp");
    assert!(!v["sequence_changes"].as_array().expect("changes").is_empty());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("did not converge: stalled at a cusp"), "{err}");
}

/// Problem 2: the hopper reaching an apex height of 0.9 m with least effort (integral of
/// thrust^2); no closed form, so the KKT claim is checked independently by finite differences.
#[test]
fn hopper_apex_least_effort_satisfies_kkt_by_finite_differences() {
    let elements: Vec<String> = (0..7).map(|k| format!("u[{k}]")).collect();
    let (model, compiled) = compiled("models/hopper_apex.hyb", &elements);
    let bounds = vec![Bounds { lower: 0.0, upper: 100.0 }; 7];
    let r = solve(&model, &compiled, bounds, "effort", &["y >= 0.9"], &OptimizeOptions::default());
    let end = r.best().expect("converged");
    let run = end.run.as_ref().expect("run");
    let names: Vec<&str> = run.events.iter().map(|e| &*e.name).collect();
    assert_eq!(names, ["touchdown", "liftoff", "apex"]);
    let kkt = end.kkt.as_ref().expect("kkt");
    assert!(kkt.stationarity <= 1e-6, "stationarity {}", kkt.stationarity);
    assert!(kkt.active[0] && kkt.multipliers[0] > 0.0, "the apex constraint binds");
    approx::assert_abs_diff_eq!(end.values[1], 0.9, epsilon = r.tolerances[0]);

    // Finite differences of effort and apex height, from the plain runs (no sensitivities).
    let plain = model.compile::<&str>(&[]).expect("compiles");
    let opts = model.sim_options();
    let at = |x: &[f64]| {
        let mut p = model.params();
        p.set_vector("u", x).expect("in range");
        let run = plain.simulate(&p, &opts).expect("runs");
        (run.state("effort").expect("effort"), run.state("y").expect("y"))
    };
    let h = 1e-4;
    let diff = |k: usize| {
        let (mut up, mut down) = (end.x.clone(), end.x.clone());
        up[k] += h;
        down[k] -= h;
        if down[k] < 0.0 {
            // One-sided at the lower bound (second order).
            let mut up2 = end.x.clone();
            up2[k] += 2.0 * h;
            let (f0, c0) = at(&end.x);
            let (f1, c1) = at(&up);
            let (f2, c2) = at(&up2);
            return ((-3.0 * f0 + 4.0 * f1 - f2) / (2.0 * h), (-3.0 * c0 + 4.0 * c1 - c2) / (2.0 * h));
        }
        let ((f1, c1), (f0, c0)) = (at(&up), at(&down));
        ((f1 - f0) / (2.0 * h), (c1 - c0) / (2.0 * h))
    };
    // The knots the box holds are reported on it, not at SLSQP's clipping noise (3.5e-15).
    for k in (0..7).filter(|&k| kkt.at_bound[k] == -1) {
        assert_eq!(end.x[k], 0.0, "u[{k}]");
    }
    let grads: Vec<(f64, f64)> = (0..7).map(diff).collect();
    let free: Vec<usize> = (0..7).filter(|&k| kkt.at_bound[k] == 0).collect();
    assert!(free.len() >= 2, "at least two thrust values are free at the optimum: {:?}", end.x);
    // The multiplier that best balances the free coordinates: d effort = mu d apex.
    let mu = free.iter().map(|&k| grads[k].0 * grads[k].1).sum::<f64>()
        / free.iter().map(|&k| grads[k].1 * grads[k].1).sum::<f64>();
    let scale = free.iter().map(|&k| grads[k].0.abs()).fold(0.0, f64::max);
    for &k in &free {
        let residual = grads[k].0 - mu * grads[k].1;
        assert!(residual.abs() <= 1e-5 * scale, "u[{k}]: d effort - mu d apex = {residual} (scale {scale})");
    }
    // A thrust held at 0 may only be held there by the objective: raising it costs more than
    // the height it buys is worth.
    for k in (0..7).filter(|&k| kkt.at_bound[k] == -1) {
        assert!(grads[k].0 - mu * grads[k].1 >= -1e-5 * scale, "u[{k}] at 0 would rather rise");
    }
    approx::assert_relative_eq!(mu, kkt.multipliers[0], max_relative = 1e-4);
}

fn json(out: &std::process::Output) -> Value {
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stdout)))
}

#[test]
fn cli_json_and_the_set_list_reproduce_the_optimum_in_hybc_run() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let svg = dir.path().join("ball.svg");
    let out = hybc(&[
        "optimize",
        "models/ball.hyb",
        "--free",
        "h0,e",
        "--minimize",
        "h0",
        "--subject-to",
        "energy = 2",
        "--subject-to",
        "y = 0.1",
        "--bounds",
        "h0=0.5:2",
        "--format",
        "json",
        "--quiet",
        "--plot",
        svg.to_str().expect("utf-8 path"),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v = json(&out);
    // The figure is the optimum's run: its title lists the parameters.
    let figure = std::fs::read_to_string(&svg).expect("the plot is written");
    let h0 = v["optimum"]["h0"].as_f64().expect("h0");
    assert!(
        figure.starts_with("<svg") && figure.contains(&format!("h0 = {h0}")),
        "an SVG of the optimum's run"
    );
    assert_eq!(v["converged"], true);
    assert_eq!(v["reason"], "converged");
    assert_eq!(v["events"].as_array().map(Vec::len), Some(4));
    assert!(v["kkt"]["stationarity"].as_f64().expect("number") <= 1e-6);
    let mut args = vec!["run", "models/ball.hyb", "--format", "json"];
    let sets: Vec<String> =
        v["set"].as_array().expect("set").iter().map(|s| s.as_str().expect("text").to_string()).collect();
    for s in &sets {
        args.extend(["--set", s.as_str()]);
    }
    let run = json(&hybc(&args));
    let energy = run["final"]["outputs"]["energy"].as_f64().expect("energy");
    let y = run["final"]["state"]["y"].as_f64().expect("y");
    for (c, value) in v["constraints"].as_array().expect("constraints").iter().zip([energy, y]) {
        let bound = c["bound"].as_f64().expect("bound");
        assert!((value - bound).abs() <= c["tolerance"].as_f64().expect("tol"), "{c} vs {value}");
    }
}

#[test]
fn cli_refuses_bad_input_with_usage_errors_and_reports_non_convergence() {
    let base = ["optimize", "models/ball.hyb", "--free", "h0,e", "--quiet"];
    let case = |extra: &[&str]| {
        let mut args = base.to_vec();
        args.extend(extra);
        let out = hybc(&args);
        (out.status.code(), String::from_utf8_lossy(&out.stderr).to_string())
    };
    let (code, err) = case(&["--minimize", "enrgy"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("--minimize") && err.contains("did you mean `energy`"), "{err}");
    let (code, err) = case(&["--minimize", "h0", "--subject-to", "energy ~ 2"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("expected QUANTITY = VALUE"), "{err}");
    let (code, err) = case(&["--minimize", "h0", "--subject-to", "y@0:2:1 >= 0"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("path grid"), "{err}");
    let (code, err) = case(&["--minimize", "h0", "--subject-to", "y@0:2.5:2001 >= 0"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("N at most 2000"), "{err}");
    let (code, err) = case(&["--minimize", "h0", "--starts", "10001", "--bounds", "h0=0.5:2"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("--starts: at most 10000"), "{err}");
    let (code, err) = case(&["--minimize", "h0", "--max-iter", "0"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("--max-iter: at least 1"), "{err}");
    let (code, err) = case(&["--minimize", "h0", "--starts", "4"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("`h0` has no finite range"), "{err}");
    let (code, err) = case(&["--minimize", "h0", "--bounds", "e=0.5:1.5"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("leaves its declared range"), "{err}");
    let out = hybc(&["optimize", "models/ball.hyb", "--free", "hh0", "--minimize", "h0"]);
    assert_eq!(out.status.code(), Some(2));
    // A value at a time the run (0 to 2.5) does not reach, named with its cause (it was the run's
    // "sample time 3 is not in order", exit 3).
    let (code, err) = case(&["--minimize", "y@3"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("--minimize: `y@3`: time 3 is after t_end = 2.5"), "{err}");
    let (code, err) = case(&["--minimize", "e", "--subject-to", "y@-1:2:4 >= 0"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("--subject-to: `y@-1:2:4 >= 0`: time -1 is before t_start = 0"), "{err}");
    // Three runs are not enough: exit 4 with the reason.
    let (code, err) = case(&[
        "--minimize",
        "h0",
        "--subject-to",
        "energy = 2",
        "--subject-to",
        "y = 0.1",
        "--max-iter",
        "3",
    ]);
    assert_eq!(code, Some(4));
    assert!(
        err.contains("did not converge: the optimiser used up its --max-iter evaluations (3 runs)"),
        "{err}"
    );
}

/// A multi-start run in shards (`OptimizeOptions::shard`, what `hybc.dask.optimize` sends each
/// task) and merged (`optimize::merge_shards`) reports what one process running every start
/// reports, timings apart, however the starts are cut; shards out of order or with a gap are
/// refused.
#[test]
fn a_multi_start_in_shards_merges_into_the_report_of_one_process() {
    use hybc::optimize::merge_shards;
    let (model, compiled) = compiled("models/ball.hyb", &["h0", "e"]);
    let subject_to = ["energy = 2".to_string(), "y = 0.1".to_string()];
    let report = |shard: Option<(usize, usize)>| -> Value {
        let options =
            OptimizeOptions { starts: 32, seed: 1, threads: 1, shard, ..OptimizeOptions::default() };
        let request = hybc::OptimizeRequest {
            minimize: "h0",
            subject_to: &subject_to,
            bounds: ball_bounds(),
            start: model.params().values().to_vec(),
            sim: model.sim_options(),
            options,
            solver: hybc::optimize::SolverChoice::Auto,
        };
        let mut json = request.run(&compiled, None).expect("solves").to_json();
        json["stats"]["compile_seconds"] = Value::Null;
        json
    };
    let without_time = |mut v: Value| {
        v["stats"]["optimize_seconds"] = Value::Null;
        v
    };
    let whole = without_time(report(None));
    assert_eq!(whole["optima"].as_array().unwrap().len(), 3);
    for cuts in [vec![0, 32], vec![0, 5, 11, 32], (0..=32).step_by(2).collect::<Vec<_>>()] {
        let shards: Vec<Value> = cuts.windows(2).map(|w| report(Some((w[0], w[1])))).collect();
        let merged = merge_shards(&shards, &ball_bounds()).expect("merges");
        assert_eq!(without_time(merged), whole, "cuts {cuts:?}");
    }
    let (a, b) = (report(Some((0, 8))), report(Some((8, 16))));
    assert!(merge_shards(&[b.clone(), a.clone()], &ball_bounds()).is_err(), "out of order");
    assert!(merge_shards(&[b], &ball_bounds()).is_err(), "starts 0..8 missing");
    assert!(merge_shards(&[a], &ball_bounds()[..1]).is_err(), "bounds for another problem");
}

#[test]
fn a_wide_box_does_not_make_an_interior_point_look_held_at_its_bound() {
    // min k^2 over k in [0, 1e13], stopped after the start (k = 5, gradient 10): not converged.
    // With "on the bound" measured against the box's width (1e-12 x 1e13 = 10), k = 5 counted as
    // held at 0, its gradient was projected away, and the start was called a KKT point.
    let dir = tempfile::tempdir().expect("temporary directory");
    let path = dir.path().join("wide.hyb");
    std::fs::write(
        &path,
        "model wide\nparam k = 5 in [0, 1e13]\nstate x = 0\nder(x) = 1\noutput f = k^2\nsimulate t_end = 1\n",
    )
    .expect("writes");
    let file = path.to_str().expect("utf-8 path");
    let stopped = hybc(&[
        "optimize",
        file,
        "--free",
        "k",
        "--minimize",
        "f",
        "--max-iter",
        "1",
        "--quiet",
        "--format",
        "json",
    ]);
    assert_eq!(stopped.status.code(), Some(4), "{}", String::from_utf8_lossy(&stopped.stdout));
    let v = json(&stopped);
    assert_eq!(v["reason"], "max_iterations");
    assert_eq!(v["at_bound"], serde_json::json!({}));
    // Given the evaluations it needs, it ends at the lower bound, held there exactly.
    let solved =
        json(&hybc(&["optimize", file, "--free", "k", "--minimize", "f", "--quiet", "--format", "json"]));
    assert_eq!(solved["reason"], "converged");
    assert_eq!(solved["optimum"]["k"], 0.0);
    assert_eq!(solved["at_bound"]["k"], "lower");
}
