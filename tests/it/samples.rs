//! Values and derivatives at given times (`SimOptions::at`, `hybc run --at`): the ball between
//! bounces against its closed form, samples at and near event instants, times the run does not
//! reach, and samples that leave the run itself unchanged.

use approx::assert_relative_eq;
use hybc::sim::Sample;

use crate::support::cli::hybc;
use crate::support::runs::run;

const BALL: &str = "model ball\nparam g = 9.81\nparam e = 0.8\nparam h0 = 1\nstate y = h0\nstate v = 0\n\
                    der(y) = v\nder(v) = -g\nevent touchdown when y <= 0 {\n    v := -e * v\n}\n\
                    output energy = 0.5 * v^2 + g * y\n";

/// The ball's height and its derivatives with respect to (e, h0) at `t`, before the second
/// touchdown: `t1 = sqrt(2 h0 / g)`; after it, `y = e g t1 (t - t1) - g (t - t1)^2 / 2`.
fn ball_closed_form(t: f64, g: f64, e: f64, h0: f64) -> (f64, f64, f64) {
    let t1 = (2.0 * h0 / g).sqrt();
    if t <= t1 {
        return (h0 - 0.5 * g * t * t, 0.0, 1.0);
    }
    let tau = t - t1;
    let y = e * g * t1 * tau - 0.5 * g * tau * tau;
    // dt1/dh0 = 1 / (g t1); d tau / dh0 = -dt1/dh0.
    let dt1 = 1.0 / (g * t1);
    let dy_dh0 = e * g * dt1 * tau - e * g * t1 * dt1 + g * tau * dt1;
    (y, g * t1 * tau, dy_dh0)
}

fn state(s: &Sample, i: usize) -> f64 {
    s.state[i]
}

/// `dstate[j * n + i]`.
fn dstate(s: &Sample, i: usize, j: usize, n: usize) -> f64 {
    s.dstate.expect("derivatives")[j * n + i]
}

#[test]
fn the_ball_between_bounces_matches_its_closed_form_with_derivatives() {
    // 41 times over the first flight and the second (the second touchdown is at
    // t1 (1 + 2 e) = 1.174).
    let at: Vec<f64> = (0..=40).map(|k| 1.15 * k as f64 / 40.0).collect();
    let r = run(BALL, &["e", "h0"], |o| {
        o.t_end = 1.15;
        o.at = at.clone();
    });
    assert_eq!(r.samples().len(), at.len());
    for s in r.samples().iter() {
        let s = &s;
        let (y, dy_de, dy_dh0) = ball_closed_form(s.time, 9.81, 0.8, 1.0);
        assert!(s.reached);
        assert_relative_eq!(state(s, 0), y, epsilon = 1e-9);
        assert_relative_eq!(dstate(s, 0, 0, 2), dy_de, epsilon = 1e-8);
        assert_relative_eq!(dstate(s, 0, 1, 2), dy_dh0, epsilon = 1e-8);
        // The output and its derivative: energy = v^2 / 2 + g y, d energy = v dv + g dy.
        let (v, dv_de) = (state(s, 1), dstate(s, 1, 0, 2));
        assert_relative_eq!(s.outputs[0], 0.5 * v * v + 9.81 * y, epsilon = 1e-8);
        let de = s.doutputs.unwrap()[0];
        assert_relative_eq!(de, v * dv_de + 9.81 * dy_de, epsilon = 1e-7);
    }
}

#[test]
fn samples_do_not_cut_the_steps_or_change_the_run() {
    let plain = run(BALL, &["e"], |o| o.t_end = 2.5);
    let sampled = run(BALL, &["e"], |o| {
        o.t_end = 2.5;
        o.at = (0..100).map(|k| 0.025 * k as f64).collect();
    });
    assert_eq!(plain.result().stats.steps, sampled.result().stats.steps);
    assert_eq!(plain.result().final_state, sampled.result().final_state);
    assert_eq!(plain.events(), sampled.events());
    assert!(plain.samples().is_empty());
    // The last sample (t = 2.475) from the dense output of the last step: the interpolant's
    // value, not a step end.
    assert_eq!(sampled.samples().len(), 100);
}

#[test]
fn a_sample_at_an_event_instant_is_taken_after_its_events() {
    // A time event at t = 1 adds 1 to x (x = t before): at t = 1 the sample reads 2, flagged;
    // a sample 1e-3 before reads 0.999 and is not.
    let text =
        "model kick\nparam a = 1\nstate x = 0\nder(x) = 1\nevent kick when t >= a {\n    x := x + 1\n}\n";
    let r = run(text, &["a"], |o| {
        o.t_end = 2.0;
        o.at = vec![0.999, 1.0, 1.5];
    });
    let s: Vec<Sample> = r.samples().iter().collect();
    assert!(!s[0].after_events && s[0].near_event.is_none());
    assert_relative_eq!(s[0].state[0], 0.999, epsilon = 1e-12);
    assert!(s[1].after_events);
    assert_eq!(s[1].near_event, Some(0));
    assert_relative_eq!(s[1].state[0], 2.0, epsilon = 1e-12);
    // Away from the kick, x = t + 1 and dx/da = 0 (the kick adds 1 whenever it comes).
    assert!(!s[2].after_events && s[2].near_event.is_none());
    assert_relative_eq!(s[2].state[0], 2.5, epsilon = 1e-12);
    assert_eq!(dstate(&s[2], 0, 0, 1), 0.0);
}

