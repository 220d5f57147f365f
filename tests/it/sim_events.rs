//! Integrator event-handling tests: a guard crossed and re-crossed within one step, grazing,
//! mode switching against a closed form (thermostat), simultaneous events in declaration order,
//! no re-firing at the same instant and no firing when starting on a guard.

use crate::support::hand_systems::{close, Ball, Counter, Oscillator, Thermostat};
use crate::support::reference::ThermostatForm;
use hybc::sim::{run, Method, SimOptions, SimWarning, StopReason, TrajectoryRequest};

#[test]
fn short_hop_through_a_ceiling_within_one_step_is_caught() {
    // Thrown up from the floor at 5 m/s; the ceiling sits 1 mm below the apex, so the guard is
    // negative only for about 28 ms around the apex.
    let (g, v0) = (9.81f64, 5.0f64);
    let apex = v0 * v0 / (2.0 * g);
    let c = apex - 1e-3;
    let root = (v0 * v0 - 2.0 * g * c).sqrt();
    let (t_in, t_out) = ((v0 - root) / g, (v0 + root) / g);
    let o = SimOptions {
        t_end: 0.8,
        rtol: 1e-8,
        atol: 1e-10,
        method: Method::Dopri5,
        trajectory: TrajectoryRequest::Steps,
        ..SimOptions::default()
    };
    // With the event disabled the stepping is the same up to the crossing: no step ends inside
    // the window, so only the extremum search can have found the crossing.
    let off = run(&Ball::with_ceiling(v0, c, false), &[g, 0.8, 0.0], &o).expect("valid");
    assert!(off.events.is_empty());
    let rows = off.trajectory.expect("steps requested");
    assert!(
        rows.iter().all(|r| r.t <= t_in || r.t >= t_out),
        "a step ended inside the window; the test would not exercise the short hop"
    );

    let on = run(&Ball::with_ceiling(v0, c, true), &[g, 0.8, 0.0], &o).expect("valid");
    let ev = on.events.first().expect("the ceiling event fires");
    assert_eq!(&*ev.name, "ceiling");
    assert!(close(ev.time, t_in, 1e-12), "{} vs {t_in}", ev.time);
    assert!(!ev.grazing);
    // t_c solves h0 + v0 t - g t^2 / 2 = c: dt/dg = (t^2/2) / (v0 - g t), dt/dh0 = -1/(v0 - g t).
    let vel = v0 - g * t_in;
    let dt = ev.dtime.as_ref().unwrap();
    assert!(close(dt[0], 0.5 * t_in * t_in / vel, 1e-8), "{dt:?}");
    assert!(dt[1].abs() < 1e-12);
    assert!(close(dt[2], -1.0 / vel, 1e-8), "{dt:?}");
}

fn grazing_run(ceiling: f64) -> hybc::sim::SimResult {
    // g = 8, v0 = 4: apex exactly at y = 1, t = 0.5 (all exact in binary).
    let o = SimOptions { t_end: 1.2, rtol: 1e-10, atol: 1e-12, ..SimOptions::default() };
    run(&Ball::with_ceiling(4.0, ceiling, true), &[8.0, 0.8, 0.0], &o).expect("valid")
}

