//! `hybc fit` against the bouncing ball's closed forms (../shared/reference/closed-forms.md): the
//! library API for the numbers, the binary for flags, JSON and exit codes.
//!
//! Ball (g = 9.81, dropped from h0 at rest, restitution e; `support::reference::BallForm`): the
//! first touchdown is at t1 = sqrt(2 h0 / g), the k-th at t_k = t1 (1 + 2 e + ... + 2 e^(k-1));
//! after k bounces the energy is E = g h0 e^(2k) and, a time s after the k-th bounce,
//! y = e^k v1 s - g s^2 / 2 with v1 = sqrt(2 g h0). The fits run at the model's own tolerances (rtol 1e-10, atol 1e-12), where
//! `hybc run` matches these forms to relative 1e-9 (tests/cli_run.rs). The fitted parameters are
//! compared at relative 1e-8: an error of 1e-9 in E moves e = (E / (g h0))^(1/8) by 1.3e-10, and the
//! solver stops once its Gauss-Newton step is below xtol = 1e-10 relative.

use crate::support::cli::hybc;
use crate::support::reference::BallForm;

use std::process::Output;

use approx::assert_relative_eq;
use hybc::codegen::{compile, CompileOptions, CompiledModel};
use hybc::fit::{
    fit, Bounds, FitError, FitOptions, FitProblem, FitResult, FitStop, Outcome, Rejection, StallCause,
    Target, TargetError,
};
use hybc::lower::{lower, system_info};
use hybc::sema::Model;
use hybc::sim::SimOptions;
use serde_json::Value;

const G: f64 = 9.81;
const T: f64 = 2.5;
const BALL: &str = include_str!("../../models/ball.hyb");

/// The ball's closed forms at `h0` and `e` (g = 9.81).
fn ball_form(h0: f64, e: f64) -> BallForm {
    BallForm { h0, e, ..BallForm::DEFAULT }
}

/// Touchdowns before T.
fn bounces(h0: f64, e: f64) -> usize {
    ball_form(h0, e).touchdowns_before(T).len()
}

/// (y, energy) at T.
fn final_y_energy(h0: f64, e: f64) -> (f64, f64) {
    let ball = ball_form(h0, e);
    (ball.state_at(T).0, ball.energy(bounces(h0, e) as i32))
}

/// Root of `f` in [a, b] by bisection (f(a), f(b) of opposite signs).
fn bisect(f: impl Fn(f64) -> f64, mut a: f64, mut b: f64) -> f64 {
    let fa = f(a);
    assert!(fa * f(b) < 0.0, "no sign change in [{a}, {b}]");
    for _ in 0..200 {
        let m = 0.5 * (a + b);
        if (f(m) > 0.0) == (fa > 0.0) {
            a = m;
        } else {
            b = m;
        }
    }
    0.5 * (a + b)
}

struct Fixture {
    model: Model,
    compiled: CompiledModel,
}

fn compile_with_free(source: &str, free: &[&str]) -> Fixture {
    let model = hybc::check_source(source).expect("model checks");
    let grad: Vec<_> = free.iter().map(|n| model.param_index(n).expect("parameter")).collect();
    let compiled =
        compile(&lower(&model), system_info(&model, &grad), &CompileOptions::default()).expect("compiles");
    Fixture { model, compiled }
}

impl Fixture {
    fn ball(free: &[&str]) -> Fixture {
        compile_with_free(BALL, free)
    }

    fn problem(&self, start: &[(&str, f64)], targets: &[&str], t_end: f64) -> FitProblem<'_, CompiledModel> {
        let info = self.compiled.info();
        let mut p: Vec<f64> = self.model.params.iter().map(|p| p.default).collect();
        for (name, v) in start {
            p[self.model.param_index(name).expect("parameter").0 as usize] = *v;
        }
        FitProblem {
            system: &self.compiled,
            start: p,
            bounds: info
                .grad_params
                .iter()
                .map(|&j| Bounds::from_range(self.model.params[j].range))
                .collect(),
            targets: targets.iter().map(|t| Target::parse(t, info).expect("target parses")).collect(),
            sim: SimOptions { t_end, rtol: 1e-10, atol: 1e-12, ..SimOptions::default() },
        }
    }

    fn fit(&self, start: &[(&str, f64)], targets: &[&str]) -> FitResult {
        fit(&self.problem(start, targets, T), &FitOptions::default()).expect("fit starts")
    }

    fn param(&self, r: &FitResult, name: &str) -> f64 {
        r.params[self.model.param_index(name).expect("parameter").0 as usize]
    }
}

use hybc::sim::HybridSystem as _;

