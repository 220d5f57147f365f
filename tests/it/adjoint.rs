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
use hybc::sim::{run, LinearSolver, Method, Sens, SimOptions, SimResult, StopReason};

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

/// The values of the quantities of [`quantities`], in its order.
fn values(r: &SimResult, n: usize, k: usize) -> Vec<f64> {
    let mut out: Vec<f64> = r.events.iter().map(|e| e.time).collect();
    let f = &r.final_state;
    let by_event = matches!(r.stopped_by, StopReason::Event { .. });
    for total in [false, true] {
        if !total || by_event {
            out.extend(&f.state[..n]);
            out.extend(&f.outputs[..k]);
        }
    }
    out
}

/// How many times a run's round-off may be amplified in a gradient before the gap is called a
/// defect: the measure below is one sample of the amplification, and a derivative takes several
/// roundings for each of its value's.
const AMPLIFICATION_MARGIN: f64 = 100.0;

/// The run's own amplification of round-off, per quantity: the run again with every parameter
/// one ulp away (lower, else higher), taking as many steps to the same events, moves each
/// quantity by its derivative's prediction (`dQ/dp . dp`, about `eps |p dQ/dp|`) plus the run's
/// round-off as the run amplifies it; that remainder over `eps |Q|` is the amplification `A`,
/// and a gradient's own round-off is about `A eps` relative. An explicit pair whose steps pass
/// its stability limit multiplies round-off in the fast modes by up to `|R(h lambda)|` a step
/// (the chain: `A` from 4e3 to 1e5, docs/accuracy.md); a well-conditioned run gives `A` of a
/// few, which leaves the bound at 1e-11. `None` where both nudged runs take another number of
/// steps.
fn amplified_round_off<S: hybc::sim::HybridSystem>(
    sys: &S,
    p: &[f64],
    opts: &SimOptions,
    base: &SimResult,
    rows: &[(String, Seed, Vec<f64>)],
) -> Option<Vec<f64>> {
    // The same accepted steps and events (the rejected ones may differ: past the stability
    // limit the step control itself follows the amplified round-off).
    let same_steps =
        |other: &SimResult| other.stats.steps == base.stats.steps && other.events.len() == base.events.len();
    // One ulp lower, else one ulp higher.
    let (nudged, other) = [f64::next_down, f64::next_up].into_iter().find_map(|nudge| {
        let nudged: Vec<f64> = p.iter().map(|&v| nudge(v)).collect();
        let other = run(sys, &nudged, opts).ok()?;
        same_steps(&other).then_some((nudged, other))
    })?;
    let info = sys.info();
    let (n, k) = (info.n_states(), info.n_outputs());
    let (q0, q1) = (values(base, n, k), values(&other, n, k));
    let grad_of = &info.grad_params;
    let amplification = rows
        .iter()
        .zip(q0.iter().zip(&q1))
        .map(|((_, _, d), (a, b))| {
            let predicted: f64 = d.iter().zip(grad_of).map(|(dq, &j)| dq * (nudged[j] - p[j])).sum();
            let remainder = (b - a - predicted).abs();
            remainder / (f64::EPSILON * a.abs().max(f64::MIN_POSITIVE))
        })
        .collect();
    Some(amplification)
}

/// Forward and adjoint gradients of every quantity of one run of `sys` at `p`: `Ok(worst gap,
/// its quantity)`, or the adjoint's refusal. Panics on a gap above 1e-11 (or, where the run
/// amplifies round-off, above [`AMPLIFICATION_MARGIN`] times that amplified round-off).
fn compare<S: hybc::sim::HybridSystem>(
    label: &str,
    sys: &S,
    p: &[f64],
    opts: &SimOptions,
) -> Result<(f64, String), &'static str> {
    compare_within(label, sys, p, opts, 1e-11)
}

