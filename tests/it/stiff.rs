//! Stiff models and the Rosenbrock steppers (issue #25): the compiled Jacobian kernels against
//! central differences of the flow kernels, stiff hybrid problems in closed form (values,
//! gradients and the dense output: with time events, each Rosenbrock method; with a state event
//! that cuts steps, every stepper), the soft ball and Robertson's
//! kinetics with their step counts and gradient checks.

use hybc::sim::{HybridSystem, Method, SimOptions, TrajectoryRequest};
use hybc::Model;

use crate::support::models::shipped_models;

/// Relative step of the central differences below: truncation `~h^2` and round-off `~eps/h`
/// balance near the cube root of eps.
const FD: f64 = 6e-6;
/// The kernels against central differences: `1e-7 max(|value|, scale)` (the differences' error
/// is about `1e-10` relative to the function's size, the margin is for curvature).
const KERNEL_TOL: f64 = 1e-7;

/// A nonlinear, time-dependent flow with parameters in every place the kernels read them.
const NONLINEAR: &str = "model nl
param a = 0.7
param b = -1.3
param c = 0.4
state x = 1.2
state y = -0.5
state w = 0.3
der(x) = a * x * y + sin(t) * y^2 + b * w
der(y) = -c * y^3 + x * exp(-a * t) + a * b * x
der(w) = sqrt(1 + x^2) * c - w * t * y + cos(b * w)
";

fn close(got: f64, want: f64, scale: f64) -> bool {
    (got - want).abs() <= KERNEL_TOL * want.abs().max(scale)
}

/// Checks `flow_jac` and `sens_dir` of every mode of `sys` at `(t, x, s)` against central
/// differences of `flow` and `flow_sens`.
fn check_kernels(tag: &str, sys: &dyn HybridSystem, p: &[f64], t: f64, x: &[f64], s: &[f64]) {
    let info = sys.info();
    let (n, m) = (info.n_states(), info.n_grad());
    sys.prepare_jacobians().unwrap_or_else(|e| panic!("{tag}: {e}"));
    for mode in 0..info.modes.len() {
        let (mut fx, mut ft, mut st) = (vec![0.0; n * n], vec![0.0; n], vec![0.0; n * m]);
        sys.flow_jac(mode, t, x, s, p, &mut fx, &mut ft, &mut st);
        let flow = |t: f64, x: &[f64]| {
            let mut f = vec![0.0; n];
            sys.flow(mode, t, x, p, &mut f);
            f
        };
        let sens = |t: f64, x: &[f64]| {
            let (mut f, mut ds) = (vec![0.0; n], vec![0.0; n * m]);
            sys.flow_sens(mode, t, x, s, p, &mut f, &mut ds);
            ds
        };
        let f0 = flow(t, x);
        let scale = f0.iter().fold(1.0f64, |a, b| a.max(b.abs()));
        for c in 0..n {
            let h = FD * x[c].abs().max(1.0);
            let (mut xp, mut xm) = (x.to_vec(), x.to_vec());
            xp[c] += h;
            xm[c] -= h;
            let (fp, fm) = (flow(t, &xp), flow(t, &xm));
            for i in 0..n {
                let want = (fp[i] - fm[i]) / (xp[c] - xm[c]);
                assert!(
                    close(fx[i * n + c], want, scale),
                    "{tag} mode {mode}: f_x[{i}][{c}] {} vs {want}",
                    fx[i * n + c]
                );
            }
        }
        let h = FD * t.abs().max(1.0);
        let (fp, fm) = (flow(t + h, x), flow(t - h, x));
        for i in 0..n {
            let want = (fp[i] - fm[i]) / ((t + h) - (t - h));
            assert!(close(ft[i], want, scale), "{tag} mode {mode}: f_t[{i}] {} vs {want}", ft[i]);
        }
        let (sp, sm) = (sens(t + h, x), sens(t - h, x));
        let s_scale = sens(t, x).iter().fold(1.0f64, |a, b| a.max(b.abs()));
        for k in 0..n * m {
            let want = (sp[k] - sm[k]) / ((t + h) - (t - h));
            assert!(close(st[k], want, s_scale), "{tag} mode {mode}: sens_t[{k}] {} vs {want}", st[k]);
        }
        // A direction with every component non-zero.
        let v: Vec<f64> =
            (0..n).map(|i| 0.3 + 0.17 * i as f64 * if i % 2 == 0 { 1.0 } else { -1.0 }).collect();
        let xv: Vec<f64> = x.iter().chain(&v).copied().collect();
        let mut dir = vec![0.0; n * m];
        sys.sens_dir(mode, t, &xv, s, p, &mut dir);
        let h = FD * x.iter().fold(1.0f64, |a, b| a.max(b.abs()));
        let xp: Vec<f64> = x.iter().zip(&v).map(|(x, v)| x + h * v).collect();
        let xm: Vec<f64> = x.iter().zip(&v).map(|(x, v)| x - h * v).collect();
        let (sp, sm) = (sens(t, &xp), sens(t, &xm));
        for k in 0..n * m {
            let want = (sp[k] - sm[k]) / (2.0 * h);
            assert!(close(dir[k], want, s_scale), "{tag} mode {mode}: sens_dir[{k}] {} vs {want}", dir[k]);
        }
    }
}