#[test]
fn energy_fit_matches_the_closed_form_restitution() {
    let ball = Fixture::ball(&["e"]);
    for energy in [1.7, 2.0, 2.6] {
        // k = 4 bounces at the solution, and still 4 a little either side of it.
        let e_star = (energy / G).powf(1.0 / 8.0);
        for e in [e_star - 1e-3, e_star, e_star + 1e-3] {
            assert_eq!(bounces(1.0, e), 4, "E* = {energy}: e = {e}");
        }
        for start in [0.79, 0.83, 0.86] {
            let r = ball.fit(&[("e", start)], &[&format!("energy={energy}")]);
            assert!(r.is_converged(), "E* = {energy} from {start}: {:?}", r.stop);
            assert_relative_eq!(ball.param(&r, "e"), e_star, max_relative = 1e-8);
            assert_eq!(r.evaluation.events.len(), 4);
            assert!(r.cusps.is_empty(), "no cusp between {start} and {e_star}");
            // The Jacobian is the exact dE/de = 8 g h0 e^7 at the fitted point.
            assert_relative_eq!(
                r.evaluation.jacobian[(0, 0)],
                ball_form(1.0, e_star).energy_grad(4)[1],
                max_relative = 1e-7
            );
        }
    }
}

#[test]
fn energy_fit_from_another_bounce_count_crosses_the_cusp() {
    let ball = Fixture::ball(&["e"]);
    let energy = 2.0;
    let e_star = (energy / G).powf(1.0 / 8.0);
    // e = 0.9 bounces 3 times before T, e = 0.77 five times; the solution 4 times.
    for (start, k_start) in [(0.9, 3), (0.77, 5)] {
        assert_eq!(bounces(1.0, start), k_start);
        let r = ball.fit(&[("e", start)], &["energy=2.0"]);
        assert!(r.is_converged(), "from {start}: {:?}", r.stop);
        assert_relative_eq!(ball.param(&r, "e"), e_star, max_relative = 1e-8);
        assert!(!r.cusps.is_empty(), "from {start} the event count must change");
        assert_eq!(r.cusps[0].events_before, k_start);
        let crossing = r.cusps.iter().find(|c| c.accepted).expect("one cusp crossed");
        assert_eq!(crossing.events_after, 4);
        let it = &r.iterations[crossing.iteration];
        assert!(it.cusp && it.outcome == Outcome::Accepted);
    }
}

#[test]
fn energy_in_the_jump_stalls_at_the_cusp_and_says_so() {
    // At e_c the 4th touchdown reaches T: E jumps from g e_c^8 = 3.09 (4 bounces) to g e_c^6 =
    // 4.12 (3 bounces). No e gives E = 3.5; the closest the objective gets is at e_c from below.
    let e_c = bisect(|e| ball_form(1.0, e).touchdown(4) - T, 0.8, 0.9);
    assert!(ball_form(1.0, e_c).energy(4) < 3.5 && 3.5 < ball_form(1.0, e_c).energy(3));
    let ball = Fixture::ball(&["e"]);
    let r = ball.fit(&[("e", 0.84)], &["energy=3.5"]);
    assert!(!r.is_converged());
    match &r.stop {
        FitStop::Stalled(StallCause::Cusp(c)) => assert_eq!((c.events_before, c.events_after), (4, 3)),
        other => panic!("expected a stall at the cusp, got {other:?}"),
    }
    let e = ball.param(&r, "e");
    assert!(e < e_c, "the fit stays on the 4-bounce side");
    assert_relative_eq!(e, e_c, max_relative = 1e-7);
    assert!(r.cusps.iter().all(|c| !c.accepted));
}

#[test]
fn bounds_hold_the_restitution_at_the_end_of_its_range() {
    // E = g h0 = 9.81 at e = 1 is the most a bounce can keep: E* = 12 pins e to its bound.
    let ball = Fixture::ball(&["e"]);
    let r = ball.fit(&[("e", 0.95)], &["energy=12"]);
    assert_eq!(r.stop, FitStop::Gradient);
    // A least-squares minimum, but the equation energy = 12 is not solved there.
    assert!(!r.is_converged() && !r.targets_met(), "{:?}", r.met);
    assert_eq!(r.tolerances, vec![100.0 * (1e-10 * 12.0 + 1e-12)]);
    assert_eq!(ball.param(&r, "e"), 1.0);
    assert_relative_eq!(r.evaluation.residuals[0], G - 12.0, max_relative = 1e-9);
    for it in &r.iterations {
        assert!(it.free[0] <= 1.0, "iteration {} left the range: {}", it.iteration, it.free[0]);
    }
}

