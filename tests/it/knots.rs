//! Input knots as a queue of breakpoints (issue #39): a step ends exactly on each knot, with the
//! input read on the knot's earlier side at the step's end, so a knot costs a step end and no
//! rejected attempt; events that meet a `pwc` knot at its instant keep exactly the derivatives
//! that are the same on both sides of it; a short window with gradients on its ends runs.
//!
//! The flows below are piecewise constant or linear in `t`, integrated without truncation error
//! between knots, so values and derivatives are checked against closed forms to round-off
//! (relative 1e-12, 1e-9 where a window of 1e-12 scales the round-off up).

use hybc::sim::{Method, SimWarning, StopReason};
use hybc::{Model, SimOptions};

const METHODS: [Method; 4] = [Method::Dopri5, Method::Dop853, Method::Rodas5p, Method::Rodas4];

fn close(a: f64, b: f64, tol: f64, what: &str) {
    assert!((a - b).abs() <= tol * b.abs().max(1.0), "{what}: {a} vs {b} (relative tolerance {tol})");
}

/// `src` compiled with gradients for `grad`, run with `set` to `t_end` by `method`.
fn run(src: &str, grad: &[&str], set: &[(&str, &[f64])], t_end: f64, method: Method) -> hybc::Run {
    let model = Model::parse(src).expect("checks");
    let compiled = model.compile(grad).expect("compiles");
    let mut params = model.params();
    for (name, values) in set {
        params = match values {
            [v] => params.with(name, *v),
            _ => params.with_vector(name, values),
        }
        .expect("in range");
    }
    let opts = SimOptions { t_end, method, ..model.sim_options() };
    compiled.simulate(&params, &opts).expect("runs")
}

fn at_knot_warnings(run: &hybc::Run) -> usize {
    run.warnings().iter().filter(|w| matches!(w, SimWarning::EventAtKnot { .. })).count()
}

#[test]
fn a_knot_costs_one_step_end_and_no_rejected_attempt() {
    // 1000 knots on [0, 10], a constant or linear flow between them: the steps are the knot
    // intervals and the steps the same flow takes without knots (to grow from the first step's
    // size, and past the window), under every stepper.
    let n = 1000;
    let plain =
        "model plain\nparam c = 1\nstate x = 0\nder(x) = c * t\nsimulate rtol = 1e-10, atol = 1e-12\n";
    let u: Vec<f64> = (0..n).map(|k| ((k * 37) % 11) as f64 / 4.0 - 1.0).collect();
    for input in ["pwc", "pwl"] {
        let src = format!(
            "model big\nparam u[{n}] = 0 in [-5, 5]\nparam t1 = 10\nstate x = 0\nder(x) = {input}(t, 0, t1, u)\n\
             simulate rtol = 1e-10, atol = 1e-12\n"
        );
        for method in METHODS {
            let r = run(&src, &["u[500]", "t1"], &[("u", &u)], 12.0, method);
            let stats = &r.result().stats;
            let intervals = if input == "pwc" { n } else { n - 1 };
            let alone = run(plain, &["c"], &[], 12.0, method).result().stats.steps;
            assert_eq!(stats.rejected, 0, "{input} {method:?}: {stats:?}");
            assert!(
                stats.steps > intervals && stats.steps <= intervals + alone,
                "{input} {method:?}: {} steps for {intervals} knot intervals, {alone} without knots",
                stats.steps
            );
            let switches = if input == "pwc" { n - 1 } else { 0 };
            assert_eq!(stats.switches, switches, "{input} {method:?}");
            // x(12) = (10 / N) sum u + 2 u[N-1] (pwc), the trapezoid rule (pwl); the knots move
            // with t1: dx/dt1 = mean(u) - u[N-1] (pwc) or the trapezoid mean less u[N-1].
            let sum: f64 = u.iter().sum();
            let (x, dt1) = if input == "pwc" {
                (10.0 * sum / n as f64 + 2.0 * u[n - 1], sum / n as f64 - u[n - 1])
            } else {
                let trap = sum - 0.5 * (u[0] + u[n - 1]);
                (10.0 * trap / (n - 1) as f64 + 2.0 * u[n - 1], trap / (n - 1) as f64 - u[n - 1])
            };
            close(r.state("x").expect("x"), x, 1e-11, &format!("{input} {method:?} x"));
            close(r.dstate("x", "t1").expect("dx/dt1"), dt1, 1e-10, &format!("{input} {method:?} dx/dt1"));
        }
    }
}

