//! `hybc run --check-grad` and the `hybc::gradcheck` library behind it: passes on every shipped
//! model, fails on an absurd tolerance or a corrupted derivative, reports cusps instead of
//! failing, and puts its result in the JSON report.

use crate::support::cli::hybc;

use std::process::Output;

use hybc::codegen::{compile, CompileOptions};
use hybc::gradcheck::{check, CheckOptions};
use hybc::lower::{lower, system_info};
use hybc::sema::ParamIdx;
use hybc::sim::{run, SimOptions};
use serde_json::Value;

fn json_of(out: &Output) -> Value {
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("not JSON ({e}): {}", String::from_utf8_lossy(&out.stdout)))
}

#[test]
fn every_shipped_model_passes_its_gradient_check() {
    let mut paths: Vec<_> = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/models"))
        .expect("models")
        .map(|e| e.expect("entry").path())
        .collect();
    paths.sort();
    for path in paths {
        let path = path.to_str().expect("utf-8");
        let out = hybc(&["run", path, "--grad", "all", "--check-grad", "--format", "json"]);
        assert_eq!(out.status.code(), Some(0), "{path}: {}", String::from_utf8_lossy(&out.stdout));
        let json = json_of(&out);
        let check = &json["check_grad"];
        let params = check["params"].as_array().expect("check_grad.params");
        assert_eq!(params.len(), json["grad"].as_array().expect("grad").len(), "{path}");
        let tol = check["options"]["tol"].as_f64().expect("tol");
        for p in params {
            assert!(p["checked"].as_u64().expect("checked") > 0, "{path}: {p}");
            assert!(p["cusp"].is_null(), "{path}: {p}");
            let d = p["worst"]["discrepancy"].as_f64().expect("discrepancy");
            assert!(d <= tol, "{path}: {p}");
            println!("{path} {}: worst discrepancy {d:.1e}", p["name"]);
        }
    }
}

#[test]
fn an_absurdly_tight_check_tolerance_fails_with_exit_code_4() {
    let out = hybc(&["run", "models/ball.hyb", "--grad", "all", "--check-grad", "--check-tol", "1e-15"]);
    assert_eq!(out.status.code(), Some(4));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("gradient check FAILED"), "{stdout}");
    let help = hybc(&["run", "--help"]);
    assert!(String::from_utf8_lossy(&help.stdout).contains("4 --check-grad found a derivative"));
}

