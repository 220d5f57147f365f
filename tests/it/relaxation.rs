//! Sensitivities through a relaxation oscillation's fast jump (issue #37 item 1.5), and the rule
//! behind them: a sensitivity's error is held to its own size `rtol |s|` only up to
//! `K (atol + rtol |x|) / |p|` (`errnorm::Scales`, K = 1e3), so that a derivative that grows by
//! orders of magnitude inside a jump and shrinks back is not integrated with the peak's
//! tolerance. Both sides: Van der Pol at `mu = 1e3` across one jump under each stiff stepper,
//! against central differences, and the same derivative through a parameter at 0 (which has no
//! scale, so no cap: the error the rule removes); models whose relative sensitivities stay
//! below K take the same steps, with the same derivatives, whether their parameter is at a value
//! or at 0.

use hybc::sim::{Method, SimOptions};
use hybc::Model;

/// Van der Pol at `mu = 1e3` from `x = 2 + d` (so `x0` and `d` are the same derivative), an
/// event inside the jump: one fast jump near `t = 807`, then the slow branch to `t = 1000`.
const VDP: &str = "model vdp
param mu = 1000
param x0 = 2
param d = 0
state x = x0 + d
state y = 0
der(x) = y
der(y) = mu * (1 - x^2) * y - x
event cross when x crosses 0
";

fn opts(method: Method, rtol: f64) -> SimOptions {
    SimOptions { t_end: 1000.0, rtol, atol: rtol / 100.0, method, ..SimOptions::default() }
}

/// `(x, y)` at `t = 1000` for `x0`, without gradients.
fn final_state(x0: f64, method: Method, rtol: f64) -> [f64; 2] {
    let c = Model::parse(VDP).expect("parses").compile::<&str>(&[]).expect("compiles");
    let mut p = c.params();
    p.set("x0", x0).unwrap();
    let run = c.simulate(&p, &opts(method, rtol)).expect("runs");
    [run.state("x").unwrap(), run.state("y").unwrap()]
}

/// `d(x, y)(1000)/dx0` by central differences of runs at rtol 1e-11 (Rodas5P, 5,133 steps each):
/// `dx/dx0` agrees with the same differences at rtol 1e-12 to 5e-10 relative, far below the
/// bounds asserted.
fn reference() -> [f64; 2] {
    let h = 1e-5;
    let (plus, minus) =
        (final_state(2.0 + h, Method::Rodas5p, 1e-11), final_state(2.0 - h, Method::Rodas5p, 1e-11));
    [(plus[0] - minus[0]) / (2.0 * h), (plus[1] - minus[1]) / (2.0 * h)]
}

/// The largest relative error of `d(x, y)(1000)/dp` against `want`, and the steps.
fn sens_error(param: &str, method: Method, rtol: f64, want: [f64; 2]) -> (f64, usize) {
    let c = Model::parse(VDP).expect("parses").compile(&[param]).expect("compiles");
    let run = c.simulate(&c.params(), &opts(method, rtol)).expect("runs");
    assert_eq!(run.events().len(), 1, "{method:?}: one crossing, inside the jump");
    let got = [run.dstate("x", param).unwrap(), run.dstate("y", param).unwrap()];
    let err = got.iter().zip(&want).map(|(g, w)| ((g - w) / w).abs()).fold(0.0, f64::max);
    (err, run.result().stats.steps)
}

