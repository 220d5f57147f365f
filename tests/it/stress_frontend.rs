//! Generated models that stress the front end: 5,000 chained `let`s (in both declaration
//! orders), 60 `let`s that each use their predecessor twice, 20,000 `let`s that square their
//! predecessor (a derivative nested 20,000 deep for `hybc derive`), a chain of 10,000 states, 700
//! states that each read one shared sum (a dense Jacobian), and a chain of `let`s nested past
//! `MAX_EXPR_DEPTH`. Each gives its closed form, through the library and
//! through the `hybc` command with generous time and peak-memory limits (the real figures are
//! in docs/performance.md, "Large models", with their commands).

use std::time::Duration;

use approx::assert_relative_eq;
use hybc::Model;

use crate::support::measured::{assert_bounded, hybc_measured};

#[path = "../../benches/support/stress_models.rs"]
mod stress_models;
use stress_models::{doubling_lets, let_chain, shared_sum, squaring_lets, state_chain, state_chain_loop};

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
fn twenty_thousand_squaring_lets_derive_in_linear_time_and_memory() {
    let n = 20_000;
    let text = squaring_lets(n);
    let (out, err, code, elapsed, peak) = hybc_measured(&text, &["derive"]);
    assert_eq!(code, Some(0), "{err}");
    // Every a_k but the last is used more than once (twice by a_(k+1), and by the derivative),
    // so each is hoisted into a `let` of the mode block; the derivative df/dc nests n deep: one
    // line of O(n) characters. Printing kept the text of every partial derivative, O(n^2)
    // characters (out of memory at 4 GB for this model).
    let lets = out.lines().filter(|l| l.trim_start().starts_with("let w")).count();
    assert_eq!(lets, n - 1);
    let f_c = out.lines().find(|l| l.trim_start().starts_with("f_c = [1 + 2 * ")).expect("f_c");
    assert!(f_c.matches("1 + 2 * ").count() >= n - 1000, "{}", &f_c[..200]);
    assert!(out.len() < 100 * n, "{} bytes", out.len());
    assert_bounded("20,000 squaring lets, hybc derive", elapsed, peak, Duration::from_secs(60), 400.0);

    // One flow entry whose sensitivity kernel computes 140,000 nodes: 36 s to compile with the
    // backtracking allocator (release build), a fraction of a second with the single-pass one
    // that `RegAlloc::Auto` now picks past `AUTO_REGALLOC_NODE_LIMIT`.
    let model = Model::parse(&text).expect("checks");
    let started = std::time::Instant::now();
    let compiled = model.compile(&["c"]).expect("compiles");
    let compile_time = started.elapsed();
    assert!(compile_time < Duration::from_secs(20), "compile took {compile_time:?}");
    let run = compiled.simulate(&model.params(), &model.sim_options()).expect("runs");
    let c: f64 = 0.01;
    let root = (1.0 - 4.0 * c).sqrt();
    assert_relative_eq!(run.state("x").unwrap(), (1.0 - root) / 2.0, max_relative = 1e-12);
    assert_relative_eq!(run.dstate("x", "c").unwrap(), 1.0 / root, max_relative = 1e-12);
}

#[test]
fn states_reading_one_shared_sum_compile_in_time_linear_in_their_dense_jacobian() {
    // f_x has n^2 = 490,000 entries: "linear in the model's size" means in those. Lowering took
    // O(n^3) (every entry's derivative re-walked the whole sum): 3.7 s at n = 200, 22-43 s at
    // 500, over 300 s at 1000 (release builds); now about 5 s here.
    let n = 700;
    let text = shared_sum(n);
    let (out, err, code, elapsed, peak) =
        hybc_measured(&text, &["run", "--grad", "k", "--format", "json", "--quiet"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(out.is_empty(), "{out}");
    assert_bounded("700 states reading one sum, hybc run", elapsed, peak, Duration::from_secs(60), 400.0);

    let model = Model::parse(&text).expect("checks");
    let compiled = model.compile(&["k"]).expect("compiles");
    let run = compiled.simulate(&model.params(), &model.sim_options()).expect("runs");
    let x = (0.001 * n as f64 - 1.0).exp();
    for i in [0, n / 2, n - 1] {
        let name = format!("x{i}");
        assert_relative_eq!(run.state(&name).unwrap(), x, max_relative = 1e-6);
        assert_relative_eq!(run.dstate(&name, "k").unwrap(), -x, max_relative = 1e-6);
    }
}

/// The same chain written as two loops over an array (`x[i - 1]` for `x{i}`) flattens to the same
/// model: checked within the flat text's bounds, the same values and gradients.
#[test]
fn ten_thousand_states_written_as_a_loop_are_their_flat_model() {
    let n = 10_000;
    let (out, err, code, elapsed, peak) = hybc_measured(&state_chain_loop(n), &["check"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        out.contains("10000 states") && out.contains("state arrays: x[0 .. 9999]"),
        "{}",
        &out[..out.len().min(200)]
    );
    assert_bounded("10,000 states as a loop, hybc check", elapsed, peak, Duration::from_secs(15), 300.0);
    let n = 500;
    let (flat, arr) =
        (Model::parse(&state_chain(n)).expect("checks"), Model::parse(&state_chain_loop(n)).expect("checks"));
    let rf =
        flat.compile(&["k"]).expect("compiles").simulate(&flat.params(), &flat.sim_options()).expect("runs");
    let ra =
        arr.compile(&["k"]).expect("compiles").simulate(&arr.params(), &arr.sim_options()).expect("runs");
    for i in 1..=n {
        let (xf, xa) = (format!("x{i}"), format!("x[{}]", i - 1));
        assert_eq!(ra.state(&xa), rf.state(&xf), "{xa}");
        assert_eq!(ra.dstate(&xa, "k"), rf.dstate(&xf, "k"), "d{xa}/dk");
    }
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