/// Sensitivities with every entry non-zero and distinct.
fn some_sens(n: usize, m: usize) -> Vec<f64> {
    (0..n * m).map(|k| 0.5 - 0.11 * k as f64 + 0.02 * (k * k) as f64).collect()
}

#[test]
fn stiff_kernels_match_central_differences_of_the_flow_kernels() {
    let model = Model::parse(NONLINEAR).expect("parses");
    let compiled = model.compile(&["a", "b", "c"]).expect("compiles");
    let sys = compiled.native();
    let p = compiled.params().values().to_vec();
    let x = [1.2, -0.5, 0.3];
    check_kernels("nonlinear", sys, &p, 0.8, &x, &some_sens(3, 3));
    for shipped in shipped_models() {
        let model = Model::parse(&shipped.source).expect("parses");
        let compiled = model.compile_all().expect("compiles");
        let sys = compiled.native();
        let info = sys.info();
        let p = compiled.params().values().to_vec();
        let mut x = vec![0.0; info.n_states()];
        sys.initial_state(&p, &mut x);
        // Away from zero, where kinks (`abs`, `max`) would spoil the differences.
        for v in &mut x {
            *v += 0.37;
        }
        check_kernels(&shipped.name, sys, &p, 0.61, &x, &some_sens(info.n_states(), info.n_grad()));
    }
}

/// `y1' = -y1`, `y2' = 999 y1 - 1000 y2`, and jumps of `(J, J)` at `t = k dt`, `k = 1..100`,
/// written as 100 time events. Between jumps `y1` decays as `e^-t` and `d = y2 - y1` as
/// `e^-1000t`; a jump leaves `d` unchanged. So, with `y1(0) = a`, `y2(0) = b`:
/// `y1(t) = a e^-t + J sum_{k dt <= t} e^-(t - k dt)`, `y2(t) = y1(t) + (b - a) e^-1000t`.
fn jumps_model() -> String {
    let mut text = String::from(
        "model jumps\nparam a = 1\nparam b = 3\nparam J = 1\nparam dt = 0.05\n\
         state y1 = a\nstate y2 = b\nder(y1) = -y1\nder(y2) = 999 * y1 - 1000 * y2\n",
    );
    for k in 1..=100 {
        text.push_str(&format!("event jump{k} when t >= {k} * dt {{\n  y1 := y1 + J\n  y2 := y2 + J\n}}\n"));
    }
    text
}

/// The closed form and its derivatives with respect to `(a, b, J, dt)` at `t` (`t` not a jump
/// time): `[y1, y2]` and `[[dy1/dp], [dy2/dp]]` per parameter.
fn jumps_exact(t: f64, (a, b, jump, dt): (f64, f64, f64, f64)) -> ([f64; 2], [[f64; 2]; 4]) {
    let (mut sum, mut dsum_ddt) = (0.0, 0.0);
    for k in 1..=100 {
        let tk = k as f64 * dt;
        if tk <= t {
            sum += (-(t - tk)).exp();
            dsum_ddt += k as f64 * (-(t - tk)).exp();
        }
    }
    let (e1, e1000) = ((-t).exp(), (-1000.0 * t).exp());
    let y1 = a * e1 + jump * sum;
    let y2 = y1 + (b - a) * e1000;
    let d = [[e1, e1 - e1000], [0.0, e1000], [sum, sum], [jump * dsum_ddt, jump * dsum_ddt]];
    ([y1, y2], d)
}

const JUMP_PARAMS: [&str; 4] = ["a", "b", "J", "dt"];

