//! `hybc sobol` and `hybc::sobol`: the Ishigami function's analytic indices within the bootstrap
//! errors, intervals that shrink as N grows, each policy for rows without a value with exact
//! counts (the ball's third touchdown, which the closed form says fires or not), the design file
//! in SALib's order, and bad flags as usage errors.
//! Closed forms (bouncing ball): ../shared/reference/closed-forms.md.

use std::f64::consts::PI;

use crate::support::cli::hybc;

use hybc::sobol::{self, Design, Output, OutputIndices, Prior, RowKind};
use hybc::{Model, SimOptions, SobolRequest};
use serde_json::Value;

const ISHIGAMI: &str = "tests/data/sobol/ishigami.hyb";

fn model(path: &str) -> Model {
    Model::from_file(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(path)).expect("model")
}

/// The Ishigami function's indices (a = 7, b = 0.1, uniform on [-pi, pi]): S1 and ST.
fn ishigami_indices() -> ([f64; 3], [f64; 3]) {
    let (a, b) = (7.0, 0.1);
    let pi4 = PI.powi(4);
    let v1 = 0.5 + b * pi4 / 5.0 + b * b * pi4 * pi4 / 50.0;
    let v2 = a * a / 8.0;
    let v13 = b * b * pi4 * pi4 * (1.0 / 18.0 - 1.0 / 50.0);
    let v = v1 + v2 + v13;
    ([v1 / v, v2 / v, 0.0], [(v1 + v13) / v, v2 / v, v13 / v])
}

fn ishigami(n: usize, seed: u64, bootstrap: usize) -> OutputIndices {
    let model = model(ISHIGAMI);
    let compiled = model.compile::<&str>(&[]).expect("compiles");
    let varied = (0..3).map(|i| (i, Prior::Uniform { lo: -PI, hi: PI })).collect();
    let design = Design::new(compiled.params().values().to_vec(), varied, n, false, seed).expect("design");
    let outputs = ["f".to_string()];
    let request = SobolRequest {
        design,
        seed,
        outputs: &outputs,
        on_fail: "error",
        bootstrap,
        sim: model.sim_options(),
        threads: 0,
    };
    let mut report = request.run(&compiled, &|| ()).expect("runs");
    assert!(report.evaluated.ended_early.is_empty());
    report.outputs.remove(0).expect("every row has a value")
}

#[test]
fn ishigami_gives_the_analytic_indices_within_three_standard_errors() {
    // Seed 28 (the number), fixed before this test first ran.
    let r = ishigami(1 << 14, 28, 300);
    let (s1, st) = ishigami_indices();
    approx::assert_relative_eq!(s1[0], 0.3139, epsilon = 1e-4);
    approx::assert_relative_eq!(st[2], 0.2437, epsilon = 1e-4);
    let se = r.errors.as_ref().expect("bootstrap");
    for i in 0..3 {
        assert!(
            (r.indices.s1[i] - s1[i]).abs() <= 3.0 * se.s1[i],
            "S1_{i}: {} vs {} (se {})",
            r.indices.s1[i],
            s1[i],
            se.s1[i]
        );
        assert!(
            (r.indices.st[i] - st[i]).abs() <= 3.0 * se.st[i],
            "ST_{i}: {} vs {} (se {})",
            r.indices.st[i],
            st[i],
            se.st[i]
        );
        // The errors are small enough for the test to mean something.
        assert!(se.s1[i] < 0.02 && se.st[i] < 0.02, "{se:?}");
    }
    // The variance is the function's: 13.8446 (a sampling error of a few percent at most).
    approx::assert_relative_eq!(r.indices.variance, 13.8446, max_relative = 0.03);
    assert_eq!((r.used_points, r.dropped_points, r.failed_rows), (1 << 14, 0, 0));
}

#[test]
fn intervals_shrink_as_n_grows() {
    // 16 times the base points: Monte Carlo errors shrink by 4; ask for at least 2 on every index.
    let small = ishigami(1 << 10, 5, 200);
    let large = ishigami(1 << 14, 5, 200);
    let (se_small, se_large) = (small.errors.expect("bootstrap"), large.errors.expect("bootstrap"));
    for i in 0..3 {
        assert!(se_large.s1[i] < se_small.s1[i] / 2.0, "S1_{i}: {} then {}", se_small.s1[i], se_large.s1[i]);
        assert!(se_large.st[i] < se_small.st[i] / 2.0, "ST_{i}: {} then {}", se_small.st[i], se_large.st[i]);
    }
}