#[test]
fn two_parameter_fit_reproduces_energy_and_height() {
    // Targets from the closed form at h0 = 1, e = 0.8 (4 bounces), rounded. Independent solution:
    // on the 4-bounce piece E fixes h0 = E / (g e^8), and y(T) along that curve crosses y* twice,
    // once in each bracket below (the curve's y has a maximum near e = 0.786 between them). Each
    // start lies near one of them.
    let (y_star, energy_star) = final_y_energy(1.0, 0.8);
    let (y_star, energy_star) = ((y_star * 1e6).round() / 1e6, (energy_star * 1e6).round() / 1e6);
    let h0_of = |e: f64| energy_star / ball_form(1.0, e).energy(4); // E is proportional to h0
    let ball = Fixture::ball(&["h0", "e"]);
    let targets = [format!("energy={energy_star}"), format!("y={y_star}")];
    let targets: Vec<&str> = targets.iter().map(String::as_str).collect();
    for (start, bracket) in [((1.0, 0.81), (0.79, 0.81)), ((1.3, 0.77), (0.766, 0.782))] {
        let e_ref = bisect(|e| final_y_energy(h0_of(e), e).0 - y_star, bracket.0, bracket.1);
        let h0_ref = h0_of(e_ref);
        assert_eq!(bounces(h0_ref, e_ref), 4);
        let r = ball.fit(&[("h0", start.0), ("e", start.1)], &targets);
        assert!(r.is_converged(), "from {start:?}: {:?}", r.stop);
        let (h0, e) = (ball.param(&r, "h0"), ball.param(&r, "e"));
        assert_relative_eq!(h0, h0_ref, max_relative = 1e-8);
        assert_relative_eq!(e, e_ref, max_relative = 1e-8);
        // The closed form at the fitted values reproduces both targets.
        let (y, energy) = final_y_energy(h0, e);
        assert_relative_eq!(energy, energy_star, max_relative = 1e-8);
        assert_relative_eq!(y, y_star, max_relative = 1e-7);
        assert!(r.condition.is_finite() && r.condition > 1.0);
    }
}

#[test]
fn event_time_targets_match_the_touchdown_closed_forms() {
    // t2 = t1 (1 + 2 e): e = (t2 / t1 - 1) / 2 with h0 = 1.
    let t1 = BallForm::DEFAULT.t1();
    let ball = Fixture::ball(&["e"]);
    let r = ball.fit(&[("e", 0.8)], &["touchdown#2=1.2"]);
    assert!(r.is_converged(), "{:?}", r.stop);
    assert_relative_eq!(ball.param(&r, "e"), (1.2 / t1 - 1.0) / 2.0, max_relative = 1e-8);

    // t1 = sqrt(2 h0 / g): h0 = g t1^2 / 2.
    let ball = Fixture::ball(&["h0"]);
    let r = ball.fit(&[], &["touchdown#1=0.5"]);
    assert!(r.is_converged(), "{:?}", r.stop);
    assert_relative_eq!(ball.param(&r, "h0"), G * 0.25 / 2.0, max_relative = 1e-8);

    // Both from t1 and t3 = t1 (1 + 2 e + 2 e^2): e solves e^2 + e = (t3 / t1 - 1) / 2.
    let ball = Fixture::ball(&["h0", "e"]);
    let r = ball.fit(&[], &["touchdown#1=0.5", "touchdown#3=1.9"]);
    assert!(r.is_converged(), "{:?}", r.stop);
    let c: f64 = (1.9 / 0.5 - 1.0) / 2.0;
    assert_relative_eq!(ball.param(&r, "h0"), G * 0.25 / 2.0, max_relative = 1e-8);
    assert_relative_eq!(ball.param(&r, "e"), (-1.0 + (1.0 + 4.0 * c).sqrt()) / 2.0, max_relative = 1e-8);
}

#[test]
fn trials_without_the_target_event_or_with_a_failed_run_are_rejected() {
    // From e = 0.7 (11 touchdowns) the first Gauss-Newton steps for t4 = 2.45 land beyond e = 0.867,
    // where the ball touches down only 3 times before T: those trials are rejected and shortened.
    let e_star = bisect(|e| ball_form(1.0, e).touchdown(4) - 2.45, 0.8, 0.86);
    let ball = Fixture::ball(&["e"]);
    let r = ball.fit(&[("e", 0.7)], &["touchdown#4=2.45"]);
    assert!(r.is_converged(), "{:?}", r.stop);
    assert_relative_eq!(ball.param(&r, "e"), e_star, max_relative = 1e-8);
    assert!(r
        .iterations
        .iter()
        .any(|it| matches!(&it.outcome, Outcome::Failed(Rejection::MissingEvent { fired: 3, .. }))));

    // Lowering the energy from e = 0.7 pushes e towards the Zeno point near 0.695 (where the
    // bounces accumulate before T): runs that stop as Zeno are rejected, never a crash.
    let r = ball.fit(&[("e", 0.7)], &["energy=0.0001"]);
    assert!(r
        .iterations
        .iter()
        .any(|it| matches!(&it.outcome, Outcome::Failed(Rejection::RunStopped { .. }))));
    assert!(!r.is_converged());
}

