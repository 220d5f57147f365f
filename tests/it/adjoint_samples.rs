//! The adjoint carries samples at `--at` times (`SimOptions::at`): each sample's states and
//! outputs, as their own seeds, equal forward mode's derivatives of the same run (with the
//! sensitivities out of the error test) to round-off, however the sample was read: off a step's
//! dense output, at the end of a step retaken to land on it, at an event instant (after its
//! events), on an input knot (after it), at `t_start`, at `t_end`, before a stop; under every
//! method, landing on events or not, with checkpoints every 2 steps, the default and the full
//! tape (bit for bit the same); and through `hybc run --sens adjoint`'s door.

use hybc::sim::adjoint::{record_with, Checkpoints, SampleSeed, Seed};
use hybc::sim::{run, HybridSystem, Method, Sens, SimOptions, SimResult};

use crate::adjoint::compiled;

/// Forward mode's derivatives of every reached sample's states and outputs, with the seeds that
/// ask for them: `(label, seed, row of m)`.
fn sample_rows(r: &SimResult, n: usize, k: usize, m: usize) -> Vec<(String, Seed, Vec<f64>)> {
    let mut out = Vec::new();
    for (row, s) in r.samples.iter().enumerate().filter(|(_, s)| s.reached) {
        let (ds, dy) = (s.dstate.expect("dstate"), s.doutputs.expect("doutputs"));
        for i in 0..n {
            let mut w = vec![0.0; n];
            w[i] = 1.0;
            let seed = Seed {
                samples: vec![SampleSeed { row, state: w, ..SampleSeed::default() }],
                ..Seed::default()
            };
            out.push((format!("x{i}@{}", s.time), seed, (0..m).map(|j| ds[j * n + i]).collect()));
        }
        for i in 0..k {
            let mut w = vec![0.0; k];
            w[i] = 1.0;
            let seed = Seed {
                samples: vec![SampleSeed { row, outputs: w, ..SampleSeed::default() }],
                ..Seed::default()
            };
            out.push((format!("y{i}@{}", s.time), seed, (0..m).map(|j| dy[j * k + i]).collect()));
        }
    }
    out
}

/// The largest difference between two rows, relative to the larger of the forward row's largest
/// entry and `floor`.
fn rel_gap(adjoint: &[f64], forward: &[f64], floor: f64) -> f64 {
    let scale = forward.iter().fold(floor, |a, b| a.max(b.abs()));
    let gap = adjoint.iter().zip(forward).fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
    if scale == 0.0 {
        gap
    } else {
        gap / scale
    }
}

fn bits(rows: &[Vec<f64>]) -> Vec<Vec<u64>> {
    rows.iter().map(|r| r.iter().map(|x| x.to_bits()).collect()).collect()
}

/// Every reached sample's gradients by the adjoint against forward mode's, for the full tape,
/// checkpoints every 2 steps and the default (the three bit for bit the same); and the door
/// (`Sens::Adjoint`) reports the same. Returns the worst gap and how many samples were reached.
fn compare(label: &str, sys: &impl HybridSystem, p: &[f64], opts: &SimOptions) -> (f64, usize) {
    let opts = SimOptions { sens_error_control: false, ..opts.clone() };
    let forward = run(sys, p, &opts).expect("runs");
    let info = sys.info();
    let (n, k, m) = (info.n_states(), info.n_outputs(), info.n_grad());
    let rows = sample_rows(&forward, n, k, m);
    let floor = 1e-3 * rows.iter().flat_map(|r| &r.2).fold(0.0f64, |a, b| a.max(b.abs()));
    let seeds: Vec<Seed> = rows.iter().map(|r| r.1.clone()).collect();
    let mut by_tape = Vec::new();
    for checkpoints in [Checkpoints::Every(1), Checkpoints::Every(2), Checkpoints::Sqrt] {
        let recorded = record_with(sys, p, &opts, checkpoints).expect("records");
        let value_bits = |r: &SimResult| -> Vec<u64> {
            r.samples.iter().flat_map(|s| s.state.iter().chain(s.outputs)).map(|v| v.to_bits()).collect()
        };
        assert_eq!(value_bits(&recorded.result), value_bits(&forward), "{label}: the samples' values");
        let got =
            recorded.gradients(sys, p, &seeds).unwrap_or_else(|e| panic!("{label} {checkpoints:?}: {e}"));
        by_tape.push(got);
    }
    for other in &by_tape[1..] {
        assert_eq!(bits(other), bits(&by_tape[0]), "{label}: checkpoints change the gradients");
    }
    let mut worst = 0.0f64;
    for ((what, _, fwd), adj) in rows.iter().zip(&by_tape[0]) {
        let gap = rel_gap(adj, fwd, floor);
        assert!(gap <= 1e-11, "{label} {what}: adjoint {adj:?}\nforward {fwd:?}\ngap {gap:e}");
        worst = worst.max(gap);
    }
    // The door: the same samples' derivatives in the result, the run said to be the adjoint's.
    let door = run(sys, p, &SimOptions { sens: Sens::Adjoint, ..opts.clone() }).expect("runs");
    assert_eq!(door.stats.sens, Some(Sens::Adjoint), "{label}: {:?}", door.warnings);
    for (f, a) in forward.samples.iter().zip(door.samples.iter()) {
        assert_eq!((f.time, f.reached, f.after_events), (a.time, a.reached, a.after_events));
        match (f.dstate, a.dstate, f.doutputs, a.doutputs) {
            (Some(fs), Some(as_), Some(fy), Some(ay)) => {
                assert!(rel_gap(as_, fs, floor) <= 1e-11, "{label} @{}: {as_:?} vs {fs:?}", f.time);
                assert!(rel_gap(ay, fy, floor) <= 1e-11, "{label} @{}: {ay:?} vs {fy:?}", f.time);
            }
            (None, None, None, None) => assert!(!f.reached),
            other => panic!("{label} @{}: {other:?}", f.time),
        }
    }
    (worst, rows.len() / (n + k).max(1))
}

