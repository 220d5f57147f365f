//! Convergence: as the tolerance falls (rtol 1e-6, 1e-8, 1e-10, 1e-12, atol = rtol / 100), the
//! error of the event times and of their gradients falls. References: the closed form for the
//! thermostat; for the pendulum (no closed form) a run at rtol 1e-13. Asserted robustly: the error
//! at 1e-12 is at least 100x smaller than at 1e-6, and no step down the ladder increases it by more
//! than a factor 3 (slack for error estimates that are not exact) unless it is already at the
//! references' own level (1e-11 relative).
//!
//! The ball has no trend to show: its flights are quadratics in time, which every Runge-Kutta
//! method of order >= 2 integrates exactly, so its errors sit at round-off at every tolerance; the
//! test asserts exactly that. `--nocapture` prints the errors (docs/accuracy.md).

use crate::support::reference::{ball_reference, derivative, thermostat_reference, Compiled, Reference};
use hybc::sim::SimResult;

const RTOLS: [f64; 4] = [1e-6, 1e-8, 1e-10, 1e-12];
const SLACK: f64 = 3.0;
const FLOOR: f64 = 1e-11;

/// Largest relative error of the event times and of the event-time gradients (against
/// `max(|want|, 1e-3)`, since some gradients are exactly zero).
fn event_errors(r: &SimResult, times: &[f64], grads: &[Vec<f64>]) -> (f64, f64) {
    assert_eq!(r.events.len(), times.len());
    let mut et: f64 = 0.0;
    let mut eg: f64 = 0.0;
    for (k, ev) in r.events.iter().enumerate() {
        et = et.max((ev.time - times[k]).abs() / times[k].abs());
        for (got, want) in ev.dtime.as_ref().expect("no grazing").iter().zip(&grads[k]) {
            eg = eg.max((got - want).abs() / want.abs().max(1e-3));
        }
    }
    (et, eg)
}

fn assert_converges(what: &str, errors: &[f64]) {
    println!("{what}: {}", errors.iter().map(|e| format!("{e:.1e}")).collect::<Vec<_>>().join(" -> "));
    assert!(errors[3] * 100.0 <= errors[0].max(100.0 * FLOOR), "{what}: {errors:?}");
    for w in errors.windows(2) {
        assert!(w[1] <= SLACK * w[0] || w[1] <= FLOOR, "{what} grows: {errors:?}");
    }
}

/// Event times and `grads[event][param]` of a closed form, its gradients by central differences.
fn closed_form(reference: impl Fn(&[f64]) -> Reference, p: &[f64]) -> (Vec<f64>, Vec<Vec<f64>>) {
    let times = reference(p).times;
    let by_param: Vec<Vec<f64>> = (0..p.len()).map(|j| derivative(|q| reference(q).flat(), p, j)).collect();
    let grads = (0..times.len()).map(|e| by_param.iter().map(|d| d[e]).collect()).collect();
    (times, grads)
}

/// Errors at every tolerance of the ladder: (event times, event-time gradients).
fn ladder(m: &Compiled, p: &[f64], t_end: f64, times: &[f64], grads: &[Vec<f64>]) -> (Vec<f64>, Vec<f64>) {
    RTOLS.iter().map(|&rtol| event_errors(&m.run(p, t_end, rtol), times, grads)).unzip()
}

#[test]
fn ball_event_errors_are_at_round_off_at_every_tolerance() {
    let m = Compiled::from_file("models/ball.hyb");
    let t_end = 2.5;
    let (times, grads) = closed_form(|q| ball_reference(q, t_end), &m.defaults);
    let (et, eg) = ladder(&m, &m.defaults, t_end, &times, &grads);
    let show = |v: &[f64]| v.iter().map(|e| format!("{e:.1e}")).collect::<Vec<_>>().join(", ");
    println!("ball event times: {}; event-time gradients: {}", show(&et), show(&eg));
    assert!(et.iter().chain(&eg).all(|&e| e <= FLOOR), "{et:?} {eg:?}");
}

#[test]
fn thermostat_event_errors_fall_with_the_tolerance() {
    let m = Compiled::from_file("models/thermostat.hyb");
    let t_end = 60.0;
    let (times, grads) = closed_form(|q| thermostat_reference(q, t_end), &m.defaults);
    let (et, eg) = ladder(&m, &m.defaults, t_end, &times, &grads);
    assert_converges("thermostat event times", &et);
    assert_converges("thermostat event-time gradients", &eg);
}

#[test]
fn pendulum_event_errors_fall_with_the_tolerance() {
    let m = Compiled::from_file("models/pendulum_wall.hyb");
    let p = m.defaults.clone();
    let t_end = 5.0;
    let reference = m.run(&p, t_end, 1e-13);
    let times: Vec<f64> = reference.events.iter().map(|e| e.time).collect();
    let grads: Vec<Vec<f64>> =
        reference.events.iter().map(|e| e.dtime.clone().expect("no grazing")).collect();
    assert!(times.len() >= 3, "{} wall hits", times.len());
    let (et, eg) = ladder(&m, &p, t_end, &times, &grads);
    assert_converges("pendulum event times", &et);
    assert_converges("pendulum event-time gradients", &eg);
}