/// Values to `1e-8` relative and gradients to `1e-7` relative (floor `1e-10` for the
/// derivatives that are 0 or as small as `e^-1000t`), at rtol 1e-10: the global error of 100
/// segments, each started from a jump, stays within a few hundred local tolerances.
#[test]
fn stiff_jumps_match_their_closed_form_with_each_rosenbrock_method() {
    let model = Model::parse(&jumps_model()).expect("parses");
    let compiled = model.compile(&JUMP_PARAMS).expect("compiles");
    let t_end = 5.025;
    for method in [Method::Rodas5p, Method::Rodas4] {
        let opts = SimOptions { t_end, rtol: 1e-10, atol: 1e-12, method, ..SimOptions::default() };
        let run = compiled.simulate(&compiled.params(), &opts).expect("runs");
        assert!(run.is_complete(), "{method:?}: {:?}", run.stopped_by());
        assert_eq!(run.events().len(), 100, "{method:?}");
        let (y, d) = jumps_exact(t_end, (1.0, 3.0, 1.0, 0.05));
        for (i, name) in ["y1", "y2"].iter().enumerate() {
            let got = run.state(name).expect("state");
            assert!((got - y[i]).abs() <= 1e-8 * y[i].abs(), "{method:?} {name}: {got} vs {}", y[i]);
            for (j, param) in JUMP_PARAMS.iter().enumerate() {
                let got = run.dstate(name, param).expect("gradient");
                let want = d[j][i];
                assert!(
                    (got - want).abs() <= 1e-7 * want.abs() + 1e-10,
                    "{method:?} d{name}/d{param}: {got} vs {want}"
                );
            }
        }
        eprintln!("{method:?}: {} steps, {} rejected", run.result().stats.steps, run.result().stats.rejected);
    }
    // Where stability rather than accuracy limits the step (rtol 1e-6), the explicit pair needs
    // `h < 3.3e-3` (Dormand-Prince's stability interval on `-1000`) over the whole run; the
    // Rosenbrock methods take a few steps per segment.
    let steps = |method| {
        let opts = SimOptions { t_end, rtol: 1e-6, atol: 1e-8, method, ..SimOptions::default() };
        let run = compiled.simulate(&compiled.params(), &opts).expect("runs");
        assert!(run.is_complete());
        let stats = &run.result().stats;
        eprintln!("rtol 1e-6 {method:?}: {} steps, {} rejected", stats.steps, stats.rejected);
        stats.steps + stats.rejected
    };
    let (r5, r4, dp) = (steps(Method::Rodas5p), steps(Method::Rodas4), steps(Method::Dopri5));
    assert!(dp > 1500, "dopri5 {dp}");
    assert!(r5 <= 200 && r4 <= 200, "rodas5p {r5}, rodas4 {r4}");
}

/// The dense output, values and sensitivities, at every sample of a fine grid between the jumps
/// (the first steps after each jump included, where interpolants restarted from a reset are
/// built): within `1e-7` relative of the closed form (floor `1e-9`) at rtol 1e-10.
#[test]
fn stiff_jumps_dense_output_matches_the_closed_form_between_jumps() {
    let model = Model::parse(&jumps_model()).expect("parses");
    let compiled = model.compile(&JUMP_PARAMS).expect("compiles");
    for method in [Method::Rodas5p, Method::Rodas4] {
        let opts = SimOptions {
            t_end: 5.025,
            rtol: 1e-10,
            atol: 1e-12,
            method,
            trajectory: TrajectoryRequest::Every(0.0025),
            ..SimOptions::default()
        };
        let run = compiled.simulate(&compiled.params(), &opts).expect("runs");
        let rows = run.result().trajectory.as_ref().expect("trajectory");
        let mut checked = 0;
        for row in rows {
            // Samples on a jump time belong to either side: only those between jumps count.
            let phase = (row.t / 0.05).fract();
            if !(0.01..=0.99).contains(&phase) {
                continue;
            }
            let (y, d) = jumps_exact(row.t, (1.0, 3.0, 1.0, 0.05));
            for i in 0..2 {
                let tol = |want: f64| 1e-7 * want.abs() + 1e-9;
                assert!(
                    (row.x[i] - y[i]).abs() <= tol(y[i]),
                    "{method:?} t {}: y{} {} vs {}",
                    row.t,
                    i + 1,
                    row.x[i],
                    y[i]
                );
                for j in 0..4 {
                    let got = row.s[j * 2 + i];
                    assert!(
                        (got - d[j][i]).abs() <= tol(d[j][i]),
                        "{method:?} t {}: dy{}/d{} {got} vs {}",
                        row.t,
                        i + 1,
                        JUMP_PARAMS[j],
                        d[j][i]
                    );
                }
            }
            checked += 1;
        }
        assert!(checked > 1500, "{method:?}: {checked} samples checked");
    }
}

/// The same stiff pair with a *state* event, so that steps are cut by it (the jumps above are
/// time events, which the steps land on): `y1' = -y1`, `y2' = 999 y1 - 1000 y2`, and when `y1`
/// falls to 1/2 both jump by `J`. From `y1(0) = a`, `y2(0) = b`: the k-th event at
/// `t_k = ln(2a) + (k - 1) ln(1 + 2J)`, `y1 = (1/2 + J) e^-(t - t_k)` after it, and
/// `y2 = y1 + (b - a) e^-1000t` throughout (a jump leaves `y2 - y1` alone).
fn state_jump_model() -> &'static str {
    "model kicks\nparam a = 1\nparam b = 3\nparam J = 0.25\n\
     state y1 = a\nstate y2 = b\nder(y1) = -y1\nder(y2) = 999 * y1 - 1000 * y2\n\
     event kick when y1 <= 0.5 {\n  y1 := y1 + J\n  y2 := y2 + J\n}\n"
}

