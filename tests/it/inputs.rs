//! Inputs interpolated in time (`pwl`, `pwc` of a vector parameter) against closed forms.
//!
//! A constant or linear flow between breakpoints is integrated without truncation error, and the
//! knots are breakpoints, so every value and derivative below is exact up to round-off (checked
//! to relative 1e-12, 1e-10 where a flow switch's side is found a few spacings of `t` past it):
//! - `der(x) = pwl(t, 0, 1, u)`: `x(1)` is the trapezoid rule of `u` with spacing
//!   `h = 1/(N-1)`, `dx/du_k` its weights `h/2, h, ..., h, h/2`;
//! - `der(x) = pwc(t, t0, t1, u)` to `t_end > t1`: `x = u_0 t0 + w sum u_k + u_{N-1} (t_end - t1)`
//!   with `w = (t1 - t0)/N`; `dx/dt0 = u_0 - mean(u)`, `dx/dt1 = mean(u) - u_{N-1}` (each knot
//!   moves the sensitivities by the flow's jump times `dt_k/dp`);
//! - a free final time, `pwl(t, 0, T, u)` with a stop at `t >= T`: `x(T) = (T/(N-1)) sum w_k u_k`,
//!   so `dx(T)/dT = x(T)/T` (the total derivative, the stop's time moving with `T`).

use std::time::Instant;

use hybc::codegen::{CompileOptions, CompiledModel};
use hybc::expr::Tape;
use hybc::lower::{lower, system_info, Interpreter};
use hybc::sema::ParamIdx;
use hybc::sim::HybridSystem;
use hybc::{Model, SimOptions};

use crate::support::cli::hybc;
use crate::support::hand_functions::same;

fn close(a: f64, b: f64, tol: f64, what: &str) {
    assert!((a - b).abs() <= tol * b.abs().max(1.0), "{what}: {a} vs {b} (relative tolerance {tol})");
}

/// The trapezoid weights of `n` knots spaced `h`.
fn trapezoid(n: usize, h: f64) -> Vec<f64> {
    (0..n).map(|k| if k == 0 || k == n - 1 { h / 2.0 } else { h }).collect()
}

fn element_names(v: &str, n: usize) -> Vec<String> {
    (0..n).map(|k| format!("{v}[{k}]")).collect()
}

#[test]
fn pwl_integrates_to_the_trapezoid_rule_and_its_weights() {
    let u = [1.0, 2.0, 4.0, 3.0, -0.5, 0.25, 2.0];
    let n = u.len();
    let src = format!("model trap\nparam u[{n}] = 0 in [-5, 5]\nstate x = 0\nder(x) = pwl(t, 0, 1, u)\n");
    let model = Model::parse(&src).expect("checks");
    let names = element_names("u", n);
    let compiled = model.compile(&names).expect("compiles");
    let params = model.params().with_vector("u", &u).expect("in range");
    let run = compiled.simulate(&params, &SimOptions { t_end: 1.0, ..SimOptions::default() }).expect("runs");
    let w = trapezoid(n, 1.0 / (n - 1) as f64);
    let want: f64 = w.iter().zip(&u).map(|(w, u)| w * u).sum();
    close(run.state("x").expect("x"), want, 1e-12, "x(1)");
    for (k, name) in names.iter().enumerate() {
        close(run.dstate("x", name).expect("dx/du"), w[k], 1e-12, &format!("dx/d{name}"));
    }
    // A kink is landed on, not located: no flow switch is counted and nothing is an event.
    assert!(run.events().is_empty());
    assert_eq!(run.result().stats.switches, 0);
}

/// `der(x) = pwc(t, t0, t1, u)` run to `t_end`, with every derivative.
fn pwc_run(u: &[f64], t0: f64, t1: f64, t_end: f64) -> hybc::Run {
    let n = u.len();
    let src = format!(
        "model zoh\nparam u[{n}] = 0 in [-5, 5]\nparam t0 = 0\nparam t1 = 1\nstate x = 0\n\
         der(x) = pwc(t, t0, t1, u)\n"
    );
    let model = Model::parse(&src).expect("checks");
    let mut names = element_names("u", n);
    names.extend(["t0".to_string(), "t1".to_string()]);
    let compiled = model.compile(&names).expect("compiles");
    let params = model
        .params()
        .with_vector("u", u)
        .and_then(|p| p.with("t0", t0))
        .and_then(|p| p.with("t1", t1))
        .expect("in range");
    compiled.simulate(&params, &SimOptions { t_end, ..SimOptions::default() }).expect("runs")
}