/// The ball (g, e, h0 in declaration order) dropped from h0: touchdown times from the closed form,
/// `t1 = sqrt(2 h0 / g)`, then flights of `2 e^k v1 / g` with `v1 = g t1`.
fn touchdowns(p: &[f64], t_end: f64) -> Vec<f64> {
    let (g, e, h0) = (p[0], p[1], p[2]);
    let t1 = (2.0 * h0 / g).sqrt();
    let mut times = vec![t1];
    let mut flight = 2.0 * e * t1;
    while times[times.len() - 1] + flight < t_end && times.len() < 100 {
        times.push(times[times.len() - 1] + flight);
        flight *= e;
    }
    times
}

const T_END: f64 = 1.6;

/// A ball design whose third touchdown, at `t1 (1 + 2 e + 2 e^2)` from 1.12 s to 2.55 s, fires
/// before T_END for some rows only (and no row comes near Zeno: the accumulation time
/// `t1 (1 + 2 e / (1 - e))` is above 2.1 s for e >= 0.75).
fn ball_design(n: usize, seed: u64) -> (Model, Design) {
    let model = model("models/ball.hyb");
    let varied = vec![
        (2, Prior::Uniform { lo: 0.5, hi: 1.5 }),
        (1, Prior::Uniform { lo: 0.75, hi: 0.9 }),
        (0, Prior::Uniform { lo: 9.0, hi: 10.5 }),
    ];
    let design = Design::new(model.params().values().to_vec(), varied, n, false, seed).expect("design");
    (model, design)
}

#[test]
fn shards_of_rows_put_end_to_end_are_the_whole_design_bit_for_bit() {
    // At T = 5 the rows with a low e reach their accumulation point (Zeno) first: shards then
    // carry counts of runs that ended early, which must add up to the whole design's.
    let (model, design) = ball_design(32, 3);
    let compiled = model.compile::<&str>(&[]).expect("compiles");
    let opts = SimOptions { t_end: 5.0, ..model.sim_options() };
    let outputs: Vec<Output> = ["energy", "touchdown#last"]
        .iter()
        .map(|o| Output::parse(o, compiled.info()).expect("parses"))
        .collect();
    let whole = sobol::evaluate(compiled.native(), &design, &outputs, &opts, 2, &|| ()).expect("runs");
    let rows = design.rows().expect("small");
    assert!(!whole.ended_early.is_empty(), "some rows end by Zeno at T = 5");
    let mut values = Vec::new();
    let mut counts: Vec<(&str, usize)> = Vec::new();
    let mut first: Option<usize> = None;
    // Cuts inside base points' blocks too: a shard is any range of rows.
    for range in [0..7, 7..8, 8..101, 101..rows] {
        let part =
            sobol::evaluate_rows(compiled.native(), &design, range.clone(), &outputs, &opts, 1, &|| ())
                .expect("runs");
        assert_eq!(part.values.len(), range.len() * outputs.len());
        values.extend(part.values);
        for (word, count) in part.ended_early {
            match counts.iter_mut().find(|c| c.0 == word) {
                Some(c) => c.1 += count,
                None => counts.push((word, count)),
            }
        }
        first = match (first, part.first_ended_early) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
    }
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
    assert_eq!(bits(&values), bits(&whole.values));
    assert_eq!(counts, whole.ended_early);
    assert_eq!(first, whole.first_ended_early);
}

