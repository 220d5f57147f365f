//! Many events pending in one step: 10,000 thresholds `x >= k / 10000` crossed by `x = t`, all
//! within the reach of the first step. Each must fire once, in time order, at its time, and the
//! run must stay linear in the number of guards per step (it took over two minutes when every
//! located crossing re-evaluated every guard; the bound here is generous, the figure is in
//! `cargo bench --bench events`).
//!
//! Many events in one run: 10^5 events of a ticker written as JSON, whose peak memory must stay
//! that of the run's event records (it was a JSON tree of about 4 KB per event).

use std::time::{Duration, Instant};

use hybc::sim::StopReason;
use hybc::Model;
use serde_json::Value;

use crate::support::measured::{assert_bounded, hybc_measured};

fn thresholds(n: usize) -> String {
    let mut text = String::from("model many\nstate x = 0\nder(x) = 1\n");
    for k in 1..=n {
        text.push_str(&format!("event e{k} when x >= {k} / {n}\n"));
    }
    text
}

#[test]
fn ten_thousand_events_pending_in_one_step_fire_in_order_in_bounded_time() {
    let n = 10_000;
    let model = Model::parse(&thresholds(n)).expect("parses");
    let compiled = model.compile::<&str>(&[]).expect("compiles");
    let mut opts = model.sim_options();
    opts.t_end = 1.5;
    opts.max_events = n + 1;
    let started = Instant::now();
    let run = compiled.simulate(&model.params(), &opts).expect("runs");
    let elapsed = started.elapsed();
    assert_eq!(*run.stopped_by(), StopReason::TEnd);
    assert_eq!(run.events().len(), n);
    for (k, ev) in run.events().iter().enumerate() {
        assert_eq!(&*ev.name, format!("e{}", k + 1));
        // x = t is integrated over some 10,000 steps: its round-off, not the location, limits this.
        let t = (k + 1) as f64 / n as f64;
        assert!((ev.time - t).abs() <= 1e-12, "{} at {} not {t}", ev.name, ev.time);
    }
    assert!(elapsed < Duration::from_secs(120), "{elapsed:?}");
}

/// `x` rises at rate `r` and wraps to 0 at 1 (event `wrap`), crossing `e_k: x >= k / 1000` on the
/// way: 1000 events per unit of time, the k-th at `t = (q + k / 1000) / r` in period `q`, so
/// `dt/dr = -t / r`.
fn ticker() -> String {
    let mut text = String::from("model ticker\nparam r = 1\nstate x = 0\nder(x) = r\n");
    text.push_str("event wrap when x >= 1 {\n    x := 0\n}\n");
    for k in 1..1000 {
        text.push_str(&format!("event e{k} when x >= {k} / 1000\n"));
    }
    text
}

#[test]
fn a_hundred_thousand_events_stream_as_json_in_the_memory_of_their_records() {
    // 99 whole periods and the thresholds up to 0.95 of the 100th: 99,950 events.
    let args = ["run", "--t-end", "99.9505", "--grad", "r", "--max-events", "1000000", "--format", "json"];
    let (out, err, code, elapsed, peak) = hybc_measured(&ticker(), &args);
    assert_eq!(code, Some(0), "{err}");
    let json: Value = serde_json::from_str(&out).expect("one JSON object");
    let events = json["events"].as_array().expect("events");
    assert_eq!(events.len(), 99_950);
    assert_eq!(json["stats"]["events"], 99_950);
    for (j, e) in events.iter().enumerate() {
        let (q, k) = (j / 1000, j % 1000 + 1);
        let name = if k == 1000 { "wrap".to_string() } else { format!("e{k}") };
        let want = q as f64 + k as f64 / 1000.0;
        let (t, dt) = (e["time"].as_f64().unwrap(), e["dtime"]["r"].as_f64().unwrap());
        assert_eq!((e["index"].as_u64(), e["name"].as_str()), (Some(j as u64), Some(name.as_str())));
        // Times accumulate round-off over the periods (about 1e-13 relative here).
        assert!((t - want).abs() <= 1e-9 * want && (dt + want).abs() <= 1e-9 * want, "{e}");
    }
    // The records take about 150 bytes an event (15 MiB here) beside the compiled model of 1000
    // events; the JSON tree of the old output took some 400 MiB at this count.
    assert_bounded("99,950 events as JSON", elapsed, peak, Duration::from_secs(120), 150.0);
}