/// The closed form of `state_jump_model` at `t` (not an event time): `[y1, y2]`, their
/// derivatives `[[dy1/dp, dy2/dp]]` for `p = (a, b, J)`, and the event times before `t`.
fn state_jump_exact(t: f64, (a, b, jump): (f64, f64, f64)) -> ([f64; 2], [[f64; 2]; 3]) {
    let period = (1.0 + 2.0 * jump).ln();
    let t1 = (2.0 * a).ln();
    let e1000 = (-1000.0 * t).exp();
    let (y1, dy1) = if t < t1 {
        (a * (-t).exp(), [(-t).exp(), 0.0, 0.0])
    } else {
        let k = ((t - t1) / period).floor() + 1.0;
        let tk = t1 + (k - 1.0) * period;
        let y1 = (0.5 + jump) * (-(t - tk)).exp();
        (y1, [y1 / a, 0.0, (-(t - tk)).exp() + y1 * (k - 1.0) * 2.0 / (1.0 + 2.0 * jump)])
    };
    let y2 = y1 + (b - a) * e1000;
    ([y1, y2], [[dy1[0], dy1[0] - e1000], [0.0, e1000], [dy1[2], dy1[2]]])
}

/// Every stepper (both Rosenbrock methods, both explicit pairs and `auto`) against the closed
/// form of a stiff problem whose steps are cut by a state event: the event times and their
/// gradients (`1e-9`), the final state and gradients (`1e-8`, `1e-7`), and the dense output at
/// the midpoint of every step an event cut and of every first step after an event (values and
/// sensitivities, `1e-7` relative, floor `1e-9`), where interpolants are built on a step that
/// ends at an event or starts from a reset.
#[test]
fn a_stiff_state_event_matches_its_closed_form_and_interpolant_with_every_stepper() {
    let params = ["a", "b", "J"];
    let p = (1.0, 3.0, 0.25);
    let model = Model::parse(state_jump_model()).expect("parses");
    let compiled = model.compile(&params).expect("compiles");
    let t_end = 5.0;
    let period = (1.5f64).ln();
    let n_events = ((t_end - 2f64.ln()) / period).floor() as usize + 1;
    let tol = |want: f64, rel: f64, floor: f64| rel * want.abs() + floor;
    for method in [Method::Rodas5p, Method::Rodas4, Method::Dopri5, Method::Dop853, Method::Auto] {
        let base = SimOptions { t_end, rtol: 1e-10, atol: 1e-12, method, ..SimOptions::default() };
        let opts = SimOptions { trajectory: TrajectoryRequest::Steps, ..base.clone() };
        let run = compiled.simulate(&compiled.params(), &opts).expect("runs");
        assert!(run.is_complete(), "{method:?}: {:?}", run.stopped_by());
        assert_eq!(run.events().len(), n_events, "{method:?}");
        for (k, ev) in run.events().iter().enumerate() {
            let want = 2f64.ln() + k as f64 * period;
            assert!((ev.time - want).abs() <= 1e-9 * want, "{method:?} t_{k}: {} vs {want}", ev.time);
            let dt = ev.dtime.as_ref().expect("event-time gradients");
            let dwant = [1.0 / p.0, 0.0, k as f64 * 2.0 / (1.0 + 2.0 * p.2)];
            for j in 0..3 {
                assert!(
                    (dt[j] - dwant[j]).abs() <= tol(dwant[j], 1e-9, 1e-12),
                    "{method:?} dt_{k}/d{}",
                    params[j]
                );
            }
        }
        let (y, d) = state_jump_exact(t_end, p);
        for (i, name) in ["y1", "y2"].iter().enumerate() {
            let got = run.state(name).expect("state");
            assert!((got - y[i]).abs() <= tol(y[i], 1e-8, 0.0), "{method:?} {name}: {got} vs {}", y[i]);
            for (j, param) in params.iter().enumerate() {
                let got = run.dstate(name, param).expect("gradient");
                assert!(
                    (got - d[j][i]).abs() <= tol(d[j][i], 1e-7, 1e-10),
                    "{method:?} d{name}/d{param}: {got} vs {}",
                    d[j][i]
                );
            }
        }
        // The steps around each event, from the trajectory of step ends (both sides of each
        // event are rows at its time): the midpoints of the step the event cut and of the next.
        let rows = run.result().trajectory.as_ref().expect("trajectory");
        let times: Vec<f64> = rows.iter().map(|r| r.t).collect();
        let mut mids = Vec::new();
        for ev in run.events() {
            let before = times.iter().rev().find(|&&t| t < ev.time).copied().expect("a step before");
            let after = times.iter().find(|&&t| t > ev.time).copied().expect("a step after");
            mids.push(0.5 * (before + ev.time));
            mids.push(0.5 * (ev.time + after));
        }
        let sampled = SimOptions { at: mids.clone(), ..base };
        let run = compiled.simulate(&compiled.params(), &sampled).expect("runs");
        assert_eq!(run.result().samples.len(), mids.len());
        for s in run.result().samples.iter() {
            assert!(s.reached);
            let (y, d) = state_jump_exact(s.time, p);
            let ds = s.dstate.expect("sensitivities");
            for i in 0..2 {
                assert!(
                    (s.state[i] - y[i]).abs() <= tol(y[i], 1e-7, 1e-9),
                    "{method:?} t {}: y{} {} vs {}",
                    s.time,
                    i + 1,
                    s.state[i],
                    y[i]
                );
                for j in 0..3 {
                    assert!(
                        (ds[j * 2 + i] - d[j][i]).abs() <= tol(d[j][i], 1e-7, 1e-9),
                        "{method:?} t {}: dy{}/d{} {} vs {}",
                        s.time,
                        i + 1,
                        params[j],
                        ds[j * 2 + i],
                        d[j][i]
                    );
                }
            }
        }
    }
}

