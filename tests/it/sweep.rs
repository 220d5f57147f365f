//! `hybc sweep` and `hybc::sweep`: which points a sweep runs (grids, lists, seeded samples), that
//! every row is exactly the single run at its point whatever the thread count, that a failing
//! point is reported in its row while the sweep goes on, and that bad flags are usage errors.
//! Closed forms (bouncing ball): ../shared/reference/closed-forms.md.

use crate::support::cli::hybc;
use crate::support::reference::BallForm;

use approx::assert_relative_eq;
use hybc::codegen::{compile, CompileOptions, CompiledModel};
use hybc::lower::{lower, system_info};
use hybc::sema::ParamIdx;
use hybc::sim::{self, SimOptions};
use hybc::sweep::{self, Columns, Format};
use serde_json::Value;

fn sweep_ok(args: &[&str]) -> String {
    let mut all = vec!["sweep"];
    all.extend_from_slice(args);
    let out = hybc(&all);
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    // No progress bar when stderr is not a terminal, and nothing else to say.
    assert!(out.stderr.is_empty(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).expect("utf-8")
}

/// The rows of a sweep in which some points may end early (Zeno), which exits with 3.
fn sweep_rows(args: &[&str]) -> String {
    let mut all = vec!["sweep"];
    all.extend_from_slice(args);
    let out = hybc(&all);
    assert!(matches!(out.status.code(), Some(0 | 3)), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).expect("utf-8")
}

/// The JSON lines of a sweep, one object per point.
fn jsonl(out: &[u8]) -> Vec<Value> {
    String::from_utf8_lossy(out)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
        .collect()
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// Splits one CSV line (RFC 4180 quoting, no line breaks inside fields).
fn csv_fields(line: &str) -> Vec<String> {
    let (mut fields, mut cur, mut quoted, mut chars) =
        (Vec::new(), String::new(), false, line.chars().peekable());
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                cur.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(std::mem::take(&mut cur)),
            _ => cur.push(c),
        }
    }
    fields.push(cur);
    fields
}

fn ball(grad: &[u32]) -> (hybc::sema::Model, CompiledModel) {
    let model = hybc::check_source(include_str!("../../models/ball.hyb")).expect("ball checks");
    let grad: Vec<ParamIdx> = grad.iter().map(|&j| ParamIdx(j)).collect();
    let compiled =
        compile(&lower(&model), system_info(&model, &grad), &CompileOptions::default()).expect("compiles");
    (model, compiled)
}

#[test]
fn grids_are_full_products_in_flag_order_and_lists_keep_their_order() {
    let rows = jsonl(
        sweep_ok(&["models/ball.hyb", "--vary", "e=0.75:0.95:5", "--vary", "h0=3,1,2", "--format", "jsonl"])
            .as_bytes(),
    );
    assert_eq!(rows.len(), 15);
    for (i, row) in rows.iter().enumerate() {
        let e = 0.75 + 0.05 * (i / 3) as f64;
        assert_relative_eq!(f(&row["e"]), e, max_relative = 1e-15);
        assert_eq!(f(&row["h0"]), [3.0, 1.0, 2.0][i % 3], "the last --vary varies fastest");
        assert_eq!(f(&row["g"]), 9.81, "unvaried parameters keep their defaults");
    }
    assert_eq!((f(&rows[0]["e"]), f(&rows[14]["e"])), (0.75, 0.95), "grid ends are exact");
    // --set moves the base point of every row.
    let rows = jsonl(
        sweep_ok(&["models/ball.hyb", "--vary", "e=0.7,0.8", "--set", "g=9", "--format", "jsonl"]).as_bytes(),
    );
    assert!(rows.iter().all(|r| f(&r["g"]) == 9.0));
}

#[test]
fn samples_stay_in_their_ranges_and_vary_only_the_sampled_parameters() {
    // Without --vary: every parameter with a declared range (the ball has one: e in [0, 1]).
    let rows = jsonl(
        sweep_rows(&["models/ball.hyb", "--samples", "200", "--seed", "1", "--format", "jsonl"]).as_bytes(),
    );
    assert_eq!(rows.len(), 200);
    let es: Vec<f64> = rows.iter().map(|r| f(&r["e"])).collect();
    assert!(es.iter().all(|e| (0.0..=1.0).contains(e)));
    // Uniform on [0, 1]: the mean of 200 draws has standard deviation 0.02; 0.1 is 5 of them.
    assert!((es.iter().sum::<f64>() / 200.0 - 0.5).abs() < 0.1);
    assert!(rows.iter().all(|r| f(&r["g"]) == 9.81 && f(&r["h0"]) == 1.0));
    // --vary P=LO:HI gives a range to a parameter without one; P alone takes the declared one.
    let out = sweep_rows(&[
        "models/ball.hyb",
        "--samples",
        "50",
        "--vary",
        "h0=2:3",
        "--vary",
        "e",
        "--format",
        "jsonl",
    ]);
    let rows = jsonl(out.as_bytes());
    assert_eq!(rows.len(), 50);
    assert!(rows.iter().all(|r| (2.0..=3.0).contains(&f(&r["h0"])) && (0.0..=1.0).contains(&f(&r["e"]))));
    assert!(rows.iter().all(|r| f(&r["g"]) == 9.81));
}

