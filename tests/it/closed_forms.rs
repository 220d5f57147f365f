//! Every quantity `hybc` reports, against references computed inside the test, at several
//! parameter points of each model: the vertical ball (closed form; also its saltation matrix),
//! the tilted floor (each flight solved exactly as a quadratic), the thermostat (exponential
//! solutions) and dosing (linear kinetics). Gradients of the references are Richardson-extrapolated
//! central differences of those exact computations (`support::reference`, ~1e-12).
//! Nonlinear models without closed form are checked against central differences of the compiled
//! model itself by `hybc::gradcheck`, at tight tolerances and several points.
//!
//! All runs use the models' tolerances, rtol 1e-10 (atol 1e-12). Stated tolerances: event times
//! 1e-9 relative; gradients, final states and outputs 1e-8 relative with an absolute floor of
//! 1e-9 (a derivative that is exactly zero is reported as ~1e-12, not 0). `cargo test --test it
//! closed_forms -- --nocapture` prints the largest errors seen (docs/accuracy.md).

use crate::support::reference::{
    ball_reference, derivative, dosing_reference, mid_flight, thermostat_reference, tilted_reference,
    BallForm, Compiled, Errors, Reference,
};
use hybc::gradcheck::{check, CheckOptions};
use hybc::sim::{SimOptions, SimResult};

const RTOL: f64 = 1e-10;
const TIME_REL: f64 = 1e-9;
const REL: f64 = 1e-8;
const ABS: f64 = 1e-9;

/// Compares every event time, final state and output of `r`, and their gradients with respect to
/// every parameter, with `reference` (a function of all parameters) at `p`.
fn compare(
    tag: &str,
    m: &Compiled,
    p: &[f64],
    r: &SimResult,
    reference: impl Fn(&[f64]) -> Reference,
    errs: &mut Errors,
) {
    let nominal = reference(p);
    assert_eq!(r.events.len(), nominal.times.len(), "{tag}: number of events");
    for (k, (ev, t)) in r.events.iter().zip(&nominal.times).enumerate() {
        errs.check("event times", &format!("{tag} t{k}"), ev.time, *t, TIME_REL, 0.0);
        assert!(!ev.grazing, "{tag}: event {k} grazes");
    }
    let f = &r.final_state;
    let reported: Vec<f64> = f.state.iter().chain(&f.outputs).copied().collect();
    assert_eq!(reported.len(), nominal.finals.len(), "{tag}: states and outputs");
    for (i, (a, b)) in reported.iter().zip(&nominal.finals).enumerate() {
        errs.check("final states and outputs", &format!("{tag} final[{i}]"), *a, *b, REL, ABS);
    }
    let (n, k, m_grad) = (f.state.len(), f.outputs.len(), p.len());
    let ds = f.dstate.as_ref().expect("dstate");
    let dy = f.doutputs.as_ref().expect("doutputs");
    for (j, name) in m.names.iter().enumerate() {
        let want = derivative(|q| reference(q).flat(), p, j);
        let (want_times, want_finals) = want.split_at(nominal.times.len());
        for (e, (ev, w)) in r.events.iter().zip(want_times).enumerate() {
            let got = ev.dtime.as_ref().expect("dtime")[j];
            errs.check("event-time gradients", &format!("{tag} dt{e}/d{name}"), got, *w, REL, ABS);
        }
        let got_finals = (0..n).map(|i| ds[j * n + i]).chain((0..k).map(|i| dy[j * k + i]));
        for (i, (got, w)) in got_finals.zip(want_finals).enumerate() {
            errs.check(
                "final-state and output gradients",
                &format!("{tag} dfinal[{i}]/d{name}"),
                got,
                *w,
                REL,
                ABS,
            );
        }
        assert_eq!(ds.len(), n * m_grad);
    }
}

// ---- vertical ball: p = [g, e, h0] -------------------------------------------------------------