/// `models/soft_ball.hyb`: a ball on a penalty spring-damper of bandwidth `wc` instead of a
/// reset (spring `wc^2 max(0, -y)`, damper `2 zeta wc v` while `y < 0`, a flow switch), at rest
/// on the spring (`y = -g / wc^2`) well before `T = 10` (its own `t_end` is 0.6, in the flight
/// after the first bounce).
fn soft_ball() -> Model {
    let source =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/models/soft_ball.hyb")).expect("reads");
    Model::parse(&source).expect("parses")
}

/// The soft ball at its default `wc = 1e3` (a spring of 1e6) with gradients with respect to the
/// damping and the drop height:
/// an explicit pair stops at a million steps (issue #25); Rodas5P completes in a few thousand,
/// (987 attempts measured, 1200 asserted), its final state at rest on the spring, and its
/// gradients pass `hybc::gradcheck` at rtol
/// 1e-8 (the checker's default tolerance there, 1e-3, with its own rules for noise).
#[test]
fn the_soft_ball_at_a_stiffness_of_1e6_completes_with_rodas5p_and_its_gradients_check() {
    let model = soft_ball();
    let compiled = model.compile(&["zeta", "h0"]).expect("compiles");
    let opts =
        SimOptions { t_end: 10.0, rtol: 1e-8, atol: 1e-10, method: Method::Rodas5p, ..SimOptions::default() };
    let run = compiled.simulate(&compiled.params(), &opts).expect("runs");
    assert!(run.is_complete(), "{:?}", run.stopped_by());
    let stats = &run.result().stats;
    eprintln!(
        "soft ball rodas5p: {} steps, {} rejected, {} rhs calls",
        stats.steps, stats.rejected, stats.rhs_calls
    );
    assert!(stats.steps + stats.rejected <= 1200, "{} steps, {} rejected", stats.steps, stats.rejected);
    // At rest on the spring: y = -g / wc.
    let y = run.state("y").unwrap();
    assert!((y + 9.81e-6).abs() <= 1e-9, "y = {y}");
    crate::support::assert_gradients_check(&run, &opts);
}

/// The soft ball at a bandwidth of `wc = 1e6` (a spring of 1e12: contact eigenvalues of size
/// 1e6) with gradients, to `T = 10`: Rodas5P completes in a couple of thousand attempts (1,888
/// measured with every parameter differentiated, 2,500 asserted), at rest on the spring.
#[test]
fn the_soft_ball_at_a_bandwidth_of_1e6_completes_with_rodas5p_in_a_few_thousand_steps() {
    let model = soft_ball();
    let compiled = model.compile(&["g", "wc", "zeta", "h0"]).expect("compiles");
    let p = model.params().with("wc", 1e6).unwrap();
    let opts = SimOptions { t_end: 10.0, method: Method::Rodas5p, ..model.sim_options() };
    let run = compiled.simulate(&p, &opts).expect("runs");
    assert!(run.is_complete(), "{:?}", run.stopped_by());
    let stats = &run.result().stats;
    eprintln!("soft ball wc = 1e6 rodas5p: {} steps, {} rejected", stats.steps, stats.rejected);
    assert!(stats.steps + stats.rejected <= 2500, "{} steps, {} rejected", stats.steps, stats.rejected);
    let y = run.state("y").unwrap();
    assert!((y + 9.81e-12).abs() <= 1e-15, "y = {y}");
    // `auto` completes too: DOP853 through the bounces (each contact a transient of a few
    // microseconds, over before 15 stiffness tests in a row), Rodas5P from when the ball rests
    // on the spring: 5,376 steps and 1,482 rejections measured, 10,000 attempts asserted.
    let opts = SimOptions { method: Method::Auto, ..opts };
    let run = compiled.simulate(&p, &opts).expect("runs");
    assert!(run.is_complete(), "{:?}", run.stopped_by());
    let stats = &run.result().stats;
    assert!(stats.steps + stats.rejected <= 10_000, "{} steps, {} rejected", stats.steps, stats.rejected);
    assert_eq!(run.result().methods.last().unwrap().method, Method::Rodas5p, "{:?}", run.result().methods);
}