#[test]
fn seeded_sampling_is_reproducible_and_differs_for_another_seed() {
    let ranges = [(1, 0.0, 1.0), (2, 2.0, 3.0)];
    let a = sweep::uniform_samples(&[9.81, 0.8, 1.0], &ranges, 100, 42);
    assert_eq!(a, sweep::uniform_samples(&[9.81, 0.8, 1.0], &ranges, 100, 42));
    let b = sweep::uniform_samples(&[9.81, 0.8, 1.0], &ranges, 100, 43);
    assert!(a.iter().zip(&b).all(|(p, q)| p[1] != q[1] && p[2] != q[2]));
    assert!(a.iter().all(|p| p[0] == 9.81 && (0.0..=1.0).contains(&p[1]) && (2.0..=3.0).contains(&p[2])));
    // The CLI: same seed, same bytes; another seed, other points.
    let run =
        |seed: &str| sweep_rows(&["models/ball.hyb", "--samples", "20", "--seed", seed, "--events", "0"]);
    assert_eq!(run("7"), run("7"));
    assert_ne!(run("7"), run("8"));
}

#[test]
fn every_result_is_bit_for_bit_the_single_run_at_its_point() {
    let (model, compiled) = ball(&[0, 1, 2]);
    let opts = SimOptions { t_end: 2.5, rtol: 1e-10, atol: 1e-12, ..SimOptions::default() };
    let base: Vec<f64> = model.params.iter().map(|p| p.default).collect();
    let points = sweep::full_grid(&base, &[(1, sweep::linspace(0.6, 0.95, 8)), (2, vec![0.5, 1.0, 4.0])]);
    let results = sweep::run_points(&compiled, &points, &opts, 2, &|| ()).expect("pool");
    assert_eq!(results.len(), points.len());
    for (p, r) in points.iter().zip(&results) {
        // Debug prints every f64 in its shortest round-trip form (and -0.0 apart from 0.0), so
        // equal texts are equal bits.
        assert_eq!(format!("{r:?}"), format!("{:?}", sim::run(&compiled, p, &opts)), "at {p:?}");
    }
}

#[test]
fn csv_rows_hold_the_numbers_hybc_run_prints() {
    let out = sweep_ok(&["models/ball.hyb", "--vary", "e=0.8,0.9", "--grad", "e,h0", "--events", "3"]);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 3);
    let header = csv_fields(lines[0]);
    for (line, e) in lines[1..].iter().zip(["0.8", "0.9"]) {
        let row = csv_fields(line);
        assert_eq!(row.len(), header.len());
        let cell = |name: &str| -> f64 {
            let i = header.iter().position(|h| h == name).unwrap_or_else(|| panic!("no column {name}"));
            row[i].parse().unwrap_or_else(|_| panic!("{name}: `{}`", row[i]))
        };
        let run = hybc(&[
            "run",
            "models/ball.hyb",
            "--set",
            &format!("e={e}"),
            "--grad",
            "e,h0",
            "--format",
            "json",
        ]);
        let json: Value = serde_json::from_slice(&run.stdout).expect("json");
        assert_eq!(row[header.iter().position(|h| h == "status").expect("status")], "ok");
        assert_eq!(cell("events") as usize, json["events"].as_array().expect("events").len());
        for k in 1..=3 {
            let ev = &json["events"][k - 1];
            assert_eq!(cell(&format!("t{k}")).to_bits(), f(&ev["time"]).to_bits());
            assert_eq!(cell(&format!("dt{k}/dh0")).to_bits(), f(&ev["dtime"]["h0"]).to_bits());
        }
        for s in ["y", "v"] {
            assert_eq!(cell(s).to_bits(), f(&json["final"]["state"][s]).to_bits());
            assert_eq!(cell(&format!("d{s}/de")).to_bits(), f(&json["final"]["dstate"][s]["e"]).to_bits());
        }
        assert_eq!(cell("denergy/dh0").to_bits(), f(&json["final"]["doutputs"]["energy"]["h0"]).to_bits());
    }
    // And the column is what its name says: at e = 0.8 four bounces before 2.5 s, dE/de = 8 g h0 e^7.
    let row = csv_fields(lines[1]);
    let i = header.iter().position(|h| h == "denergy/de").expect("column");
    assert_relative_eq!(
        row[i].parse::<f64>().expect("number"),
        BallForm::DEFAULT.energy_grad(4)[1],
        max_relative = 1e-9
    );
}