#[test]
fn a_ball_under_a_control_of_many_knots_takes_a_step_per_knot_and_what_it_needs_besides() {
    // The ball of the issue, `der(v) = -g + pwl(t, 0, 2.5, u)`: beside the knot intervals, the
    // steps are those the ball takes without the control (its bounces) and one per event. The
    // same ball with the control's constant value as a parameter is the reference.
    let ball = |force: &str, n: usize| {
        format!(
            "model ball\nparam g = 9.81\nparam e = 0.8 in [0, 1]\nparam h0 = 1\nparam c = 0.5\n\
             param u[{n}] = 0.5 in [-50, 50]\nstate y = h0\nstate v = 0\nder(y) = v\n\
             der(v) = -g + {force}\nevent touchdown when y <= 0 {{\n    v := -e * v\n}}\n\
             simulate t_end = 2.5, rtol = 1e-10, atol = 1e-12\n"
        )
    };
    let plain = run(&ball("c", 2), &[], &[], 2.5, Method::Dop853);
    for n in [100, 1000] {
        let r = run(&ball("pwl(t, 0, 2.5, u)", n), &[], &[], 2.5, Method::Dop853);
        assert_eq!(r.events().len(), plain.events().len());
        close(r.state("y").expect("y"), plain.state("y").expect("y"), 1e-9, "y");
        let stats = &r.result().stats;
        let (steps, events) = (plain.result().stats.steps, plain.events().len());
        assert!(
            stats.steps <= (n - 1) + steps + events,
            "{n} knots: {} steps, the ball alone {steps} with {events} events",
            stats.steps
        );
        assert!(stats.rejected <= plain.result().stats.rejected, "{n} knots: {stats:?}");
    }
}

#[test]
fn a_falling_window_meets_its_knots_from_above() {
    // pwc(t, 1, 0, u): the position 4 (1 - t) falls, knot k at t = 1 - k / 4, and at a knot
    // exactly the input still reads the segment above it. Over [0, 1] each value holds a
    // quarter: x(1) = sum(u) / 4; the window's ends move the knots by -(1 - k/4) and -k/4.
    let src = "model back\nparam u[4] = 0 in [-5, 5]\nparam t0 = 1\nparam t1 = 0\nstate x = 0\n\
               der(x) = pwc(t, t0, t1, u)\nsimulate rtol = 1e-10, atol = 1e-12\n";
    let u = [1.0, -2.0, 4.0, 0.5];
    for method in METHODS {
        let r = run(src, &["t0", "t1", "u[2]"], &[("u", &u)], 1.0, method);
        let stats = &r.result().stats;
        assert_eq!((stats.rejected, stats.switches), (0, 3), "{method:?}: {stats:?}");
        close(r.state("x").expect("x"), u.iter().sum::<f64>() / 4.0, 1e-12, "x(1)");
        close(r.dstate("x", "u[2]").expect("dx/du2"), 0.25, 1e-12, "dx/du[2]");
        // Knot k (between u[k-1] below and u[k] above) at t_k = t0 + k (t1 - t0) / 4: the state
        // gains (u[k] - u[k-1]) dt_k.
        let (mut dt0, mut dt1) = (0.0, 0.0);
        for k in 1..4 {
            let jump = u[k] - u[k - 1];
            dt0 += jump * (1.0 - k as f64 / 4.0);
            dt1 += jump * (k as f64 / 4.0);
        }
        close(r.dstate("x", "t0").expect("dx/dt0"), dt0, 1e-12, "dx/dt0");
        close(r.dstate("x", "t1").expect("dx/dt1"), dt1, 1e-12, "dx/dt1");
    }
}

