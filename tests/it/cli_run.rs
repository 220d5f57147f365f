//! `hybc run` end to end, where a property is asserted in code: the binary's JSON against the
//! bouncing ball's closed form (`support::reference`), a quick Zeno stop, grazing reports, total
//! derivatives at a stop event, every shipped model, the trajectory file. What hybc prints for
//! given flags (exit codes, error messages, reports) is pinned by the cases in tests/data/cli
//! (`cli_cases.rs`).

use crate::support::cli::hybc;
use crate::support::models::shipped_models;
use crate::support::reference::BallForm;

use std::process::Output;
use std::time::{Duration, Instant};

use approx::assert_relative_eq;
use serde_json::Value;

fn run_json(args: &[&str]) -> (Value, Output) {
    let mut all = vec!["run"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--format", "json"]);
    let out = hybc(&all);
    let json: Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("not JSON ({e}): {}", String::from_utf8_lossy(&out.stdout)));
    (json, out)
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

#[test]
fn ball_reproduces_the_closed_form_to_1e_9() {
    let (json, out) = run_json(&["models/ball.hyb", "--grad", "e,h0"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let ball = BallForm::DEFAULT;
    let events = json["events"].as_array().expect("events");
    assert_eq!(events.len(), 4, "four bounces before 2.5 s");
    for (ev, k) in events.iter().zip(1..) {
        assert_relative_eq!(f(&ev["time"]), ball.touchdown(k), max_relative = 1e-9);
        assert_eq!(ev["grazing"], Value::Bool(false));
    }
    assert_relative_eq!(f(&events[0]["dtime"]["h0"]), 1.0 / ball.v1(), max_relative = 1e-9);
    assert_relative_eq!(f(&events[0]["dtime"]["h0"]), 0.2257618205, max_relative = 1e-9);
    let [_, denergy_de, denergy_dh0] = ball.energy_grad(4);
    let fin = &json["final"];
    assert_relative_eq!(f(&fin["outputs"]["energy"]), ball.energy(4), max_relative = 1e-9);
    assert_relative_eq!(f(&fin["doutputs"]["energy"]["e"]), denergy_de, max_relative = 1e-9);
    assert_relative_eq!(f(&fin["doutputs"]["energy"]["h0"]), denergy_dh0, max_relative = 1e-9);
    assert_eq!(json["stopped_by"], "t_end");
    assert_eq!(json["grad"], serde_json::json!(["e", "h0"]));
}

#[test]
fn zeno_ball_is_reported_quickly_with_its_accumulation_point() {
    let started = Instant::now();
    let out = hybc(&["run", "models/ball.hyb", "--grad", "e", "--t-end", "10"]);
    assert!(started.elapsed() < Duration::from_secs(1), "took {:?}", started.elapsed());
    assert_eq!(out.status.code(), Some(3));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("Zeno"), "{stderr}");
    assert!(stderr.contains("4.06371276"), "accumulation point t* = 4.0637127689 missing: {stderr}");
}

#[test]
fn grazing_contact_is_flagged_with_its_denominator_and_no_gradient() {
    let (json, out) = run_json(&["tests/data/run/ceiling_graze.hyb", "--grad", "all"]);
    assert!(out.status.success());
    let ev = &json["events"][0];
    assert_eq!(ev["name"], "ceiling");
    assert_eq!(ev["grazing"], Value::Bool(true));
    assert!(f(&ev["denominator"]).abs() < 1e-3, "{ev}");
    assert_eq!(ev["dtime"], Value::Null, "gradients of a grazing event are not meaningful");
    assert!(String::from_utf8_lossy(&out.stderr).contains("grazes"));
    assert!(!json["warnings"].as_array().expect("warnings").is_empty());
}

#[test]
fn stop_event_reports_total_derivatives() {
    // Time-triggered stop at t = 1: y(1) = h0 - g/2, and dy/dt_stop = v(1) = -g.
    let src = "model s\nparam g = 9.81\nparam h0 = 10\nparam ts = 1\nstate y = h0\nstate v = 0\n\
               der(y) = v\nder(v) = -g\nevent done when t >= ts {\n    stop\n}\n";
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("stop.hyb");
    std::fs::write(&path, src).expect("write model");
    let (json, out) = run_json(&[path.to_str().expect("utf-8 path"), "--grad", "ts,h0", "--t-end", "5"]);
    assert!(out.status.success());
    assert_eq!(json["stopped_by"], "done");
    let fin = &json["final"];
    assert_relative_eq!(f(&fin["time"]), 1.0, max_relative = 1e-12);
    assert_relative_eq!(f(&fin["dstate_total"]["y"]["ts"]), -9.81, max_relative = 1e-9);
    assert_relative_eq!(f(&fin["dstate_total"]["v"]["ts"]), -9.81, max_relative = 1e-9);
    assert_relative_eq!(f(&fin["dstate_total"]["y"]["h0"]), 1.0, max_relative = 1e-9);
}

#[test]
fn every_shipped_model_runs_and_the_table_shows_its_gradients() {
    for model in shipped_models() {
        let out = hybc(&["run", &model.path, "--grad", "all"]);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{}: {}", model.path, String::from_utf8_lossy(&out.stderr));
        assert!(stdout.contains("final: t = "), "{stdout}");
        assert!(stdout.contains("d/d"), "{stdout}");
    }
}

#[test]
fn trajectory_csv_has_a_header_and_uniform_samples() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("traj.csv");
    let out = hybc(&[
        "run",
        "models/ball.hyb",
        "--grad",
        "e",
        "--trajectory",
        path.to_str().expect("utf-8"),
        "--sample",
        "0.5",
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let csv = std::fs::read_to_string(&path).expect("csv written");
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("t,mode,y,v,energy,dy/de,dv/de,denergy/de"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').filter(|c| *c != "main").map(|c| c.parse().expect("number")).collect())
        .collect();
    let times: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    // dE/de at t = 2.5 (after 4 bounces) is 8 g h0 e^7, the closed form.
    let last = rows.last().expect("rows");
    assert_relative_eq!(last[6], BallForm::DEFAULT.energy_grad(4)[1], max_relative = 1e-8);
    assert_eq!(times.len(), 6, "t = 0, 0.5, ..., 2.5: {times:?}");
    for (k, t) in times.iter().enumerate() {
        assert_relative_eq!(*t, 0.5 * k as f64, epsilon = 1e-12);
    }
}

#[test]
fn ball_with_each_rosenbrock_method_reproduces_the_closed_form_and_checks_its_gradients() {
    // The same closed form through `--method rodas5p|rodas4`, to the same 1e-9, with
    // `--check-grad` (exit 0 only when every derivative passes).
    for method in ["rodas5p", "rodas4"] {
        let (json, out) =
            run_json(&["models/ball.hyb", "--grad", "e,h0", "--method", method, "--check-grad"]);
        assert!(out.status.success(), "{method}: {}", String::from_utf8_lossy(&out.stderr));
        let ball = BallForm::DEFAULT;
        let events = json["events"].as_array().expect("events");
        assert_eq!(events.len(), 4, "{method}: four bounces before 2.5 s");
        for (ev, k) in events.iter().zip(1..) {
            assert_relative_eq!(f(&ev["time"]), ball.touchdown(k), max_relative = 1e-9);
        }
    }
}

#[test]
fn h_max_caps_the_step_size() {
    // The ball's free flight is a parabola, which the explicit pair steps over in a few steps; a
    // cap of 0.01 s makes at least 2.5 / 0.01 of them, and the bounces stay where they were.
    let (free, _) = run_json(&["models/ball.hyb"]);
    let (capped, out) = run_json(&["models/ball.hyb", "--h-max", "0.01"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let steps = |json: &Value| json["stats"]["steps"].as_u64().expect("steps");
    assert!(steps(&free) < 100, "{}", steps(&free));
    assert!(steps(&capped) >= 250, "{}", steps(&capped));
    let times = |json: &Value| -> Vec<f64> {
        json["events"].as_array().unwrap().iter().map(|e| f(&e["time"])).collect()
    };
    for (a, b) in times(&free).iter().zip(times(&capped)) {
        assert_relative_eq!(*a, b, max_relative = 1e-8);
    }
}