/// A ball under a `pwc` push (knots at 0.5, 1, 1.5), kicked by a time event at 0.7, bouncing.
const BALL: &str = "model ball\nparam g = 9.81\nparam e = 0.8\nparam h0 = 1\nparam k = 0.6\nparam u[4] = 0\n\
                    state y = h0\nstate v = 0\n\
                    der(y) = v\nder(v) = -g + pwc(t, 0, 2, u) * (1 + 0.1 * y)\n\
                    event touchdown when y <= 0 {\n v := -e * v\n}\n\
                    event kick when t >= 0.7 {\n v := v + k\n}\n\
                    output energy = 0.5 * v^2 + g * y\n";

/// Samples every 0.05 from `t_start` to `t_end`: on the knots, on the kick, at both ends.
fn grid(t_end: f64) -> Vec<f64> {
    let count = (t_end * 20.0).round() as usize;
    (0..=count).map(|i| i as f64 / 20.0).collect()
}

#[test]
fn the_adjoint_carries_samples_under_every_method_landing_on_events_or_not() {
    let u = [1.0, -2.0, 0.5, 3.0];
    let (compiled, p) = compiled(BALL, &[("u", &u)]);
    let t_end = 2.5;
    let at = grid(t_end);
    for method in [Method::Auto, Method::Dopri5, Method::Dop853, Method::Rodas5p, Method::Rodas4] {
        for land in [None, Some(true), Some(false)] {
            let opts = SimOptions {
                t_end,
                rtol: 1e-10,
                atol: 1e-12,
                method,
                land_events: land,
                at: at.clone(),
                ..SimOptions::default()
            };
            let label = format!("ball {method:?} {land:?}");
            let (worst, reached) = compare(&label, compiled.system(), &p, &opts);
            assert_eq!(reached, at.len(), "{label}");
            eprintln!("{label}: {reached} samples, worst {worst:.1e}");
        }
    }
    // Samples do not break the chains of steps recomputed from one checkpoint: the tape keeps
    // the same states with and without them.
    for method in [Method::Dopri5, Method::Rodas5p] {
        let opts = SimOptions { t_end, rtol: 1e-10, atol: 1e-12, method, ..SimOptions::default() };
        let kept = |at: Vec<f64>| {
            let r = record_with(compiled.system(), &p, &SimOptions { at, ..opts.clone() }, Checkpoints::Sqrt);
            let tape = r.expect("records").tape;
            (tape.steps(), tape.kept_states())
        };
        let (without, with) = (kept(Vec::new()), kept(at.clone()));
        assert_eq!(without, with, "{method:?}: (steps, kept states) without and with samples");
        assert!(with.1 < with.0, "{method:?}: {with:?}");
    }
    // The run these samples test: events, knots, a sample at the kick taken after it.
    let r =
        run(compiled.system(), &p, &SimOptions { t_end, at: at.clone(), ..SimOptions::default() }).unwrap();
    assert!(r.events.len() >= 3 && r.stats.switches >= 3, "{:?}", r.stats);
    let kick = r.samples.at_time(0.7).expect("asked for");
    assert!(kick.after_events, "the sample at the kick's instant is taken after it");
}