#[test]
fn a_start_without_the_target_is_an_error_not_a_fit() {
    let ball = Fixture::ball(&["e"]);
    let err =
        fit(&ball.problem(&[], &["touchdown#5=2.4"], T), &FitOptions::default()).expect_err("no 5th bounce");
    assert_eq!(err, FitError::Start(Rejection::MissingEvent { target: "touchdown#5".to_string(), fired: 4 }));
    let err = fit(&ball.problem(&[], &["energy=1"], 10.0), &FitOptions::default()).expect_err("Zeno");
    assert!(matches!(err, FitError::Start(Rejection::RunStopped { .. })), "{err:?}");
}

#[test]
fn weights_pull_the_fit_towards_the_heavier_target() {
    // Two energies with weights 1 and 3: the minimum of (E - 2)^2 + 9 (E - 2.2)^2 is E = 2.18.
    let ball = Fixture::ball(&["e"]);
    // The two targets contradict each other: the weighted least-squares minimum is found (inside
    // the bounds), but neither equation holds there, so the fit is not converged.
    let r = ball.fit(&[], &["energy=2.0", "energy=2.2@3"]);
    assert!(r.stop.is_converged(), "{:?}", r.stop);
    assert!(!r.is_converged());
    assert_eq!(r.met, vec![false, false]);
    assert_relative_eq!(ball.param(&r, "e"), (2.18 / G).powf(1.0 / 8.0), max_relative = 1e-8);
    assert_relative_eq!(r.evaluation.residuals[1], 3.0 * (2.18 - 2.2), max_relative = 1e-6);
}

#[test]
fn a_stop_event_target_uses_the_total_derivative() {
    // The run stops at t = ts: y(ts) = h0 - g ts^2 / 2, so y = 5 needs ts = sqrt(2 (h0 - 5) / g).
    // At fixed time dy/dts would be 0; only the total derivative -g ts moves the fit.
    let src = "model s\nparam g = 9.81\nparam h0 = 10\nparam ts = 0.5\nstate y = h0\nstate v = 0\n\
               der(y) = v\nder(v) = -g\nevent done when t >= ts {\n    stop\n}\n";
    let fixture = compile_with_free(src, &["ts"]);
    let r = fit(&fixture.problem(&[], &["y=5"], 5.0), &FitOptions::default()).expect("fit starts");
    assert!(r.is_converged(), "{:?}", r.stop);
    assert_relative_eq!(fixture.param(&r, "ts"), (2.0 * 5.0 / G).sqrt(), max_relative = 1e-9);
}

// ---- the binary ----

fn fit_json(args: &[&str]) -> (Value, Output) {
    let mut all = vec!["fit", "models/ball.hyb"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--format", "json"]);
    let out = hybc(&all);
    let json = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("not JSON ({e}): {}", String::from_utf8_lossy(&out.stdout)));
    (json, out)
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

#[test]
fn cli_fit_prints_the_documented_json_and_exits_0() {
    let (json, out) = fit_json(&["--free", "e", "--target", "energy=2.0", "--set", "e=0.9"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    assert_relative_eq!(f(&json["params"]["e"]), (2.0 / G).powf(1.0 / 8.0), max_relative = 1e-8);
    assert_eq!(json["params"]["h0"], 1.0);
    assert_eq!(json["free"], serde_json::json!(["e"]));
    assert_eq!(json["converged"], true);
    assert_eq!(json["reason"], "step");
    assert_relative_eq!(f(&json["condition"]), 1.0);
    let res = &json["residuals"][0];
    assert_eq!(res["target"], "energy");
    assert!(f(&res["residual"]).abs() < 1e-9);
    let iterations = json["iterations"].as_array().expect("iterations");
    assert_eq!(iterations[0]["outcome"], "start");
    assert_eq!(iterations[0]["events"], 3);
    assert!(iterations.iter().all(|it| it["objective"].is_number() && it["params"]["e"].is_number()));
    let cusps = json["cusps"].as_array().expect("cusps");
    assert!(cusps.iter().any(|c| c["accepted"] == true && c["events_before"] == 3 && c["events_after"] == 4));
}

#[test]
fn cli_fit_table_shows_iterations_result_residuals_and_condition() {
    let out = hybc(&["fit", "models/ball.hyb", "--free", "e", "--target", "energy=2.0", "--set", "e=0.9"]);
    assert_eq!(out.status.code(), Some(0));
    let table = String::from_utf8_lossy(&out.stdout);
    for needle in [
        "objective",
        "damping",
        "events",
        "accepted across a cusp",
        "converged",
        "e = 0.8",
        "residual",
        "condition number: 1",
    ] {
        assert!(table.contains(needle), "missing `{needle}`:\n{table}");
    }
}

#[test]
fn cli_exit_codes_for_no_convergence_and_a_bad_start() {
    let out = hybc(&["fit", "models/ball.hyb", "--free", "e", "--target", "energy=3.5", "--set", "e=0.84"]);
    assert_eq!(out.status.code(), Some(4));
    assert!(String::from_utf8_lossy(&out.stderr).contains("stalled at a cusp"));
    let out = hybc(&["fit", "models/ball.hyb", "--free", "e", "--target", "energy=2", "--max-iter", "1"]);
    assert_eq!(out.status.code(), Some(4));
    assert!(String::from_utf8_lossy(&out.stderr).contains("did not converge in 1 trials"));

    let out = hybc(&["fit", "models/ball.hyb", "--free", "e", "--target", "touchdown#5=2.4"]);
    assert_eq!(out.status.code(), Some(3));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("starting point") && stderr.contains("fired only 4 times"), "{stderr}");
    let out = hybc(&["fit", "models/ball.hyb", "--free", "e", "--target", "energy=1", "--t-end", "10"]);
    assert_eq!(out.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&out.stderr).contains("Zeno"));
    // The ball grazes the ceiling: no gradient of the final state exists at the start.
    let out = hybc(&["fit", "tests/data/run/ceiling_graze.hyb", "--free", "v0", "--target", "y=0.5"]);
    assert_eq!(out.status.code(), Some(3));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("target `y` has no gradient: a grazing event"), "{stderr}");
}