/// A rate that jumps from `v[0]` to `v[1]` at the knot `t = 0.5` while `x` reaches `c`: the
/// event counts (`n := n + 1`) and `y` integrates the count.
const RATE_KNOT: &str = "model rate\nparam v[2] = 1 in [0.1, 10]\nparam c = 0.5\nstate x = 0\nstate n = 0\n\
                         state y = 0\nder(x) = pwc(t, 0, 1, v)\nder(n) = 0\nder(y) = n\n\
                         event hit when x >= c {\n    n := n + 1\n}\nsimulate rtol = 1e-10, atol = 1e-12\n";

#[test]
fn a_state_event_exactly_on_a_pwc_knot_has_no_time_derivative_under_every_stepper() {
    // With v = [1, 2] and c = 0.5 the crossing is at the knot. Before it, t_e = c / v0: dt/dc =
    // 1, dt/dv0 = -0.5; after it, t_e = 0.5 + (c - 0.5 v0) / v1: dt/dc = 0.5, dt/dv0 = -0.25.
    // Both sides have dt/dv1 = 0. y(1) = 1 - t_e follows the event's time; x does not.
    for method in METHODS {
        let r = run(RATE_KNOT, &["v[0]", "v[1]", "c"], &[("v", &[1.0, 2.0])], 1.0, method);
        assert_eq!(r.events().len(), 1, "{method:?}");
        close(r.events()[0].time, 0.5, 1e-12, "t_e");
        assert_eq!(r.devent_time(0, "c"), None, "{method:?}: dt/dc");
        assert_eq!(r.devent_time(0, "v[0]"), None, "{method:?}: dt/dv0");
        close(r.devent_time(0, "v[1]").expect("dt/dv1"), 0.0, 1e-12, "dt/dv1");
        assert_eq!(at_knot_warnings(&r), 1, "{method:?}: {:?}", r.warnings());
        assert!(
            !r.warnings().iter().any(|w| matches!(w, SimWarning::Grazing { .. })),
            "{method:?}: not a graze: {:?}",
            r.warnings()
        );
        // x(1) = 0.5 v0 + 0.5 v1 on both sides; y's derivatives follow t_e's.
        close(r.state("x").expect("x"), 1.5, 1e-12, "x");
        close(r.dstate("x", "v[0]").expect("dx/dv0"), 0.5, 1e-12, "dx/dv0");
        close(r.dstate("x", "c").expect("dx/dc"), 0.0, 1e-12, "dx/dc");
        close(r.state("y").expect("y"), 0.5, 1e-12, "y");
        assert_eq!(r.dstate("y", "c"), None, "{method:?}: dy/dc");
        assert_eq!(r.dstate("y", "v[0]"), None, "{method:?}: dy/dv0");
        close(r.dstate("y", "v[1]").expect("dy/dv1"), 0.0, 1e-12, "dy/dv1");
    }
}

#[test]
fn a_state_event_off_the_knot_keeps_its_time_derivative() {
    // c = 0.4: before the knot, t_e = 0.4; c = 0.7: after it, t_e = 0.6.
    for method in METHODS {
        let before =
            run(RATE_KNOT, &["v[0]", "v[1]", "c"], &[("v", &[1.0, 2.0]), ("c", &[0.4])], 1.0, method);
        close(before.events()[0].time, 0.4, 1e-12, "t_e");
        close(before.devent_time(0, "c").expect("dt/dc"), 1.0, 1e-10, "dt/dc");
        close(before.devent_time(0, "v[0]").expect("dt/dv0"), -0.4, 1e-10, "dt/dv0");
        close(before.dstate("y", "c").expect("dy/dc"), -1.0, 1e-10, "dy/dc");
        let after = run(RATE_KNOT, &["v[0]", "v[1]", "c"], &[("v", &[1.0, 2.0]), ("c", &[0.7])], 1.0, method);
        close(after.events()[0].time, 0.6, 1e-12, "t_e");
        close(after.devent_time(0, "c").expect("dt/dc"), 0.5, 1e-10, "dt/dc");
        close(after.devent_time(0, "v[0]").expect("dt/dv0"), -0.25, 1e-10, "dt/dv0");
        close(after.devent_time(0, "v[1]").expect("dt/dv1"), -0.05, 1e-10, "dt/dv1");
        close(after.dstate("y", "v[1]").expect("dy/dv1"), 0.05, 1e-10, "dy/dv1");
        for r in [&before, &after] {
            assert!(r.warnings().is_empty(), "{method:?}: {:?}", r.warnings());
        }
    }
}