#[test]
fn vertical_ball_against_its_closed_form_at_four_points() {
    let m = Compiled::from_file("models/ball.hyb");
    let mut errs = Errors::default();
    for (t_end, sets) in [
        (2.5, vec![]),
        (4.0, vec![("h0", 10.0)]),
        (3.0, vec![("g", 3.7), ("e", 0.6), ("h0", 2.5)]),
        (1.2, vec![("e", 0.95), ("h0", 0.3)]),
    ] {
        let p = m.params(&sets);
        let tag = format!("ball {sets:?}");
        // Keep the end time away from a bounce, where the final state is not differentiable.
        let t_end = mid_flight(&ball_reference(&p, 10.0 * t_end).times, t_end);
        let r = m.run(&p, t_end, RTOL);
        assert!(r.events.len() >= 2, "{tag}: at least two bounces");
        compare(&tag, &m, &p, &r, |q| ball_reference(q, t_end), &mut errs);
        // Energy after k bounces is g h0 e^(2k), independent of the end time.
        let k = r.events.len() as i32;
        let energy = r.final_state.outputs[0];
        errs.check(
            "final states and outputs",
            &format!("{tag} energy"),
            energy,
            BallForm::at(&p).energy(k),
            REL,
            0.0,
        );
    }
    errs.print("vertical ball");
}

#[test]
fn published_ball_values_hold() {
    // closed-forms.md: the four bounce times at the defaults, dt1/dh0 and E(T) = g h0 e^8.
    let m = Compiled::from_file("models/ball.hyb");
    let r = m.run(&m.defaults, 2.5, RTOL);
    let published = [0.4515236410, 1.1739614666, 1.7519117270, 2.2142719354];
    assert_eq!(r.events.len(), published.len());
    for (ev, t) in r.events.iter().zip(published) {
        approx::assert_relative_eq!(ev.time, t, max_relative = 1e-10);
    }
    approx::assert_relative_eq!(r.events[0].dtime.as_ref().unwrap()[2], 0.2257618205, max_relative = 1e-9);
    approx::assert_relative_eq!(r.final_state.outputs[0], 1.6458448896, max_relative = 1e-9);
}

/// The ball with its initial velocity as a parameter too, so that the sensitivities with respect
/// to the initial state `(y0, v0)` are the state-transition matrix.
const BALL_XV: &str = "model ball_xv\nparam g = 9.81\nparam e = 0.8\nparam y0 = 1\nparam v0 = 0\n\
                       state y = y0\nstate v = v0\nder(y) = v\nder(v) = -g\n\
                       event touchdown when y <= 0 {\n    v := -e * v\n}\n";

/// `[[a, b], [c, d]]` row-major products.
fn mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] + a[1] * b[2],
        a[0] * b[1] + a[1] * b[3],
        a[2] * b[0] + a[3] * b[2],
        a[2] * b[1] + a[3] * b[3],
    ]
}