#[test]
fn each_failure_policy_counts_the_rows_the_closed_form_says_have_no_value() {
    let (model, design) = ball_design(64, 0);
    let compiled = model.compile::<&str>(&[]).expect("compiles");
    let opts = SimOptions { t_end: T_END, ..model.sim_options() };
    let info = compiled.info();
    let outputs: Vec<Output> = ["touchdown#3", "energy", "touchdown#last"]
        .iter()
        .map(|o| Output::parse(o, info).expect("parses"))
        .collect();
    // Which rows have a third touchdown, by the closed form.
    let rows = design.rows().expect("small");
    let mut p = vec![0.0; 3];
    let mut missing = vec![false; rows];
    let mut last = vec![0.0; rows];
    for r in 0..rows {
        design.fill(r, &mut p);
        let t = touchdowns(&p, T_END);
        assert!(
            t.iter().chain([&(t[t.len() - 1] + 1e-3)]).all(|t| (t - T_END).abs() > 1e-6),
            "row {r} borderline"
        );
        missing[r] = t.len() < 3;
        last[r] = t[t.len() - 1];
    }
    let failed = missing.iter().filter(|m| **m).count();
    let block = design.block();
    let complete_points = (0..64).filter(|b| (0..block).all(|j| !missing[b * block + j])).count();
    assert!(failed > 0 && (2..64).contains(&complete_points), "{failed} {complete_points}");

    let labels: Vec<String> = outputs.iter().map(|o| o.label.clone()).collect();
    let run = |on_fail: &str, threads: usize| {
        let request = SobolRequest {
            design: design.clone(),
            seed: 0,
            outputs: &labels,
            on_fail,
            bootstrap: 0,
            sim: opts.clone(),
            threads,
        };
        let report = request.run(&compiled, &|| ()).expect("runs");
        (report.evaluated, report.outputs)
    };
    let (evaluated, results) = run("error", 1);
    assert!(evaluated.ended_early.is_empty(), "{:?}", evaluated.ended_early);
    for r in 0..rows {
        let (t3, energy, t_last) =
            (evaluated.values[3 * r], evaluated.values[3 * r + 1], evaluated.values[3 * r + 2]);
        assert_eq!(t3.is_nan(), missing[r], "row {r}");
        assert!(energy.is_finite());
        approx::assert_relative_eq!(t_last, last[r], max_relative = 1e-8);
    }
    let first = missing.iter().position(|m| *m).expect("some") + 1;
    match &results[0] {
        Err(sobol::AnalysisError::Failed { failed_rows, rows: all, first_row, .. }) => {
            assert_eq!((*failed_rows, *all, *first_row), (failed, rows, first));
        }
        other => panic!("{other:?}"),
    }
    // The other outputs exist in every row: their indices are given under `error` too.
    assert!(results[1].as_ref().is_ok_and(|r| r.failed_rows == 0 && r.used_points == 64));
    assert!(results[2].is_ok());

    let (again, dropped) = run("drop", 3);
    assert!(again.values.iter().zip(&evaluated.values).all(|(a, b)| a.to_bits() == b.to_bits()), "threads");
    let dropped = dropped[0].as_ref().expect("drop analyses");
    assert_eq!(
        (dropped.failed_rows, dropped.used_points, dropped.dropped_points),
        (failed, complete_points, 64 - complete_points)
    );

    let (_, valued) = run(&format!("value={T_END}"), 2);
    let valued = valued[0].as_ref().expect("value analyses");
    assert_eq!((valued.failed_rows, valued.used_points, valued.dropped_points), (failed, 64, 0));
    // With the missing times set to t_end, the output is min(t3, t_end), computed here.
    let y: Vec<f64> = evaluated.values.chunks(3).map(|v| if v[0].is_nan() { T_END } else { v[0] }).collect();
    let blocks = sobol::Blocks { y: &y, stride: 1, offset: 0, d: 3, second_order: false };
    let all: Vec<u32> = (0..64).collect();
    let by_hand = sobol::estimate::indices(&blocks, &all, sobol::estimate::centre(&blocks, &all));
    assert_eq!(valued.indices, by_hand);
}

fn sobol_cli(args: &[&str]) -> std::process::Output {
    let mut all = vec!["sobol"];
    all.extend_from_slice(args);
    hybc(&all)
}

const BALL_ARGS: [&str; 10] = [
    "models/ball.hyb",
    "--vary",
    "h0=0.5:1.5",
    "--vary",
    "e=0.75:0.9",
    "--vary",
    "g=9:10.5",
    "--t-end",
    "1.6",
    "-n",
];

#[test]
fn the_cli_reports_counts_and_exits_3_when_the_policy_refuses() {
    let (_, design) = ball_design(64, 0);
    let mut p = vec![0.0; 3];
    let rows = design.rows().expect("small");
    let failed = (0..rows)
        .filter(|&r| {
            design.fill(r, &mut p);
            touchdowns(&p, T_END).len() < 3
        })
        .count();
    let mut args = BALL_ARGS.to_vec();
    args.extend(["64", "--output", "touchdown#3,energy", "--format", "json", "--bootstrap", "50"]);
    let out = sobol_cli(&args);
    assert_eq!(out.status.code(), Some(3), "{}", String::from_utf8_lossy(&out.stderr));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(&format!("output `touchdown#3`: {failed} of {rows} rows have no value")),
        "{stderr}"
    );
    let json: Value = serde_json::from_slice(&out.stdout).expect("JSON");
    assert_eq!(json["runs"], rows);
    assert_eq!(json["outputs"][0]["name"], "touchdown#3");
    assert!(json["outputs"][0]["error"].as_str().is_some_and(|e| e.contains("--on-fail drop")));
    assert_eq!(json["outputs"][1]["S1"].as_array().map(Vec::len), Some(3));
    assert_eq!(json["outputs"][1]["ST_conf"].as_array().map(Vec::len), Some(3));

    args.extend(["--on-fail", "drop"]);
    let out = sobol_cli(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let json: Value = serde_json::from_slice(&out.stdout).expect("JSON");
    assert_eq!(json["outputs"][0]["failed_rows"], failed);
    assert_eq!(json["on_fail"], "drop");
    let used = json["outputs"][0]["base_points"].as_u64().expect("count");
    assert_eq!(used + json["outputs"][0]["dropped_base_points"].as_u64().expect("count"), 64);
}