/// A rate that jumps from `r[0]` to `r[1]` at the knot `t = 0.5`, and a time event at `T` that
/// scales the state by `v`.
const SCALE_AT: &str = "model scale\nparam r[2] = 1 in [0.1, 10]\nparam T = 0.5\nparam v = 1\nstate x = 0\n\
                        der(x) = pwc(t, 0, 1, r)\nevent at when t >= T {\n    x := v * x\n}\n\
                        simulate rtol = 1e-10, atol = 1e-12\n";

#[test]
fn a_time_event_on_a_fixed_pwc_knot_keeps_the_derivatives_that_exist() {
    // T = 0.5 on the knot, r = [1, 2]: x(1) = v (r0 T) + ... ; with the event before the knot
    // x(1) = v r0 T + r0 (0.5 - T) + 0.5 r1, after it v (0.5 r0 + r1 (T - 0.5)) + r1 (1 - T):
    // dx/dv = 0.5 r0 and dx/dr = (0.5 v, 0.5) on both sides; dx/dT is (v - 1) r0 before and
    // (v - 1) r1 after, equal (0) only for v = 1.
    for method in METHODS {
        let same = run(SCALE_AT, &["v", "T", "r[0]", "r[1]"], &[("r", &[1.0, 2.0])], 1.0, method);
        close(same.state("x").expect("x"), 1.5, 1e-12, "x");
        close(same.dstate("x", "v").expect("dx/dv"), 0.5, 1e-12, "dx/dv");
        close(same.dstate("x", "T").expect("dx/dT"), 0.0, 1e-12, "dx/dT");
        close(same.dstate("x", "r[0]").expect("dx/dr0"), 0.5, 1e-12, "dx/dr0");
        close(same.devent_time(0, "T").expect("dt/dT"), 1.0, 1e-12, "dt/dT");
        assert!(same.warnings().is_empty(), "{method:?}: {:?}", same.warnings());
        let scaled =
            run(SCALE_AT, &["v", "T", "r[0]", "r[1]"], &[("r", &[1.0, 2.0]), ("v", &[2.0])], 1.0, method);
        close(scaled.state("x").expect("x"), 2.0, 1e-12, "x");
        close(scaled.dstate("x", "v").expect("dx/dv"), 0.5, 1e-12, "dx/dv");
        close(scaled.dstate("x", "r[0]").expect("dx/dr0"), 1.0, 1e-12, "dx/dr0");
        assert_eq!(scaled.dstate("x", "T"), None, "{method:?}: dx/dT is 1 before, 2 after");
        close(scaled.devent_time(0, "T").expect("dt/dT"), 1.0, 1e-12, "dt/dT");
        assert_eq!(at_knot_warnings(&scaled), 1, "{method:?}: {:?}", scaled.warnings());
        // Off the knot: dx/dT = (v - 1) r0 at T = 0.3, (v - 1) r1 at T = 0.7.
        for (t_event, rate) in [(0.3, 1.0), (0.7, 2.0)] {
            let sets: [(&str, &[f64]); 3] = [("r", &[1.0, 2.0]), ("v", &[2.0]), ("T", &[t_event])];
            let off = run(SCALE_AT, &["v", "T"], &sets, 1.0, method);
            close(off.dstate("x", "T").expect("dx/dT"), rate, 1e-12, "dx/dT off the knot");
            assert!(off.warnings().is_empty(), "{method:?}: {:?}", off.warnings());
        }
    }
}

