//! Checkpoints of the adjoint tape (`sim::adjoint::Checkpoints`): the backward pass recomputes
//! the step start states the tape did not keep, by the same steppers from the checkpoint before
//! them, so the gradients are the full tape's to the bit, under every method, through events,
//! knots, flow switches and `auto`'s switches, for a segment of 2, 3 or 7 steps, one longer than
//! the run, and the default (`sqrt` of the steps); and the tape keeps the states it says it does.

use hybc::codegen::{compile, CompileOptions};
use hybc::lower::{lower, system_info};
use hybc::sema::ParamIdx;
use hybc::sim::adjoint::{record_with, AdjointError, Checkpoints, Recorded, Seed};
use hybc::sim::{HybridSystem, LinearSolver, Method, SimOptions, StopReason};

use crate::support::models::{shipped_models, ShippedModel};

/// Every quantity a run reports, as a seed: event times, final states and outputs (and their
/// total derivatives at a stop event).
fn seeds(r: &Recorded, n: usize, k: usize) -> Vec<Seed> {
    let mut out: Vec<Seed> =
        (0..r.result.events.len()).map(|e| Seed { event_times: vec![(e, 1.0)], ..Seed::default() }).collect();
    let at_stop = matches!(r.result.stopped_by, StopReason::Event { .. });
    for total in [false, true].into_iter().filter(|&t| !t || at_stop) {
        for i in 0..n {
            let mut w = vec![0.0; n];
            w[i] = 1.0;
            out.push(Seed { state: w, total, ..Seed::default() });
        }
        for i in 0..k {
            let mut w = vec![0.0; k];
            w[i] = 1.0;
            out.push(Seed { outputs: w, total, ..Seed::default() });
        }
    }
    out
}

fn bits(rows: &[Vec<f64>]) -> Vec<Vec<u64>> {
    rows.iter().map(|r| r.iter().map(|x| x.to_bits()).collect()).collect()
}

/// The checkpoint choices compared with the full tape.
const CHOICES: [Checkpoints; 5] = [
    Checkpoints::Every(2),
    Checkpoints::Every(3),
    Checkpoints::Every(7),
    Checkpoints::Every(1 << 40),
    Checkpoints::Sqrt,
];

/// The gradients of every quantity of one run of `sys` at `p` with each checkpoint choice,
/// against the full tape's (`Every(1)`), bit for bit. Returns the run's steps and the least
/// states a checkpointed tape kept (so that a caller can see recomputation happened), or the
/// adjoint's refusal.
fn same_bits<S: HybridSystem>(
    label: &str,
    sys: &S,
    p: &[f64],
    opts: &SimOptions,
) -> Result<(usize, usize), String> {
    let full = record_with(sys, p, opts, Checkpoints::Every(1)).expect("records");
    let info = sys.info();
    let all = seeds(&full, info.n_states(), info.n_outputs());
    let want = match full.gradients(sys, p, &all) {
        Ok(rows) => rows,
        Err(AdjointError::Unsupported(why)) => return Err(why.to_string()),
        Err(e) => panic!("{label}: {e}"),
    };
    let steps = full.tape.steps();
    assert_eq!(full.tape.kept_states(), steps, "{label}: the full tape keeps every step's start");
    let mut least = steps;
    for choice in CHOICES {
        let tape = record_with(sys, p, opts, choice).expect("records");
        // The recording itself is the same run.
        assert_eq!(tape.result.final_state.state, full.result.final_state.state, "{label} {choice:?}");
        assert_eq!(tape.tape.steps(), steps, "{label} {choice:?}");
        let got = tape.gradients(sys, p, &all).unwrap_or_else(|e| panic!("{label} {choice:?}: {e}"));
        assert!(bits(&got) == bits(&want), "{label} {choice:?}: {got:?}\nfull tape: {want:?}");
        least = least.min(tape.tape.kept_states());
    }
    Ok((steps, least))
}

fn compiled(src: &str) -> (hybc::Compiled, Vec<f64>) {
    let model = hybc::Model::parse(src).unwrap_or_else(|e| panic!("{e}"));
    let names: Vec<String> = model.params().iter().map(|(name, _)| name.to_string()).collect();
    let compiled = model.compile(&names).expect("compiles");
    let p = compiled.params().values().to_vec();
    (compiled, p)
}