#[test]
fn pwc_integrates_exactly_and_its_knots_move_with_t0_and_t1() {
    let u = [1.0, 2.0, 4.0, 3.0];
    let (t0, t1, t_end) = (0.1, 0.9, 1.0);
    let run = pwc_run(&u, t0, t1, t_end);
    let n = u.len();
    let w = (t1 - t0) / n as f64;
    let sum: f64 = u.iter().sum();
    let mean = sum / n as f64;
    let x = u[0] * t0 + w * sum + u[n - 1] * (t_end - t1);
    close(run.state("x").expect("x"), x, 1e-12, "x(t_end)");
    for k in 0..n {
        let extra = if k == 0 { t0 } else { 0.0 } + if k == n - 1 { t_end - t1 } else { 0.0 };
        close(run.dstate("x", &format!("u[{k}]")).expect("dx/du"), w + extra, 1e-12, &format!("dx/du[{k}]"));
    }
    close(run.dstate("x", "t0").expect("dx/dt0"), u[0] - mean, 1e-12, "dx/dt0");
    close(run.dstate("x", "t1").expect("dx/dt1"), mean - u[n - 1], 1e-12, "dx/dt1");
    // The N - 1 interior knots are flow switches; t0 and t1 themselves are not jumps.
    assert_eq!(run.result().stats.switches, n - 1);
    assert!(run.events().is_empty());
}

#[test]
fn pwc_holds_its_end_values_outside_the_window() {
    // Before t0 the first value, after t1 the last: over [0, 3] with the window [1, 2].
    let u = [2.0, -1.0, 0.5];
    let run = pwc_run(&u, 1.0, 2.0, 3.0);
    let w = 1.0 / 3.0;
    close(run.state("x").expect("x"), 2.0 * 1.0 + w * 1.5 + 0.5 * 1.0, 1e-12, "x(3)");
    close(run.dstate("x", "t0").expect("dx/dt0"), 2.0 - 0.5, 1e-12, "dx/dt0");
    close(run.dstate("x", "t1").expect("dx/dt1"), 0.5 - 0.5, 1e-12, "dx/dt1");
}

#[test]
fn a_free_final_time_differentiates_through_the_window_and_the_stop() {
    let u = [1.0, 2.0, 4.0, 3.0, 0.5];
    let n = u.len();
    let src = format!(
        "model free_time\nparam u[{n}] = 0 in [-5, 5]\nparam T = 2 in [0.5, 5]\nstate x = 0\n\
         der(x) = pwl(t, 0, T, u)\nevent finish when t >= T {{\n    stop\n}}\n"
    );
    let model = Model::parse(&src).expect("checks");
    let mut names = element_names("u", n);
    names.push("T".to_string());
    let compiled = model.compile(&names).expect("compiles");
    for big_t in [0.75, 2.0, 3.5] {
        let params = model.params().with_vector("u", &u).and_then(|p| p.with("T", big_t)).expect("in range");
        let run =
            compiled.simulate(&params, &SimOptions { t_end: 10.0, ..SimOptions::default() }).expect("runs");
        let w = trapezoid(n, big_t / (n - 1) as f64);
        let x: f64 = w.iter().zip(&u).map(|(w, u)| w * u).sum();
        assert_eq!(run.events().len(), 1, "the stop fires once");
        close(run.final_time(), big_t, 1e-15, "stop time");
        close(run.state("x").expect("x"), x, 1e-12, "x(T)");
        close(run.dstate_total("x", "T").expect("dx(T)/dT"), x / big_t, 1e-12, "dx(T)/dT");
        for (k, weight) in w.iter().enumerate() {
            let name = format!("u[{k}]");
            close(run.dstate_total("x", &name).expect("dx/du"), *weight, 1e-12, &format!("dx/d{name}"));
        }
    }
}