#[test]
fn cli_unreachable_targets_exit_4_naming_the_residuals_and_the_bound() {
    // From e = 0.8 (4 bounces) E = 20 is beyond g h0 = 9.81, the most any e keeps: the fit crosses
    // to the 3-bounce branch and stops at the bound e = 1, a least-squares minimum that misses the
    // target by 10.19. Before issue 24 this printed "converged" and exited 0.
    let out = hybc(&["fit", "models/ball.hyb", "--free", "e", "--target", "energy=20"]);
    assert_eq!(out.status.code(), Some(4));
    let stderr = String::from_utf8_lossy(&out.stderr);
    for needle in [
        "error: targets not met: the fit stopped at a least-squares minimum (the gradient vanishes",
        "energy = 9.81 against the goal 20 (off by -10.19, tolerance 2.0e-7)",
        "held at a bound: e = 1",
    ] {
        assert!(stderr.contains(needle), "missing `{needle}`:\n{stderr}");
    }
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(table.contains("not met") && !table.contains("converged"), "{table}");

    let (json, out) = fit_json(&["--free", "e", "--target", "energy=20"]);
    assert_eq!(out.status.code(), Some(4));
    assert_eq!(json["converged"], false);
    assert_eq!(json["reason"], "targets_not_met");
    assert_eq!(json["residuals"][0]["met"], false);
    assert_relative_eq!(f(&json["residuals"][0]["tolerance"]), 100.0 * (1e-10 * 20.0 + 1e-12));
    assert_relative_eq!(f(&json["residuals"][0]["value"]), G, max_relative = 1e-9);

    // Contradictory targets inside the bounds: the weighted minimum E = 2.18 meets neither.
    let out =
        hybc(&["fit", "models/ball.hyb", "--free", "e", "--target", "energy=2", "--target", "energy=2.2@3"]);
    assert_eq!(out.status.code(), Some(4));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("targets not met") && stderr.contains("energy = 2.18"), "{stderr}");
    assert!(!stderr.contains("held at a bound"), "{stderr}");

    // A met target still exits 0 and says so per residual.
    let (json, out) = fit_json(&["--free", "e", "--target", "energy=2"]);
    assert_eq!(out.status.code(), Some(0));
    assert_eq!(json["residuals"][0]["met"], true);
}

#[test]
fn cli_underdetermined_fit_warns_and_reports_an_infinite_condition() {
    let (json, out) = fit_json(&["--free", "e,h0", "--target", "energy=2.0"]);
    assert_eq!(out.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&out.stderr).contains("underdetermined"));
    assert_eq!(json["condition"], Value::Null);
    let (e, h0) = (f(&json["params"]["e"]), f(&json["params"]["h0"]));
    assert_eq!(bounces(h0, e), 4);
    assert_relative_eq!(ball_form(h0, e).energy(4), 2.0, max_relative = 1e-8);
}

