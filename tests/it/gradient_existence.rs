//! Gradients are reported exactly when they exist (docs/design.md: grazing from conditioning;
//! derivatives that do not exist). Each test against a closed form or an exact pattern of
//! existing and missing derivatives.

use approx::assert_relative_eq;
use hybc::sim::SimWarning;
use hybc::{Model, Run, SimOptions};

use super::support::cli::hybc;
use super::support::reference::BallForm;

fn run_at(text: &str, grad: &[&str], set: &[(&str, f64)], opts: impl FnOnce(&mut SimOptions)) -> Run {
    let model = Model::parse(text).unwrap_or_else(|e| panic!("{e}"));
    let compiled = model.compile(grad).expect("compiles");
    let mut params = model.params();
    for &(name, value) in set {
        params.set(name, value).expect("a valid value");
    }
    let mut o = model.sim_options();
    opts(&mut o);
    compiled.simulate(&params, &o).expect("valid options")
}

const BALL_REST: &str = include_str!("../data/run/ball_rest.hyb");

/// E(T) and dE/de of the ball with the rest rule at T = 2.5, from the bounce sequence: bounce k
/// arrives at e^(k-1) v1 and leaves at e^k v1 while e times the arrival speed is at least
/// v_rest; then it settles (E = 0 and dE/de = 0 from then on). In flight after k bounces
/// E = g h0 e^(2k), dE/de = 2 k g h0 e^(2k - 1).
fn ball_rest_closed_form(e: f64) -> (f64, f64) {
    let (ball, v_rest, t_end) = (BallForm { e, ..BallForm::DEFAULT }, 1e-3, 2.5);
    let mut k = 0;
    while ball.touchdown(k + 1) <= t_end {
        let arrival = e.powi(k) * ball.v1();
        if e * arrival < v_rest {
            return (0.0, 0.0);
        }
        k += 1;
    }
    (ball.energy(k), ball.energy_grad(k)[1])
}

fn assert_energy(e: f64, energy: f64, denergy: f64) {
    let (want, dwant) = ball_rest_closed_form(e);
    if want == 0.0 {
        assert_eq!((energy, denergy), (0.0, 0.0), "e = {e}: settled");
    } else {
        assert_relative_eq!(energy, want, max_relative = 1e-8);
        assert_relative_eq!(denergy, dwant, max_relative = 1e-8);
    }
}

#[test]
fn the_ball_with_a_rest_rule_has_its_gradient_at_every_restitution() {
    let model = Model::parse(BALL_REST).expect("parses");
    let compiled = model.compile(&["e"]).expect("compiles");
    let mut sim = compiled.simulator(&model.sim_options()).expect("valid options");
    let mut settled = 0;
    for i in 0..1000 {
        let e = 0.65 + 0.25 * i as f64 / 999.0;
        let r = sim.run(&model.params().with("e", e).expect("in range")).expect("runs");
        assert!(r.is_complete(), "e = {e}: {:?}", r.stopped_by());
        let (energy, denergy) = (r.output("energy").unwrap(), r.doutput("energy", "e"));
        let denergy = denergy.unwrap_or_else(|| panic!("e = {e}: no dE/de; {:?}", r.warnings()));
        assert_energy(e, energy, denergy);
        settled += usize::from(energy == 0.0);
    }
    // Both regimes are covered: balls that settle before T and balls still bouncing at T.
    assert!(settled > 100 && settled < 900, "{settled} settled");
}

