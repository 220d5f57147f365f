//! Many events pending in one step: 10,000 thresholds `x >= k / 10000` crossed by `x = t`, all
//! within the reach of the first step. Each must fire once, in time order, at its time, and the
//! run must stay linear in the number of guards per step (it took over two minutes when every
//! located crossing re-evaluated every guard; the bound here is generous, the figure is in
//! `cargo bench --bench events`).

use std::time::{Duration, Instant};

use hybc::sim::StopReason;
use hybc::Model;

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