#[test]
fn saltation_matrix_at_the_first_bounce() {
    // The sensitivities to the initial state after the first bounce are S(T) = Phi(T - t1) Sigma
    // Phi(t1), with the free-flight transition Phi(tau) = [[1, tau], [0, 1]] (exact for constant
    // gravity). So the saltation matrix the integrator applied is recovered from the reported
    // dstate as Sigma = Phi(-(T - t1)) S(T) Phi(-t1), and must equal the closed form
    // [[-e, 0], [-(1 + e) g / v-, -e]] with the pre-impact velocity v- = v0 - g t1.
    let m = Compiled::from_source(BALL_XV);
    let mut errs = Errors::default();
    for sets in [
        vec![],
        vec![("y0", 10.0)],
        vec![("y0", 0.5), ("v0", 2.0), ("e", 0.5)],
        vec![("y0", 2.0), ("v0", -3.0), ("g", 3.7), ("e", 0.9)],
    ] {
        let p = m.params(&sets);
        let (g, e, y0, v0) = (p[0], p[1], p[2], p[3]);
        let t1 = (v0 + (v0 * v0 + 2.0 * g * y0).sqrt()) / g;
        let v_minus = v0 - g * t1;
        // Halfway through the second flight, which lasts 2 e |v-| / g.
        let t_end = t1 + e * v_minus.abs() / g;
        let r = m.run(&p, t_end, RTOL);
        assert_eq!(r.events.len(), 1, "{sets:?}");
        let ds = r.final_state.dstate.as_ref().expect("dstate");
        // Columns 2 and 3 are y0 and v0; S row-major [[dy/dy0, dy/dv0], [dv/dy0, dv/dv0]].
        let s = [ds[2 * 2], ds[3 * 2], ds[2 * 2 + 1], ds[3 * 2 + 1]];
        let t1_run = r.events[0].time;
        let sigma = mul(mul([1.0, -(t_end - t1_run), 0.0, 1.0], s), [1.0, -t1_run, 0.0, 1.0]);
        let want = [-e, 0.0, -(1.0 + e) * g / v_minus, -e];
        for (i, (a, b)) in sigma.iter().zip(want).enumerate() {
            errs.check("saltation entries", &format!("{sets:?} Sigma[{i}]"), *a, b, REL, ABS);
        }
        if sets == vec![("y0", 10.0)] {
            // closed-forms.md, second point: [[-0.8, 0], [1.26064269323, -0.8]].
            approx::assert_relative_eq!(sigma[2], 1.26064269323, max_relative = 1e-9);
        }
    }
    errs.print("saltation matrix");
}

// ---- tilted floor: p = [g, e, s, vx0, h0] ------------------------------------------------------

#[test]
fn tilted_floor_against_exact_flights_at_four_points() {
    let m = Compiled::from_file("models/tilted_ball.hyb");
    let mut errs = Errors::default();
    // (End times before each point's accumulation of bounces: 4.1 s at the defaults.)
    for (around, sets) in [
        (3.0, vec![]),
        (1.5, vec![("s", 0.3), ("vx0", 0.5), ("e", 0.6)]),
        (3.0, vec![("s", -0.2), ("vx0", 2.0), ("h0", 1.5)]), // uphill
        (5.0, vec![("e", 0.9), ("g", 3.7), ("s", 0.05)]),
    ] {
        let p = m.params(&sets);
        let tag = format!("tilted {sets:?}");
        let t_end = mid_flight(&tilted_reference(&p, 30.0).times, around);
        let r = m.run(&p, t_end, RTOL);
        assert!(r.events.len() >= 3, "{tag}: {} bounces", r.events.len());
        compare(&tag, &m, &p, &r, |q| tilted_reference(q, t_end), &mut errs);
    }
    errs.print("tilted floor");
}

#[test]
fn first_tilted_bounce_is_delayed_by_a_steeper_downhill_floor() {
    // t1 = (s vx0 + sqrt(s^2 vx0^2 + 2 g h0)) / g, so dt1/ds = (vx0 + s vx0^2 / sqrt(..)) / g,
    // +0.1581 at the defaults (the notebook printed -0.0000).
    let m = Compiled::from_file("models/tilted_ball.hyb");
    let r = m.run(&m.defaults, 3.0, RTOL);
    let (g, s, vx0, h0) = (9.81_f64, 0.1_f64, 1.5_f64, 1.0_f64);
    let root = (s * s * vx0 * vx0 + 2.0 * g * h0).sqrt();
    let dt_ds = r.events[0].dtime.as_ref().unwrap()[2];
    approx::assert_relative_eq!(dt_ds, (vx0 + s * vx0 * vx0 / root) / g, max_relative = 1e-8);
    assert!((dt_ds - 0.1581).abs() < 5e-5, "{dt_ds}");
    assert_eq!(r.events.len(), 6, "six bounces before T = 3 (closed-forms.md)");
}

// ---- thermostat: p = [k, P, T_out, T_lo, T_hi, T0] ---------------------------------------------