#[test]
fn a_short_pwl_window_with_gradients_on_its_ends_runs_down_to_a_width_of_1e_12() {
    // x' = pwl(t, a, b, u) with b - a = w: x(1) = u0 a + (u0 + u1) w / 2 + u1 (1 - b), so
    // dx/da = dx/db = (u0 - u1) / 2 and dx/du0 = a + w / 2. Inside the window the sensitivities
    // with respect to its ends change at (u1 - u0) / w^2 a unit of time, and the step across it
    // reads its stages at times rounded to spacings of t: each end's derivative is known to a
    // few spacings over w (16 allowed: 2e-3 at w = 1e-12), their sum (a shift of the window)
    // exactly.
    let src = "model short\nparam u[2] = 0 in [-5, 5]\nparam a = 0.5\nparam b = 0.6\nstate x = 0\n\
               der(x) = pwl(t, a, b, u)\n";
    let (u0, u1, a) = (1.0, 3.0, 0.5);
    for rtol in [1e-8, 1e-10] {
        for width in [1e-3, 1e-5, 1e-7, 1e-9, 1e-12] {
            let b = a + width;
            let w = b - a;
            for method in METHODS {
                let model = Model::parse(src).expect("checks");
                let compiled = model.compile(&["a", "b", "u[0]"]).expect("compiles");
                let params = model
                    .params()
                    .with_vector("u", &[u0, u1])
                    .and_then(|p| p.with("b", b))
                    .expect("in range");
                let opts =
                    SimOptions { t_end: 1.0, rtol, atol: 1e-2 * rtol, method, ..SimOptions::default() };
                let r = compiled.simulate(&params, &opts).expect("runs");
                let what = format!("{method:?} rtol {rtol:e} width {width:e}");
                assert_eq!(r.stopped_by(), &StopReason::TEnd, "{what}");
                let x = u0 * a + 0.5 * (u0 + u1) * w + u1 * (1.0 - b);
                close(r.state("x").expect("x"), x, 1e-12, &what);
                let tol = 1e-11 + 16.0 * (b.next_up() - b) / w;
                let (da, db) = (r.dstate("x", "a").expect("dx/da"), r.dstate("x", "b").expect("dx/db"));
                close(da, 0.5 * (u0 - u1), tol, &what);
                close(db, 0.5 * (u0 - u1), tol, &what);
                close(da + db, u0 - u1, 1e-12, &what);
                close(r.dstate("x", "u[0]").expect("dx/du0"), a + 0.5 * w, 1e-12, &what);
            }
        }
    }
}

#[test]
fn a_window_without_length_stops_the_run_naming_the_input() {
    let src = "model flat\nparam u[3] = 1\nparam t0 = 0.5\nstate x = 0\nder(x) = pwl(t, t0, t0, u)\n";
    let r = run(src, &[], &[], 1.0, Method::Dopri5);
    let StopReason::Fault { error } = r.stopped_by() else { panic!("{:?}", r.stopped_by()) };
    let text = error.to_string();
    assert!(text.contains("the knots of `pwl(t, .., u)` are not finite at t = 0"), "{text}");
    // The same input in a mode the run never enters costs nothing.
    let src =
        "model other\nparam u[3] = 1\nparam t0 = 0.5\nstate x = 0\ninitial mode a {\n    der(x) = 1\n}\n\
               mode b {\n    der(x) = pwl(t, t0, t0, u)\n}\n";
    let r = run(src, &[], &[], 1.0, Method::Dopri5);
    assert_eq!(r.stopped_by(), &StopReason::TEnd);
}