#[test]
fn an_end_time_at_a_bounce_is_a_cusp_not_a_failure() {
    // t_end = t4 = 2.2142719354 (rounded): at h0 - h the fourth bounce comes earlier and at h0 + h
    // later than t_end, so the runs see 4 and 3 bounces; the first three bounce times are still
    // checked, the final state (which jumps with the bounce) is not.
    let out = hybc(&[
        "run",
        "models/ball.hyb",
        "--grad",
        "h0",
        "--check-grad",
        "--t-end",
        "2.2142719354",
        "--format",
        "json",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let p = &json_of(&out)["check_grad"]["params"][0];
    assert_eq!(p["name"], "h0");
    assert_eq!(p["cusp"]["first_difference"], 3, "{p}");
    let counts: Vec<u64> =
        p["cusp"]["events"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
    assert_ne!(counts[0], counts[2], "{p}");
    assert_eq!(p["checked"], 3, "only the three bounces before the cusp: {p}");
    let table = hybc(&["run", "models/ball.hyb", "--grad", "h0", "--check-grad", "--t-end", "2.2142719354"]);
    assert!(String::from_utf8_lossy(&table.stdout).contains("cusp in h0"));
}

#[test]
fn a_corrupted_derivative_is_found() {
    let source =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/models/tilted_ball.hyb")).unwrap();
    let model = hybc::check_source(&source).expect("valid");
    let grad: Vec<ParamIdx> = (0..model.params.len()).map(|i| ParamIdx(i as u32)).collect();
    let compiled =
        compile(&lower(&model), system_info(&model, &grad), &CompileOptions::default()).expect("compiles");
    let p: Vec<f64> = model.params.iter().map(|p| p.default).collect();
    let opts = SimOptions { t_end: 3.0, rtol: 1e-10, atol: 1e-12, ..SimOptions::default() };
    let nominal = run(&compiled, &p, &opts).expect("runs");
    let defaults = CheckOptions::for_rtol(opts.rtol);
    assert!(check(&compiled, &p, &opts, &nominal, &defaults).unwrap().passed());
    // dt/ds of the fourth bounce off by 0.1%: ten times the default tolerance.
    let mut bad = nominal.clone();
    bad.events[3].dtime.as_mut().unwrap()[2] *= 1.001;
    let c = check(&compiled, &p, &opts, &bad, &defaults).unwrap();
    assert!(!c.passed());
    let failed: Vec<&str> = c.failures().map(|f| f.name.as_str()).collect();
    assert_eq!(failed, ["s"]);
    let worst = c.params[2].worst.as_ref().unwrap();
    assert_eq!(worst.quantity, "time of event #3 (impact)");
    approx::assert_relative_eq!(worst.discrepancy, 1e-3, max_relative = 0.01);
    // A final-state sensitivity with the wrong sign.
    let mut bad = nominal.clone();
    let ds = bad.final_state.dstate.as_mut().unwrap();
    ds[0] = -ds[0];
    let c = check(&compiled, &p, &opts, &bad, &defaults).unwrap();
    assert_eq!(c.failures().map(|f| f.name.as_str()).collect::<Vec<_>>(), ["g"]);
}

#[test]
fn grazing_and_zeno_runs_are_skipped_with_notes() {
    // The grazing ceiling: the ceiling is reached at p - h or p + h but not both, a cusp.
    let out =
        hybc(&["run", "tests/data/run/ceiling_graze.hyb", "--grad", "H", "--check-grad", "--format", "json"]);
    assert_eq!(out.status.code(), Some(0));
    assert!(!json_of(&out)["check_grad"]["params"][0]["cusp"].is_null());
    // The Zeno ball stops early (exit 3 wins over the check); its final state is not checked.
    let out =
        hybc(&["run", "models/ball.hyb", "--grad", "e", "--check-grad", "--t-end", "10", "--format", "json"]);
    assert_eq!(out.status.code(), Some(3));
    let p = &json_of(&out)["check_grad"]["params"][0];
    // The bounces before the first grazing one are checked; that one and the rest are not.
    let notes = p["notes"].as_array().expect("notes");
    assert!(notes[0].as_str().unwrap().contains("grazes"), "{p}");
    assert!(notes[1].as_str().unwrap().contains("stopped early"), "{p}");
    assert!(p["checked"].as_u64().unwrap() >= 20, "{p}");
    assert!(p["worst"]["discrepancy"].as_f64().unwrap() < 1e-4, "{p}");
}

#[test]
fn check_flags_are_validated() {
    let code = |args: &[&str]| hybc(args).status.code();
    assert_eq!(code(&["run", "models/ball.hyb", "--check-grad"]), Some(2), "needs --grad");
    assert_eq!(
        code(&["run", "models/ball.hyb", "--grad", "e", "--check-tol", "1e-3"]),
        Some(2),
        "needs --check-grad"
    );
    assert_eq!(code(&["run", "models/ball.hyb", "--grad", "e", "--check-grad", "--check-tol", "0"]), Some(2));
    assert_eq!(
        code(&["run", "models/ball.hyb", "--grad", "e", "--check-grad", "--check-tol", "nan"]),
        Some(2)
    );
    let err = hybc(&["run", "models/ball.hyb", "--grad", "e", "--check-grad", "--check-tol", "0"]);
    assert!(String::from_utf8_lossy(&err.stderr).contains("error: --check-tol: expected a positive number"));
}

#[test]
fn default_check_passes_every_model_from_rtol_1e_6_to_1e_12() {
    // The default step and tolerance (`CheckOptions::for_rtol`) must hold at every tolerance a
    // user may pick, not only at the models' own; the worst discrepancies are printed for the
    // README (`--nocapture`).
    let mut paths: Vec<_> = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/models"))
        .expect("models")
        .map(|e| e.expect("entry").path())
        .collect();
    paths.sort();
    let rtols = [1e-6, 1e-8, 1e-10, 1e-12];
    let mut worst = [0.0_f64; 4];
    for path in paths {
        let model = hybc::check_source(&std::fs::read_to_string(&path).unwrap()).expect("valid");
        let grad: Vec<ParamIdx> = (0..model.params.len()).map(|i| ParamIdx(i as u32)).collect();
        let compiled = compile(&lower(&model), system_info(&model, &grad), &CompileOptions::default())
            .expect("compiles");
        let p: Vec<f64> = model.params.iter().map(|p| p.default).collect();
        for (w, rtol) in worst.iter_mut().zip(rtols) {
            let t_end = model.simulate.t_end.expect("shipped models set t_end");
            let opts = SimOptions { t_end, rtol, atol: rtol * 1e-2, ..SimOptions::default() };
            let nominal = run(&compiled, &p, &opts).expect("runs");
            let c = check(&compiled, &p, &opts, &nominal, &CheckOptions::for_rtol(rtol)).unwrap();
            assert!(c.passed(), "{} at rtol {rtol:e}:\n{}", path.display(), c.to_table());
            *w = c.params.iter().map(|x| x.worst_discrepancy()).fold(*w, f64::max);
        }
    }
    for (w, rtol) in worst.iter().zip(rtols) {
        println!("rtol {rtol:.0e}: worst --check-grad discrepancy over the shipped models {w:.1e}");
    }
}
