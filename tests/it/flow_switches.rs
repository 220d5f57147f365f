//! Flows that jump (`if` and `sign` of the time or the state): the switch is located like an event
//! and the sensitivities take the saltation jump `(f- - f+) dt/dp` there, so the gradients match
//! the closed forms; the kinks of `min`, `max` and `abs` are located and landed on the same way,
//! and nothing jumps there. Without it they are silently wrong: in `rising_state_switch` the reported
//! dx/dp would be 1 instead of 2. Values and gradients to relative 1e-8 at rtol 1e-10.

use crate::support::cli::hybc;
use approx::assert_relative_eq;
use hybc::codegen::{compile, CompileOptions};
use hybc::lower::{lower, system_info};
use hybc::sema::ParamIdx;
use hybc::sim::{run, SimOptions, SimResult};

const TOL: f64 = 1e-8;

/// Runs `src` to `t_end` with gradients for every parameter and the parameter values `p`.
fn simulate(src: &str, p: &[f64], t_end: f64) -> SimResult {
    let model = hybc::check_source(src).expect("model checks");
    let grad: Vec<ParamIdx> = (0..model.params.len() as u32).map(ParamIdx).collect();
    let compiled =
        compile(&lower(&model), system_info(&model, &grad), &CompileOptions::default()).expect("compiles");
    let opts = SimOptions { t_end, rtol: 1e-10, atol: 1e-12, ..SimOptions::default() };
    run(&compiled, p, &opts).expect("runs")
}

/// The final value of the only state and its gradient.
fn final_x(r: &SimResult) -> (f64, Vec<f64>) {
    let f = &r.final_state;
    (f.state[0], f.dstate.clone().expect("gradients"))
}

#[test]
fn rising_state_switch() {
    // x' = 1 until x = 1 at t* = 1 - p, then 2: x(T) = 2 T - 1 + 2 p, dx/dp = 2.
    let src = "model s\nparam p = 0.5\nstate x = p\nder(x) = if x < 1 then 1 else 2\n";
    for p in [0.3, 0.5, 0.8] {
        let r = simulate(src, &[p], 2.0);
        let (x, dx) = final_x(&r);
        assert_relative_eq!(x, 3.0 + 2.0 * p, max_relative = TOL);
        assert_relative_eq!(dx[0], 2.0, max_relative = TOL);
        assert!(r.events.is_empty(), "a flow switch is not an event: {:?}", r.events);
        assert_eq!(r.stats.switches, 1);
    }
}

#[test]
fn falling_state_switch_with_parameters_on_both_sides() {
    // x' = -a until x = 1 at t* = (p - 1) / a, then -b: x(T) = 1 - b (T - t*).
    let src = "model s\nparam p = 2\nparam a = 1\nparam b = 3\nstate x = p\n\
               der(x) = if x > 1 then -a else -b\n";
    let t_end = 2.0;
    for (p, a, b) in [(2.0, 1.0, 3.0), (1.5, 2.0, 0.5)] {
        let r = simulate(src, &[p, a, b], t_end);
        let (x, dx) = final_x(&r);
        let ts = (p - 1.0) / a;
        assert_relative_eq!(x, 1.0 - b * (t_end - ts), max_relative = TOL);
        assert_relative_eq!(dx[0], b / a, max_relative = TOL);
        assert_relative_eq!(dx[1], -b * (p - 1.0) / (a * a), max_relative = TOL);
        assert_relative_eq!(dx[2], -(t_end - ts), max_relative = TOL);
    }
}

#[test]
fn time_switch_through_sign() {
    // x' = k sign(t - tau): x(T) = x0 + k (T - 2 tau). On the switch itself sign is 0, neither
    // branch: the flow after it is read strictly past it.
    let src = "model s\nparam k = 1.5\nparam tau = 0.7\nparam x0 = 2\nstate x = x0\n\
               der(x) = k * sign(t - tau)\n";
    let (k, tau, x0, t_end) = (1.5, 0.7, 2.0, 1.2);
    let r = simulate(src, &[k, tau, x0], t_end);
    let (x, dx) = final_x(&r);
    assert_relative_eq!(x, x0 + k * (t_end - 2.0 * tau), max_relative = TOL);
    assert_relative_eq!(dx[0], t_end - 2.0 * tau, max_relative = TOL);
    assert_relative_eq!(dx[1], -2.0 * k, max_relative = TOL);
    assert_relative_eq!(dx[2], 1.0, max_relative = TOL);
}