#[test]
fn thermostat_switching_times_from_the_exponential_solution() {
    let m = Compiled::from_file("models/thermostat.hyb");
    let mut errs = Errors::default();
    for sets in [
        vec![],
        vec![("k", 0.05), ("P", 1.5), ("T_out", 5.0), ("T_lo", 18.0), ("T_hi", 22.0)],
        vec![("k", 0.2), ("P", 4.0), ("T0", 19.5), ("T_hi", 20.5)],
    ] {
        let p = m.params(&sets);
        let tag = format!("thermostat {sets:?}");
        let t_end = mid_flight(&thermostat_reference(&p, 600.0).times, 60.0);
        let r = m.run(&p, t_end, RTOL);
        assert!(r.events.len() >= 10, "{tag}: {} switches", r.events.len());
        compare(&tag, &m, &p, &r, |q| thermostat_reference(q, t_end), &mut errs);
    }
    errs.print("thermostat");
}

// ---- dosing: p = [ka, ke, dose, t_dose, tau, V] ------------------------------------------------

#[test]
fn dosing_amounts_from_linear_kinetics() {
    let m = Compiled::from_file("models/dosing.hyb");
    let mut errs = Errors::default();
    for sets in [
        vec![],
        vec![("ka", 0.5), ("ke", 0.3), ("dose", 50.0), ("t_dose", 1.0), ("tau", 8.0), ("V", 20.0)],
        vec![("ka", 2.0), ("ke", 0.1), ("t_dose", 3.5), ("tau", 4.0)],
    ] {
        let p = m.params(&sets);
        let r = m.run(&p, 12.0, RTOL);
        assert_eq!(r.events.len(), 2);
        compare(&format!("dosing {sets:?}"), &m, &p, &r, |q| dosing_reference(q, 12.0), &mut errs);
    }
    errs.print("dosing");
}

/// Parameter values to set by name.
type Sets<'a> = Vec<(&'a str, f64)>;

// ---- nonlinear models: central differences of the compiled model --------------------------------

#[test]
fn nonlinear_models_match_central_differences_at_several_points() {
    // rtol 1e-12 and a check tolerance of 1e-5: at these tolerances the worst discrepancy of the
    // shipped models is ~1e-6 (the truncation of the difference, docs/accuracy.md).
    let cases: [(&str, f64, Vec<Sets>); 3] = [
        (
            "models/pendulum_wall.hyb",
            5.0,
            vec![vec![], vec![("theta0", 0.5), ("e", 0.9), ("c", 0.2)], vec![("L", 2.0), ("theta_w", -0.1)]],
        ),
        (
            "models/hopper.hyb",
            3.0,
            vec![vec![], vec![("k", 300.0), ("b", 5.0), ("h0", 0.8)], vec![("m", 2.0), ("L0", 0.4)]],
        ),
        (
            "models/engine_redline.hyb",
            4.0,
            vec![vec![], vec![("ramp", 0.8), ("omega_on", 600.0)], vec![("J", 0.3), ("c", 0.05)]],
        ),
    ];
    for (path, t_end, points) in cases {
        let m = Compiled::from_file(path);
        let mut worst: f64 = 0.0;
        for sets in points {
            let p = m.params(&sets);
            let opts = SimOptions { t_end, rtol: 1e-12, atol: 1e-14, ..SimOptions::default() };
            let nominal = hybc::sim::run(&m.model, &p, &opts).expect("runs");
            let c = check(&m.model, &p, &opts, &nominal, &CheckOptions { rel_step: 1e-5, tol: 1e-5 })
                .expect("checks");
            for pc in &c.params {
                assert!(
                    pc.cusp.is_none() && pc.notes.is_empty(),
                    "{path} {sets:?} {}: {:?} {:?}",
                    pc.name,
                    pc.cusp,
                    pc.notes
                );
                assert_eq!(
                    pc.checked,
                    nominal.events.len()
                        + nominal.final_state.state.len()
                        + nominal.final_state.outputs.len()
                );
                worst = worst.max(pc.worst_discrepancy());
            }
            assert!(c.passed(), "{path} {sets:?}:\n{}", c.to_table());
            assert!(nominal.events.len() >= 2, "{path} {sets:?}: events to check");
        }
        println!("{path}: max discrepancy vs central differences at rtol 1e-12: {worst:.1e}");
    }
}