#[test]
fn inputs_in_a_reset_an_output_and_a_guard() {
    // x rises at 1; the kick at x >= 0.7 adds pwc(t, 0, 2, w) (t = 0.7 is in w's second quarter
    // [0.5, 1)); the output at t = 1.6 reads pwl(t, 0, 2, u) at knot position 1.6.
    let src = "model io\nparam u[3] = 0 in [-5, 5]\nparam w[4] = 0 in [-5, 5]\nstate x = 0\nder(x) = 1\n\
               event kick when x >= 0.7 {\n    x := x + pwc(t, 0, 2, w)\n}\noutput y = pwl(t, 0, 2, u)\n";
    let model = Model::parse(src).expect("checks");
    let mut names = element_names("u", 3);
    names.extend(element_names("w", 4));
    let compiled = model.compile(&names).expect("compiles");
    let (u, w) = ([1.0, 2.0, -3.0], [0.5, 1.5, -2.0, 4.0]);
    let params = model.params().with_vector("u", &u).and_then(|p| p.with_vector("w", &w)).expect("in range");
    let run = compiled.simulate(&params, &SimOptions { t_end: 1.6, ..SimOptions::default() }).expect("runs");
    close(run.state("x").expect("x"), 1.6 + w[1], 1e-12, "x");
    close(run.output("y").expect("y"), 0.4 * u[1] + 0.6 * u[2], 1e-12, "y");
    for (k, want) in [0.0, 1.0, 0.0, 0.0].into_iter().enumerate() {
        close(run.dstate("x", &format!("w[{k}]")).expect("dx/dw"), want, 1e-12, "dx/dw");
    }
    for (k, want) in [0.0, 0.4, 0.6].into_iter().enumerate() {
        close(run.doutput("y", &format!("u[{k}]")).expect("dy/du"), want, 1e-12, "dy/du");
    }

    // A pwl in a guard: x = t meets 1.5 - t (pwl through 1.5, 0.5 on [0, 1]) at t_e = 0.75;
    // g = t - ((1 - t) u0 + t u1), g_t = 1 + u0 - u1 = 2: dt_e/du0 = (1 - t_e)/2, dt_e/du1 = t_e/2.
    let src = "model meet\nparam u[3] = 0 in [-5, 5]\nstate x = 0\nder(x) = 1\n\
               event meet when x >= pwl(t, 0, 2, u) {\n    stop\n}\n";
    let model = Model::parse(src).expect("checks");
    let names = element_names("u", 3);
    let compiled = model.compile(&names).expect("compiles");
    let params = model.params().with_vector("u", &[1.5, 0.5, 0.0]).expect("in range");
    let run = compiled.simulate(&params, &SimOptions { t_end: 2.0, ..SimOptions::default() }).expect("runs");
    assert_eq!(run.events().len(), 1);
    close(run.events()[0].time, 0.75, 1e-12, "t_e");
    close(run.devent_time(0, "u[0]").expect("dt/du0"), 0.125, 1e-10, "dt_e/du0");
    close(run.devent_time(0, "u[1]").expect("dt/du1"), 0.375, 1e-10, "dt_e/du1");
    close(run.devent_time(0, "u[2]").expect("dt/du2"), 0.0, 1e-10, "dt_e/du2");
}

/// The flow's instructions, and those of its derivative with respect to `u[k]`, for an input of
/// `n` knots: what one evaluation costs.
fn evaluation_sizes(n: usize, k: usize) -> (usize, usize) {
    let src = format!(
        "model big\nparam u[{n}] = 1\nstate x = 0\nder(x) = -x + pwl(t, 0, 7, u) * pwc(t, 0, 7, u)\n"
    );
    let model = hybc::check_source(&src).expect("checks");
    let funcs = lower(&model);
    let flow = &funcs.modes[0];
    let entry = flow.flow_p.entries.iter().find(|e| e.1 == k as u32).expect("an entry for u[k]").2;
    (Tape::new(&funcs.store, &flow.flow).len(), Tape::new(&funcs.store, &[entry]).len())
}

#[test]
fn a_thousand_knots_cost_what_ten_do_per_evaluation_and_a_step_per_interval() {
    // Structurally: the value and each element's derivative read the knot position, not the
    // other elements.
    assert_eq!(evaluation_sizes(20, 5), evaluation_sizes(1000, 5));

    // Measured: the JIT's flow, at positions spread over the window, best of 5 batches.
    let time_flow = |n: usize| {
        let src = format!("model big\nparam u[{n}] = 1\nstate x = 0\nder(x) = -x + pwl(t, 0, 10, u)\n");
        let model = hybc::check_source(&src).expect("checks");
        let compiled =
            CompiledModel::compile(&lower(&model), system_info(&model, &[]), &CompileOptions::default())
                .expect("compiles");
        let p: Vec<f64> = (0..n).map(|k| (k % 7) as f64).collect();
        let (x, mut dx, mut acc) = ([0.5], [0.0], 0.0);
        let mut best = f64::INFINITY;
        for _ in 0..5 {
            let start = Instant::now();
            for i in 0..20_000 {
                compiled.flow(0, (i % 1000) as f64 * 0.01, &x, &p, &mut dx);
                acc += dx[0];
            }
            best = best.min(start.elapsed().as_secs_f64());
        }
        assert!(acc.is_finite());
        best
    };
    let (small, large) = (time_flow(10), time_flow(1000));
    // For docs/performance.md (`cargo test --test it inputs -- --nocapture`).
    println!("20000 flows: {:.3} ms with 10 knots, {:.3} ms with 1000", small * 1e3, large * 1e3);
    assert!(large < 3.0 * small + 1e-3, "1000 knots: {large} s, 10 knots: {small} s for 20000 flows");

    // A run: every knot is a breakpoint, so at least one step per knot interval, and the
    // integral is exact: x(10) = (10 / 1000) sum u.
    let n = 1000;
    let src = format!("model big\nparam u[{n}] = 0 in [-5, 5]\nstate x = 0\nder(x) = pwc(t, 0, 10, u)\n");
    let model = Model::parse(&src).expect("checks");
    let u: Vec<f64> = (0..n).map(|k| ((k * 37) % 11) as f64 / 4.0 - 1.0).collect();
    let params = model.params().with_vector("u", &u).expect("in range");
    let compiled = model.compile(&["u[500]"]).expect("compiles");
    let run = compiled.simulate(&params, &SimOptions { t_end: 10.0, ..SimOptions::default() }).expect("runs");
    let stats = &run.result().stats;
    assert!(stats.steps >= n, "{} steps for {n} knot intervals", stats.steps);
    assert_eq!(stats.switches, n - 1);
    // Each of the 999 switches is crossed a few spacings of `t` (~1e-15) past its knot, on the
    // value of the interval before: up to ~1e-14 each, ~1e-11 in all.
    close(run.state("x").expect("x"), 0.01 * u.iter().sum::<f64>(), 1e-10, "x(10)");
    close(run.dstate("x", "u[500]").expect("dx/du"), 0.01, 1e-12, "dx/du[500]");
}