#[test]
fn the_adjoint_carries_samples_before_a_stop_and_leaves_the_later_ones_unreached() {
    // The ball stops on its way up after the first bounce (a state guard, at about t = 0.6);
    // the samples after it are not reached.
    let src = "model drop\nparam g = 9.81\nparam e = 0.8\nparam h0 = 1\nstate y = h0\nstate v = 0\n\
               der(y) = v\nder(v) = -g\n\
               event touchdown when y <= 0 {\n v := -e * v\n}\n\
               event high when t * y >= 0.3 {\n stop\n}\n\
               output energy = 0.5 * v^2 + g * y\n";
    let (compiled, p) = compiled(src, &[]);
    for method in [Method::Dopri5, Method::Rodas5p] {
        let opts = SimOptions {
            t_end: 3.0,
            rtol: 1e-10,
            atol: 1e-12,
            method,
            at: grid(3.0),
            ..SimOptions::default()
        };
        let (_, reached) = compare(&format!("drop {method:?}"), compiled.system(), &p, &opts);
        let r = run(compiled.system(), &p, &opts).unwrap();
        assert!(matches!(r.stopped_by, hybc::sim::StopReason::Event { .. }), "{:?}", r.stopped_by);
        assert!(reached > 0 && reached < opts.at.len(), "{reached} of {}", opts.at.len());
    }
}

#[test]
fn the_adjoint_gives_the_closed_form_of_samples_of_a_ramp() {
    // x' = p, x(0) = 1: x(t_k) = 1 + p t_k, dx(t_k)/dp = t_k; y = p x: dy/dp = x + p t_k.
    let src = "model ramp\nparam p = 0.7\nstate x = 1\nder(x) = p\noutput y = p * x\n";
    let (compiled, params) = compiled(src, &[]);
    let at: Vec<f64> = (0..=40).map(|i| i as f64 * 0.0625).collect();
    for method in [Method::Dopri5, Method::Dop853, Method::Rodas5p, Method::Rodas4] {
        let opts =
            SimOptions { t_end: 2.5, at: at.clone(), method, sens: Sens::Adjoint, ..SimOptions::default() };
        let r = run(compiled.system(), &params, &opts).expect("runs");
        assert_eq!(r.stats.sens, Some(Sens::Adjoint));
        for s in r.samples.iter() {
            let (x, t, p) = (1.0 + 0.7 * s.time, s.time, 0.7);
            let (dx, dy) = (s.dstate.unwrap()[0], s.doutputs.unwrap()[0]);
            assert!((dx - t).abs() <= 1e-13 * t.max(1.0), "{method:?} dx/dp @{t}: {dx}");
            assert!((dy - (x + p * t)).abs() <= 1e-13 * x.max(1.0), "{method:?} dy/dp @{t}: {dy}");
        }
    }
}

#[test]
fn the_adjoint_gives_of_name_at_time_gradients_and_leaves_the_rest_out() {
    // `--of x@1.5`: one sample's state, one backward pass; the other samples' entries are NaN.
    let (compiled, p) = compiled(BALL, &[("u", &[1.0, -2.0, 0.5, 3.0])]);
    let info = compiled.system().info();
    let of = hybc::sim::GradientsOf { samples: vec![(false, 0, 1.5)], ..Default::default() };
    let base = SimOptions {
        t_end: 2.5,
        rtol: 1e-10,
        atol: 1e-12,
        at: vec![0.5, 1.5],
        of: Some(of),
        sens_error_control: false,
        ..SimOptions::default()
    };
    let forward = run(compiled.system(), &p, &base).unwrap();
    let adjoint = run(compiled.system(), &p, &SimOptions { sens: Sens::Adjoint, ..base }).unwrap();
    assert_eq!(adjoint.stats.sens, Some(Sens::Adjoint));
    let (n, m) = (info.n_states(), info.n_grad());
    let (f, a) = (forward.samples.get(1).unwrap(), adjoint.samples.get(1).unwrap());
    let col = |d: &[f64]| (0..m).map(|j| d[j * n]).collect::<Vec<_>>();
    let (fy, ay) = (col(f.dstate.unwrap()), col(a.dstate.unwrap()));
    assert!(rel_gap(&ay, &fy, 0.0) <= 1e-11, "{ay:?} vs {fy:?}");
    assert!(a.dstate.unwrap().iter().enumerate().all(|(i, d)| (i % n == 0) != d.is_nan()));
    assert!(adjoint.samples.get(0).unwrap().dstate.unwrap().iter().all(|d| d.is_nan()));
}