#[test]
fn a_stop_on_a_pwc_knot_keeps_its_time_derivative_and_loses_the_total_that_differs() {
    // x' = pwc(t, 0, 1, r), stopped at t = T. On the knot (T = 0.5) the final x moves with T at
    // r0 on one side and r1 on the other: no derivative; the stop's time derivative is 1 on both
    // sides, and x's with respect to r0 (0.5) does not depend on the order.
    let src =
        "model halt\nparam r[2] = 1 in [0.1, 10]\nparam T = 0.5\nstate x = 0\nder(x) = pwc(t, 0, 1, r)\n\
               event end when t >= T {\n    stop\n}\nsimulate rtol = 1e-10, atol = 1e-12\n";
    for method in METHODS {
        let on = run(src, &["T", "r[0]"], &[("r", &[1.0, 2.0])], 2.0, method);
        close(on.final_time(), 0.5, 1e-15, "stop time");
        close(on.devent_time(0, "T").expect("dt/dT"), 1.0, 1e-12, "dt/dT");
        assert_eq!(on.dstate_total("x", "T"), None, "{method:?}: r0 on one side, r1 on the other");
        close(on.dstate_total("x", "r[0]").expect("dx/dr0"), 0.5, 1e-12, "dx/dr0");
        assert_eq!(at_knot_warnings(&on), 1, "{method:?}: {:?}", on.warnings());
        for (t_stop, rate) in [(0.3, 1.0), (0.7, 2.0)] {
            let off = run(src, &["T", "r[0]"], &[("r", &[1.0, 2.0]), ("T", &[t_stop])], 2.0, method);
            close(off.dstate_total("x", "T").expect("dx/dT"), rate, 1e-12, "dx/dT off the knot");
            assert!(off.warnings().is_empty(), "{method:?}: {:?}", off.warnings());
        }
    }
}

/// The thread's floating-point control word with subnormals flushed to zero, as XLA runs its
/// threads (a `hybc.jax` call arrives that way).
#[cfg(target_arch = "x86_64")]
fn flush_subnormals_on_this_thread() {
    let mut csr: u32 = 0;
    // SAFETY: stores then loads MXCSR through a live local, setting its flush-to-zero (15) and
    // denormals-are-zero (6) bits; the thread ends right after the run that needs them.
    unsafe {
        std::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack));
        csr |= (1 << 15) | (1 << 6);
        std::arch::asm!("ldmxcsr [{}]", in(reg) &csr, options(nostack));
    }
    assert_eq!(std::hint::black_box(f64::MIN_POSITIVE) / std::hint::black_box(4.0), 0.0, "flushing");
}

/// The hang a JAX call found: a `pwl` knot at `t = 0` is searched from a spacing of `t` that
/// is `0` where subnormals flush, and the search never moved. A run holds IEEE arithmetic
/// whatever the caller's mode (src/sim/fp_mode.rs): the same bits as from an IEEE thread.
#[cfg(target_arch = "x86_64")]
#[test]
fn a_run_from_a_thread_that_flushes_subnormals_is_bit_for_bit_an_ieee_threads() {
    let src = "model ramp\nparam u[5] = 0\nparam c = 1\nstate x = 0\nder(x) = c * pwl(t, 0, 1, u)\n";
    let set: &[(&str, &[f64])] = &[("u", &[0.5, -1.0, 2.0, 3.0, -0.25]), ("c", &[2.0])];
    let bits = |r: &hybc::Run| {
        let f = &r.result().final_state;
        f.state.iter().chain(f.dstate.iter().flatten()).map(|v| v.to_bits()).collect::<Vec<_>>()
    };
    for method in METHODS {
        let ieee = run(src, &["u", "c"], set, 1.0, method);
        let flushed = std::thread::spawn(move || {
            flush_subnormals_on_this_thread();
            bits(&run(src, &["u", "c"], set, 1.0, method))
        })
        .join()
        .expect("the run ends");
        assert_eq!(flushed, bits(&ieee), "{method:?}");
        // x(1) = c * trapezoid(u), weights (1, 2, 2, 2, 1) / 8.
        close(ieee.result().final_state.state[0], 2.0625, 1e-12, "x(1)");
    }
}