#[test]
fn cli_bad_flags_are_usage_errors_with_clear_messages() {
    let cases: &[(&[&str], &str)] = &[
        (&["--free", "ee", "--target", "energy=1"], "no parameter `ee` (did you mean `e`?)"),
        (&["--free", "e,e", "--target", "energy=1"], "`e` is named twice"),
        (&["--free", "", "--target", "energy=1"], "at least one parameter"),
        (&["--free", "e", "--target", "energi=1"], "no output or state `energi` (did you mean `energy`?)"),
        (&["--free", "e", "--target", "bounce#1=1"], "no event `bounce`"),
        (&["--free", "e", "--target", "energy"], "expected NAME=VALUE"),
        (&["--free", "e", "--target", "energy=high"], "`high` is not a finite number"),
        (&["--free", "e", "--target", "energy=1@0"], "weight `0` must be a positive"),
        (&["--free", "e", "--target", "energy=1@x"], "weight `x`"),
        (&["--free", "e", "--target", "touchdown#0=1"], "whole number from 1"),
        (&["--free", "e", "--target", "touchdown#1.5=1"], "whole number from 1"),
        (&["--free", "e", "--target", "energy=1", "--set", "e=2"], "outside its range [0, 1]"),
        (&["--free", "e", "--target", "energy=1", "--rtol", "0"], "--rtol"),
        (&["--free", "e", "--target", "energy=1", "--max-iter", "0"], "--max-iter"),
        (&["--free", "e", "--target", "energy=1", "--xtol=-1"], "--xtol"),
        (&["--free", "e"], "--target"),
    ];
    for (args, message) in cases {
        let mut all = vec!["fit", "models/ball.hyb"];
        all.extend_from_slice(args);
        let out = hybc(&all);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains("error"), "{args:?}: {stderr}");
        assert!(stderr.contains(message), "{args:?}: expected `{message}` in {stderr}");
    }
}

#[test]
fn a_name_that_is_both_an_output_and_a_state_takes_a_prefix() {
    // y(1) = a + 1 and the output y = 2 y(1): y = 6 means a = 5 for the state, a = 2 for the output.
    let src = "model m\nparam a = 1\nstate y = a\nder(y) = 1\noutput y = 2 * y\n";
    let fixture = compile_with_free(src, &["a"]);
    let info = fixture.compiled.info();
    assert_eq!(Target::parse("y=6", info), Err(TargetError::Ambiguous { name: "y".to_string() }));
    for (target, a) in [("state:y=6", 5.0), ("output:y=6", 2.0)] {
        let r = fit(&fixture.problem(&[], &[target], 1.0), &FitOptions::default()).expect("fit starts");
        assert!(r.is_converged(), "{target}: {:?}", r.stop);
        assert_relative_eq!(fixture.param(&r, "a"), a, max_relative = 1e-9);
    }
}

// ---- values at times (`NAME@TIME`) and the last firing (`EVENT#last`) ----

#[test]
fn values_at_times_are_targets_that_recover_a_rate_and_a_start_from_noiseless_samples() {
    // x = x0 exp(-k t) at three times: k = 1.3, x0 = 2.5 from k = 1, x0 = 2.
    let src =
        "model decay\nparam k = 1 in [0.1, 10]\nparam x0 = 2 in [0.1, 10]\nstate x = x0\nder(x) = -k * x\n";
    let fixture = compile_with_free(src, &["k", "x0"]);
    let targets: Vec<String> =
        [0.5f64, 1.0, 1.5].iter().map(|t| format!("x@{t}={:e}", 2.5 * (-1.3 * t).exp())).collect();
    let refs: Vec<&str> = targets.iter().map(String::as_str).collect();
    let r = fit(&fixture.problem(&[], &refs, 2.0), &FitOptions::default()).expect("fit starts");
    assert!(r.is_converged(), "{:?}", r.stop);
    assert_relative_eq!(fixture.param(&r, "k"), 1.3, max_relative = 1e-8);
    assert_relative_eq!(fixture.param(&r, "x0"), 2.5, max_relative = 1e-8);
    assert_eq!(
        Target::parse("x@0.5=1", fixture.compiled.info()).unwrap().label(fixture.compiled.info()),
        "x@0.5"
    );
}

#[test]
fn the_last_firing_is_a_target_and_a_time_after_a_stop_is_refused() {
    // The ball to T = 2.5 with e free from 0.8: its last touchdown placed where e = 0.82 puts it
    // (the 4th for both, so the target is on the start's smooth piece).
    let k = bounces(1.0, 0.82);
    assert_eq!(k, bounces(1.0, 0.8));
    let fixture = Fixture::ball(&["e"]);
    let last = ball_form(1.0, 0.82).touchdown(k as i32);
    let target = format!("touchdown#last={last:e}");
    let r = fit(&fixture.problem(&[], &[target.as_str()], T), &FitOptions::default()).expect("fit starts");
    assert!(r.is_converged(), "{:?}", r.stop);
    assert_relative_eq!(fixture.param(&r, "e"), 0.82, max_relative = 1e-8);
    // A value at a time after a `stop`: no value, so the fit cannot start.
    let src = "model s\nparam h0 = 10 in [1, 20]\nstate y = h0\nstate v = 0\nder(y) = v\nder(v) = -9.81\n\
               event done when t >= 0.5 {\n    stop\n}\n";
    let fixture = compile_with_free(src, &["h0"]);
    let err = fit(&fixture.problem(&[], &["y@0.75=1"], 1.0), &FitOptions::default()).unwrap_err();
    assert!(err.to_string().contains("the run stopped before its time"), "{err}");
}