/// W4a from wc = 1e5 to 1e8: the ball settles through micro-bounces that graze the damper's
/// switch `if y < 0`, whose jump `2 zeta wc v` vanishes with the crossing speed `v`; the
/// derivatives exist (docs/language.md, rule 12) and were NaN before the rule knew it. With
/// Rodas5P every gradient is finite, no crossing is reported as grazing, the ball rests at
/// `y = -g / wc^2`, and the gradients pass `hybc::gradcheck` at rtol 1e-8.
#[test]
fn the_soft_ball_keeps_its_gradients_through_the_grazes_of_its_damper_up_to_1e8() {
    let model = soft_ball();
    let compiled = model.compile(&["zeta", "h0"]).expect("compiles");
    for wc in [1e5, 1e6, 1e7, 1e8] {
        let mut p = compiled.params();
        p.set("wc", wc).unwrap();
        let opts = SimOptions {
            t_end: 10.0,
            rtol: 1e-8,
            atol: 1e-10,
            method: Method::Rodas5p,
            ..SimOptions::default()
        };
        let run = compiled.simulate(&p, &opts).expect("runs");
        assert!(run.is_complete(), "wc = {wc}: {:?}", run.stopped_by());
        let result = run.result();
        let ds = result.final_state.dstate.as_ref().expect("gradients");
        assert!(ds.iter().all(|v| v.is_finite()), "wc = {wc}: {ds:?}");
        assert!(
            result.warnings.iter().all(|w| !matches!(w, hybc::sim::SimWarning::Grazing { .. })),
            "wc = {wc}: {:?}",
            result.warnings
        );
        let y = run.state("y").unwrap();
        assert!((y + 9.81 / (wc * wc)).abs() <= 1e-3 * 9.81 / (wc * wc), "wc = {wc}: y = {y}");
        let check = hybc::gradcheck::check(
            compiled.native(),
            p.values(),
            &opts,
            result,
            &hybc::gradcheck::CheckOptions::for_rtol(opts.rtol),
        )
        .expect("checks");
        assert!(check.passed(), "wc = {wc}: {check:#?}");
    }
}

/// The soft ball at wc = 1e5 under DOP853 (and `auto`, which runs it through the contacts):
/// after a flow switch located in a step of 2e-15, the search for the switch's far side read that
/// step's dense output 6e-5 past its end and the run went on from `y = 7.2e41`. It dissipates:
/// its energy may never exceed the drop's, and by t = 1.2 the ball is within its first metre.
#[test]
fn the_soft_ball_never_gains_energy_across_its_damper_switch_with_dop853() {
    let soft = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/models/soft_ball.hyb")).unwrap();
    let model = Model::parse(&soft).expect("parses");
    let compiled = model.compile(&["zeta", "h0"]).expect("compiles");
    let mut p = compiled.params();
    p.set("wc", 1e5).unwrap();
    for method in [Method::Dop853, Method::Auto] {
        let opts = SimOptions { t_end: 1.2, rtol: 1e-8, atol: 1e-10, method, ..SimOptions::default() };
        let run = compiled.simulate(&p, &opts).expect("runs");
        assert!(run.is_complete(), "{method:?}: {:?}", run.stopped_by());
        let (y, energy) = (run.state("y").unwrap(), run.output("energy").unwrap());
        assert!(y.abs() < 1.0 && energy <= 9.81 * 1.0 * (1.0 + 1e-8), "{method:?}: y {y}, energy {energy}");
    }
}

/// No stepper fails on the soft ball with "step size underflow": with gradients, at bandwidths
/// 1e3 and 1e6, each explicit pair either completes or stops at its step budget (20,000 here)
/// with that message; each Rosenbrock method completes.
#[test]
fn no_stepper_underflows_on_the_soft_ball() {
    let model = soft_ball();
    let compiled = model.compile(&["g", "wc", "zeta", "h0"]).expect("compiles");
    for wc in [1e3, 1e6] {
        let p = model.params().with("wc", wc).unwrap();
        for method in [Method::Dopri5, Method::Dop853, Method::Rodas5p, Method::Rodas4] {
            let opts = SimOptions { t_end: 10.0, method, max_steps: 20_000, ..model.sim_options() };
            let run = compiled.simulate(&p, &opts).expect("runs");
            let failure = run.report().failure().map(|m| m.to_string());
            if let Some(message) = &failure {
                assert!(!message.contains("underflow"), "{method:?} wc = {wc}: {message}");
                assert!(message.contains("more than 20000 steps"), "{method:?} wc = {wc}: {message}");
                assert!(!method.is_rosenbrock(), "{method:?} wc = {wc}: {message}");
            }
            // At wc = 1e6 the explicit pairs need about 200,000 steps: they stop.
            if wc == 1e6 && !method.is_rosenbrock() {
                assert!(failure.is_some(), "{method:?} completed at wc = 1e6");
            }
        }
    }
}