/// After the jump, `dx/dx0` and `dy/dx0` are within 100 tolerances under Rodas5P, Rodas4 and
/// `auto` (measured at rtol 1e-6: 1.8e-5, 8.2e-6, 3.4e-5; at 1e-8: 3.2e-7, 9.3e-8, 4.3e-8). The
/// same derivative through `d = 0`, which the cap cannot scale, keeps the error made at the
/// jump's peak, where `|dy/dx0|` reaches 2e9: 1.2e-2, 3.9e-2 and 0.24 measured, above 1e3
/// tolerances asserted. So the accuracy is the rule's, and the rule is what binds here.
#[test]
fn van_der_pol_sensitivities_through_a_fast_jump_are_within_100_tolerances() {
    let want = reference();
    let rtol = 1e-6;
    for method in [Method::Rodas5p, Method::Rodas4, Method::Auto] {
        let (capped, steps) = sens_error("x0", method, rtol, want);
        assert!(capped < 100.0 * rtol, "{method:?}: dx/dx0 {capped:.1e} off ({steps} steps)");
        let (uncapped, plain_steps) = sens_error("d", method, rtol, want);
        assert!(uncapped > 1e3 * rtol, "{method:?}: dx/dd {uncapped:.1e} off: the cap is not what binds");
        // The price: more steps inside the jump (measured 1,044 against 494 under Rodas5P, 2,849
        // against 912 under Rodas4, 1,079 against 585 under `auto`), fewer than four times as
        // many in all.
        assert!(steps > plain_steps && steps < 4 * plain_steps, "{method:?}: {steps} vs {plain_steps}");
    }
}

/// The other side: models whose relative sensitivities stay below K, where the cap never binds.
/// A parameter at its value and the same parameter as an offset from 0 give the same steps and
/// the same derivatives to round-off, under every stepper: the ball's restitution and drop
/// height, the thermostat's initial temperature and heater power.
#[test]
fn ordinary_models_take_the_same_steps_with_the_cap_or_without() {
    let ball = |offset: bool| {
        let (params, e, h0) = if offset {
            ("param de = 0\nparam dh = 0", "(0.8 + de)", "1 + dh")
        } else {
            ("param de = 0.8\nparam dh = 1", "de", "dh")
        };
        format!(
            "model ball\nparam g = 9.81\n{params}\nstate y = {h0}\nstate v = 0\nder(y) = v\nder(v) = -g\n\
             event touchdown when y <= 0 {{\n    v := -{e} * v\n}}\n"
        )
    };
    let thermostat = |offset: bool| {
        let (params, t0, power) = if offset {
            ("param dT = 0\nparam dP = 0", "20 + dT", "(2 + dP)")
        } else {
            ("param dT = 20\nparam dP = 2", "dT", "dP")
        };
        format!(
            "model thermostat\nparam k = 0.1\n{params}\nstate T = {t0}\ninitial mode heating {{\n    \
             der(T) = {power} - k * (T - 10)\n    event warm when T >= 21 -> cooling\n}}\n\
             mode cooling {{\n    der(T) = -k * (T - 10)\n    event cold when T <= 19 -> heating\n}}\n"
        )
    };
    let cases: [(String, String, [&str; 2], &[&str], f64); 2] = [
        (ball(false), ball(true), ["de", "dh"], &["y", "v"], 2.5),
        (thermostat(false), thermostat(true), ["dT", "dP"], &["T"], 60.0),
    ];
    for (valued, offset, grad, states, t_end) in &cases {
        for method in [Method::Auto, Method::Dopri5, Method::Dop853, Method::Rodas5p, Method::Rodas4] {
            let opts = SimOptions { t_end: *t_end, rtol: 1e-8, atol: 1e-10, method, ..SimOptions::default() };
            let run = |text: &str| {
                let c = Model::parse(text).expect("parses").compile(grad).expect("compiles");
                c.simulate(&c.params(), &opts).expect("runs")
            };
            let (a, b) = (run(valued), run(offset));
            assert_eq!(a.result().stats.steps, b.result().stats.steps, "{method:?} {grad:?}");
            assert_eq!(a.result().stats.rejected, b.result().stats.rejected, "{method:?} {grad:?}");
            for (state, p) in states.iter().flat_map(|s| grad.iter().map(move |p| (s, p))) {
                let (da, db) = (a.dstate(state, p).unwrap(), b.dstate(state, p).unwrap());
                assert!(
                    (da - db).abs() <= 1e-12 * da.abs().max(1.0),
                    "{method:?} d{state}/d{p}: {da} vs {db}"
                );
            }
        }
    }
}
