//! The discrete adjoint (`sim::adjoint`) against the forward sensitivities of the same run: for
//! every shipped model, every parameter differentiated, each reported quantity (event times,
//! final states, final outputs; the total derivatives at a stop event) as its own seed. The
//! adjoint differentiates the steps a run with the sensitivities out of the error test takes, so
//! the forward run compared with has `sens_error_control` off; both are the derivative of one
//! computation and agree to round-off. A run the backward pass does not carry yet must say so
//! (`AdjointError::Unsupported`), never give a number.

use hybc::codegen::{compile, CompileOptions};
use hybc::lower::{lower, system_info};
use hybc::sema::ParamIdx;
use hybc::sim::adjoint::{record, AdjointError, Seed};
use hybc::sim::{run, Method, SimOptions, SimResult, StopReason};

use crate::support::models::{shipped_models, ShippedModel};

/// Largest difference between the adjoint's and the forward gradient of one quantity, relative
/// to the forward gradient's largest entry, or to `floor` (the run's largest gradient entry times
/// 1e-3) where that is smaller: a quantity that does not move with the parameters (a state the
/// stop's reset sets) has forward derivatives of round-off, and so has the adjoint.
fn rel_gap(adjoint: &[f64], forward: &[f64], floor: f64) -> f64 {
    let scale = forward.iter().fold(floor, |a, b| a.max(b.abs()));
    let gap = adjoint.iter().zip(forward).fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
    if scale == 0.0 {
        gap
    } else {
        gap / scale
    }
}

/// The forward gradient rows of every quantity, with the seed that asks for it.
fn quantities(r: &SimResult, n: usize, k: usize, m: usize) -> Vec<(String, Seed, Vec<f64>)> {
    let mut out = Vec::new();
    for (e, rec) in r.events.iter().enumerate() {
        let seed = Seed { event_times: vec![(e, 1.0)], ..Seed::default() };
        out.push((
            format!("event {e} ({})", rec.name),
            seed,
            rec.dtime.clone().expect("event time gradient"),
        ));
    }
    let f = &r.final_state;
    let by_event = matches!(r.stopped_by, StopReason::Event { .. });
    for total in [false, true] {
        if total && !by_event {
            continue;
        }
        let (ds, dy) = if total { (&f.dstate_total, &f.doutputs_total) } else { (&f.dstate, &f.doutputs) };
        let (ds, dy) = (ds.as_ref().expect("dstate"), dy.as_ref().expect("doutputs"));
        for i in 0..n {
            let mut w = vec![0.0; n];
            w[i] = 1.0;
            let seed = Seed { state: w, total, ..Seed::default() };
            out.push((format!("state {i} total={total}"), seed, (0..m).map(|j| ds[j * n + i]).collect()));
        }
        for i in 0..k {
            let mut w = vec![0.0; k];
            w[i] = 1.0;
            let seed = Seed { outputs: w, total, ..Seed::default() };
            out.push((format!("output {i} total={total}"), seed, (0..m).map(|j| dy[j * k + i]).collect()));
        }
    }
    out
}

fn check_every_model(method: Method, land: Option<bool>) {
    let (mut carried, mut refused) = (Vec::new(), Vec::new());
    for ShippedModel { path, source, .. } in shipped_models() {
        let model = hybc::check_source(&source).unwrap_or_else(|e| panic!("{path}: {e}"));
        let funcs = lower(&model);
        let grad: Vec<ParamIdx> = (0..model.params.len()).map(|i| ParamIdx(i as u32)).collect();
        let info = system_info(&model, &grad);
        let compiled = compile(&funcs, info, &CompileOptions::default()).expect("compiles");
        let opts = SimOptions {
            t_end: model.simulate.t_end.unwrap_or(5.0),
            rtol: 1e-10,
            atol: 1e-12,
            method,
            land_events: land,
            sens_error_control: false,
            ..SimOptions::default()
        };
        let p: Vec<f64> = model.params.iter().map(|p| p.default).collect();
        let forward = run(&compiled, &p, &opts).expect("runs");
        let recorded = record(&compiled, &p, &opts).expect("records");
        // The same steps: the same events at the same times, the same final state, bit for bit.
        let times = |r: &SimResult| r.events.iter().map(|e| (e.event, e.time.to_bits())).collect::<Vec<_>>();
        assert_eq!(times(&forward), times(&recorded.result), "{path}: events");
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&forward.final_state.state), bits(&recorded.result.final_state.state), "{path}");
        let (n, k, m) = (forward.final_state.state.len(), forward.final_state.outputs.len(), grad.len());
        let mut worst = (0.0f64, String::new());
        let rows = quantities(&forward, n, k, m);
        let floor = 1e-3 * rows.iter().flat_map(|r| &r.2).fold(0.0f64, |a, b| a.max(b.abs()));
        for (what, seed, fwd) in rows {
            match recorded.gradient(&compiled, &p, &seed) {
                Ok(adj) => {
                    let gap = rel_gap(&adj, &fwd, floor);
                    assert!(gap <= 1e-11, "{path} {what}: adjoint {adj:?}\nforward {fwd:?}\ngap {gap:e}");
                    if gap > worst.0 {
                        worst = (gap, what);
                    }
                }
                Err(AdjointError::Unsupported(why)) => {
                    refused.push(format!("{path}: {why}"));
                    break;
                }
                Err(e) => panic!("{path} {what}: {e}"),
            }
        }
        if refused.last().is_none_or(|r| !r.starts_with(&path)) {
            carried.push(format!("{path}: worst {:.1e} ({})", worst.0, worst.1));
        }
    }
    eprintln!(
        "{method:?} land={land:?}\ncarried:\n  {}\nrefused:\n  {}",
        carried.join("\n  "),
        refused.join("\n  ")
    );
    assert!(carried.len() >= 5, "too few models carried: {carried:?}");
}

#[test]
fn the_adjoint_equals_forward_sensitivities_on_every_shipped_model() {
    check_every_model(Method::Auto, None);
}

#[test]
fn the_adjoint_equals_forward_sensitivities_under_each_pair_landing_on_events_or_not() {
    for method in [Method::Dopri5, Method::Dop853] {
        for land in [true, false] {
            check_every_model(method, Some(land));
        }
    }
}