#[test]
fn checkpointed_gradients_are_the_full_tapes_on_every_shipped_model_under_every_method() {
    let mut recomputed = 0;
    for ShippedModel { path, source, .. } in shipped_models() {
        let model = hybc::check_source(&source).unwrap_or_else(|e| panic!("{path}: {e}"));
        let grad: Vec<ParamIdx> = (0..model.params.len()).map(|i| ParamIdx(i as u32)).collect();
        let compiled =
            compile(&lower(&model), system_info(&model, &grad), &CompileOptions::default()).unwrap();
        let p: Vec<f64> = model.params.iter().map(|p| p.default).collect();
        for method in [Method::Auto, Method::Dopri5, Method::Dop853, Method::Rodas5p, Method::Rodas4] {
            for land in [None, Some(false)] {
                let opts = SimOptions {
                    t_end: model.simulate.t_end.unwrap_or(5.0),
                    rtol: 1e-10,
                    atol: 1e-12,
                    method,
                    land_events: land,
                    ..SimOptions::default()
                };
                let label = format!("{path} {method:?} {land:?}");
                let (steps, least) =
                    same_bits(&label, &compiled, &p, &opts).unwrap_or_else(|why| panic!("{label}: {why}"));
                recomputed += steps - least;
            }
        }
    }
    assert!(recomputed > 1000, "the checkpointed tapes recomputed {recomputed} states in all");
}

#[test]
fn checkpointed_gradients_are_the_full_tapes_through_knots_switches_cascades_and_stiff_steps() {
    let inputs = "model inputs\nparam u[5] = 0.5\nparam w[4] = 0.3\n\
                  param t0 = 0.1\nparam t1 = 1.7\nparam k = 0.8\n\
                  state y = 1\nstate v = 0\nstate c = 0\n\
                  der(y) = v\nder(v) = -9.81 + pwc(t, t0, t1, u) * (1 + 0.1 * y) - k * v\n\
                  der(c) = pwl(t, 0, 2, w) * y^2\n\
                  event bounce when y <= 0 {\n v := -k * v\n}\n";
    let relay = "model relay\nparam a = 1.3\nparam b = 0.4\nparam w = 3\n\
                 state x = 0.2\nstate y = 0\n\
                 der(x) = if x > b then a * (1 + 0.5 * x) else 2 * a\n\
                 der(y) = if sin(w * t) > 0.2 then x else -x * x\n\
                 event kick when y >= 0.3 {\n y := 0\n}\n";
    let cascade = "model cascade\nparam h = 1\nparam k = 0.7\nstate x = 0\nstate n = 0\nstate y = 0.2\n\
                   der(x) = 1 + 0.1 * y\nder(n) = 0\nder(y) = k * x\n\
                   event a when x >= h {\n x := 2 * h\n y := y + k\n}\n\
                   event b when x >= 1.5 * h {\n n := n + x\n y := 0.5 * y\n}\n\
                   event c when y >= 2 {\n y := 0\n}\n\
                   event d when y >= 2 {\n n := n + 1\n}\n";
    // `auto` switching from Dormand-Prince to Rodas5P and back inside the run.
    let jump = "model jump\nparam k0 = 1\nparam k1 = 1e6\nparam x0 = 1\nstate x = x0\nstate u = 0\n\
                state k = k0\nder(x) = -k * (x - cos(t)) + 0.1 * x^2\nder(u) = 1\nder(k) = 0\n\
                event stiffen when u >= 1 {\n k := k1\n}\nevent relax when u >= 3 {\n k := k0\n}\n";
    let robertson = "model robertson\nparam k1 = 0.04\nparam k2 = 3e7\nparam k3 = 1e4\n\
                     state y1 = 1\nstate y2 = 0\nstate y3 = 0\nstate k = k1\n\
                     der(y1) = -k * y1 + k3 * y2 * y3\nder(y2) = k * y1 - k3 * y2 * y3 - k2 * y2 * y2\n\
                     der(y3) = k2 * y2 * y2\nder(k) = 0\nevent faster when y1 <= 0.5 {\n k := 2 * k\n}\n";
    let vdp = "model vdp\nparam mu = 100\nparam a = 2\nstate x = a\nstate y = 0\n\
               der(x) = y\nder(y) = mu * ((1 - x^2) * y - x)\n\
               event half when x <= 1 {\n y := 0.9 * y\n}\noutput e = x^2 + y^2 / mu^2\n";
    let w5 = crate::support::chain::diffusion_source(12, true);
    let cases: [(&str, &str, f64, f64, &[Method]); 7] = [
        ("inputs", inputs, 2.5, 1e-10, &[Method::Dopri5, Method::Dop853, Method::Rodas5p, Method::Rodas4]),
        ("relay", relay, 3.0, 1e-10, &[Method::Dopri5, Method::Rodas4]),
        ("cascade", cascade, 3.0, 1e-10, &[Method::Dop853, Method::Rodas5p]),
        ("jump", jump, 10.0, 1e-6, &[Method::Auto]),
        ("robertson", robertson, 1e3, 1e-8, &[Method::Rodas5p, Method::Auto]),
        ("vdp", vdp, 1.0, 1e-8, &[Method::Rodas4, Method::Auto]),
        ("w5", &w5, 6.0, 1e-8, &[Method::Rodas5p, Method::Dopri5]),
    ];
    for (label, src, t_end, rtol, methods) in cases {
        let (compiled, p) = compiled(src);
        for &method in methods {
            let solvers: &[LinearSolver] = if label == "w5" {
                &[LinearSolver::Banded, LinearSolver::Sparse, LinearSolver::Dense]
            } else {
                &[LinearSolver::Auto]
            };
            for &linear_solver in solvers {
                let opts = SimOptions {
                    t_end,
                    rtol,
                    atol: rtol * 1e-2,
                    method,
                    linear_solver,
                    ..SimOptions::default()
                };
                let label = format!("{label} {method:?} {linear_solver:?}");
                let (steps, least) = same_bits(&label, compiled.system(), &p, &opts)
                    .unwrap_or_else(|why| panic!("{label}: {why}"));
                eprintln!("{label}: {steps} steps, {least} kept at the fewest");
                assert!(least < steps, "{label}: nothing was recomputed");
            }
        }
    }
}

