//! Issue #25 item 5: how accurate are the reported derivatives against the values? The
//! diffusion chain of W5 with 10 cells (`benches/support/chain.rs`), here with a source that is
//! refilled whenever it drains to half (`x0 := 1` at `x0 <= 0.5`, 19 refills in T = 10: every
//! refill moves the sensitivities through an event), the 10 conductances differentiated. Each
//! method at rtol 1e-8 (atol 1e-10), with and without the sensitivities in the error control,
//! and with them, landing a step on each event instant or not (`SimOptions::land_events`),
//! against DOP853 at rtol 1e-12 (atol 1e-14) landing on each. Printed: steps, the largest error of the final
//! states (relative to the largest state), of the final sensitivities (relative to the largest
//! sensitivity), of the event times, of the event-time gradients (relative to the largest of
//! each event's), and the worst relative error of a single final sensitivity entry (entries
//! above 1e-6 of the largest).
//!
//! Run: `cargo run --release --example w5_accuracy`. The figures are in docs/accuracy.md.

use hybc::sim::{Method, SimOptions};
use hybc::Model;

#[path = "../support/chain.rs"]
mod chain;
use chain::{refill_source, D_NAMES};

fn max_abs<'a>(v: impl IntoIterator<Item = &'a f64>) -> f64 {
    v.into_iter().fold(0.0f64, |a, b| a.max(b.abs()))
}

fn main() {
    let model = Model::parse(&refill_source(10)).unwrap();
    let c = model.compile(&D_NAMES).unwrap();
    let p = c.params();
    // `land` None: each method's default (the Rosenbrock methods land, the explicit pairs not).
    let run = |rtol: f64, method: Method, sens_error_control: bool, land: Option<bool>| {
        let opts = SimOptions {
            t_end: 10.0,
            rtol,
            atol: rtol / 100.0,
            method,
            sens_error_control,
            land_events: land,
            ..SimOptions::default()
        };
        c.simulate(&p, &opts).unwrap().into_result()
    };
    let reference = run(1e-12, Method::Dop853, true, Some(true));
    let (xr, sr) = (&reference.final_state.state, reference.final_state.dstate.as_ref().unwrap());
    // The last row: what a run gets with no option set (`auto`, sensitivities in the error
    // control, each method's own landing rule).
    let cases = [Method::Dopri5, Method::Dop853, Method::Rodas5p]
        .into_iter()
        .flat_map(|m| [(m, false, Some(false)), (m, true, Some(false)), (m, true, Some(true))])
        .chain([(Method::Auto, true, None)]);
    for (method, sens, land) in cases {
        {
            let r = run(1e-8, method, sens, land);
            let (x, s) = (&r.final_state.state, r.final_state.dstate.as_ref().unwrap());
            let ex = max_abs(&x.iter().zip(xr).map(|(a, b)| a - b).collect::<Vec<_>>()) / max_abs(xr);
            let es = max_abs(&s.iter().zip(sr).map(|(a, b)| a - b).collect::<Vec<_>>()) / max_abs(sr);
            let (mut et, mut eg) = (0.0f64, 0.0f64);
            for (e, er) in r.events.iter().zip(&reference.events) {
                et = et.max((e.time - er.time).abs());
                let (a, b) = (e.dtime.as_ref().unwrap(), er.dtime.as_ref().unwrap());
                eg = eg.max(max_abs(&a.iter().zip(b).map(|(a, b)| a - b).collect::<Vec<_>>()) / max_abs(b));
            }
            let floor = 1e-6 * max_abs(sr);
            let worst = s
                .iter()
                .zip(sr)
                .filter(|(_, b)| b.abs() > floor)
                .map(|(a, b)| (a - b).abs() / b.abs())
                .fold(0.0, f64::max);
            println!(
                "{method:?} sens in error control {sens}, landing {land:?}: {} steps ({} rejected), {}/{} events; final states \
                 {ex:.1e}, final sensitivities {es:.1e}, event times {et:.1e}, event-time gradients \
                 {eg:.1e}, worst sensitivity entry {worst:.1e}",
                r.stats.steps,
                r.stats.rejected,
                r.events.len(),
                reference.events.len()
            );
            if method == Method::Auto {
                println!(
                    "  auto's segments: {:?}",
                    r.methods.iter().map(|s| (s.method, s.from, s.to, s.steps)).collect::<Vec<_>>()
                );
            }
        }
    }
}