/// [`compare`], panicking on a gap above `bound`.
pub(crate) fn compare_within<S: hybc::sim::HybridSystem>(
    label: &str,
    sys: &S,
    p: &[f64],
    opts: &SimOptions,
    bound: f64,
) -> Result<(f64, String), &'static str> {
    let opts = SimOptions { sens_error_control: false, ..opts.clone() };
    let forward = run(sys, p, &opts).expect("runs");
    let recorded = record(sys, p, &opts).expect("records");
    // The same steps: the same events at the same times, the same final state, bit for bit.
    let times = |r: &SimResult| r.events.iter().map(|e| (e.event, e.time.to_bits())).collect::<Vec<_>>();
    assert_eq!(times(&forward), times(&recorded.result), "{label}: events");
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&forward.final_state.state), bits(&recorded.result.final_state.state), "{label}");
    let info = sys.info();
    let (n, k, m) = (info.n_states(), info.n_outputs(), info.n_grad());
    let mut worst = (0.0f64, String::new());
    let rows = quantities(&forward, n, k, m);
    let floor = 1e-3 * rows.iter().flat_map(|r| &r.2).fold(0.0f64, |a, b| a.max(b.abs()));
    // Measured only where a gap needs it (one more run).
    let mut amplification: Option<Option<Vec<f64>>> = None;
    for (row, (what, seed, fwd)) in rows.iter().enumerate() {
        match recorded.gradient(sys, p, seed) {
            Ok(adj) => {
                let gap = rel_gap(&adj, fwd, floor);
                let measured = if gap > bound {
                    amplification
                        .get_or_insert_with(|| amplified_round_off(sys, p, &opts, &forward, &rows))
                        .as_ref()
                        .map(|a| a[row])
                } else {
                    None
                };
                let allowed = bound.max(AMPLIFICATION_MARGIN * measured.unwrap_or(0.0) * f64::EPSILON);
                assert!(
                    gap <= allowed,
                    "{label} {what}: adjoint {adj:?}\nforward {fwd:?}\ngap {gap:e}, allowed {allowed:e} \
                     (round-off amplified {measured:?} times; None: a parameter one ulp away changes the steps)"
                );
                if gap > worst.0 {
                    let what =
                        if gap > bound { format!("{what}, allowed {allowed:.1e}") } else { what.clone() };
                    worst = (gap, what);
                }
            }
            Err(AdjointError::Unsupported(why)) => return Err(why),
            Err(e) => panic!("{label} {what}: {e}"),
        }
    }
    Ok(worst)
}

fn check_every_model(method: Method, land: Option<bool>) {
    let mut carried = Vec::new();
    let mut refused = Vec::new();
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
            ..SimOptions::default()
        };
        let p: Vec<f64> = model.params.iter().map(|p| p.default).collect();
        match compare(&path, &compiled, &p, &opts) {
            Ok((gap, what)) => carried.push(format!("{path}: worst {gap:.1e} ({what})")),
            Err(why) => refused.push(format!("{path}: {why}")),
        }
    }
    eprintln!("{method:?} land={land:?}\ncarried:\n  {}", carried.join("\n  "));
    assert!(refused.is_empty(), "refused: {refused:?}");
}

/// Compiles `src` with every parameter (vector elements each) differentiated, at its defaults
/// with the vectors `vectors` set.
pub(crate) fn compiled(src: &str, vectors: &[(&str, &[f64])]) -> (hybc::Compiled, Vec<f64>) {
    let model = hybc::Model::parse(src).unwrap_or_else(|e| panic!("{e}"));
    let names: Vec<String> = model.params().iter().map(|(name, _)| name.to_string()).collect();
    let compiled = model.compile(&names).expect("compiles");
    let mut params = compiled.params();
    for (name, values) in vectors {
        params.set_vector(name, values).expect("a vector of the model");
    }
    (compiled, params.values().to_vec())
}

