//! Landing a step on each event instant (`SimOptions::land_events`, `Stepper::land`): the state
//! and sensitivities the events jump from come from a step end under the error control, not from
//! the dense output. Measured on the W5 diffusion chain of `benches/measure/w5_accuracy.rs` (10 cells, a
//! source refilled 19 times, the 10 conductances differentiated) against DOP853 at rtol 1e-12.

use hybc::sim::{Method, SimOptions, SimResult};
use hybc::Model;

use crate::support::chain::refill_source;

/// The largest error of the event-time gradients of `r` against `reference`, relative to the
/// largest entry of each event's gradient.
fn event_gradient_error(r: &SimResult, reference: &SimResult) -> f64 {
    assert_eq!(r.events.len(), reference.events.len());
    let max_abs = |v: &[f64]| v.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    let mut worst = 0.0f64;
    for (e, er) in r.events.iter().zip(&reference.events) {
        let (a, b) = (e.dtime.as_ref().unwrap(), er.dtime.as_ref().unwrap());
        let diff: Vec<f64> = a.iter().zip(b).map(|(a, b)| a - b).collect();
        worst = worst.max(max_abs(&diff) / max_abs(b));
    }
    worst
}

#[test]
fn landing_on_events_makes_event_time_gradients_as_accurate_as_values() {
    let names: Vec<String> = (0..10).map(|k| format!("d[{k}]")).collect();
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    let model = Model::parse(&refill_source(10)).unwrap();
    let c = model.compile(&names).unwrap();
    let p = c.params();
    let run = |rtol: f64, method: Method, land_events: Option<bool>| {
        let opts = SimOptions {
            t_end: 10.0,
            rtol,
            atol: rtol / 100.0,
            method,
            land_events,
            ..SimOptions::default()
        };
        c.simulate(&p, &opts).unwrap().into_result()
    };
    let reference = run(1e-12, Method::Dop853, Some(true));
    assert_eq!(reference.events.len(), 19);
    // DOP853 at rtol 1e-8 (measured: 2.3e-6 from the dense output, 9.0e-8 landed; the final
    // states are within 1.4e-10, so a gradient is still some 100 times less accurate than a value
    // of this chain, no longer 1000).
    let dense = event_gradient_error(&run(1e-8, Method::Dop853, Some(false)), &reference);
    let landed = event_gradient_error(&run(1e-8, Method::Dop853, Some(true)), &reference);
    assert!(dense > 1e-6, "{dense:e}");
    assert!(landed < 4e-7, "{landed:e}");
    // By default DOP853 lands where its step is held by stability, which this chain's steps
    // are (measured: 1.3e-7), and so does the default method (`auto`, DOP853 throughout here).
    for method in [Method::Dop853, Method::Auto] {
        let default = event_gradient_error(&run(1e-8, method, None), &reference);
        assert!(default < 4e-7, "{method:?}: {default:e}");
    }
    // Rodas5P lands by default (measured: 3.5e-8 from the dense output, 5.3e-9 landed).
    let rodas = event_gradient_error(&run(1e-8, Method::Rodas5p, None), &reference);
    assert!(rodas < 2e-8, "{rodas:e}");
}

#[test]
fn land_events_on_the_command_line_lands_the_explicit_default_within_its_tolerance() {
    use crate::support::cli::hybc;
    let run = |extra: &[&str]| {
        let mut args = vec!["run", "models/thermostat.hyb", "--grad", "all", "--format", "json"];
        args.extend_from_slice(extra);
        let out = hybc(&args);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice::<serde_json::Value>(&out.stdout).expect("json")
    };
    let times = |v: &serde_json::Value| -> Vec<f64> {
        v["events"].as_array().unwrap().iter().map(|e| e["time"].as_f64().unwrap()).collect()
    };
    let rhs_calls = |v: &serde_json::Value| v["stats"]["rhs_calls"].as_u64().unwrap();
    let (plain, landed) = (run(&[]), run(&["--land-events"]));
    // The same 30 switches, the same steps; one more attempt per event (DOP853: 12 evaluations).
    assert_eq!(times(&plain).len(), 30);
    assert_eq!(times(&plain).len(), times(&landed).len());
    assert_eq!(plain["stats"]["steps"], landed["stats"]["steps"]);
    assert_eq!(rhs_calls(&landed) - rhs_calls(&plain), 12 * 30);
    // Both within the model's tolerances (rtol 1e-10) of each other.
    for (a, b) in times(&plain).iter().zip(times(&landed)) {
        assert!((a - b).abs() <= 1e-9 * a.abs(), "{a} {b}");
    }
}

#[test]
fn the_explicit_pairs_land_by_default_only_where_stability_holds_the_step() {
    // The other side: on models whose steps accuracy holds (the ball, the thermostat, the tilted
    // floor), the explicit pairs do not land by default: exactly the evaluations of a run told
    // not to land (landing costs an attempt per event: the ball's 133 would be 181).
    for file in ["models/ball.hyb", "models/thermostat.hyb", "models/tilted_ball.hyb"] {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
        let model = Model::parse(&std::fs::read_to_string(&path).unwrap()).unwrap();
        let c = model.compile_all().unwrap();
        for method in [Method::Dopri5, Method::Dop853] {
            let calls = |land_events: Option<bool>| {
                let opts = SimOptions { method, land_events, ..model.sim_options() };
                let r = c.simulate(&c.params(), &opts).unwrap().into_result();
                assert!(!r.events.is_empty());
                r.stats.rhs_calls
            };
            assert_eq!(calls(None), calls(Some(false)), "{file} {method:?}");
            assert!(calls(Some(true)) > calls(None), "{file} {method:?}");
        }
    }
}