/// A run with no event, knot or switch: one chain of steps.
const DECAY: &str = "model decay\nparam k = 0.5\nparam w = 3\nstate x = 1\nstate y = 0\n\
                     der(x) = -k * x + sin(w * t)\nder(y) = x\n";

#[test]
fn the_tape_keeps_one_state_per_segment_and_the_first_stages_it_recomputes_from() {
    let (compiled, p) = compiled(DECAY);
    let sys = compiled.system();
    let opts =
        SimOptions { t_end: 40.0, rtol: 1e-10, atol: 1e-12, method: Method::Dopri5, ..SimOptions::default() };
    let full = record_with(sys, &p, &opts, Checkpoints::Every(1)).unwrap();
    let steps = full.tape.steps();
    assert!(steps > 300, "{steps} steps");
    let n = sys.info().n_states();
    for k in [1, 2, 3, 10, 100, steps, steps + 1] {
        let r = record_with(sys, &p, &opts, Checkpoints::Every(k)).unwrap();
        let segments = steps.div_ceil(k);
        assert_eq!(r.tape.kept_states(), segments, "K = {k}");
        // A state per segment, and its first stage's derivative where a step is recomputed
        // from it: 2n numbers a segment of more than one step, n for one of a single step.
        let single = usize::from(steps % k == 1 || k == 1);
        let numbers = n * (2 * segments - if k == 1 { segments } else { single });
        assert_eq!(r.tape.stored_numbers(), numbers, "K = {k}");
    }
    // The default: a segment of at most ceil(sqrt(j)) steps at the j-th step, so about
    // 2 sqrt(steps) checkpoints.
    let r = record_with(sys, &p, &opts, Checkpoints::Sqrt).unwrap();
    let kept = r.tape.kept_states();
    let bound = 2.0 * (steps as f64).sqrt() + 2.0;
    assert!((kept as f64) <= bound && (kept as f64) >= bound / 2.0 - 2.0, "{kept} kept of {steps} steps");
    // The memory the tape reports shrinks with them (a long run: 1e4 steps).
    let long = SimOptions { t_end: 2000.0, ..opts.clone() };
    let full = record_with(sys, &p, &long, Checkpoints::Every(1)).unwrap();
    let sparse = record_with(sys, &p, &long, Checkpoints::Sqrt).unwrap();
    let steps = full.tape.steps();
    assert!(steps > 10_000, "{steps} steps");
    assert_eq!(full.tape.stored_numbers(), n * steps);
    assert!(sparse.tape.stored_numbers() <= n * (2 * sparse.tape.kept_states()));
    assert!(
        sparse.tape.stored_numbers() * 20 < full.tape.stored_numbers(),
        "{} of {}",
        sparse.tape.stored_numbers(),
        full.tape.stored_numbers()
    );
    assert!(sparse.tape.bytes() < full.tape.bytes());
    let all = seeds(&full, n, 0);
    assert_eq!(
        bits(&full.gradients(sys, &p, &all).unwrap()),
        bits(&sparse.gradients(sys, &p, &all).unwrap())
    );
}