#[test]
fn the_one_spelling_is_refused_clearly_where_it_names_nothing() {
    let fixture = Fixture::ball(&["e"]);
    let info = fixture.compiled.info();
    for (text, needle) in [
        ("y@abc=1", "the time of NAME@TIME must be a finite number"),
        ("touchdown@1=1", "no output or state `touchdown`"),
        ("touchdown#first=1", "or `last`"),
        ("nothing#last=1", "no event `nothing`"),
    ] {
        let e = Target::parse(text, info).unwrap_err().to_string();
        assert!(e.contains(needle), "{text}: {e}");
    }
}

// ---- fits to time series (`--data`) ----

/// The dosing model's concentration in closed form (two doses, first-order absorption).
fn dosing_conc(t: f64, ka: f64, ke: f64) -> f64 {
    [2.0, 8.0]
        .iter()
        .map(|t_d| t - t_d)
        .filter(|s| *s > 0.0)
        .map(|s| 100.0 * ka / (ka - ke) * ((-ke * s).exp() - (-ka * s).exp()))
        .sum::<f64>()
        / 40.0
}

fn data_file(name: &str, text: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("hybc-data-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn noiseless_measurements_give_back_the_rates_to_1e_8() {
    // Concentrations and gut amounts (a state) every hour, with a missing cell: the fit from the
    // model's defaults (ka 1, ke 0.2) recovers ka = 1.3, ke = 0.25.
    let mut text = String::from("time,conc,gut\n");
    for k in 1..=12 {
        let t = k as f64;
        let gut: f64 = [2.0, 8.0]
            .iter()
            .map(|t_d| t - t_d)
            .filter(|s| *s >= 0.0)
            .map(|s| 100.0 * (-1.3 * s).exp())
            .sum();
        let gut = if k == 5 { String::new() } else { format!("{gut:e}") };
        text += &format!("{t},{:e},{gut}\n", dosing_conc(t, 1.3, 0.25));
    }
    let path = data_file("noiseless.csv", &text);
    let out = hybc(&[
        "fit",
        "models/dosing.hyb",
        "--free",
        "ka,ke",
        "--data",
        path.to_str().unwrap(),
        "--format",
        "json",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let json: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_relative_eq!(f(&json["params"]["ka"]), 1.3, max_relative = 1e-8);
    assert_relative_eq!(f(&json["params"]["ke"]), 0.25, max_relative = 1e-8);
    assert_eq!(json["data"]["observations"], 23);
    // No sigma columns: the standard errors are scaled by the residual variance.
    assert_eq!(json["data"]["sigma_known"], false);
    assert_eq!(json["data"]["by_name"][0]["name"], "conc");
    assert_eq!(json["data"]["by_name"][1]["count"], 11);
    assert!(f(&json["data"]["by_name"][0]["rms"]) < 1e-8);
}

#[test]
fn the_shipped_noisy_measurements_give_the_true_rates_within_three_standard_errors() {
    // examples/data/dosing_conc.csv: ka = 1.3, ke = 0.25 with noise of sd 0.02 (its script).
    let out = hybc(&[
        "fit",
        "models/dosing.hyb",
        "--free",
        "ka,ke",
        "--data",
        "examples/data/dosing_conc.csv",
        "--format",
        "json",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let json: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["data"]["sigma_known"], true);
    for (name, truth) in [("ka", 1.3), ("ke", 0.25)] {
        let (value, se) = (f(&json["params"][name]), f(&json["data"]["standard_errors"][name]));
        assert!(se > 0.0 && (value - truth).abs() <= 3.0 * se, "{name} = {value} +/- {se}");
    }
    // The residuals are of the size of the noise.
    let rms = f(&json["data"]["by_name"][0]["rms"]);
    assert!(rms > 0.01 && rms < 0.03, "{rms}");
}

#[test]
fn a_data_file_that_names_nothing_or_holds_no_number_is_refused_with_its_line() {
    for (text, needle) in [
        ("time,cons\n1,2\n", "column `cons` is not an output or a state of the model (did you mean `conc`?)"),
        ("t,conc\n1,2\n", ":1: no `time` column"),
        ("time,conc\n1,2\n2,x\n", ":3: column `conc`: `x` is not a finite number"),
        ("time,conc,sigma_gut\n1,2,3\n", "`sigma_gut` has no column `gut`"),
        ("time,conc,sigma_conc\n1,2,0\n", ":2: column `sigma_conc`: a standard deviation must be positive"),
        ("time,conc\n1,2,3\n", ":2: expected 2 cells"),
        ("time,conc\n1,\n", "no measurements"),
        // A time the run does not reach (dosing runs from 0 to 12), named with its line and the span.
        (
            "time,conc\n1,2\n13,1\n",
            ":3: time 13 is after t_end = 12: the run goes from t_start = 0 to t_end = 12",
        ),
        ("time,conc\n-1,2\n", ":2: time -1 is before t_start = 0"),
        // An invisible character in a name is shown.
        ("time,con\u{200b}c\n1,2\n", ":1: column `con<U+200B>c` is not an output or a state"),
        ("\u{feff}t,conc\n1,2\n", ":1: no `time` column in the header (columns: t, conc)"),
    ] {
        let path = data_file("bad.csv", text);
        let out = hybc(&["fit", "models/dosing.hyb", "--free", "ka", "--data", path.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(2), "{text}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "{text}: {err}");
    }
}

#[test]
fn a_target_at_a_time_the_run_does_not_reach_is_refused_with_its_cause() {
    let out = hybc(&["fit", "models/ball.hyb", "--free", "e", "--target", "y@3=0.1"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("`y@3=0.1`: time 3 is after t_end = 2.5: the run goes from t_start = 0 to t_end = 2.5"),
        "{err}"
    );
    // The same target in a run that reaches it is a fit: y(3) = 0.1 with e free.
    let out = hybc(&["fit", "models/ball.hyb", "--free", "e", "--target", "y@3=0.1", "--t-end", "3"]);
    assert_ne!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn a_data_file_with_a_byte_order_mark_reads_as_the_same_file_without() {
    // Spreadsheets start a UTF-8 CSV with U+FEFF; it is no part of the first column's name.
    let text = "time,conc\n3,1.5\n5,1.8\n9,2.1\n";
    let plain = data_file("plain.csv", text);
    let marked = data_file("marked.csv", &format!("\u{feff}{text}"));
    let fit = |path: &std::path::Path| {
        let out = hybc(&[
            "fit",
            "models/dosing.hyb",
            "--free",
            "ka",
            "--data",
            path.to_str().unwrap(),
            "--format",
            "json",
        ]);
        assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
        let v: Value = serde_json::from_slice(&out.stdout).unwrap();
        v["params"].clone()
    };
    assert_eq!(fit(&marked), fit(&plain));
}

/// The soft floor tends to the hard reset: the damping ratio that loses the energy of a hard
/// bounce with `e = 0.8` (`E = e^2 g h0` after the first bounce) tends to the linear
/// spring-damper's `exp(-zeta pi / sqrt(1 - zeta^2)) = e` as `wc` grows, with a gap from gravity
/// acting during the contact that falls as `1 / wc` (2.2e-4 at 1e3 measured; `0.3 / wc` asserted,
/// and at least `0.1 / wc`, so that a fit that ignored the contact's gravity would fail too).
/// docs/tutorial.md, section 13, quotes these fits.
#[test]
fn the_soft_balls_damping_fitted_to_a_hard_bounce_tends_to_the_closed_form_as_1_over_wc() {
    // Bisection on the closed form, independent of hybc.
    let restitution = |z: f64| (-z * std::f64::consts::PI / (1.0 - z * z).sqrt()).exp();
    let zeta_closed = bisect(|z| restitution(z) - 0.8, 0.01, 0.5);
    assert!((zeta_closed - 0.0708503).abs() < 1e-7, "{zeta_closed}");
    let model = concat!(env!("CARGO_MANIFEST_DIR"), "/models/soft_ball.hyb");
    let target = format!("energy={}", 0.64 * 9.81);
    for wc in [1e3, 1e4, 1e5] {
        let set_wc = format!("wc={wc}");
        let out = hybc(&[
            "fit", model, "--free", "zeta", "--target", &target, "--set", "zeta=0.3", "--set", &set_wc,
            "--format", "json",
        ]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let report: Value = serde_json::from_slice(&out.stdout).expect("json");
        assert_eq!(report["converged"], true, "{report}");
        let zeta = report["params"]["zeta"].as_f64().unwrap();
        let gap = zeta_closed - zeta;
        assert!(gap > 0.1 / wc && gap < 0.3 / wc, "wc = {wc}: zeta {zeta} against {zeta_closed}");
        // Gauss-Newton on one well-conditioned residual converges quadratically: from 0.3 the
        // objective is at its noise floor (1e-16 of the start's) by the fifth trial. The trials
        // after that, which decide the step test on noise, are not counted.
        let objectives: Vec<f64> = report["iterations"]
            .as_array()
            .unwrap()
            .iter()
            .map(|it| it["objective"].as_f64().unwrap())
            .collect();
        let floor = objectives.iter().position(|&o| o < 1e-16 * objectives[0]).expect("reaches the floor");
        assert!(floor <= 5, "wc = {wc}: {objectives:?}");
        assert!(report["stats"]["runs"].as_u64().unwrap() <= 10, "{report}");
    }
}