#[test]
fn parameter_switches_and_kinks_that_never_move_are_not_switches() {
    // A condition on parameters alone never changes during a run, nor does a `min` of parameters;
    // a kink that moves but is never crossed (x stays below 2) is located on no step.
    let src = "model s\nparam p = 1\nstate x = 1\n\
               der(x) = min(p, 2) + abs(x - 2) * 0.1 + (if p > 0 then 1 else 2)\n";
    let r = simulate(src, &[1.0], 0.3);
    assert_eq!(r.stats.switches, 0);
    let out = hybc(&["check", "models/ball.hyb"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(!text.contains("flow switch") && !text.contains("kink"), "{text}");
}

#[test]
fn a_kink_is_crossed_where_nothing_jumps_and_its_gradients_are_the_closed_forms() {
    // x = e^(-a t), y' = max(x - c, 0): the kink at t* = ln(1/c) / a, after which y stays at
    // y = (1 - c) / a - c ln(1/c) / a, with dy/da = -y / a and dy/dc = -ln(1/c) / a (the kink
    // moves, but nothing jumps there: its time derivative is not needed). Integrated across
    // the kink, the sensitivities' flow jumps (d max / dc is -1, then 0) and a step that
    // straddles it was 2e-8 off.
    let src = "model s\nparam a = 1\nparam c = 0.3\nstate x = 1\nstate y = 0\n\
               der(x) = -a * x\nder(y) = max(x - c, 0)\n";
    for (a, c) in [(1.0, 0.3), (2.0, 0.7)] {
        let r = simulate(src, &[a, c], 3.0);
        let f = &r.final_state;
        let ds = f.dstate.clone().expect("gradients");
        let l = (1.0 / c).ln();
        let y = (1.0 - c) / a - c * l / a;
        assert_relative_eq!(f.state[1], y, max_relative = TOL);
        // `dstate` is parameter-major: [dx/da, dy/da, dx/dc, dy/dc].
        assert_relative_eq!(ds[1], -y / a, max_relative = TOL);
        assert_relative_eq!(ds[3], -l / a, max_relative = TOL);
        assert_eq!(r.stats.switches, 1);
        assert!(r.events.is_empty(), "a kink is not an event: {:?}", r.events);
    }
    let out = hybc(&["check", "models/engine_redline.hyb"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("kink 2 of mode fueled: at ramp * t - 0.1 = 0"), "{text}");
    assert!(!text.contains("flow switch"), "{text}");
}

#[test]
fn a_kink_met_tangentially_still_has_gradients() {
    // y' = max(c - (t - 1)^2, 0): with c > 0 the kink is crossed twice, y = 4 c^(3/2) / 3 and
    // dy/dc = 2 sqrt(c); with c = 0 it is touched at t = 1 (grazing), and y = 0 with
    // dy/dc = 0 (one-sided, both sides agree): a grazing kink voids nothing, where a
    // grazing switch whose flow jumps would.
    let src = "model s\nparam c = 0.01\nstate y = 0\nder(y) = max(c - (t - 1)^2, 0)\n";
    let r = simulate(src, &[0.01], 2.0);
    let (y, dy) = final_x(&r);
    assert_relative_eq!(y, 4.0 * 0.001 / 3.0, max_relative = TOL);
    assert_relative_eq!(dy[0], 0.2, max_relative = TOL);
    assert_eq!(r.stats.switches, 2);
    let r = simulate(src, &[0.0], 2.0);
    let (y, dy) = final_x(&r);
    assert!(y.abs() < 1e-12, "{y}");
    assert!(dy[0].abs() < 1e-8, "dy/dc = {} at a touch", dy[0]);
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
}

#[test]
fn the_adjoint_crosses_kinks_as_forward_mode_does() {
    // The kink models above with parameters in the model text, and the engine: the adjoint's
    // derivatives equal forward mode's with the same steps (`support::runs::check_adjoint`).
    let models = [
        "model s\nparam a = 2\nparam c = 0.7\nstate x = 1\nstate y = 0\n\
         der(x) = -a * x\nder(y) = max(x - c, 0)\nsimulate t_end = 3, rtol = 1e-10, atol = 1e-12\n",
        "model s\nparam c = 0.01\nstate y = 0\nder(y) = max(c - (t - 1)^2, 0)\n\
         simulate t_end = 2, rtol = 1e-10, atol = 1e-12\n",
        "model s\nparam c = 0\nstate y = 0\nder(y) = max(c - (t - 1)^2, 0)\n\
         simulate t_end = 2, rtol = 1e-10, atol = 1e-12\n",
        &std::fs::read_to_string("models/engine_redline.hyb").expect("the engine"),
        // A kink on an input knot (at t = 0.5, the middle knot): nothing to order there, so the
        // adjoint carries it (a switch whose flow jumps there is left to forward mode).
        "model s\nparam a = 1\nparam u[3] = 0\nstate y = 0\n\
         der(y) = a * max(pwl(t, 0, 1, u) + t - 0.5, 0)\nsimulate t_end = 2, rtol = 1e-10, atol = 1e-12\n",
    ];
    let (checked, carried) = crate::support::runs::with_adjoint_check(|| {
        for text in models {
            let model = hybc::Model::parse(text).unwrap_or_else(|e| panic!("{e}"));
            let names: Vec<String> = model.param_names().map(str::to_owned).collect();
            let grad: Vec<&str> = names.iter().map(String::as_str).collect();
            crate::support::runs::run(text, &grad, |_| {});
        }
    });
    assert_eq!((checked, carried), (5, 5));
}

#[test]
fn steps_land_on_a_kink_instead_of_creeping_up_to_it() {
    // The engine's throttle `min(max(ramp t - 0.1, 0), 1)`: the sensitivities' flow jumps at
    // t = 0.2, where the error control used to shrink the step 75 times in a row, down to 1e-12,
    // before passing it (`--grad all`); landed on, the run takes at most a couple of rejections.
    let out = hybc(&["run", "models/engine_redline.hyb", "--grad", "all", "--format", "json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    let rejected = json["stats"]["rejected"].as_u64().expect("a count");
    assert!(rejected <= 3, "{rejected} rejected steps");
    assert_eq!(json["stats"]["switches"], 1);
}

#[test]
fn check_lists_switches_apart_from_events_and_json_counts_them() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("s.hyb");
    std::fs::write(&path, "model s\nparam p = 0.5\nstate x = p\nder(x) = if x < 1 then 1 else 2\n")
        .expect("write model");
    let path = path.to_str().expect("utf-8");
    let out = hybc(&["check", path]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("0 events"), "{text}");
    assert!(text.contains("flow switch of mode main: at x - 1 = 0"), "{text}");
    let out = hybc(&["run", path, "--grad", "p", "--format", "json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert_eq!(json["stats"]["switches"], 1);
    assert_eq!(json["events"].as_array().map(Vec::len), Some(0));
    // A flow switch is not an event a fit can target.
    let out = hybc(&["fit", path, "--free", "p", "--target", "flow switch of mode main#1=0.5"]);
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn switch_at_the_instant_of_an_event_that_moved_the_state_voids_the_gradients() {
    // At t = 1 the declared event moves x, and the flow switches: the flow before the switch is
    // not known at the moved state, so no gradient is given rather than a guessed one.
    let src = "model s\nparam p = 1\nstate x = p\nder(x) = if t < 1 then 1 else 2\n\
               event kick when t >= 1 {\n    x := x + 1\n}\n";
    let r = simulate(src, &[1.0], 2.0);
    assert_eq!(r.events.len(), 1);
    assert_eq!(r.stats.switches, 1);
    assert!(r.final_state.dstate.is_none());
    let warning = r.warnings.first().map(ToString::to_string).unwrap_or_default();
    assert!(warning.contains("together with an event"), "{warning}");
    // The state itself is still right: x(2) = p + 1 + 1 + 2.
    assert_relative_eq!(r.final_state.state[0], 5.0, max_relative = TOL);
}

/// The dip model: a parabola `y = a (t - 1)^2 / 2 - c` that dips `c` below a floor whose damper,
/// `if y < 0 then k v`, switches on inside it. The flow's jump at the switch, `k v`, vanishes with
/// the crossing speed `v`; `PUSH` is the same floor with a force `k` switched on instead, a jump
/// that does not vanish.
pub(crate) const DIP: &str = "model dip\nparam a = 1\nparam c = 1e-11\nparam k = 5\n\
                              state y = 0.5 * a - c\nstate v = -a\nder(y) = v\n\
                              der(v) = a - (if y < 0 then k * v else 0)\n";
pub(crate) const PUSH: &str = "model push\nparam a = 1\nparam c = 1e-11\nparam k = 5\n\
                               state y = 0.5 * a - c\nstate v = -a\nder(y) = v\n\
                               der(v) = a - (if y < 0 then k else 0)\n";

/// `(t2 - 1)^2` for the dip model, `t2` the exit from the floor, exactly: the entry is at
/// `1 - r`, `r = sqrt(2 c / a)`, with `v = -a r`; inside, `v' = a - k v` gives
/// `y(s) = a s / k + (v_e - a / k) (1 - e^(-k s)) / k`, whose root `s* > 0` is found by Newton
/// (`expm1` keeps the small terms exact). Since `(v - v_free)' = -k v` integrates to `-k` times
/// the change of `y`, zero over the dip, `v` leaves the floor on the free parabola's velocity,
/// and `y(T) = a (1 - (t2 - 1)^2) / 2` at `T = 2`.
fn dip_exit_squared(p: &[f64]) -> f64 {
    let (a, c, k) = (p[0], p[1], p[2]);
    let r = (2.0 * c / a).sqrt();
    let ve = -a * r;
    let y = |s: f64| a * s / k - (ve - a / k) * (-k * s).exp_m1() / k;
    let dy = |s: f64| a / k + (ve - a / k) * (-k * s).exp();
    let mut s = 2.0 * r;
    for _ in 0..50 {
        let step = y(s) / dy(s);
        s -= step;
        if step.abs() <= 1e-15 * s {
            break;
        }
    }
    (s - r) * (s - r)
}

fn simulate_with(src: &str, p: &[f64], t_end: f64, method: hybc::sim::Method) -> SimResult {
    let model = hybc::check_source(src).expect("model checks");
    let grad: Vec<ParamIdx> = (0..model.params.len() as u32).map(ParamIdx).collect();
    let compiled =
        compile(&lower(&model), system_info(&model, &grad), &CompileOptions::default()).expect("compiles");
    let opts = SimOptions { t_end, rtol: 1e-10, atol: 1e-12, method, ..SimOptions::default() };
    run(&compiled, p, &opts).expect("runs")
}

#[test]
fn a_grazing_switch_whose_jump_vanishes_with_its_speed_keeps_its_gradients() {
    // c = 1e-11 against atol 1e-12: kappa = a atol / (2 c) = 0.05, a graze by the rule. The
    // derivative exists (the saltation's `(J / d)` tends to `k`); dy/dc differs from the free
    // parabola's -1 by 4.5e-5 through the dip, which the reported value must resolve.
    use hybc::sim::Method;
    let p = [1.0, 1e-11, 5.0];
    // Richardson-extrapolated central differences of the exact `(t2 - 1)^2`, at a step relative
    // to `c` (`support::reference::derivative` steps by 1e-4 absolute here: far too large).
    let h = 1e-3 * p[1];
    let q = |c: f64| dip_exit_squared(&[p[0], c, p[2]]);
    let central = |h: f64| (q(p[1] + h) - q(p[1] - h)) / (2.0 * h);
    let dq_exact = (4.0 * central(h / 2.0) - central(h)) / 3.0;
    let dy_dc = -0.5 * p[0] * dq_exact;
    assert!((dy_dc + 1.0).abs() > 4e-5, "the dip moves dy/dc off the free -1: {dy_dc}");
    for method in [Method::Rodas5p, Method::Rodas4, Method::Dopri5, Method::Dop853] {
        let r = simulate_with(DIP, &p, 2.0, method);
        let ds = r.final_state.dstate.clone().expect("gradients");
        assert_eq!(r.stats.switches, 2, "{method:?}: in and out of the floor");
        assert!(
            r.warnings.iter().all(|w| !matches!(w, hybc::sim::SimWarning::Grazing { .. })),
            "{method:?}: no grazing warning for a jump that vanishes: {:?}",
            r.warnings
        );
        // ds is column-major per parameter: [dy/da, dv/da, dy/dc, dv/dc, dy/dk, dv/dk].
        let y_exact = 0.5 * p[0] * (1.0 - q(p[1]));
        assert_relative_eq!(r.final_state.state[0], y_exact, max_relative = 1e-9);
        assert!((ds[2] - dy_dc).abs() < 2e-7, "{method:?}: dy/dc {} against {dy_dc}", ds[2]);
        assert!((ds[0] - 0.5).abs() < 1e-7, "{method:?}: dy/da {}", ds[0]);
        assert!(ds[4].abs() < 1e-9 && ds[5].abs() < 1e-9, "{method:?}: d/dk ~ k r^3: {ds:?}");
        assert!(
            (ds[1] - 1.0).abs() < 1e-7 && ds[3].abs() < 1e-7,
            "{method:?}: v leaves on the free parabola: {ds:?}"
        );
    }
}

#[test]
fn a_grazing_switch_whose_jump_stays_finite_has_no_gradient() {
    // The same graze with a force switched on at contact: J = k at zero speed, so J / d has no
    // limit and dt/dc ~ 1 / sqrt(c) reaches the state: no derivative w.r.t. a or c; k acts only
    // after the graze and keeps its derivative.
    use hybc::sim::Method;
    for method in [Method::Rodas5p, Method::Dopri5, Method::Dop853] {
        let r = simulate_with(PUSH, &[1.0, 1e-11, 5.0], 2.0, method);
        let ds = r.final_state.dstate.clone().expect("gradients");
        assert!(
            r.warnings.iter().any(|w| matches!(w, hybc::sim::SimWarning::Grazing { .. })),
            "{method:?}: {:?}",
            r.warnings
        );
        assert!(ds[0].is_nan() && ds[2].is_nan(), "{method:?}: {ds:?}");
        assert!(ds[4].is_finite(), "{method:?}: {ds:?}");
    }
}