#[test]
fn output_bytes_do_not_depend_on_the_thread_count() {
    // T = 10 makes most points Zeno, so error rows are compared too.
    let args = |threads: &'static str, format: &'static str| {
        let a = ["models/ball.hyb", "--samples", "300", "--seed", "5", "--vary", "e", "--vary", "h0=0.5:2"];
        let mut v: Vec<&str> = a.to_vec();
        v.extend(["--grad", "all", "--t-end", "10", "--threads", threads, "--format", format]);
        let mut all = vec!["sweep"];
        all.extend(v);
        hybc(&all)
    };
    for format in ["csv", "jsonl"] {
        let one = args("1", format);
        assert_eq!(one.status.code(), Some(3), "some points are Zeno");
        assert_eq!(String::from_utf8_lossy(&one.stdout).lines().count(), 300 + usize::from(format == "csv"));
        for threads in ["2", "3"] {
            assert!(one.stdout == args(threads, format).stdout, "{format} with {threads} threads differs");
        }
    }
}

#[test]
fn a_zeno_point_has_its_error_in_the_row_and_the_sweep_goes_on() {
    // To T = 3: e = 0.5 accumulates its bounces at t* = t1 + 2 e v1 / (g (1 - e)) < 3, e = 0.8 at
    // 4.06 > 3.
    let out = hybc(&["sweep", "models/ball.hyb", "--vary", "e=0.5,0.8", "--t-end", "3", "--format", "jsonl"]);
    assert_eq!(out.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&out.stderr).contains("1 of 2 points ended early"));
    let rows = jsonl(&out.stdout);
    assert_eq!(rows.len(), 2);
    assert_eq!(rows[0]["status"], "zeno");
    assert_eq!(rows[0]["energy"], Value::Null, "no final value at t_end exists");
    let message = rows[0]["error"].as_str().expect("error text");
    assert!(message.contains("Zeno"), "{message}");
    let t_star = BallForm { e: 0.5, ..BallForm::DEFAULT }.accumulation_time();
    let near: f64 = message
        .split("near t = ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no accumulation point: {message}"));
    assert_relative_eq!(near, t_star, max_relative = 1e-8);
    assert_eq!(rows[1]["status"], "ok");
    assert_eq!(rows[1]["error"], Value::Null);
    assert_relative_eq!(f(&rows[1]["t_final"]), 3.0);
}

#[test]
fn columns_are_named_by_the_documented_scheme() {
    let (_, compiled) = ball(&[1]);
    let info = hybc::sim::HybridSystem::info(&compiled);
    let columns = Columns::new(info, 2, 1);
    let expect = "g,e,h0,status,events,event1,t1,dt1/de,event2,t2,dt2/de,t_final,y,v,energy,dy/de,dv/de,denergy/de,error";
    assert_eq!(columns.header().join(","), expect);
    let mut csv = Vec::new();
    columns.write_header(&mut csv, Format::Csv).expect("write");
    assert_eq!(String::from_utf8(csv).expect("utf-8"), format!("{expect}\n"));
    // The JSON lines use the same names, in the same order.
    let out = sweep_ok(&[
        "models/ball.hyb",
        "--vary",
        "e=0.8",
        "--grad",
        "e",
        "--events",
        "2",
        "--format",
        "jsonl",
    ]);
    let row: serde_json::Map<String, Value> = serde_json::from_str(out.trim()).expect("one object");
    assert_eq!(row.keys().cloned().collect::<Vec<_>>().join(","), expect);
}