#[test]
fn the_design_file_holds_the_rows_in_salib_order() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("design.csv");
    let path_text = path.to_str().expect("utf-8");
    let mut args = BALL_ARGS.to_vec();
    args.extend(["8", "--output", "energy", "--design-out", path_text]);
    let out = sobol_cli(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&path).expect("written");
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "h0,e,g");
    assert_eq!(lines.len(), 1 + 8 * 5);
    let (_, design) = ball_design(8, 0);
    let mut p = vec![0.0; 3];
    for (r, line) in lines[1..].iter().enumerate() {
        design.fill(r, &mut p);
        let values: Vec<f64> = line.split(',').map(|v| v.parse().expect("number")).collect();
        assert_eq!(values, [p[2], p[1], p[0]], "row {r}");
    }
    // Within a block: AB_1 differs from A in h0 alone and takes B's, B ends the block.
    assert_eq!(design.kind(1), RowKind::AB(0));
    let row = |r: usize| -> Vec<&str> { lines[1 + r].split(',').collect() };
    assert_eq!(row(1)[0], row(4)[0]);
    assert_eq!(row(1)[1..], row(0)[1..]);
}

#[test]
fn bad_flags_are_usage_errors_naming_the_flag() {
    let cases: [(&[&str], &str); 9] = [
        (&["-n", "0", "--output", "energy"], "-n: at least 2, found 0"),
        (&["-n", "99999999", "--output", "energy"], "-n: at most 4194304"),
        (&["-n", "8", "--output", "energy", "--bootstrap", "100001"], "--bootstrap: at most 100000"),
        (&["-n", "8", "--output", "energy", "--bootstrap", "1"], "--bootstrap: 1 resample"),
        (
            &["-n", "8", "--output", "energy", "--on-fail", "skip"],
            "--on-fail: expected error, drop or value=X",
        ),
        (&["-n", "8", "--output", "energy", "--on-fail", "value=nan"], "--on-fail"),
        (
            &["-n", "8", "--output", "enrgy"],
            "--output: model has no output or state `enrgy` (did you mean `energy`?)",
        ),
        (&["-n", "8", "--output", "touchdown#0"], "--output: in `touchdown#0`: the firing number K"),
        (&["-n", "8", "--output", "energy", "--vary", "h0=0.6:0.7"], "--vary: `h0` is varied twice"),
    ];
    for (extra, message) in cases {
        let mut args = BALL_ARGS[..9].to_vec();
        args.extend(extra);
        let out = sobol_cli(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{extra:?}: {stderr}");
        assert!(stderr.contains(message), "{extra:?}: {stderr}");
        assert!(out.stdout.is_empty(), "{extra:?}");
    }
    let out = sobol_cli(&["models/ball.hyb", "--vary", "e=normal:0.8:0.1", "--output", "energy"]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("the prior reaches [-inf, inf], outside `e`'s declared range [0, 1]"),
        "{stderr}"
    );
    let out = sobol_cli(&["models/ball.hyb", "--vary", "h0=x:1", "--output", "energy"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--vary: `h0=x:1`: `x` is not a finite number"));
}

#[test]
fn the_plot_has_a_bar_per_index_and_refuses_an_unknown_format() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("indices.svg");
    let mut args = BALL_ARGS.to_vec();
    args.extend(["64", "--output", "energy,touchdown#last", "--bootstrap", "20", "--plot"]);
    args.push(path.to_str().expect("utf-8"));
    let out = sobol_cli(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let svg = std::fs::read_to_string(&path).expect("plot written");
    let bars = |c: plotters::style::RGBColor| {
        let fill = format!("fill=\"#{:02X}{:02X}{:02X}\"", c.0, c.1, c.2);
        svg.split("<rect").skip(1).filter(|el| el.split('>').next().unwrap_or("").contains(&fill)).count()
    };
    // Two outputs, three parameters: an S1 bar and an ST bar each.
    assert_eq!(bars(hybc::plot::DATA_COLOR), 6);
    assert_eq!(bars(hybc::plot::TANGENT_COLOR), 6);
    let texts: Vec<&str> = svg
        .split("<text")
        .skip(1)
        .filter_map(|el| el.split_once('>').and_then(|(_, rest)| rest.split("</text>").next()))
        .map(str::trim)
        .collect();
    for name in ["h0", "e", "g", "energy: S1, ST", "touchdown#last: S1, ST"] {
        assert!(texts.contains(&name), "{name} in {texts:?}");
    }

    let bad = dir.path().join("indices.pdf");
    let mut args = BALL_ARGS.to_vec();
    args.extend(["8", "--output", "energy", "--plot", bad.to_str().expect("utf-8")]);
    let out = sobol_cli(&args);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("--plot: "),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.stdout.is_empty() && !bad.exists());
}

#[test]
fn normal_and_log_uniform_priors_reach_the_design_rows() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("design.csv");
    let args = [
        "models/ball.hyb",
        "--vary",
        "g=normal:9.81:0.2",
        "--vary",
        "h0=loguniform:0.5:2",
        "--output",
        "energy",
        "-n",
        "1024",
        "--bootstrap",
        "0",
        "--design-out",
        path.to_str().expect("utf-8"),
    ];
    let out = sobol_cli(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&path).expect("written");
    let rows: Vec<Vec<f64>> =
        text.lines().skip(1).map(|l| l.split(',').map(|v| v.parse().expect("number")).collect()).collect();
    assert_eq!(rows.len(), 1024 * 4);
    let n = rows.len() as f64;
    let mean = |f: &dyn Fn(&Vec<f64>) -> f64| rows.iter().map(f).sum::<f64>() / n;
    // g: mean 9.81 and standard deviation 0.2; the Sobol' points put the sample moments far
    // closer than a random sample's (standard error 0.003 of the mean for 4096 draws).
    let g_mean = mean(&|r| r[0]);
    let g_sd = mean(&|r| (r[0] - g_mean).powi(2)).sqrt();
    assert!((g_mean - 9.81).abs() < 0.003 && (g_sd - 0.2).abs() < 0.004, "{g_mean} {g_sd}");
    // log h0 uniform on [log 0.5, log 2]: within the range, its mean in the middle (0), its
    // variance (log 4)^2 / 12.
    assert!(rows.iter().all(|r| (0.5..=2.0).contains(&r[1])));
    let l_mean = mean(&|r| r[1].ln());
    let l_var = mean(&|r| (r[1].ln() - l_mean).powi(2));
    assert!(l_mean.abs() < 0.01, "{l_mean}");
    approx::assert_relative_eq!(l_var, 4f64.ln().powi(2) / 12.0, max_relative = 0.01);
}

#[test]
fn a_value_at_a_time_is_an_output_with_the_analytic_indices() {
    // x(0.5) = 0.5 a + b for der(x) = a + 2 b: with a, b uniform on [0, 1] the variances are
    // 0.25 / 12 and 1 / 12, so S1 = ST = (0.2, 0.8). The final value x(1) = a + 2 b is the same
    // split (1/12 against 4/12): both read off one run per row.
    let dir = std::env::temp_dir().join(format!("hybc-sobol-at-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("lin.hyb");
    std::fs::write(&path, "model lin\nparam a = 0.5\nparam b = 0.5\nstate x = 0\nder(x) = a + 2 * b\n")
        .unwrap();
    let out = sobol_cli(&[
        path.to_str().unwrap(),
        "--vary",
        "a=0:1",
        "--vary",
        "b=0:1",
        "--t-end",
        "1",
        "--output",
        "x@0.5,x",
        "-n",
        "4096",
        "--seed",
        "3",
        "--format",
        "json",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["outputs"][0]["name"], "x@0.5");
    for output in json["outputs"].as_array().unwrap() {
        for (key, conf) in [("S1", "S1_conf"), ("ST", "ST_conf")] {
            for (k, want) in [0.2, 0.8].into_iter().enumerate() {
                let got = output[key][k].as_f64().unwrap();
                let interval = output[conf][k].as_f64().unwrap();
                assert!((got - want).abs() <= 1.5 * interval + 1e-12, "{key}[{k}] = {got} +/- {interval}");
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