#[test]
fn apex_exactly_touching_the_ceiling_is_flagged_grazing() {
    for ceiling in [1.0, 1.0 - 1e-9] {
        let r = grazing_run(ceiling);
        // The floor guard starts at zero (y0 = 0): it must not fire at t = 0.
        let ev = r.events.first().expect("the touch is an event");
        assert_eq!(&*ev.name, "ceiling", "ceiling {ceiling}");
        assert!((ev.time - 0.5).abs() < 1e-4, "{}", ev.time);
        assert!(ev.grazing);
        // Parameters [g, e, h0]: the apex's time moves with g and h0, and those derivatives do
        // not exist; e has not acted yet, so the touch's time does not depend on it at all.
        let dt = ev.dtime.as_ref().expect("dt/de exists");
        assert!(dt[0].is_nan() && dt[1] == 0.0 && dt[2].is_nan(), "{dt:?}");
        assert!(ev.denominator.is_finite() && ev.denominator.abs() < 1e-2);
        assert!(matches!(r.warnings[0], SimWarning::Grazing { event: 1, .. }));
        assert!(r.warnings[0].to_string().contains("grazes"));
        // The ball comes back to the floor at t = 1; its time's derivatives in g and h0 are gone
        // too (they depend on the touch's), the one in e exists.
        assert_eq!(r.events.len(), 2);
        assert!((r.events[1].time - 1.0).abs() < 1e-4, "{}", r.events[1].time);
        let dt = r.events[1].dtime.as_ref().expect("dt/de exists");
        assert!(dt[0].is_nan() && dt[1].is_finite() && dt[2].is_nan(), "{dt:?}");
        let f = &r.final_state;
        let (n, ds) = (2, f.dstate.as_ref().expect("the e column exists"));
        assert!(ds[..n].iter().chain(&ds[2 * n..]).all(|v| v.is_nan()), "{ds:?}");
        assert!(ds[n..2 * n].iter().all(|v| v.is_finite()), "{ds:?}");
        assert!(f.state.iter().chain(&f.outputs).all(|v| v.is_finite()));
        assert_eq!(r.stopped_by, StopReason::TEnd);
        let json = serde_json::to_string(&r).expect("serialisable");
        assert!(!json.contains("NaN") && !json.contains("inf"), "{json}");
    }
}

/// The hand-written thermostat's closed form (`hand_systems::Thermostat`: p = [k, T_out, P, T_lo,
/// T_hi], starting at `t0`): switching times up to `t_end` and the final temperature.
fn thermostat_closed(p: &[f64], t0: f64, t_end: f64) -> (Vec<f64>, f64) {
    ThermostatForm { k: p[0], t_out: p[1], power: p[2], t_lo: p[3], t_hi: p[4], t0 }.switches(t_end)
}

#[test]
fn thermostat_switching_times_and_gradients_match_closed_form() {
    let p = [0.1, 10.0, 2.0, 19.0, 21.0];
    let (t0, t_end) = (18.0, 12.0);
    let (times, temp) = thermostat_closed(&p, t0, t_end);
    assert_eq!(times.len(), 5);
    for method in [Method::Dopri5, Method::Dop853] {
        let o = SimOptions { t_end, rtol: 1e-10, atol: 1e-12, method, ..SimOptions::default() };
        let r = run(&Thermostat::new(t0), &p, &o).expect("valid");
        assert_eq!(r.events.len(), times.len(), "{method:?}");
        for (ev, t) in r.events.iter().zip(&times) {
            assert!(close(ev.time, *t, 1e-9), "{method:?}: {} vs {t}", ev.time);
        }
        assert_eq!(&*r.events[0].name, "off");
        assert_eq!((r.events[0].mode_before, r.events[0].mode_after), (0, 1));
        assert_eq!((r.events[1].mode_before, r.events[1].mode_after), (1, 0));
        assert_eq!(r.final_state.mode, 1);
        assert!(close(r.final_state.state[0], temp, 1e-9));
        // Gradients against central differences of the closed form (step 1e-6 relative; the
        // difference quotient is good to about 1e-8 here).
        let s = r.final_state.dstate.as_ref().unwrap();
        for j in 0..5 {
            let hj = 1e-6 * p[j].abs();
            let (mut pp, mut pm) = (p, p);
            pp[j] += hj;
            pm[j] -= hj;
            let (tp, xp) = thermostat_closed(&pp, t0, t_end);
            let (tm, xm) = thermostat_closed(&pm, t0, t_end);
            for (i, ev) in r.events.iter().enumerate() {
                let fd = (tp[i] - tm[i]) / (2.0 * hj);
                let got = ev.dtime.as_ref().unwrap()[j];
                assert!(
                    (got - fd).abs() <= 1e-6 * fd.abs().max(1.0),
                    "{method:?} event {i} dt/dp{j}: {got} vs {fd}"
                );
            }
            let fd = (xp - xm) / (2.0 * hj);
            assert!((s[j] - fd).abs() <= 1e-6 * fd.abs().max(1.0), "{method:?} dT/dp{j}: {} vs {fd}", s[j]);
        }
    }
}

