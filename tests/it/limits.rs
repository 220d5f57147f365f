//! Hostile and careless flags (issue #18) and values that are not numbers (#17): every count a
//! flag accepts is capped with a usage error naming the flag, grid and sample arithmetic stays
//! finite and inside its range at the ends of the double range, duplicate settings are refused,
//! final values that are not finite are reported as such (exit 3, `"NaN"`/`"inf"`/`"-inf"` in
//! JSON) and a fit whose objective overflows fails with its reason (exit 4). The caps are in the
//! "Limits" table of docs/cli.md.

use crate::support::cli::hybc;

use std::time::{Duration, Instant};

use serde_json::Value;

fn stderr(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Runs `args` and asserts a usage error (exit 2, nothing on stdout) whose message holds `what`.
fn usage_error(args: &[&str], what: &str) {
    let out = hybc(args);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
    assert!(err.starts_with("error: ") && err.contains(what), "{args:?}: expected `{what}` in: {err}");
    assert!(out.stdout.is_empty(), "{args:?}");
}

#[test]
fn every_count_a_flag_accepts_is_capped_with_the_flag_named() {
    let ball = "models/ball.hyb";
    usage_error(&["run", ball, "--max-events", "1000001"], "--max-events: at most 1000000");
    usage_error(&["sweep", ball, "--vary", "e=0.5", "--max-events", "99999999999"], "--max-events: at most");
    usage_error(
        &["fit", ball, "--free", "e", "--target", "energy=1", "--max-events", "2000000"],
        "--max-events",
    );
    usage_error(
        &["fit", ball, "--free", "e", "--target", "energy=1", "--max-iter", "1000001"],
        "--max-iter: at most",
    );
    usage_error(&["sweep", ball, "--vary", "e=0.5", "--events", "1001"], "--events: at most 1000");
    usage_error(&["run", ball, "--max-steps", "1000000001"], "--max-steps: at most 1000000000");
    usage_error(&["sweep", ball, "--vary", "e=0.5", "--max-steps", "0"], "--max-steps: at least 1");
    usage_error(&["sweep", ball, "--vary", "e=0.5", "--threads", "1025"], "--threads: at most 1024");
    usage_error(&["sweep", ball, "--samples", "1000000001"], "--samples: expected 1 to 1000000000");
    usage_error(&["sweep", ball, "--vary", "e=0:1:1000000001"], "at most 1000000000 points");
    usage_error(
        &["sweep", ball, "--vary", "e=0:1:100000", "--vary", "h0=1:2:100000"],
        "the grid has 10000000000 points; at most 1000000000",
    );
    // A grid whose count overflows 64 bits is refused, not wrapped.
    let big = "1:2:1000000000";
    let h0 = format!("h0={big}");
    let g = format!("g={big}");
    let e = "e=0:1:1000000000";
    usage_error(
        &["sweep", ball, "--vary", &h0, "--vary", &g, "--vary", e],
        "more than 18446744073709551615 points",
    );
    usage_error(
        &["sweep", ball, "--vary", "e=0:1:100001", "--plot", "p.svg"],
        "--plot: the sweep has 100001 points",
    );
}

#[test]
fn a_trajectory_too_fine_to_hold_is_refused_before_the_run() {
    // 2.5 s every 1e-8 s: 2.5e8 rows (about 5.9 GB held, 50 GB of CSV).
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("traj.csv");
    let path = path.to_str().expect("utf-8");
    let started = Instant::now();
    usage_error(
        &["run", "models/ball.hyb", "--trajectory", path, "--sample", "1e-8"],
        "--sample: 1e-8 over t = 0..2.5 asks for 250000001 rows; at most 10000000",
    );
    assert!(started.elapsed() < Duration::from_secs(20), "refused before the run");
    assert!(!std::path::Path::new(path).exists(), "no file is started");
    // With --plot the rows are kept for the figure: a tenth of that.
    let plot = dir.path().join("p.svg");
    let args = [
        "run",
        "models/ball.hyb",
        "--trajectory",
        path,
        "--sample",
        "1e-6",
        "--plot",
        plot.to_str().expect("p"),
    ];
    usage_error(&args, "at most 1000000 with --plot");
    // 1e7 rows exactly is allowed: span / dt + 1 with t = 0 and t = T both sampled.
    let out = hybc(&["run", "models/ball.hyb", "--t-end", "1e-6", "--trajectory", path, "--sample", "1e-13"]);
    assert_eq!(out.status.code(), Some(2), "1e7 + 1 rows: {}", stderr(&out));
}

#[test]
fn a_sampled_trajectory_too_long_to_keep_is_refused_by_the_library_too() {
    // The library (and so Python) keeps sampled rows in memory: at most 1e6, checked before the run.
    let model =
        hybc::Model::from_file(concat!(env!("CARGO_MANIFEST_DIR"), "/models/ball.hyb")).expect("ball");
    let compiled = model.compile::<&str>(&[]).expect("compiles");
    let mut opts = model.sim_options();
    opts.trajectory = hybc::TrajectoryRequest::Every(1e-8);
    let started = Instant::now();
    let err = compiled.simulate(&model.params(), &opts).expect_err("2.5e8 rows are refused").to_string();
    assert!(started.elapsed() < Duration::from_secs(5), "refused before the run");
    assert!(err.contains("250000001 rows, more than the 1000000 a run keeps in memory"), "{err}");
    // The cap itself is allowed: t = 0 .. 2.5 every 2.5e-6 is exactly 1e6 + 1 rows, one too many;
    // every 2.5e-6 * (1 + 1e-6) fits.
    opts.trajectory = hybc::TrajectoryRequest::Every(2.5e-6 * (1.0 + 1e-6));
    let run = compiled.simulate(&model.params(), &opts).expect("1e6 rows are kept");
    assert_eq!(run.final_time(), 2.5);
}

#[test]
fn a_streamed_trajectory_is_the_file_the_kept_rows_give() {
    // Without --plot the rows go to the file as they are recorded; with it they are kept and
    // written after the run. Same rows, same bytes, for every step and for samples.
    let dir = tempfile::tempdir().expect("temp dir");
    for sample in [None, Some("0.01")] {
        let mut files = Vec::new();
        for plot in [false, true] {
            let path = dir.path().join(format!("t{plot}.csv"));
            let mut args = vec!["run", "models/ball.hyb", "--grad", "e,h0", "--quiet"];
            let path_text = path.to_str().expect("utf-8").to_string();
            args.extend(["--trajectory", &path_text]);
            if let Some(dt) = sample {
                args.extend(["--sample", dt]);
            }
            let svg = dir.path().join("p.svg").to_str().expect("p").to_string();
            if plot {
                args.extend(["--plot", &svg]);
            }
            let out = hybc(&args);
            assert!(out.status.success(), "{args:?}: {}", stderr(&out));
            files.push(std::fs::read(&path).expect("written"));
        }
        let rows = String::from_utf8_lossy(&files[0]).lines().count();
        assert!(rows > 10, "{sample:?}: {rows} rows");
        if sample.is_some() {
            assert_eq!(rows, 1 + 251, "t = 0, 0.01, ..., 2.5 and the header");
        }
        assert!(files[0] == files[1], "{sample:?}: streamed and kept files differ");
    }
}

#[test]
fn duplicate_settings_are_usage_errors_naming_the_flag() {
    usage_error(&["run", "models/ball.hyb", "--set", "g=1", "--set", "g=2"], "--set: `g` is set twice");
    usage_error(
        &["sweep", "models/ball.hyb", "--vary", "e=0.5", "--set", "g=1", "--set", "g=2"],
        "--set: `g`",
    );
    usage_error(
        &["fit", "models/ball.hyb", "--free", "e", "--target", "energy=1", "--set", "g=1", "--set", "g=2"],
        "--set",
    );
    usage_error(
        &["sweep", "models/ball.hyb", "--vary", "e=0.5", "--vary", "e=0.6"],
        "--vary: `e` is varied twice",
    );
    usage_error(&["run", "models/ball.hyb", "--grad", "e,e"], "--grad: `e` is named twice");
}

#[test]
fn unattainable_tolerances_are_diagnosed_as_such() {
    let out = hybc(&["run", "models/ball.hyb", "--rtol", "1e-16", "--atol", "1e-300"]);
    let err = stderr(&out);
    assert_ne!(out.status.code(), Some(0), "{err}");
    assert!(err.contains("rtol 1e-16 cannot be met"), "{err}");
    assert!(!err.contains("underflow"), "{err}");
}

/// Reads a column of a CSV sweep as numbers.
fn csv_column(out: &[u8], name: &str) -> Vec<f64> {
    let text = String::from_utf8_lossy(out);
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let i = header.iter().position(|h| *h == name).unwrap_or_else(|| panic!("no column {name}"));
    lines.map(|l| l.split(',').nth(i).expect("cell").parse().expect("number")).collect()
}

#[test]
fn a_grid_over_the_whole_double_range_is_finite_in_range_and_monotone() {
    // The ball at g = -1e308 and other absurd values faults or runs away: exit 3, but the rows
    // hold the points asked for.
    let out = hybc(&["sweep", "models/ball.hyb", "--vary", "g=-1e308:1e308:5", "--t-end", "0.1"]);
    assert!(matches!(out.status.code(), Some(0 | 3)), "{}", stderr(&out));
    let g = csv_column(&out.stdout, "g");
    assert_eq!(g.len(), 5);
    assert_eq!((g[0], g[2], g[4]), (-1e308, 0.0, 1e308), "ends exact, the middle exactly 0");
    assert!(g.windows(2).all(|w| w[0] < w[1]), "{g:?}");
    approx::assert_relative_eq!(g[3], 5e307, max_relative = 1e-15);
    let out =
        hybc(&["sweep", "models/ball.hyb", "--vary", "h0=-1.7976931348623157e308:1.7976931348623157e308:7"]);
    let h0 = csv_column(&out.stdout, "h0");
    assert!(h0.iter().all(|v| v.is_finite()) && h0.windows(2).all(|w| w[0] < w[1]), "{h0:?}");
}

#[test]
fn samples_over_the_whole_double_range_are_finite_and_spread() {
    let out = hybc(&[
        "sweep",
        "models/ball.hyb",
        "--samples",
        "200",
        "--vary",
        "g=-1.7e308:1.7e308",
        "--t-end",
        "0.1",
    ]);
    assert!(matches!(out.status.code(), Some(0 | 3)), "{}", stderr(&out));
    let g = csv_column(&out.stdout, "g");
    assert_eq!(g.len(), 200);
    assert!(g.iter().all(|v| v.is_finite() && v.abs() <= 1.7e308), "{g:?}");
    // Uniform over the range: both signs, and not all at an end (before: 1.7e308 every time).
    let positive = g.iter().filter(|v| **v > 0.0).count();
    assert!((60..=140).contains(&positive), "{positive} of 200 positive");
    assert!(g.iter().filter(|v| v.abs() == 1.7e308).count() <= 1, "{g:?}");
}

/// Outputs that are +inf, -inf and NaN at the end of a run that otherwise ends as asked.
const NON_FINITE: &str = "model nonfinite\nparam c = 0\nstate x = 1\nder(x) = -x\n\
                          output inv = 1 / c\noutput neg = log(c)\noutput nan = c / c\noutput fine = x\n\
                          simulate t_end = 1\n";

fn non_finite_model(dir: &tempfile::TempDir) -> String {
    let path = dir.path().join("nonfinite.hyb");
    std::fs::write(&path, NON_FINITE).expect("model written");
    path.to_str().expect("utf-8").to_string()
}

#[test]
fn non_finite_final_values_warn_exit_3_and_are_strings_in_json() {
    let dir = tempfile::tempdir().expect("temp dir");
    let model = non_finite_model(&dir);
    let out = hybc(&["run", &model, "--format", "json"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(3), "{err}");
    assert!(err.contains("warning: final values not finite at t = 1 in mode"), "{err}");
    assert!(err.contains("inv = inf, neg = -inf, nan = NaN") && !err.contains("fine"), "{err}");
    let json: Value = serde_json::from_slice(&out.stdout).expect("json");
    let outputs = &json["final"]["outputs"];
    assert_eq!(
        (&outputs["inv"], &outputs["neg"], &outputs["nan"]),
        (&"inf".into(), &"-inf".into(), &"NaN".into())
    );
    assert_relative_eq_exp(&outputs["fine"]);
    assert_eq!(json["stopped_by"], "t_end", "the run itself ended as asked");
    let warnings = json["warnings"].as_array().expect("warnings");
    assert!(warnings.iter().any(|w| w.as_str().is_some_and(|w| w.contains("inv = inf"))), "{warnings:?}");
    // The table prints them as they are.
    let out = hybc(&["run", &model]);
    assert_eq!(out.status.code(), Some(3));
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(
        table.lines().any(|l| l.trim_start().starts_with("inv") && l.trim_end().ends_with("inf")),
        "{table}"
    );
    // A finite run of the same model is clean.
    let out = hybc(&["run", &model, "--set", "c=2", "--format", "json"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
}

fn assert_relative_eq_exp(v: &Value) {
    let x = v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"));
    approx::assert_relative_eq!(x, (-1.0f64).exp(), max_relative = 1e-6);
}

#[test]
fn non_finite_sweep_cells_are_distinct_from_missing_ones() {
    let dir = tempfile::tempdir().expect("temp dir");
    let model = non_finite_model(&dir);
    let out = hybc(&["sweep", &model, "--vary", "c=0,2", "--format", "jsonl"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(3), "{err}");
    assert!(err.contains("1 of 2 points ended early or have final values that are not finite"), "{err}");
    let rows: Vec<Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("json"))
        .collect();
    assert_eq!(rows[0]["status"], "non_finite");
    assert_eq!(
        (&rows[0]["inv"], &rows[0]["neg"], &rows[0]["nan"]),
        (&"inf".into(), &"-inf".into(), &"NaN".into())
    );
    assert!(rows[0]["error"].as_str().is_some_and(|e| e.contains("inv = inf")), "{}", rows[0]["error"]);
    assert_relative_eq_exp(&rows[0]["fine"]);
    assert_eq!(rows[1]["status"], "ok");
    assert_eq!(rows[1]["inv"], 0.5);
    assert_eq!(rows[1]["error"], Value::Null);
    let out = hybc(&["sweep", &model, "--vary", "c=0,2", "--events", "0"]);
    let text = String::from_utf8_lossy(&out.stdout);
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("c,status,events,t_final,x,inv,neg,nan,fine,error"));
    let row: Vec<&str> = lines.next().expect("row").split(',').collect();
    assert_eq!(&row[..4], ["0", "non_finite", "0", "1"], "{text}");
    assert_eq!(&row[5..8], ["inf", "-inf", "NaN"], "{text}");
}

#[test]
fn a_fit_whose_objective_overflows_fails_with_its_reason() {
    // energy - 1e160 is finite, its square is not: no convergence test means anything.
    let out = hybc(&["fit", "models/ball.hyb", "--free", "e", "--target", "energy=1e160"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(4), "{err}");
    assert!(err.contains("the objective 0.5 sum(residual^2) overflows"), "{err}");
    assert!(err.contains("target `energy`"), "{err}");
    assert!(!String::from_utf8_lossy(&out.stdout).contains("converged"));
    // A large but representable objective still fits (energy 1e100 is out of reach: e <= 1).
    let out = hybc(&["fit", "models/ball.hyb", "--free", "e", "--target", "energy=1e100"]);
    assert!(!stderr(&out).contains("overflows"), "{}", stderr(&out));
}

#[test]
fn fault_messages_name_the_mode_and_the_states_in_run_sweep_and_fit() {
    // g = -1e308 makes the first step's error estimate overflow: the run faults at t = 0.
    let named = "at t = 0 in mode main, state y = 1, v = 0";
    let out = hybc(&["run", "models/ball.hyb", "--set", "g=-1e308"]);
    assert_eq!(out.status.code(), Some(3));
    assert!(stderr(&out).contains(named), "{}", stderr(&out));
    let out = hybc(&["sweep", "models/ball.hyb", "--vary", "g=-1e308,9.81", "--format", "jsonl"]);
    assert_eq!(out.status.code(), Some(3));
    let first: Value =
        serde_json::from_str(String::from_utf8_lossy(&out.stdout).lines().next().expect("row"))
            .expect("json");
    assert_eq!(first["status"], "fault");
    assert!(first["error"].as_str().is_some_and(|e| e.contains(named)), "{}", first["error"]);
    let out = hybc(&["fit", "models/ball.hyb", "--free", "e", "--target", "energy=1", "--set", "g=-1e308"]);
    assert_eq!(out.status.code(), Some(3));
    assert!(stderr(&out).contains(named), "{}", stderr(&out));
}

#[test]
fn a_fault_without_the_model_at_hand_says_the_same_with_indices() {
    use hybc::sim::SimError;
    let fault = SimError::NonFinite { t: 1.5, mode: 0, state: vec![f64::NAN, 2.0] };
    assert_eq!(fault.to_string(), "non-finite state at t = 1.5 in mode 0, state x[0] = NaN, x[1] = 2");
    let fault = SimError::TooManySteps { t: 0.25, max_steps: 5, mode: 1, state: vec![0.1] };
    assert_eq!(fault.to_string(), "more than 5 steps at t = 0.25 in mode 1, state x[0] = 0.1");
}

// ---- issue 24, item 13: bad input gets a clear message ----

/// `source` written to a file in `dir`, its path.
fn model_file(dir: &tempfile::TempDir, source: &str) -> String {
    let path = dir.path().join("m.hyb");
    std::fs::write(&path, source).expect("model written");
    path.to_str().expect("utf-8").to_string()
}

/// `hybc check` of `source`: exit 1 and the rendered diagnostics (stderr).
fn check_error(source: &str) -> String {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = model_file(&dir, source);
    let out = hybc(&["check", &path]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    err.replace(&path, "m.hyb")
}

#[test]
fn max_events_0_is_refused_instead_of_reported_as_1() {
    // The cap is checked after each instant, so 0 used to fire the first touchdown and say
    // "reached --max-events 1". Refused everywhere, with the flag and the bound named.
    usage_error(&["run", "models/ball.hyb", "--max-events", "0"], "--max-events: at least 1, found 0");
    usage_error(
        &["sweep", "models/ball.hyb", "--vary", "e=0.5", "--max-events", "0"],
        "--max-events: at least 1",
    );
    usage_error(
        &["fit", "models/ball.hyb", "--free", "e", "--target", "energy=1", "--max-events", "0"],
        "--max-events: at least 1",
    );
    // The library refuses it too (Python's `max_events=0` and every other caller).
    let model = hybc::Model::parse(include_str!("../../models/ball.hyb")).expect("ball checks");
    let compiled = model.compile::<&str>(&[]).expect("compiles");
    let opts = hybc::SimOptions { max_events: 0, ..model.sim_options() };
    let err = compiled.simulate(&model.params(), &opts).expect_err("refused").to_string();
    assert!(err.contains("max_events"), "{err}");
    // 1 is the smallest cap and means what it says.
    let out = hybc(&["run", "models/ball.hyb", "--max-events", "1"]);
    assert!(stderr(&out).contains("reached --max-events 1 at t = 0.45"), "{}", stderr(&out));
}

#[test]
fn a_simulate_setting_given_twice_is_an_error_at_the_second() {
    let err = check_error("model m\nstate x = 1\nder(x) = 1\nsimulate t_end = 1, t_end = 2\n");
    assert!(err.contains("error: `t_end` is set twice on the `simulate` line"), "{err}");
    assert!(err.contains("m.hyb:4:21"), "{err}");
    assert!(err.contains("expected each setting once; the first is at line 4, column 10"), "{err}");
    // The caret is under the second `t_end`.
    let line = err.lines().find(|l| l.contains("simulate t_end")).expect("source line");
    let caret = err.lines().find(|l| l.contains('^')).expect("caret line");
    assert_eq!(caret.find('^'), line.rfind("t_end"), "{err}");
    assert_eq!(caret.matches('^').count(), "t_end".len(), "{err}");
}

#[test]
fn numbers_a_double_cannot_hold_are_refused_not_rounded_to_0() {
    // In the model text: a parse error with a caret under the literal.
    let err = check_error("model m\nparam a = 1e-400\nstate x = a\nder(x) = 1\n");
    assert!(err.contains("error: number `1e-400` is too small for a double: it would round to 0"), "{err}");
    assert!(err.contains("m.hyb:2:11"), "{err}");
    assert!(err.contains("expected a number of magnitude at least 4.9e-324, or 0"), "{err}");
    let err = check_error("model m\nstate x = 1\nder(x) = 2.5e-999 * x\n");
    assert!(err.contains("number `2.5e-999` is too small") && err.contains("m.hyb:3:10"), "{err}");
    // A subnormal is a double: accepted. An explicit zero is zero.
    let dir = tempfile::tempdir().expect("temp dir");
    let path = model_file(&dir, "model m\nparam a = 1e-310\nparam b = 0e-999\nstate x = a\nder(x) = b\n");
    assert_eq!(hybc(&["check", &path]).status.code(), Some(0));
    // On the command line: the flag and the value named.
    usage_error(
        &["run", "models/ball.hyb", "--set", "h0=1e-400"],
        "--set h0: `1e-400` is too small for a double: it would round to 0",
    );
    usage_error(
        &["sweep", "models/ball.hyb", "--vary", "h0=1e-400:1:3"],
        "`1e-400` is too small for a double",
    );
    usage_error(
        &["fit", "models/ball.hyb", "--free", "e", "--target", "energy=1e-400"],
        "--target: `1e-400` is too small for a double",
    );
    usage_error(&["run", "models/ball.hyb", "--set", "h0=1e400"], "--set: `1e400` is not a finite number");
}

#[test]
fn zero_width_and_combining_characters_are_escaped_in_diagnostics() {
    // `e` + U+0301 used to print as `é` with no caret; U+200B (zero width) as nothing.
    let err = check_error("model m\nstate x = 1\nder(x) = 1 + e\u{301} 2\n");
    assert!(!err.contains('\u{301}'), "{err}");
    assert!(err.contains("error: unexpected combining character <U+0301>"), "{err}");
    assert!(err.contains("der(x) = 1 + e<U+0301> 2"), "{err}");
    assert!(err.contains("m.hyb:3:15"), "{err}");
    let caret = err.lines().find(|l| l.contains('^')).expect("caret line");
    let line = err.lines().find(|l| l.contains("<U+0301>") && l.contains("der")).expect("line");
    assert_eq!(caret.find('^'), line.find("<U+0301>"), "{err}");
    for (c, tag) in [
        ('\u{200B}', "<U+200B>"),
        ('\u{200D}', "<U+200D>"),
        ('\u{2060}', "<U+2060>"),
        ('\u{FEFF}', "<U+FEFF>"),
    ] {
        let err = check_error(&format!("model m\nstate x = 1\nder(x) = 1 +{c} 2\n"));
        assert!(!err.contains(c), "{tag}: {err}");
        assert!(err.contains(&format!("unexpected invisible character {tag}")), "{tag}: {err}");
        assert!(err.contains(&format!("der(x) = 1 +{tag} 2")), "{tag}: {err}");
    }
}

#[test]
fn max_steps_replaces_the_fixed_step_cap() {
    // The ball to 2.5 takes 9 steps at its tolerances: a cap of 5 stops it with a fault (exit 3)
    // naming the cap, and the default lets it finish.
    let out = hybc(&["run", "models/ball.hyb", "--max-steps", "5"]);
    assert_eq!(out.status.code(), Some(3), "{}", stderr(&out));
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), stderr(&out));
    assert!(text.contains("more than 5 steps"), "{text}");
    let out = hybc(&["run", "models/ball.hyb", "--max-steps", "1000"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
}