#[test]
fn the_jit_reads_inside_the_vector_at_any_time_and_agrees_with_the_evaluator() {
    // Positions far outside the window, infinite and NaN: the index is clamped before the load,
    // and the JIT agrees with the reference evaluator bit for bit.
    let src = "model edges\nparam u[4] = 1\nparam t0 = -1\nparam t1 = 2\nstate x = 0\n\
               der(x) = pwl(t, t0, t1, u) + 10 * pwc(t, t0, t1, u) + x * pwl(t, t0, t1, u)\n";
    let model = hybc::check_source(src).expect("checks");
    let funcs = lower(&model);
    let grad: Vec<ParamIdx> = (0..model.n_params() as u32).map(ParamIdx).collect();
    let info = system_info(&model, &grad);
    let jit = CompiledModel::compile(&funcs, info.clone(), &CompileOptions::default()).expect("compiles");
    let reference = Interpreter::new(funcs, info);
    let p = [0.5, -2.0, 3.0, 7.0, -1.0, 2.0];
    let (m, n) = (p.len(), 1);
    let times = [
        f64::NEG_INFINITY,
        -1e300,
        -1.0,
        -0.25,
        0.0,
        0.5,
        1.25,
        2.0,
        2.0f64.next_up(),
        1e300,
        f64::INFINITY,
        f64::NAN,
    ];
    for t in times {
        let x = [0.25];
        let s: Vec<f64> = (0..n * m).map(|k| k as f64 * 0.1).collect();
        let (mut a, mut b) = ((vec![0.0; n], vec![0.0; n * m]), (vec![0.0; n], vec![0.0; n * m]));
        jit.flow_sens(0, t, &x, &s, &p, &mut a.0, &mut a.1);
        reference.flow_sens(0, t, &x, &s, &p, &mut b.0, &mut b.1);
        for (j, r) in a.0.iter().chain(&a.1).zip(b.0.iter().chain(&b.1)) {
            assert!(same(*j, *r), "t = {t}: JIT {j} vs evaluator {r}");
        }
        if t.is_finite() {
            assert!(a.0[0].is_finite(), "t = {t}: {}", a.0[0]);
        }
    }
    // Ends held: u[0] before t0 and u[3] after t1, for both inputs.
    let mut dx = [0.0];
    jit.flow(0, -5.0, &[0.0], &p, &mut dx);
    assert_eq!(dx[0], 0.5 + 10.0 * 0.5);
    jit.flow(0, 1e300, &[0.0], &p, &mut dx);
    assert_eq!(dx[0], 7.0 + 10.0 * 7.0);
}

#[test]
fn the_cli_checks_gradients_of_a_model_with_inputs() {
    let out = hybc(&[
        "run",
        "models/hopper_thrust.hyb",
        "--set",
        "f=0,10,20,10,5,0",
        "--set",
        "b=1,3,2",
        "--grad",
        "all",
        "--check-grad",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("gradient check passed"), "{stdout}");
}

#[test]
fn check_shows_inputs_and_their_knots() {
    let out = hybc(&["check", "models/hopper_thrust.hyb"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for line in [
        "  f[6] = 5  in [0, 50]  (f[0] .. f[5])",
        "    der(v) = (k * (L0 - y) - pwc(b @ 3 * t / 2.5) * v + pwl(f @ 5 * t / 2.5)) / m - g",
        "  pwl(t, .., f) in mode stance: knots 0 .. 5 at 5 * t / 2.5 = k (kinks: steps land on them)",
        "  pwc(t, .., b) in mode stance: knots 1 .. 2 at 3 * t / 2.5 = k (jumps: steps land on them, the gradients jump there)",
    ] {
        assert!(stdout.lines().any(|l| l == line), "missing `{line}` in:\n{stdout}");
    }
}
