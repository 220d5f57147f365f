//! Every shipped model, compiled once: the gradients `hybc run` reports (event times, final state,
//! outputs) against central finite differences of the same compiled model re-simulated at
//! p +/- h. Tolerance: relative 2e-5 with an absolute floor of 1e-7. Integration at rtol 1e-12
//! and h = 1e-5 max(|p|, 1): round-off in the difference is ~1e-7 relative, and truncation stays
//! below 1e-6 even where event times curve sharply in p (engine_redline's dt/dc changes by 50%
//! over dc = 2e-4, so h = 1e-4 would not do).

use hybc::codegen::{compile, CompileOptions};
use hybc::lower::{lower, system_info};
use hybc::sema::ParamIdx;
use hybc::sim::{run, SimOptions, SimResult};

use crate::support::models::{shipped_models, ShippedModel};

/// Every differentiable number of a run, in a fixed order, with the matching derivative row.
fn observables(r: &SimResult, n_grad: usize, j: usize) -> (Vec<f64>, Vec<f64>) {
    let f = &r.final_state;
    let mut values = Vec::new();
    let mut derivs = Vec::new();
    for e in &r.events {
        values.push(e.time);
        derivs.push(e.dtime.as_ref().expect("no grazing in shipped models")[j]);
    }
    let n = f.state.len();
    let k = f.outputs.len();
    // At a `stop` event the final time moves with the parameters: the final values' derivatives
    // are the total ones (the walker's one step).
    let by_event = matches!(r.stopped_by, hybc::sim::StopReason::Event { .. });
    let (ds, dy) = if by_event { (&f.dstate_total, &f.doutputs_total) } else { (&f.dstate, &f.doutputs) };
    let ds = ds.as_ref().expect("dstate");
    let dy = dy.as_ref().expect("doutputs");
    assert_eq!(ds.len(), n * n_grad);
    values.extend(&f.state);
    derivs.extend((0..n).map(|i| ds[j * n + i]));
    values.extend(&f.outputs);
    derivs.extend((0..k).map(|i| dy[j * k + i]));
    (values, derivs)
}

#[test]
fn every_model_gradient_matches_central_differences() {
    let mut checked = 0;
    for ShippedModel { path, source, .. } in shipped_models() {
        let model = hybc::check_source(&source).unwrap_or_else(|e| panic!("{path}: {e}"));
        let funcs = lower(&model);
        let grad: Vec<ParamIdx> = (0..model.params.len()).map(|i| ParamIdx(i as u32)).collect();
        let info = system_info(&model, &grad);
        let compiled = compile(&funcs, info, &CompileOptions::default()).expect("compiles");
        let opts = SimOptions {
            t_end: model.simulate.t_end.unwrap_or(5.0),
            rtol: 1e-12,
            atol: 1e-14,
            ..SimOptions::default()
        };
        let p0: Vec<f64> = model.params.iter().map(|p| p.default).collect();
        let base = run(&compiled, &p0, &opts).expect("runs");
        assert!(
            matches!(base.stopped_by, hybc::sim::StopReason::TEnd | hybc::sim::StopReason::Event { .. }),
            "{path}: {:?}",
            base.stopped_by
        );
        for (j, param) in model.params.iter().enumerate() {
            let h = 1e-5 * p0[j].abs().max(1.0);
            let mut plus = p0.clone();
            plus[j] += h;
            let mut minus = p0.clone();
            minus[j] -= h;
            let rp = run(&compiled, &plus, &opts).expect("runs");
            let rm = run(&compiled, &minus, &opts).expect("runs");
            // A change in the number of events is a cusp of the objective, not a gradient error.
            assert_eq!(rp.events.len(), base.events.len(), "{path}: cusp in {}", param.name);
            assert_eq!(rm.events.len(), base.events.len(), "{path}: cusp in {}", param.name);
            let (_, d) = observables(&base, p0.len(), j);
            let (vp, _) = observables(&rp, p0.len(), j);
            let (vm, _) = observables(&rm, p0.len(), j);
            for (q, ((a, b), exact)) in vp.iter().zip(&vm).zip(&d).enumerate() {
                let fd = (a - b) / (2.0 * h);
                let tol = 2e-5 * fd.abs().max(exact.abs()) + 1e-7;
                assert!(
                    (fd - exact).abs() <= tol,
                    "{path}: d(observable {q})/d{}: reported {exact}, central difference {fd}",
                    param.name
                );
                checked += 1;
            }
        }
    }
    assert!(checked > 100, "only {checked} derivatives checked");
}