#[test]
fn the_ball_with_a_rest_rule_has_its_gradient_at_every_restitution_through_hybc_sweep() {
    let out = hybc(&["sweep", "tests/data/run/ball_rest.hyb", "--vary", "e=0.65:0.9:1000", "--grad", "e"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).expect("UTF-8");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    let col =
        |name: &str| header.iter().position(|h| *h == name).unwrap_or_else(|| panic!("no column {name}"));
    let (ce, cen, cd) = (col("e"), col("energy"), col("denergy/de"));
    let mut rows = 0;
    for line in lines {
        let cells: Vec<&str> = line.split(',').collect();
        let num = |c: usize| cells[c].parse::<f64>().unwrap_or_else(|_| panic!("`{}` in {line}", cells[c]));
        assert_energy(num(ce), num(cen), num(cd));
        rows += 1;
    }
    assert_eq!(rows, 1000);
}

const BALL: &str = "model ball\nparam g = 9.81\nparam e = 0.8\nparam h0 = 1\nstate y = h0\nstate v = 0\n\
                    der(y) = v\nder(v) = -g\nevent touchdown when y <= 0 {\n    v := -e * v\n}\n\
                    output energy = 0.5 * v^2 + g * y\nsimulate t_end = 2.5, rtol = 1e-10, atol = 1e-12\n";

#[test]
fn an_unrelated_fast_state_changes_no_gradient() {
    // A clock in microseconds beside the ball: the touchdowns are as clean as without it.
    let with_clock = BALL.replace("der(y) = v\n", "der(y) = v\nstate us = 0\nder(us) = 1e6\n");
    let (a, b) = (run_at(BALL, &["e", "h0"], &[], |_| {}), run_at(&with_clock, &["e", "h0"], &[], |_| {}));
    assert_eq!(a.events().len(), 4);
    assert_eq!(b.events().len(), 4);
    assert!(b.warnings().is_empty(), "{:?}", b.warnings());
    for k in 0..4 {
        for p in ["e", "h0"] {
            let (da, db) = (a.devent_time(k, p).unwrap(), b.devent_time(k, p).unwrap());
            assert_relative_eq!(da, db, max_relative = 1e-9, epsilon = 1e-14);
        }
    }
    for p in ["e", "h0"] {
        assert_relative_eq!(
            a.doutput("energy", p).unwrap(),
            b.doutput("energy", p).unwrap(),
            max_relative = 1e-9
        );
    }
}

/// A ball thrown up at v0 = 4 towards a ceiling `overshoot` below its apex v0^2 / (2 g).
fn ceiling_run(overshoot: f64) -> Run {
    let text = "model ceiling\nparam g = 9.81\nparam v0 = 4\nparam H = 0\nstate y = 0\nstate v = v0\n\
                der(y) = v\nder(v) = -g\nevent ceiling when y >= H {\n    v := -0.5 * v\n}\n\
                simulate t_end = 0.6, rtol = 1e-10, atol = 1e-12\n";
    let apex = 16.0 / (2.0 * 9.81);
    run_at(text, &["v0", "H"], &[("H", apex - overshoot)], |_| {})
}

#[test]
fn a_ceiling_overshot_by_a_nanometre_is_flagged_and_by_a_centimetre_is_clean() {
    let close = ceiling_run(1e-9);
    let ev = &close.events()[0];
    let flagged = ev.grazing || ev.margin.is_some();
    assert!(flagged, "{ev:?}");
    assert!(close
        .warnings()
        .iter()
        .any(|w| matches!(w, SimWarning::Grazing { .. } | SimWarning::NearGrazing { .. })));
    let clean = ceiling_run(1e-2);
    let ev = &clean.events()[0];
    assert!(!ev.grazing && ev.margin.is_none(), "{ev:?}");
    assert!(clean.warnings().is_empty(), "{:?}", clean.warnings());
    // t_c solves v0 t - g t^2 / 2 = H: dt/dH = 1 / (v0 - g t_c).
    let speed = 4.0 - 9.81 * ev.time;
    assert_relative_eq!(clean.devent_time(0, "H").unwrap(), 1.0 / speed, max_relative = 1e-9);
}

#[test]
fn quadratic_drag_from_rest_has_its_gradient() {
    // F = -c |v| v is C1; its Jacobian is 0/0 at rest, where the sensitivities are still zero.
    // Falling from rest: vy = -sqrt(g/c) tanh(sqrt(g c) t).
    let text = "model drag\nparam g = 9.81\nparam c = 0.1\nstate vx = 0\nstate vy = 0\n\
                der(vx) = -c * hypot(vx, vy) * vx\nder(vy) = -g - c * hypot(vx, vy) * vy\n";
    let r = run_at(text, &["c"], &[], |o| {
        o.t_end = 1.0;
        o.rtol = 1e-10;
        o.atol = 1e-12;
    });
    assert!(r.is_complete() && r.warnings().is_empty(), "{:?} {:?}", r.stopped_by(), r.warnings());
    let (g, c, t) = (9.81f64, 0.1f64, 1.0f64);
    let (v_inf, k) = ((g / c).sqrt(), (g * c).sqrt());
    assert_relative_eq!(r.state("vy").unwrap(), -v_inf * (k * t).tanh(), max_relative = 1e-9);
    let sech2 = 1.0 / (k * t).cosh().powi(2);
    let dvy_dc = v_inf * (k * t).tanh() / (2.0 * c) - v_inf * t * k * sech2 / (2.0 * c);
    assert_relative_eq!(r.dstate("vy", "c").unwrap(), dvy_dc, max_relative = 1e-7);
    assert_eq!(r.dstate("vx", "c"), Some(0.0));
}

#[test]
fn a_flow_not_differentiable_at_the_state_says_so_and_keeps_its_values() {
    // x' = sqrt(|x|) from x0 = p = 0: the flow's derivative is infinite at x = 0, where both x = 0
    // and x = t^2 / 4 solve the equation; dx/dp does not exist. The run goes on (x stays 0).
    let text = "model root\nparam p = 0\nstate x = p\nstate y = 1\nder(x) = sqrt(abs(x))\nder(y) = p * y\n";
    let r = run_at(text, &["p"], &[], |o| o.t_end = 1.0);
    assert!(r.is_complete(), "{:?}", r.stopped_by());
    assert_eq!(r.state("x"), Some(0.0));
    assert_eq!(r.dstate("x", "p"), None);
    // y = exp(p t) does not read x: its derivative exists, dy/dp = t exp(p t) = 1 at t = 1.
    assert_relative_eq!(r.dstate("y", "p").unwrap(), 1.0, max_relative = 1e-8);
    let warning = r.warnings().iter().find(|w| matches!(w, SimWarning::NotDifferentiable { .. }));
    let text = warning.expect("a warning").to_string();
    // sign(x) / (2 sqrt(|x|)) is 0/0 at x = 0: indeterminate, withheld (its limit is infinite,
    // which hybc does not try to tell).
    assert!(
        text.contains("dx/dp is withheld from t = 0 on: the flow's derivative is indeterminate"),
        "{text}"
    );
}

// ---- issue #38, item 1: a removable singularity is compiled as its limit ----

/// `y(1) = 1 / (p + 1)` with `x = t` from 0: `dy/dp = -1 / (p + 1)^2`, whose integrand
/// `x^p ln x` tends to 0 at x = 0 for p > 0.
const POWER_FROM_ZERO: &str =
    "model power\nparam p = 1.5\nstate x = 0\nstate y = 0\nder(x) = 1\nder(y) = x^p\nsimulate t_end = 1\n";

#[test]
fn a_power_from_zero_has_its_exponent_derivative_under_every_method() {
    // `x^p` and `pow(x, p)` (y = 1 / (p + 1)), `x^(p + 1)` (y = 1 / (p + 2)); p = 1.5 (the
    // issue's case), 0.5 (x^p ln x still tends to 0, though x^p itself has an infinite slope
    // there), 1 (f_xp = 1 + ln x is -inf at x = 0: the Rosenbrock methods' second-order term,
    // not the derivative's) and 2.5.
    for (flow, shift) in [("x^p", 1.0), ("pow(x, p)", 1.0), ("x^(p + 1)", 2.0)] {
        let text = POWER_FROM_ZERO.replace("x^p\n", &format!("{flow}\n"));
        for p in [1.5, 0.5, 1.0, 2.5] {
            for method in hybc::sim::Method::ALL {
                // The Rosenbrock methods need the flow's Jacobian p x^(p-1), infinite at x = 0
                // for p < 1: forced, they stop there with that said; `auto` starts explicit.
                if method.is_rosenbrock() && p + shift < 2.0 {
                    continue;
                }
                let r = run_at(&text, &["p"], &[("p", p)], |o| o.method = method);
                let what = format!("{flow}, p = {p}, {}", method.name());
                assert!(
                    r.is_complete() && r.warnings().is_empty(),
                    "{what}: {:?} {:?}",
                    r.stopped_by(),
                    r.warnings()
                );
                assert_relative_eq!(r.state("y").unwrap(), 1.0 / (p + shift), max_relative = 1e-7);
                let dy = r.dstate("y", "p").unwrap_or_else(|| panic!("{what}: dy/dp withheld"));
                assert_relative_eq!(dy, -1.0 / (p + shift).powi(2), max_relative = 1e-7);
                assert_eq!(r.dstate("x", "p"), Some(0.0), "{what}");
            }
        }
    }
    // Forced Rosenbrock on x^0.5 from 0: the Jacobian is infinite at the start; the fault says
    // so in its own words, not "non-finite state".
    let r = run_at(POWER_FROM_ZERO, &["p"], &[("p", 0.5)], |o| o.method = hybc::sim::Method::Rodas5p);
    let hybc::sim::StopReason::Fault { error } = r.stopped_by() else { panic!("{:?}", r.stopped_by()) };
    let stop = error.to_string();
    assert!(
        stop.contains("every step attempted from a finite state gave values that are not finite"),
        "{stop}"
    );
}

#[test]
fn a_power_whose_limit_is_infinite_still_has_no_derivative() {
    // p = 0: the integrand of dy/dp is ln x, -inf at x = 0: not a removable singularity, and the
    // run says dy/dp does not exist there (the value y = t exists).
    let r = run_at(POWER_FROM_ZERO, &["p"], &[("p", 0.0)], |_| {});
    assert!(r.is_complete());
    assert_relative_eq!(r.state("y").unwrap(), 1.0, max_relative = 1e-9);
    assert_eq!(r.dstate("y", "p"), None);
    let said = r.warnings().iter().map(|w| w.to_string()).collect::<Vec<_>>().join("; ");
    assert!(said.contains("dy/dp does not exist from t = 0 on: the flow's derivative is infinite"), "{said}");
    // p < 0: x^p itself is infinite at x = 0, and the run stops with the state named.
    let r = run_at(POWER_FROM_ZERO, &["p"], &[("p", -0.5)], |_| {});
    assert!(!r.is_complete());
    let stop = format!("{:?}", r.stopped_by());
    assert!(stop.contains("Fault"), "{stop}");
}

#[test]
fn pow_log_holds_its_limits_and_its_derivatives_are_exact() {
    use hybc::expr::eval::pow_log;
    // x^b ln x at x = 0: 0 for b > 0, -inf for b <= 0; elsewhere the product.
    assert_eq!(pow_log(0.0, 1.5), 0.0);
    assert_eq!(pow_log(-0.0, 0.5), 0.0);
    assert_eq!(pow_log(0.0, 0.0), f64::NEG_INFINITY);
    assert_eq!(pow_log(0.0, -1.0), f64::NEG_INFINITY);
    assert!(pow_log(0.0, f64::NAN).is_nan());
    assert!(pow_log(-2.0, 2.0).is_nan());
    assert_relative_eq!(pow_log(2.0, 1.5), 2f64.powf(1.5) * 2f64.ln(), max_relative = 1e-15);
    // `hybc derive` prints the exponent's derivative with it.
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("power.hyb");
    std::fs::write(&path, POWER_FROM_ZERO).expect("written");
    let out = hybc(&["derive", path.to_str().unwrap(), "--wrt", "p"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("f_p = [0, pow_log(x, p)]"), "{text}");
}

#[test]
fn an_indeterminate_flow_derivative_is_withheld_not_said_not_to_exist() {
    // d/dp sqrt(p x) = x / (2 sqrt(p x)) is 0/0 at x = 0; its limit (0) and dy/dp = 1 / (3 sqrt p)
    // exist, but hybc takes no limits of quotients: it withholds dy/dp and says why, without
    // saying it does not exist. The value is right.
    let text = "model sq\nparam p = 1\nstate x = 0\nstate y = 0\nder(x) = 1\nder(y) = sqrt(p * x)\n\
                simulate t_end = 1\n";
    let r = run_at(text, &["p"], &[], |_| {});
    assert!(r.is_complete());
    assert_relative_eq!(r.state("y").unwrap(), 2.0 / 3.0, max_relative = 1e-7);
    assert_eq!(r.dstate("y", "p"), None);
    assert_eq!(r.dstate("x", "p"), Some(0.0));
    let said = r.warnings().iter().map(|w| w.to_string()).collect::<Vec<_>>().join("; ");
    assert!(said.contains("dy/dp is withheld from t = 0 on"), "{said}");
    assert!(said.contains("it may have a finite limit") && !said.contains("does not exist"), "{said}");
}

#[test]
fn a_near_grazing_margin_is_the_extremums_distance_and_a_graze_has_no_gradient() {
    // The three verdicts of a crossing near its guard's extremum (ARCHITECTURE.md, Grazing), each
    // at its closed form: the guard y - H peaks at apex - H (= the overshoot) when v = 0.
    // Near-grazing (at rtol 1e-10, kappa = g delta / d^2 between 1e-4 and 1e-2 for overshoots
    // from about 4e-7 down to 4e-9): the gradient is kept, and the margin is that distance (to
    // the accuracy of the curvature estimate from the step's data).
    for overshoot in [1e-7, 3e-8] {
        let r = ceiling_run(overshoot);
        let ev = &r.events()[0];
        assert!(!ev.grazing, "{overshoot}: {ev:?}");
        let margin = ev.margin.unwrap_or_else(|| panic!("{overshoot}: no margin: {ev:?}"));
        assert_relative_eq!(margin, overshoot, max_relative = 1e-3);
        let warned = r.warnings().iter().any(|w| matches!(w, SimWarning::NearGrazing { .. }));
        assert!(warned, "{:?}", r.warnings());
        // The kept gradient is exact: t_c solves v0 t - g t^2 / 2 = H, dt/dH = 1 / (v0 - g t_c).
        assert_relative_eq!(
            r.devent_time(0, "H").unwrap(),
            1.0 / (4.0 - 9.81 * ev.time),
            max_relative = 1e-6
        );
    }
    // Grazing: a nanometre below the apex, the crossing is not resolved by the tolerances, and
    // no time gradient is given (nor any later derivative).
    let r = ceiling_run(1e-9);
    let ev = &r.events()[0];
    assert!(ev.grazing, "{ev:?}");
    assert_eq!(r.devent_time(0, "H"), None);
    assert_eq!(r.dstate("y", "H"), None);
    assert!(r.warnings().iter().any(|w| matches!(w, SimWarning::Grazing { .. })));
}
