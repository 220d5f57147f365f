//! Generated models that stress the front end: 5,000 chained `let`s (in both declaration
//! orders), 60 `let`s that each use their predecessor twice, a chain of 10,000 states, and a chain
//! of `let`s nested past `MAX_EXPR_DEPTH`. Each gives its closed form, through the library and
//! through the `hybc` command with generous time and peak-memory limits (the real figures are
//! in the README's Limits section, with their commands).

use std::io::Write;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use approx::assert_relative_eq;
use hybc::Model;

#[path = "../../benches/support/stress_models.rs"]
mod stress_models;
use stress_models::{doubling_lets, let_chain, state_chain};

/// Runs `hybc args` on `model_text`, polling its peak resident memory (VmHWM); returns stdout,
/// stderr, the exit code, the wall time and the peak in MiB.
fn hybc_measured(model_text: &str, args: &[&str]) -> (String, String, Option<i32>, Duration, f64) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("stress.hyb");
    std::fs::File::create(&path).and_then(|mut f| f.write_all(model_text.as_bytes())).expect("write");
    let started = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_hybc"))
        .arg(args[0])
        .arg(&path)
        .args(&args[1..])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("hybc starts");
    let status_path = format!("/proc/{}/status", child.id());
    let mut peak_kib = 0u64;
    let (out, err) = {
        let mut stdout = child.stdout.take().expect("stdout");
        let mut stderr = child.stderr.take().expect("stderr");
        let out = std::thread::spawn(move || std::io::read_to_string(&mut stdout).unwrap_or_default());
        let err = std::thread::spawn(move || std::io::read_to_string(&mut stderr).unwrap_or_default());
        while child.try_wait().expect("wait").is_none() {
            if let Ok(status) = std::fs::read_to_string(&status_path) {
                if let Some(kib) = status
                    .lines()
                    .find_map(|l| l.strip_prefix("VmHWM:"))
                    .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
                {
                    peak_kib = peak_kib.max(kib);
                }
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        (out.join().expect("stdout reader"), err.join().expect("stderr reader"))
    };
    let code = child.wait().expect("exit").code();
    (out, err, code, started.elapsed(), peak_kib as f64 / 1024.0)
}

fn assert_bounded(what: &str, elapsed: Duration, peak_mib: f64, time_limit: Duration, mib_limit: f64) {
    eprintln!("{what}: {elapsed:.2?}, peak {peak_mib:.0} MiB");
    assert!(elapsed < time_limit, "{what} took {elapsed:?}");
    assert!(peak_mib < mib_limit, "{what} peaked at {peak_mib:.0} MiB");
}

#[test]
fn five_thousand_chained_lets_give_their_closed_form_in_either_order() {
    let n = 5000;
    for reversed in [false, true] {
        let model = Model::parse(&let_chain(n, reversed)).expect("checks");
        let compiled = model.compile(&["c"]).expect("compiles");
        let run = compiled.simulate(&model.params(), &model.sim_options()).expect("runs");
        let (c, t) = (1e-4, 1.0);
        assert_relative_eq!(run.state("x").unwrap(), n as f64 * c * t, max_relative = 1e-9);
        assert_relative_eq!(run.dstate("x", "c").unwrap(), n as f64 * t, max_relative = 1e-9);
        assert_relative_eq!(run.output("y").unwrap(), n as f64 * c, max_relative = 1e-9);
    }
}

#[test]
fn five_thousand_chained_lets_through_the_command_line_in_bounded_time_and_memory() {
    let text = let_chain(5000, true);
    for args in [&["check"][..], &["derive"][..], &["run", "--grad", "c", "--format", "json"][..]] {
        let (out, err, code, elapsed, peak) = hybc_measured(&text, args);
        assert_eq!(code, Some(0), "hybc {args:?}: {err}");
        assert!(!out.is_empty());
        assert_bounded(
            &format!("5000 lets, hybc {}", args[0]),
            elapsed,
            peak,
            Duration::from_secs(60),
            400.0,
        );
    }
}

#[test]
fn sixty_doubling_lets_stay_a_dag() {
    let text = doubling_lets(60);
    let model = Model::parse(&text).expect("checks");
    let compiled = model.compile(&["p"]).expect("compiles");
    let run = compiled.simulate(&model.params(), &model.sim_options()).expect("runs");
    // At p = 1 every step doubles exactly: d59 = 2^59, and d/dp = (1 + p)^59 + 59 p (1 + p)^58
    // = 61 * 2^58, whose partial sums have few significant bits, so both are exact.
    assert_eq!(run.output("big"), Some(2f64.powi(59)));
    assert_eq!(run.doutput("big", "p"), Some(61.0 * 2f64.powi(58)));

    let (out, err, code, elapsed, peak) = hybc_measured(&text, &["check"]);
    assert_eq!(code, Some(0), "{err}");
    // The summary prints the output's text cut at SHOWN_CHARS, not its 2^60 terms.
    let line = out.lines().find(|l| l.contains("big =")).expect("the output line");
    assert!(line.len() < hybc::lower::SHOWN_CHARS + 40 && line.ends_with("..."), "{line}");
    assert_bounded("60 doubling lets, hybc check", elapsed, peak, Duration::from_secs(20), 200.0);
}

#[test]
fn ten_thousand_states_check_in_linear_time_and_run_to_their_closed_form() {
    let n = 10_000;
    let text = state_chain(n);
    let (out, err, code, elapsed, peak) = hybc_measured(&text, &["check"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(out.contains("10000 states"), "{}", &out[..out.len().min(200)]);
    assert_bounded("10,000 states, hybc check", elapsed, peak, Duration::from_secs(15), 300.0);

    let model = Model::parse(&text).expect("checks");
    let compiled = model.compile(&["k"]).expect("compiles");
    let run = compiled.simulate(&model.params(), &model.sim_options()).expect("runs");
    let e = (-1f64).exp();
    let mut factorial = 1.0; // (i - 1)!
    for i in 1..=n {
        if i > 1 {
            factorial *= (i - 1) as f64;
        }
        let name = format!("x{i}");
        let (x, dx) = (run.state(&name).unwrap(), run.dstate(&name, "k").unwrap());
        // xi(1) = e^-1 / (i-1)!, dxi/dk = (i - 2) e^-1 / (i-1)! at k = 1.
        let (want, dwant) = (e / factorial, (i as f64 - 2.0) * e / factorial);
        if i <= 8 {
            assert_relative_eq!(x, want, max_relative = 1e-6);
            // dx2/dk is exactly 0: its error is absolute.
            assert_relative_eq!(dx, dwant, max_relative = 1e-6, epsilon = 1e-10);
        } else {
            assert!((x - want).abs() < 1e-8 && (dx - dwant).abs() < 1e-7, "{name}: {x} {dx}");
        }
    }
}

#[test]
fn lets_nested_past_the_depth_cap_are_refused_once_with_a_location() {
    // Each line adds 51 levels: a_k nests 1 + 51 k deep, past MAX_EXPR_DEPTH from k = 1961 on.
    let mut text = String::from("model deep\nstate x = 1\nder(x) = a1999\nlet a0 = x\n");
    let ones = " + 1".repeat(51);
    for k in 1..2000 {
        text.push_str(&format!("let a{k} = a{}{ones}\n", k - 1));
    }
    let err = Model::parse_named(&text, "deep.hyb").unwrap_err().to_string();
    assert_eq!(err.matches("nests expressions").count(), 1, "{}", &err[..err.len().min(2000)]);
    let depth_line = (hybc::sema::MAX_EXPR_DEPTH - 1) / 51 + 1;
    // The first let over the cap, a_k at line k + 4 (1-based).
    let expected = format!("deep.hyb:{}:5", depth_line + 4);
    assert!(err.contains(&expected), "expected {expected} in\n{err}");
}