#[test]
fn simultaneous_events_fire_in_declaration_order_once() {
    let o = SimOptions { t_end: 2.0, rtol: 1e-10, atol: 1e-12, ..SimOptions::default() };
    let r = run(&Counter::new(1.0), &[1.0], &o).expect("valid");
    // A (x := 0, c += 1) then B (c *= 10) at t = 1, and neither again although x sits on the
    // guard right after A.
    let names: Vec<&str> = r.events.iter().map(|e| &*e.name).collect();
    assert_eq!(names, ["A", "B"]);
    assert!(r.events.iter().all(|e| close(e.time, 1.0, 1e-12)));
    assert_eq!(r.final_state.state[1], 10.0);
    assert!(close(r.final_state.state[0], -1.0, 1e-10));
    // t_e = x0 / a, so dt_e/da = -1 for both; x(2) = 1 - 2a after the reset, dx/da = -2.
    for ev in &r.events {
        assert!(close(ev.dtime.as_ref().unwrap()[0], -1.0, 1e-10));
    }
    let s = r.final_state.dstate.as_ref().unwrap();
    assert!(close(s[0], -2.0, 1e-10), "{s:?}");
}

#[test]
fn starting_on_a_guard_moving_across_fires_at_the_start() {
    let o = SimOptions { t_end: 1.0, rtol: 1e-6, atol: 1e-9, ..SimOptions::default() };
    // x starts exactly at zero and the flow moves it to the crossed side: both events fire at
    // t = 0, in declaration order (c = (0 + 1) * 10). t_e = x0 / a, so dt_e/da = -x0 / a^2 = 0.
    let r = run(&Counter::new(0.0), &[1.0], &o).expect("valid");
    let fired: Vec<(&str, f64)> = r.events.iter().map(|e| (&*e.name, e.time)).collect();
    assert_eq!(fired, [("A", 0.0), ("B", 0.0)]);
    assert_eq!(r.final_state.state[1], 10.0);
    for ev in &r.events {
        assert_eq!(ev.dtime.as_ref().unwrap()[0], 0.0);
    }
}

#[test]
fn either_direction_fires_both_ways_with_identity_saltation() {
    // x = cos(w t): zeros at (pi/2 + k pi) / w, alternately falling and rising; dt_k/dw = -t_k / w.
    let w = 2.0;
    for method in [Method::Dopri5, Method::Dop853] {
        let o = SimOptions { t_end: 10.0, rtol: 1e-10, atol: 1e-12, method, ..SimOptions::default() };
        let r = run(&Oscillator::new(), &[w], &o).expect("valid");
        let want: Vec<f64> = (0..)
            .map(|k| (std::f64::consts::FRAC_PI_2 + k as f64 * std::f64::consts::PI) / w)
            .take_while(|t| *t <= 10.0)
            .collect();
        assert_eq!(r.events.len(), want.len(), "{method:?}");
        for (ev, t) in r.events.iter().zip(&want) {
            assert!(close(ev.time, *t, 1e-9), "{method:?}: {} vs {t}", ev.time);
            let dt = ev.dtime.as_ref().unwrap()[0];
            assert!(close(dt, -t / w, 1e-7), "{method:?}: dt/dw {dt} vs {}", -t / w);
        }
        // Identity reset with an unchanged flow: the saltation is the identity, so the final
        // sensitivity is the smooth one, dx/dw = -t sin(w t).
        let s = r.final_state.dstate.as_ref().unwrap();
        assert!(close(s[0], -10.0 * (w * 10.0).sin(), 1e-7), "{method:?}: {}", s[0]);
    }
}

#[test]
fn sensitivity_error_control_can_be_switched_off() {
    let p = [0.1, 10.0, 2.0, 19.0, 21.0];
    let base = SimOptions { t_end: 12.0, rtol: 1e-8, atol: 1e-10, ..SimOptions::default() };
    let on = run(&Thermostat::new(18.0), &p, &base).expect("valid");
    let off =
        run(&Thermostat::new(18.0), &p, &SimOptions { sens_error_control: false, ..base }).expect("valid");
    // Fewer constraints on the step size never need more steps; the events are the same.
    assert!(off.stats.steps <= on.stats.steps, "{} vs {}", off.stats.steps, on.stats.steps);
    assert_eq!(on.events.len(), off.events.len());
    for (a, b) in on.events.iter().zip(&off.events) {
        assert!(close(a.time, b.time, 1e-7));
    }
}