/// Robertson's kinetics (`k1 = 0.04`, `k2 = 3e7`, `k3 = 1e4`) to `t = 1e5`, with an event when
/// `y1` falls below 0.5 that doubles the rate `k1` (a state): Rodas5P takes a few hundred (496
/// attempts measured, 600 asserted)
/// steps where the explicit pairs take hundreds of thousands (issue #25), and the gradients
/// with respect to all three rates pass `hybc::gradcheck` at rtol 1e-8.
#[test]
fn robertsons_kinetics_to_1e5_with_an_event_complete_in_few_rodas5p_steps_and_check() {
    let text = "model robertson
param k1 = 0.04
param k2 = 3e7
param k3 = 1e4
state y1 = 1
state y2 = 0
state y3 = 0
state k = k1
der(y1) = -k * y1 + k3 * y2 * y3
der(y2) = k * y1 - k3 * y2 * y3 - k2 * y2 * y2
der(y3) = k2 * y2 * y2
der(k) = 0
event faster when y1 <= 0.5 {
    k := 2 * k
}
";
    let model = Model::parse(text).expect("parses");
    let compiled = model.compile(&["k1", "k2", "k3"]).expect("compiles");
    let opts =
        SimOptions { t_end: 1e5, rtol: 1e-8, atol: 1e-14, method: Method::Rodas5p, ..SimOptions::default() };
    let run = compiled.simulate(&compiled.params(), &opts).expect("runs");
    assert!(run.is_complete(), "{:?}", run.stopped_by());
    assert_eq!(run.events().len(), 1);
    let stats = &run.result().stats;
    eprintln!(
        "robertson rodas5p: {} steps, {} rejected, {} rhs calls",
        stats.steps, stats.rejected, stats.rhs_calls
    );
    assert!(stats.steps + stats.rejected <= 600, "{} steps, {} rejected", stats.steps, stats.rejected);
    // Mass is conserved (the flow's three rates sum to zero).
    let total: f64 = ["y1", "y2", "y3"].iter().map(|s| run.state(s).unwrap()).sum();
    assert!((total - 1.0).abs() <= 1e-9, "mass {total}");
    crate::support::assert_gradients_check(&run, &opts);
}

/// Every shipped model, every parameter differentiated, with each Rosenbrock method at the
/// model's own tolerances: the run completes as the explicit default's does and its derivatives
/// pass `hybc::gradcheck` (the checker's default tolerance for the model's rtol).
#[test]
fn every_shipped_model_checks_its_gradients_with_the_rosenbrock_methods() {
    let mut failed = Vec::new();
    for shipped in shipped_models() {
        let model = Model::parse(&shipped.source).expect("parses");
        let compiled = model.compile_all().expect("compiles");
        let p = compiled.params().values().to_vec();
        let explicit = compiled.simulate(&compiled.params(), &model.sim_options()).expect("runs");
        for method in [Method::Rodas5p, Method::Rodas4] {
            let opts = SimOptions { method, ..model.sim_options() };
            let run = compiled.simulate(&compiled.params(), &opts).expect("runs");
            let tag = format!("{} {method:?}", shipped.name);
            if run.stopped_by() != explicit.stopped_by() || run.events().len() != explicit.events().len() {
                failed.push(format!("{tag}: {:?} after {} events", run.stopped_by(), run.events().len()));
                continue;
            }
            let check = hybc::gradcheck::check(
                compiled.native(),
                &p,
                &opts,
                run.result(),
                &hybc::gradcheck::CheckOptions::for_rtol(opts.rtol),
            )
            .expect("checks");
            if !check.passed() {
                let worst: Vec<String> =
                    check.failures().map(|c| format!("{} {:e}", c.name, c.worst_discrepancy())).collect();
                failed.push(format!("{tag}: {worst:?}, events consistent {}", check.events.is_consistent()));
            }
        }
    }
    assert!(failed.is_empty(), "{failed:#?}");
}

/// A rate that jumps at `u = 1` from 1 to `k1` (an event on a clock), and, with `relax`, back
/// to 1 at `u = 3`: `x' = -k (x - cos t)`, stiff while `k = k1 = 1e6`.
fn jump_model(relax: bool) -> String {
    let back = if relax { "event relax when u >= 3 {\n    k := k0\n}\n" } else { "" };
    format!(
        "model jump\nparam k0 = 1\nparam k1 = 1e6\nstate x = 1\nstate u = 0\nstate k = k0\n\
         der(x) = -k * (x - cos(t))\nder(u) = 1\nder(k) = 0\nevent stiffen when u >= 1 {{\n    k := k1\n}}\n{back}"
    )
}

/// `--method auto` on `text` with gradients for `grad`: the run, after checking that its method
/// segments tile it (contiguous from the start to the final time) and add up to its step counts.
fn auto_run(text: &str, grad: &[&str], t_end: f64, rtol: f64) -> hybc::Run {
    let model = Model::parse(text).expect("parses");
    let compiled = model.compile(grad).expect("compiles");
    let opts = SimOptions { t_end, rtol, atol: rtol * 1e-2, method: Method::Auto, ..SimOptions::default() };
    let run = compiled.simulate(&compiled.params(), &opts).expect("runs");
    let r = run.result();
    let segs = &r.methods;
    assert_eq!(segs[0].from, opts.t_start);
    assert_eq!(segs.last().unwrap().to, r.final_state.time);
    for pair in segs.windows(2) {
        assert_eq!(pair[0].to, pair[1].from, "{segs:?}");
        assert_ne!(pair[0].method, pair[1].method, "{segs:?}");
    }
    assert_eq!(segs.iter().map(|s| s.steps).sum::<usize>(), r.stats.steps, "{segs:?}");
    assert_eq!(segs.iter().map(|s| s.rejected).sum::<usize>(), r.stats.rejected, "{segs:?}");
    run
}