#[test]
fn bad_flags_are_usage_errors_with_clear_messages() {
    let cases: &[(&[&str], &str)] = &[
        (&[], "nothing to vary"),
        (&["--vary", "x=1,2"], "has no parameter `x`"),
        (&["--vary", "e=0:2:3"], "outside its range [0, 1]"),
        (&["--vary", "e=0.1,1.5"], "outside its range [0, 1]"),
        (&["--vary", "e=0:1"], "ranges are for --samples"),
        (&["--vary", "e"], "ranges are for --samples"),
        (&["--vary", "e=1:0:3"], "LO must be below HI"),
        (&["--vary", "e=0:1:1"], "at least 2"),
        (&["--vary", "e=0:1:x"], "at least 2"),
        (&["--vary", "e=0.2,zero"], "`zero` is not a finite number"),
        (&["--vary", "e=0:1:2:3"], "expected P=LO:HI:N"),
        (&["--vary", "e=0.1,0.2", "--vary", "e=0.3,0.4"], "varied twice"),
        (&["--vary", "e=0.1,0.2", "--set", "e=0.3"], "both by --set and by --vary"),
        (&["--vary", "h0=1:2:100000", "--vary", "e=0:1:100000"], "at most 1000000000"),
        (&["--samples", "5", "--vary", "g"], "no declared range"),
        (&["--samples", "5", "--vary", "e=0:1:3"], "not a grid or list"),
        (&["--samples", "5", "--vary", "e=0:2"], "outside its range [0, 1]"),
        (&["--samples", "0"], "expected 1 to"),
        (&["--seed", "3", "--vary", "e=0.5,0.6"], "--samples"),
        (&["--vary", "e=0.5", "--grad", "q"], "has no parameter `q`"),
        (&["--vary", "e=0.5", "--rtol=-1"], "--rtol"),
        (&["--vary", "e=0.5", "--events", "100000000000"], "--events: at most"),
        (&["--vary", "e=0.5", "--threads", "5000"], "--threads: at most"),
        (&["--vary", "e=0.5", "--threads=-1"], "--threads"),
        (&["--vary", "e=0.5", "--format", "xml"], "xml"),
        (&["--vary", "e=0.5", "--plot", "out.pdf"], "must end in .svg or .png"),
        (&["--vary", "e=0.5", "--output", "/no/such/dir/out.csv"], "cannot write"),
    ];
    for (flags, message) in cases {
        let mut args = vec!["sweep", "models/ball.hyb"];
        args.extend_from_slice(flags);
        let out = hybc(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flags:?}: {stderr}");
        assert!(stderr.contains(message), "{flags:?}: expected `{message}` in: {stderr}");
        assert!(stderr.starts_with("error"), "{flags:?}: {stderr}");
        assert!(out.stdout.is_empty(), "{flags:?}");
    }
    // A model without declared ranges cannot be sampled without --vary ranges.
    let out = hybc(&["sweep", "models/thermostat.hyb", "--samples", "3"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("declares no parameter range"));
}

#[test]
fn output_file_gets_the_rows() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("rows.csv");
    let out = hybc(&[
        "sweep",
        "models/ball.hyb",
        "--vary",
        "e=0.7:0.9:3",
        "--output",
        path.to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.stdout.is_empty());
    let text = std::fs::read_to_string(&path).expect("written");
    assert_eq!(text, sweep_ok(&["models/ball.hyb", "--vary", "e=0.7:0.9:3"]));
    assert_eq!(text.lines().count(), 4);
}

#[test]
fn after_a_stop_event_the_gradients_are_total_derivatives() {
    // Free fall stopped at t = ts: y = h0 - g ts^2 / 2 and v = -g ts, so dy/dts = -g ts and
    // dv/dts = -g (the fixed-time sensitivities would be 0).
    let src = "model s\nparam g = 9.81\nparam h0 = 10\nparam ts = 1\nstate y = h0\nstate v = 0\n\
               der(y) = v\nder(v) = -g\nevent done when t >= ts {\n    stop\n}\n";
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("stop.hyb");
    std::fs::write(&path, src).expect("write model");
    let out = sweep_ok(&[
        path.to_str().expect("utf-8"),
        "--vary",
        "ts=0.5:1.5:3",
        "--grad",
        "ts",
        "--t-end",
        "5",
        "--format",
        "jsonl",
    ]);
    let rows = jsonl(out.as_bytes());
    assert_eq!(rows.len(), 3);
    for row in &rows {
        let ts = f(&row["ts"]);
        assert_eq!(row["status"], "ok");
        assert_relative_eq!(f(&row["t_final"]), ts, max_relative = 1e-12);
        assert_relative_eq!(f(&row["y"]), 10.0 - 9.81 * ts * ts / 2.0, max_relative = 1e-9);
        assert_relative_eq!(f(&row["dy/dts"]), -9.81 * ts, max_relative = 1e-9);
        assert_relative_eq!(f(&row["dv/dts"]), -9.81, max_relative = 1e-9);
    }
}
