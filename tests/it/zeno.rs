//! docs/language.md rule 10, from both sides: events accumulate when the intervals between them
//! shrink summably (geometrically, or like `1/k^2`), at any `t`; intervals that settle or shrink
//! like `1/k` are not Zeno, also at `t = 1e6`.

use hybc::sim::{Decay, StopReason};

use crate::support::runs::run;

const G: f64 = 9.81;

/// A particle between walls at 0 and 0.01 whose speed doubles at each hit up to 4096 (intervals
/// halve twelve times and settle at 0.01 / 4096 = 2.44e-6 s), set going by a time event at `t0`.
fn walls(t0: f64) -> String {
    format!(
        "model walls\nparam t0 = {t0:e}\nparam vmax = 4096\nstate x = 0.005\nstate v = 0\nder(x) = v\nder(v) = 0\n\
         event start when t >= t0 {{\n    v := 1\n}}\n\
         event right when x >= 0.01 {{\n    v := -min(2 * abs(v), vmax)\n}}\n\
         event left when x <= 0 {{\n    v := min(2 * abs(v), vmax)\n}}\n"
    )
}

#[test]
fn intervals_that_shrink_and_settle_are_not_zeno_at_any_t() {
    // 0.005 s to the first wall, 0.01 (1/2 + ... + 1/4096) s of halving intervals, then
    // 2.44e-6 s each: about 2,060 hits in 0.02 s, at t0 = 0 as at t0 = 1e6.
    let mut counts = Vec::new();
    for t0 in [0.0, 1e6] {
        let r = run(&walls(t0), &[], |o| {
            o.t_start = t0 - 0.001;
            o.t_end = t0 + 0.02;
        });
        assert_eq!(*r.stopped_by(), StopReason::TEnd, "t0 = {t0}: {:?}", r.report().failure());
        counts.push(r.events().len());
        let settled: Vec<f64> = r.events().windows(2).skip(20).map(|w| w[1].time - w[0].time).collect();
        for d in &settled {
            assert!((d - 0.01 / 4096.0).abs() < 1e-9, "t0 = {t0}: interval {d}");
        }
    }
    let want = 1 + 13 + ((0.02 - 0.005 - 0.01 * (1.0 - 1.0 / 4096.0)) * 4096.0 / 0.01) as usize;
    for c in &counts {
        assert!(c.abs_diff(want) <= 1, "{counts:?} vs {want}");
    }
    // Followed to --max-events, settled intervals are many events over a long time, not Zeno.
    let r = run(&walls(1e6), &[], |o| {
        o.t_start = 1e6 - 0.001;
        o.t_end = 1e6 + 1.0;
    });
    let StopReason::MaxEvents { count, .. } = *r.stopped_by() else { panic!("{:?}", r.stopped_by()) };
    assert_eq!(count, 10_000);
}

/// A ball whose restitution tends to 1 as the impact speed falls: `v := -(1 - 2 sqrt(|v| / C)) v`
/// makes `sqrt(v / C)` fall like `1/n`, the speeds and the intervals between bounces like `1/n^2`.
const SLOWING: &str = "model slowing\nparam C = 100\nstate y = 1\nstate v = 0\nder(y) = v\nder(v) = -9.81\n\
                       event floor when y <= 0 {\n    v := -(1 - 2 * sqrt(abs(v) / C)) * v\n}\n";

/// The accumulation point of [`SLOWING`] by its bounce map: the fall, then `2 w_k / g` per bounce
/// (`w_k` the speed after bounce k), ten million bounces summed and the rest, `sum_k 2 C / (g
/// k^2)` from `k = sqrt(C / w)`, added as `2 sqrt(C w) / g`.
fn slowing_accumulation(c: f64) -> f64 {
    let fall = (2.0 / G).sqrt();
    let (mut t, mut v) = (fall, G * fall);
    for _ in 0..10_000_000 {
        v *= 1.0 - 2.0 * (v / c).sqrt();
        t += 2.0 * v / G;
    }
    t + 2.0 * (c * v).sqrt() / G
}

#[test]
fn bounces_whose_intervals_fall_like_one_over_n_squared_are_zeno_with_their_accumulation_point() {
    let t_star = slowing_accumulation(100.0);
    let r = run(SLOWING, &[], |o| o.t_end = 100.0);
    let StopReason::Zeno { time, accumulation: Some(acc), .. } = r.stopped_by() else {
        panic!("{:?}", r.report().failure())
    };
    let left = t_star - time;
    assert!(left > 0.0, "stopped at {time}, past the accumulation point {t_star}");
    let Decay::Power { exponent } = acc.decay else { panic!("{acc:?}") };
    assert!((exponent - 2.0).abs() < 0.1, "exponent {exponent}");
    // The estimate is ten times closer to the accumulation point than the last event is.
    assert!((acc.estimate - t_star).abs() < 0.1 * left, "estimate {} vs {t_star}, {left} left", acc.estimate);
    let message = r.report().failure().expect("a message");
    assert!(message.contains("accumulate near t = ") && message.contains("like k^-"), "{message}");
}

#[test]
fn bounces_whose_intervals_fall_like_one_over_n_end_at_max_events() {
    // `v := -(1 - |v| / C) v`: speeds like C / n, intervals like 1/n, whose sum diverges: the
    // bounces go on for ever (t grows like log n) and the run ends at --max-events.
    let text = SLOWING.replace("2 * sqrt(abs(v) / C)", "abs(v) / C");
    let r = run(&text, &[], |o| o.t_end = 1e4);
    let StopReason::MaxEvents { count, time } = *r.stopped_by() else { panic!("{:?}", r.report().failure()) };
    assert_eq!(count, 10_000);
    // t_n ~ (2 C / g) ln n: far beyond where a summable sequence would have stopped.
    assert!(time > 100.0, "{time}");
    let message = r.report().failure().expect("a message");
    assert!(message.contains("raise --max-events"), "{message}");
}

#[test]
fn a_geometric_ball_is_zeno_with_its_ratio_and_an_upper_end_at_any_t() {
    let ball = "model ball\nparam e = 0.8\nstate y = 1\nstate v = 0\nder(y) = v\nder(v) = -9.81\n\
                event touchdown when y <= 0 {\n    v := -e * v\n}\n";
    let t1 = (2.0f64 / G).sqrt();
    for t0 in [0.0, 1e6] {
        let r = run(ball, &[], |o| {
            o.t_start = t0;
            o.t_end = t0 + 10.0;
        });
        let StopReason::Zeno { time, accumulation: Some(acc), .. } = r.stopped_by() else {
            panic!("t0 = {t0}: {:?}", r.report().failure())
        };
        let t_star = t0 + t1 * 1.8 / 0.2;
        let Decay::Geometric { ratio } = acc.decay else { panic!("t0 = {t0}: {acc:?}") };
        // At t = 1e6 the last intervals (1e-6 s) hold 1e4 spacings of t: the ratio to 1e-4.
        let ratio_tol = if t0 == 0.0 { 1e-6 } else { 1e-4 };
        assert!((ratio - 0.8).abs() < ratio_tol, "t0 = {t0}: ratio {ratio}");
        assert!(*time < t_star, "t0 = {t0}: {time}");
        assert!((acc.estimate - t_star).abs() <= 1e-6 * t_star.abs().max(1.0), "t0 = {t0}: {acc:?}");
        // Stopped once what is left is below the bounces' time accuracy, not 1e-9 |t| before.
        assert!(t_star - time < 1e-3, "t0 = {t0}: {} left", t_star - time);
    }
}