/// `src` compared under every method, landing on events or not; every run carried, and
/// each with at least `least.0` events and `least.1` flow switches or knots where the flow jumps
/// (so that the test tests what it says).
fn check_source(label: &str, src: &str, vectors: &[(&str, &[f64])], t_end: f64, least: (usize, usize)) {
    let (compiled, p) = compiled(src, vectors);
    let plain = run(compiled.system(), &p, &SimOptions { t_end, ..SimOptions::default() }).expect("runs");
    assert!(plain.events.len() >= least.0 && plain.stats.switches >= least.1, "{label}: {:?}", plain.stats);
    for method in [Method::Auto, Method::Dopri5, Method::Dop853, Method::Rodas5p, Method::Rodas4] {
        for land in [None, Some(true), Some(false)] {
            let opts = SimOptions {
                t_end,
                rtol: 1e-10,
                atol: 1e-12,
                method,
                land_events: land,
                ..SimOptions::default()
            };
            match compare(label, compiled.system(), &p, &opts) {
                Ok((gap, what)) => eprintln!("{label} {method:?} {land:?}: worst {gap:.1e} ({what})"),
                Err(why) => panic!("{label} {method:?} {land:?}: refused: {why}"),
            }
        }
    }
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

#[test]
fn the_adjoint_carries_pwc_knots_that_move_with_parameters_and_pwl_kinks() {
    // The flow jumps at each pwc knot, by an amount that depends on the state; the knots move
    // with t0 and t1. A bounce in between, so that knots and events interleave.
    let src = "model inputs\nparam u[5] = 0\nparam w[4] = 0\n\
               param t0 = 0.1\nparam t1 = 1.7\nparam k = 0.8\n\
               state y = 1\nstate v = 0\nstate c = 0\n\
               der(y) = v\nder(v) = -9.81 + pwc(t, t0, t1, u) * (1 + 0.1 * y) - k * v\n\
               der(c) = pwl(t, 0, 2, w) * y^2\n\
               event bounce when y <= 0 {\n v := -k * v\n}\n";
    let (u, w) = ([1.0, -2.0, 0.5, 3.0, -1.0], [0.2, 1.5, -0.7, 0.4]);
    check_source("inputs", src, &[("u", &u), ("w", &w)], 2.5, (3, 4));
}

#[test]
fn the_adjoint_carries_flow_switches_of_state_and_time() {
    // A rate that switches when a state passes a level, one that switches with time, and a
    // declared event.
    let src = "model relay\nparam a = 1.3\nparam b = 0.4\nparam w = 3\n\
               state x = 0.2\nstate y = 0\n\
               der(x) = if x > b then a * (1 + 0.5 * x) else 2 * a\n\
               der(y) = if sin(w * t) > 0.2 then x else -x * x\n\
               event kick when y >= 0.3 {\n y := 0\n}\n";
    check_source("relay", src, &[], 3.0, (3, 4));
}

#[test]
fn the_adjoint_carries_events_that_cascade_at_one_instant() {
    // `a` resets x past b's guard: b fires at the same instant, taking a's dt/dp; then `c`
    // (declared before `d`, both on the same guard) fire together later.
    let src = "model cascade\nparam h = 1\nparam k = 0.7\nstate x = 0\nstate n = 0\nstate y = 0.2\n\
               der(x) = 1 + 0.1 * y\nder(n) = 0\nder(y) = k * x\n\
               event a when x >= h {\n x := 2 * h\n y := y + k\n}\n\
               event b when x >= 1.5 * h {\n n := n + x\n y := 0.5 * y\n}\n\
               event c when y >= 2 {\n y := 0\n}\n\
               event d when y >= 2 {\n n := n + 1\n}\n";
    check_source("cascade", src, &[], 3.0, (4, 0));
}

#[test]
fn the_adjoint_equals_forward_sensitivities_under_each_rosenbrock_method_landing_on_events_or_not() {
    for method in [Method::Rodas5p, Method::Rodas4] {
        for land in [true, false] {
            check_every_model(method, Some(land));
        }
    }
}

/// A stiff model compared under both Rosenbrock methods and `auto` (and the factorisation
/// `solver`): every run carried, at most `bound` apart.
fn check_stiff(label: &str, src: &str, t_end: f64, rtol: f64, solver: LinearSolver, bound: f64) {
    check_stiff_with(
        label,
        src,
        t_end,
        rtol,
        solver,
        bound,
        &[Method::Rodas5p, Method::Rodas4, Method::Auto],
    );
}

/// [`check_stiff`] under `methods`.
fn check_stiff_with(
    label: &str,
    src: &str,
    t_end: f64,
    rtol: f64,
    solver: LinearSolver,
    bound: f64,
    methods: &[Method],
) {
    let (compiled, p) = compiled(src, &[]);
    for &method in methods {
        let opts = SimOptions {
            t_end,
            rtol,
            atol: rtol * 1e-2,
            method,
            linear_solver: solver,
            ..SimOptions::default()
        };
        match compare_within(label, compiled.system(), &p, &opts, bound) {
            Ok((gap, what)) => eprintln!("{label} {method:?} {solver:?}: worst {gap:.1e} ({what})"),
            Err(why) => panic!("{label} {method:?}: refused: {why}"),
        }
    }
}

const ROBERTSON: &str = "model robertson\nparam k1 = 0.04\nparam k2 = 3e7\nparam k3 = 1e4\n\
    state y1 = 1\nstate y2 = 0\nstate y3 = 0\nstate k = k1\n\
    der(y1) = -k * y1 + k3 * y2 * y3\nder(y2) = k * y1 - k3 * y2 * y3 - k2 * y2 * y2\n\
    der(y3) = k2 * y2 * y2\nder(k) = 0\nevent faster when y1 <= 0.5 {\n k := 2 * k\n}\n";

const VAN_DER_POL: &str = "model vdp\nparam mu = 100\nparam a = 2\nstate x = a\nstate y = 0\n\
    der(x) = y\nder(y) = mu * ((1 - x^2) * y - x)\n\
    event half when x <= 1 {\n y := 0.9 * y\n}\noutput e = x^2 + y^2 / mu^2\n";

#[test]
fn the_adjoint_carries_the_stiff_models_through_rosenbrock_steps() {
    // Robertson's kinetics to 1e3 (an event on y1 at about t = 20), Van der Pol at mu = 100
    // (an event on the way), the soft ball at rest on its spring. At mu = 1000 the two sums of
    // round-off differ by 3e-11 (docs/accuracy.md: the gap grows as mu^2, 2e-15 at mu = 10,
    // 5e-13 at 100: the conditioning of `W`, not the transpose, which mu = 10 shows exact).
    check_stiff("vdp", &VAN_DER_POL.replace("mu = 100", "mu = 10"), 1.0, 1e-8, LinearSolver::Auto, 1e-13);
    check_stiff("robertson", ROBERTSON, 1e3, 1e-8, LinearSolver::Auto, 1e-11);
    check_stiff("vdp", VAN_DER_POL, 1.0, 1e-8, LinearSolver::Auto, 1e-11);
    // The soft ball in flight after its first bounce (its own t_end) is among the shipped
    // models; here at rest on its spring of 1e6 (t = 2): 5.8e-13 and 2.9e-13 under `rodas5p`
    // and `rodas4`. Under `auto` the velocity at rest has derivatives of 1e-8 against the
    // height's 1e-6, and the two computations differ there by 6e-15 absolute (4.7e-9 of its own
    // largest, docs/accuracy.md): round-off on a quantity the parameters barely move, left out.
    let soft = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/models/soft_ball.hyb")).unwrap();
    let rosenbrock = [Method::Rodas5p, Method::Rodas4];
    check_stiff_with("soft ball", &soft, 2.0, 1e-8, LinearSolver::Auto, 1e-11, &rosenbrock);
}

#[test]
fn the_adjoint_carries_the_w5_chain_with_each_factorisation() {
    // The W5 diffusion chain (12 cells, its top-up event) banded, sparse and dense; the hub
    // (no band: the sparse LU) with its event.
    use crate::support::chain::{diffusion_source, hub_source};
    for solver in [LinearSolver::Banded, LinearSolver::Sparse, LinearSolver::Dense] {
        check_stiff("w5", &diffusion_source(12, true), 6.0, 1e-8, solver, 1e-11);
    }
    check_stiff("hub", &hub_source(12, true), 6.0, 1e-8, LinearSolver::Sparse, 1e-11);
}

#[test]
fn the_adjoint_carries_auto_runs_that_switch_methods_mid_run() {
    // A rate that jumps to 1e6 at u = 1 and back at u = 3: Dormand-Prince, Rodas5P, then
    // Dormand-Prince again (`tests/it/stiff.rs`), the switches inside the run.
    let src = "model jump\nparam k0 = 1\nparam k1 = 1e6\nparam x0 = 1\nstate x = x0\nstate u = 0\n\
               state k = k0\nder(x) = -k * (x - cos(t)) + 0.1 * x^2\nder(u) = 1\nder(k) = 0\n\
               event stiffen when u >= 1 {\n k := k1\n}\nevent relax when u >= 3 {\n k := k0\n}\n";
    let (compiled, p) = compiled(src, &[]);
    let opts =
        SimOptions { t_end: 10.0, rtol: 1e-6, atol: 1e-8, method: Method::Auto, ..SimOptions::default() };
    let plain = run(compiled.system(), &p, &opts).expect("runs");
    let methods: Vec<Method> = plain.methods.iter().map(|s| s.method).collect();
    assert_eq!(methods, [Method::Dopri5, Method::Rodas5p, Method::Dopri5], "{:?}", plain.methods);
    for land in [None, Some(false)] {
        let (gap, what) =
            compare("jump", compiled.system(), &p, &SimOptions { land_events: land, ..opts.clone() })
                .unwrap_or_else(|why| panic!("refused: {why}"));
        eprintln!("jump auto {land:?}: worst {gap:.1e} ({what})");
    }
}

/// A time event on a `pwc` knot that its parameter `T` moves apart from the knot: the
/// derivatives by `T` do not exist on one side (forward mode's `knot_order`), which the adjoint
/// does not carry yet.
const APART: &str = "model apart\nparam u[4] = 0\nparam T = 0.5\nparam a = 0.3\nstate x = 1\n\
                     der(x) = pwc(t, 0, 2, u) * x\nevent kick when t >= T {\n x := x + a\n}\n";

#[test]
fn what_the_adjoint_does_not_carry_yet_is_refused_by_name_never_approximated() {
    let (compiled, p) = compiled(APART, &[("u", &[1.0, -2.0, 0.5, 3.0])]);
    let opts = SimOptions { t_end: 1.0, sens_error_control: false, ..SimOptions::default() };
    let recorded = record(compiled.system(), &p, &opts).expect("records");
    let seed = Seed { state: vec![1.0], ..Seed::default() };
    let err = recorded.gradient(compiled.system(), &p, &seed).expect_err("not carried yet");
    assert!(matches!(err, AdjointError::Unsupported(w) if w.contains("input knot")), "{err}");
}

/// Runs `src` through the door with `sens`, every parameter differentiated.
fn door_run(src: &str, vectors: &[(&str, &[f64])], opts: &SimOptions) -> hybc::Run {
    let (compiled, p) = compiled(src, vectors);
    let mut params = compiled.params();
    for (name, values) in vectors {
        params.set_vector(name, values).expect("a vector");
    }
    assert_eq!(params.values(), &p[..]);
    compiled.simulate(&params, opts).expect("runs")
}

const BALL: &str = "model ball\nparam g = 9.81\nparam e = 0.8\nparam h0 = 1\nstate y = h0\nstate v = 0\n\
                    der(y) = v\nder(v) = -g\nevent touchdown when y <= 0 {\n v := -e * v\n}\n\
                    output energy = 0.5 * v^2 + g * y\n";

#[test]
fn sens_adjoint_gives_the_report_of_a_forward_run_without_sensitivity_error_control() {
    let base = SimOptions { t_end: 2.5, rtol: 1e-10, atol: 1e-12, ..SimOptions::default() };
    let forward = door_run(BALL, &[], &SimOptions { sens_error_control: false, ..base.clone() });
    let adjoint = door_run(BALL, &[], &SimOptions { sens: Sens::Adjoint, ..base.clone() });
    assert_eq!(forward.result().stats.sens, Some(Sens::Forward));
    assert_eq!(adjoint.result().stats.sens, Some(Sens::Adjoint));
    assert_eq!(forward.events().len(), 4);
    assert_eq!(forward.events().len(), adjoint.events().len());
    let close = |a: f64, b: f64, what: &str| {
        assert!((a - b).abs() <= 1e-12 * a.abs().max(b.abs()).max(1.0), "{what}: {a} vs {b}");
    };
    for param in ["g", "e", "h0"] {
        for k in 0..4 {
            let (f, a) = (forward.devent_time(k, param).unwrap(), adjoint.devent_time(k, param).unwrap());
            close(f, a, &format!("dt{k}/d{param}"));
        }
        for state in ["y", "v"] {
            close(forward.dstate(state, param).unwrap(), adjoint.dstate(state, param).unwrap(), state);
        }
        close(forward.doutput("energy", param).unwrap(), adjoint.doutput("energy", param).unwrap(), "energy");
    }
    // The same report, word for word but the timings and the summary's mode.
    let text = |run: &hybc::Run| {
        let mut text = String::new();
        run.report().write_table(&mut text).expect("writes");
        text.lines().take_while(|l| !l.contains("steps (")).map(str::to_string).collect::<Vec<_>>()
    };
    assert_eq!(text(&forward), text(&adjoint));
}

#[test]
fn sens_auto_takes_the_adjoint_only_when_the_quantities_are_few_against_the_parameters() {
    // Three parameters, 4 events + 2 states + 1 output: forward.
    let opts = SimOptions { t_end: 2.5, sens: Sens::Auto, ..SimOptions::default() };
    assert_eq!(door_run(BALL, &[], &opts).result().stats.sens, Some(Sens::Forward));
    // A control of 40 knots, 3 quantities: the adjoint.
    let src = "model drive\nparam u[40] = 0.5\nstate p = 0\nstate v = 0\n\
               der(p) = v\nder(v) = pwl(t, 0, 1, u)\noutput cost = p^2 + v^2\n";
    let opts = SimOptions { t_end: 1.0, sens: Sens::Auto, ..SimOptions::default() };
    assert_eq!(door_run(src, &[], &opts).result().stats.sens, Some(Sens::Adjoint));
}

#[test]
fn sens_adjoint_on_a_run_it_does_not_carry_computes_forward_and_says_so() {
    let opts =
        SimOptions { t_end: 1.0, rtol: 1e-10, atol: 1e-12, sens: Sens::Adjoint, ..SimOptions::default() };
    let run = door_run(APART, &[("u", &[1.0, -2.0, 0.5, 3.0])], &opts);
    assert_eq!(run.result().stats.sens, Some(Sens::Forward));
    let said: Vec<String> = run.warnings().iter().map(|w| w.to_string()).collect();
    assert!(
        said.iter().any(|w| w.contains("adjoint does not carry") && w.contains("input knot")),
        "{said:?}"
    );
    // x(1) = (e^0.5 + a) e^-1: dx/da = e^-1, from forward mode.
    let got = run.dstate("x", "a").expect("exists");
    assert!((got - (-1.0f64).exp()).abs() < 1e-8, "{got}");
}

#[test]
fn the_adjoint_carries_events_on_input_knots_fixed_or_moving_with_them() {
    // `kick` at 0.5 on u's fixed knot (no parameter moves either); `drop` at T on w's knot at
    // T (pwc over [0, 2 T] of two values), which T moves with it; the flows jump at both, by
    // amounts the resets change.
    let src = "model onknot\nparam u[4] = 0\nparam w[2] = 0\nparam T = 0.8\nparam a = 0.3\n\
               state x = 1\nstate y = 0\n\
               der(x) = pwc(t, 0, 2, u) * x - 0.2 * y\nder(y) = pwc(t, 0, 2 * T, w) * (1 + x)\n\
               event kick when t >= 0.5 {\n x := x + a\n}\n\
               event drop when t >= T {\n y := y - a * x\n}\n";
    let (u, w) = ([1.0, -2.0, 0.5, 3.0], [0.7, -1.3]);
    check_source("onknot", src, &[("u", &u), ("w", &w)], 2.0, (2, 4));
    // On the knots: u's at 0.5 (4 values over [0, 2]), w's at T.
    let vectors: [(&str, &[f64]); 2] = [("u", &u), ("w", &w)];
    let (sys, p) = compiled(src, &vectors);
    let r = run(sys.system(), &p, &SimOptions { t_end: 2.0, ..SimOptions::default() }).unwrap();
    let times: Vec<f64> = r.events.iter().map(|e| e.time).collect();
    assert_eq!(times, [0.5, 0.8]);
    // A state event on a knot, or a time event its parameter moves apart from the knot, is
    // still refused (whether forward mode finds a derivative missing or not).
    let apart = src.replace("t >= 0.5", "t >= 0.2 + a");
    let (sys, p) = compiled(&apart, &vectors);
    let opts = SimOptions { t_end: 2.0, sens_error_control: false, ..SimOptions::default() };
    let recorded = record(sys.system(), &p, &opts).expect("records");
    assert_eq!(recorded.result.events[0].time, 0.5);
    let err = recorded.gradient(sys.system(), &p, &Seed { state: vec![1.0, 0.0], ..Seed::default() });
    assert!(matches!(err, Err(AdjointError::Unsupported(w)) if w.contains("input knot")), "{err:?}");
}

#[test]
fn the_adjoint_carries_knots_of_several_pwc_inputs_at_one_time() {
    // u and w share their knots (0.5, 1, 1.5); r and q share theirs at multiples of T / 3,
    // which T moves together.
    let src = "model twin\nparam u[4] = 0\nparam w[4] = 0\nparam r[3] = 0\nparam q[3] = 0\n\
               param T = 1.2\nparam k = 0.5\nstate x = 1\nstate v = 0\n\
               der(x) = v\nder(v) = pwc(t, 0, 2, u) + pwc(t, 0, 2, w) * x - k * v \
               + pwc(t, 0, T, r) * v + pwc(t, 0, T, q)\n";
    let (u, w) = ([1.0, -2.0, 0.5, 3.0], [0.2, 1.5, -0.7, 0.4]);
    let (r, q) = ([0.3, -0.4, 0.9], [1.1, -0.6, 0.25]);
    check_source("twin", src, &[("u", &u), ("w", &w), ("r", &r), ("q", &q)], 2.0, (0, 10));
}

/// `|got - want| <= tol max(|want|, 1)`.
fn near(got: f64, want: f64, tol: f64, what: &str) {
    assert!((got - want).abs() <= tol * want.abs().max(1.0), "{what}: {got} against {want}");
}

#[test]
fn the_adjoint_gives_the_closed_forms_of_a_bounce_an_input_and_a_stop() {
    let opts = SimOptions { rtol: 1e-12, atol: 1e-14, sens: Sens::Adjoint, ..SimOptions::default() };
    // The ball's energy after four bounces is e^8 g h0 (flights conserve it exactly).
    let run = door_run(BALL, &[], &SimOptions { t_end: 2.5, ..opts.clone() });
    assert_eq!((run.events().len(), run.result().stats.sens), (4, Some(Sens::Adjoint)));
    let (g, e, h0) = (9.81f64, 0.8f64, 1.0f64);
    near(run.doutput("energy", "e").unwrap(), 8.0 * e.powi(7) * g * h0, 1e-10, "dE/de");
    near(run.doutput("energy", "h0").unwrap(), e.powi(8) * g, 1e-10, "dE/dh0");
    // der(x) = pwc(t, t0, t1, u) over 400 knots: x = u_0 t0 + w sum u_k + u_{N-1} (t_end - t1).
    let n = 400;
    let u: Vec<f64> = (0..n).map(|k| ((k * 37) % 11) as f64 / 5.0 - 1.0).collect();
    let src = format!("model zoh\nparam u[{n}] = 0\nparam t0 = 0.1\nparam t1 = 0.9\nstate x = 0\nder(x) = pwc(t, t0, t1, u)\n");
    let run = door_run(&src, &[("u", &u)], &SimOptions { t_end: 1.0, ..opts.clone() });
    assert_eq!(run.result().stats.sens, Some(Sens::Adjoint));
    let (t0, t1, t_end) = (0.1, 0.9, 1.0);
    let w = (t1 - t0) / n as f64;
    let mean = u.iter().sum::<f64>() / n as f64;
    for k in [0, 1, 57, n - 2, n - 1] {
        let extra = if k == 0 { t0 } else { 0.0 } + if k == n - 1 { t_end - t1 } else { 0.0 };
        near(run.dstate("x", &format!("u[{k}]")).unwrap(), w + extra, 1e-12, &format!("dx/du[{k}]"));
    }
    near(run.dstate("x", "t0").unwrap(), u[0] - mean, 1e-12, "dx/dt0");
    near(run.dstate("x", "t1").unwrap(), mean - u[n - 1], 1e-12, "dx/dt1");
    // A stop at a parameter's time: x(T) = x0 exp(a T); the total derivatives carry it there.
    let src = "model grow\nparam a = 0.7\nparam T = 1.3\nstate x = 2\nder(x) = a * x\n\
               event finish when t >= T {\n stop\n}\n";
    let run = door_run(src, &[], &SimOptions { t_end: 5.0, ..opts });
    assert_eq!(run.result().stats.sens, Some(Sens::Adjoint));
    let (a, t) = (0.7f64, 1.3f64);
    let x = 2.0 * (a * t).exp();
    near(run.dstate_total("x", "T").unwrap(), a * x, 1e-10, "dx/dT");
    near(run.dstate_total("x", "a").unwrap(), t * x, 1e-10, "dx/da");
    near(run.devent_time(0, "T").unwrap(), 1.0, 1e-12, "dt_stop/dT");
}

#[test]
fn the_adjoint_gives_both_sides_of_the_cusp_of_an_event_at_t_end() {
    // A time event on t_end itself: `final` is after it, `end_cusp` (JSON
    // `final.without_end_events`) before it.
    let src =
        "model tick\nparam a = 0.3\nparam k = 1.1\nstate x = 1\nstate y = 0\nder(x) = -k * x\nder(y) = x\n\
               event tick when t >= 2 {\n x := x + a\n y := y * k\n}\noutput z = x * y\n";
    let base = SimOptions {
        t_end: 2.0,
        rtol: 1e-10,
        atol: 1e-12,
        sens_error_control: false,
        ..SimOptions::default()
    };
    let forward = door_run(src, &[], &base);
    let adjoint = door_run(src, &[], &SimOptions { sens: Sens::Adjoint, ..base });
    assert_eq!(adjoint.result().stats.sens, Some(Sens::Adjoint));
    let (f, a) = (forward.result(), adjoint.result());
    let (fc, ac) = (f.end_cusp.as_ref().expect("an event at t_end"), a.end_cusp.as_ref().expect("the same"));
    for (fd, ad) in [
        (&fc.dstate, &ac.dstate),
        (&fc.doutputs, &ac.doutputs),
        (&f.final_state.dstate, &a.final_state.dstate),
    ] {
        let (fd, ad) = (fd.as_ref().expect("exists"), ad.as_ref().expect("exists"));
        assert!(rel_gap(ad, fd, 0.0) <= 1e-12, "{ad:?} vs {fd:?}");
    }
    // Before the tick x = exp(-2k): dx/da = 0 there, 1 after it.
    let (fd, ad) = (fc.dstate.as_ref().unwrap(), f.final_state.dstate.as_ref().unwrap());
    assert_eq!(fd[0], 0.0);
    assert!((ad[0] - 1.0).abs() < 1e-12);
}

#[test]
fn flow_vjp_add_adds_what_flow_vjp_writes() {
    // A control read through lookups only (scattered), one also summed, a plain parameter: the
    // accumulating product touches the kernel's columns and the elements read, and gives
    // `pbar + gp` of the overwriting one, at knots, between them and past the last.
    use hybc::sim::HybridSystem;
    let src = "model acc\nparam k = 0.7\nparam u[30] = 0\nparam w[12] = 0\nparam T = 1.5\n\
               state x = 0.3\nstate v = -0.2\n\
               der(x) = v + pwc(t, 0, T, w) * x\nder(v) = pwl(t, 0, 1, u) - k * v + 0.1 * sum(w)\n";
    let u: Vec<f64> = (0..30).map(|j| (j as f64 * 0.37).sin()).collect();
    let w: Vec<f64> = (0..12).map(|j| (j as f64 * 0.91).cos()).collect();
    let (compiled, p) = compiled(src, &[("u", &u), ("w", &w)]);
    let sys = compiled.system();
    let m = sys.info().n_grad();
    for (i, t) in [0.0, 0.2, 1.0 / 29.0 * 7.0, 0.5, 1.0, 1.2, 2.0].into_iter().enumerate() {
        let x = [0.3 + 0.1 * i as f64, -0.2 + 0.05 * i as f64];
        let wv = [0.8 - 0.1 * i as f64, 1.3];
        let base: Vec<f64> = (0..m).map(|j| (j as f64 * 0.13).sin()).collect();
        let (mut gx, mut gp) = ([0.0; 2], vec![0.0; m]);
        sys.flow_vjp(0, t, &x, &wv, &p, &mut gx, &mut gp);
        let (mut gx2, mut acc) = ([0.0; 2], base.clone());
        sys.flow_vjp_add(0, t, &x, &wv, &p, &mut gx2, &mut acc);
        assert_eq!(gx, gx2, "t = {t}");
        for j in 0..m {
            let want = base[j] + gp[j];
            let scale = base[j].abs() + gp[j].abs();
            assert!(
                (acc[j] - want).abs() <= 4.0 * f64::EPSILON * scale,
                "t = {t}, column {j}: {} vs {want}",
                acc[j]
            );
        }
    }
}

/// Issue #40's closed forms of many knots, by the adjoint: `der(x) = pwl(t, 0, 1, u)` over
/// 10,000 knots integrates to the trapezoid rule, so `dx(1)/du_k` is the spacing `h`, halved at
/// the two ends; and a double integrator `p' = v`, `v' = pwc(t, 0, T, u)` over N pieces of width
/// `w`, with the terminal cost `J = p(T) + v(T)^2 / 2`: `dv/du_k = w`,
/// `dp/du_k = w (T - t_k - w / 2)` (`t_k = k w`), so `dJ/du_k = dp/du_k + v(T) w`.
#[test]
fn the_adjoint_gives_the_closed_forms_of_many_knots() {
    let opts = SimOptions { rtol: 1e-12, atol: 1e-14, sens: Sens::Adjoint, ..SimOptions::default() };
    let n = 10_000;
    let u: Vec<f64> = (0..n).map(|k| ((k * 7) % 13) as f64 / 6.0 - 1.0).collect();
    let src = format!("model area\nparam u[{n}] = 0\nstate x = 0\nder(x) = pwl(t, 0, 1, u)\n");
    let run = door_run(&src, &[("u", &u)], &SimOptions { t_end: 1.0, ..opts.clone() });
    assert_eq!(run.result().stats.sens, Some(Sens::Adjoint));
    let h = 1.0 / (n - 1) as f64;
    for k in [0, 1, 2, 4_999, n - 2, n - 1] {
        let want = if k == 0 || k == n - 1 { h / 2.0 } else { h };
        near(run.dstate("x", &format!("u[{k}]")).unwrap(), want, 1e-12, &format!("dx/du[{k}]"));
    }
    let pieces = 200;
    let big_t = 2.0;
    let u: Vec<f64> = (0..pieces).map(|k| ((k * 5) % 9) as f64 / 4.0 - 1.0).collect();
    let src = format!(
        "model drive\nparam u[{pieces}] = 0\nparam T = {big_t}\nstate p = 0\nstate v = 0\n\
         der(p) = v\nder(v) = pwc(t, 0, T, u)\noutput J = p + v^2 / 2\n"
    );
    let run = door_run(&src, &[("u", &u)], &SimOptions { t_end: big_t, ..opts });
    assert_eq!(run.result().stats.sens, Some(Sens::Adjoint));
    let w = big_t / pieces as f64;
    let v_end = w * u.iter().sum::<f64>();
    for k in [0, 1, 77, pieces - 2, pieces - 1] {
        let dp = w * (big_t - k as f64 * w - w / 2.0);
        near(run.doutput("J", &format!("u[{k}]")).unwrap(), dp + v_end * w, 1e-11, &format!("dJ/du[{k}]"));
        near(run.dstate("v", &format!("u[{k}]")).unwrap(), w, 1e-12, &format!("dv/du[{k}]"));
    }
}