/// `auto` on a rate that jumps from 1 to 1e6 at t = 1: Dormand-Prince up to the jump, Rodas5P
/// from within 1e-3 after it (15 positive stiffness tests in a row) to the end: 76 steps
/// measured (400 asserted) where Dormand-Prince forced takes 604,927 (its stability limit
/// `h < 3.3e-6` for 5 time units) and Rodas5P forced 38.
/// The `hybc run` summary names both stretches.
#[test]
fn auto_switches_to_rodas5p_when_a_rate_jumps_stiff() {
    let run = auto_run(&jump_model(false), &["k0", "k1"], 6.0, 1e-6);
    let segs = &run.result().methods;
    assert_eq!(segs.len(), 2, "{segs:?}");
    assert_eq!(segs[0].method, Method::Dopri5);
    assert_eq!(segs[1].method, Method::Rodas5p);
    assert!(segs[1].from > 1.0 && segs[1].from < 1.001, "{segs:?}");
    assert!(run.result().stats.steps < 400, "{:?}", run.result().stats);
    // At rest on the slow manifold x = cos t (to O(1/k1)).
    assert!((run.state("x").unwrap() - 6f64.cos()).abs() < 1e-5);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("jump.hyb");
    std::fs::write(&path, jump_model(false) + "simulate t_end = 6, rtol = 1e-6, atol = 1e-8\n").unwrap();
    let out = crate::support::cli::hybc(&["run", path.to_str().unwrap(), "--grad", "k1"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("methods: dopri5 from 0 to 1.000") && text.contains(", rodas5p from 1.000"),
        "{text}"
    );
    let out = crate::support::cli::hybc(&["run", path.to_str().unwrap(), "--format", "json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert_eq!(json["methods"][1]["method"], "rodas5p");
    assert_eq!(json["methods"][1]["to"], 6.0);
}

/// `auto` switches back: the rate relaxes to 1 at t = 3, and once Rodas5P's steps are inside the
/// explicit stability region (`h ||f_x|| <= 1.6`) for 15 steps in a row the run continues with
/// Dormand-Prince (three stretches).
#[test]
fn auto_switches_back_to_the_explicit_pair_when_the_rate_relaxes() {
    let run = auto_run(&jump_model(true), &["k0", "k1"], 10.0, 1e-6);
    let segs = &run.result().methods;
    let methods: Vec<Method> = segs.iter().map(|s| s.method).collect();
    assert_eq!(methods, [Method::Dopri5, Method::Rodas5p, Method::Dopri5], "{segs:?}");
    assert!(segs[2].from > 3.0, "{segs:?}");
}

/// No shipped model but the soft ball (stiff when at rest on its spring) switches under `auto`
/// at its own settings: one stretch, the explicit pair the tolerance picks.
#[test]
fn auto_never_switches_on_the_non_stiff_shipped_models() {
    for m in shipped_models() {
        // The two stiff ones: the soft ball at rest on its spring, the diffusion chain.
        if m.name == "soft_ball" || m.name == "chain" {
            continue;
        }
        let model = Model::parse(&m.source).expect("parses");
        let compiled = model.compile::<&str>(&[]).expect("compiles");
        let opts = model.sim_options();
        let run = compiled.simulate(&compiled.params(), &opts).expect("runs");
        let segs = &run.result().methods;
        assert_eq!(segs.len(), 1, "{}: {segs:?}", m.name);
        assert_eq!(segs[0].method, Method::Auto.resolve(opts.rtol), "{}", m.name);
    }
}

/// Gradients under `auto` pass `hybc::gradcheck` across both switches (the rate model at rtol
/// 1e-10: at 1e-8 the differences' noise, 3e-11, exceeds `dx/dk1 ~ 1e-14`), and on the soft
/// ball, which switches to Rodas5P once at rest on its spring.
#[test]
fn gradients_under_auto_check_across_the_switches() {
    let check = |text: &str, grad: &[&str], t_end: f64, rtol: f64, switches: usize| {
        let model = Model::parse(text).expect("parses");
        let compiled = model.compile(grad).expect("compiles");
        let run = auto_run(text, grad, t_end, rtol);
        assert_eq!(run.result().methods.len(), switches + 1, "{:?}", run.result().methods);
        let opts =
            SimOptions { t_end, rtol, atol: rtol * 1e-2, method: Method::Auto, ..SimOptions::default() };
        let p = compiled.params().values().to_vec();
        let options = hybc::gradcheck::CheckOptions::for_rtol(rtol);
        let check =
            hybc::gradcheck::check(compiled.native(), &p, &opts, run.result(), &options).expect("checks");
        assert!(check.passed(), "{check:#?}");
    };
    // Only k0: the final x depends on k1 = 1e6 through the stiff phase's lag `sin t / k1`,
    // damped after `relax`, so dx/dk1 is about 1e-14, below what a difference over k1's step
    // (10) resolves in a run at rtol 1e-10 (2e-12 apart between Rodas5P runs).
    check(&jump_model(true), &["k0"], 6.0, 1e-10, 2);
    let soft = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/models/soft_ball.hyb")).unwrap();
    check(&soft, &["zeta", "h0"], 10.0, 1e-8, 1);
}