#[test]
fn a_sample_within_an_events_time_resolution_is_flagged_and_one_outside_is_not() {
    // x = t - 0.5 crosses 0 at 0.5; its time is known to about (atol + rtol |x|) / 1 = 1e-10.
    let text = "model cross\nstate x = -0.5\nder(x) = 1\nevent up when x >= 0 {\n    x := x - 1\n}\n";
    let r = run(text, &[], |o| {
        o.t_end = 1.0;
        o.rtol = 1e-8;
        o.atol = 1e-10;
        o.at = vec![0.5 - 1e-6, 0.5 - 1e-12, 0.5 + 1e-12, 0.5 + 1e-6];
    });
    let t_up = r.events()[0].time;
    assert!((t_up - 0.5).abs() < 1e-11, "{t_up}");
    let flags: Vec<Option<usize>> = r.samples().iter().map(|s| s.near_event).collect();
    assert_eq!(flags, vec![None, Some(0), Some(0), None]);
}

#[test]
fn times_after_a_stop_are_reported_as_not_reached() {
    // A time event lands on 0.5 exactly: the sample there is the state after it.
    let text = "model halt\nstate x = 0\nder(x) = 1\nevent halt when t >= 0.5 {\n    x := 7\n    stop\n}\n";
    let r = run(text, &[], |o| {
        o.t_end = 1.0;
        o.at = vec![0.25, 0.5, 0.75];
    });
    let s: Vec<Sample> = r.samples().iter().collect();
    assert!(s[0].reached && s[1].reached && !s[2].reached);
    assert!(s[1].after_events);
    assert_eq!(s[1].state[0], 7.0);
    assert!(s[2].state[0].is_nan() && s[2].dstate.is_none());
}

#[test]
fn sample_times_out_of_order_or_outside_the_run_are_refused() {
    let model = hybc::Model::parse(BALL).unwrap();
    let compiled = model.compile::<&str>(&[]).unwrap();
    for at in [vec![0.5, 0.2], vec![-0.1], vec![11.0], vec![f64::NAN]] {
        let mut o = model.sim_options();
        o.at = at.clone();
        let e = compiled.simulate(&model.params(), &o).unwrap_err();
        assert!(e.to_string().contains("sample time"), "{at:?}: {e}");
    }
}

#[test]
fn the_cli_names_why_a_sample_time_is_refused() {
    // The ball runs from 0 to 2.5: a time past either end, or out of order, is named with its
    // cause (not "not in order" for all three); the span's own ends are taken.
    for (at, needle) in [
        ("--at=3", "--at: time 3 is after t_end = 2.5: the run goes from t_start = 0 to t_end = 2.5"),
        ("--at=-1", "--at: time -1 is before t_start = 0: the run goes from t_start = 0 to t_end = 2.5"),
        ("--at=2,1", "--at: the times must ascend, but 1 comes after 2"),
    ] {
        let out = hybc(&["run", "models/ball.hyb", at]);
        assert_eq!(out.status.code(), Some(2), "{at}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "{at}: {err}");
        assert!(!err.contains("not in order"), "{at}: {err}");
    }
    let out = hybc(&["run", "models/ball.hyb", "--at=0,2.5", "--t-end", "2.5"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    // --t-end moves the span the times are checked against.
    let out = hybc(&["run", "models/ball.hyb", "--at=3", "--t-end", "3.5"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn the_cli_writes_samples_to_the_table_json_and_csv_alike() {
    let dir = std::env::temp_dir().join(format!("hybc-samples-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("s.csv");
    let csv_arg = csv.to_str().unwrap();
    let out = hybc(&[
        "run",
        "models/ball.hyb",
        "--grad",
        "e,h0",
        "--at",
        "0:2.5:11",
        "--format",
        "json",
        "--samples-out",
        csv_arg,
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let samples = json["samples"].as_array().expect("samples");
    assert_eq!(samples.len(), 11);
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(head[..7], ["time", "reached", "after_events", "near_event", "energy", "y", "v"]);
    assert_eq!(head[7..], ["denergy/de", "dy/de", "dv/de", "denergy/dh0", "dy/dh0", "dv/dh0"]);
    for (line, sample) in lines.zip(samples) {
        let cells: Vec<&str> = line.split(',').collect();
        let cell = |i: usize| cells[i].parse::<f64>().unwrap();
        assert_eq!(cell(0), sample["time"].as_f64().unwrap());
        assert_eq!(cell(5), sample["state"]["y"].as_f64().unwrap());
        assert_eq!(cell(11), sample["dstate"]["y"]["h0"].as_f64().unwrap());
    }
    let table = hybc(&["run", "models/ball.hyb", "--at", "0,1.25,2.5"]);
    let table = String::from_utf8_lossy(&table.stdout);
    assert!(table.contains("samples: 3"), "{table}");
    std::fs::remove_dir_all(&dir).ok();
}
