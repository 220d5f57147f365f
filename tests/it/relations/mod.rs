//! Relations that need no hand-written answer, checked on generated models under every stepper
//! (docs/accuracy.md, "The relation harness"). Each generated model (`generate.rs`, data in
//! `model.rs`) has an exact reference (`exact.rs`, double-double dual numbers): every run is
//! compared with it, and every variant of the model a relation makes (shifted in time, `t` read
//! from a clock state, a bystander state, events declared in another order, a mode split in two)
//! is compared with the reference; and one run per model has its gradients checked against
//! central differences of itself (`hybc::gradcheck`). A model with a `sin` guard has no exact
//! reference: a run of its own at rtol 1e-12 stands in for it.
//!
//! `cargo test --test it relations` runs the fast subset CI runs (a fixed seed). The full run:
//! `HYBC_RELATIONS=full cargo test --release --test it relations -- --nocapture` (at least 1,000
//! models, every relation, every stepper; `HYBC_RELATIONS_SEED`, `HYBC_RELATIONS_MODELS` and
//! `HYBC_RELATIONS_SECONDS` change the seed, the count and the time budget; `HYBC_RELATIONS_FIRST`
//! the first model's index, so that `HYBC_RELATIONS_FIRST=509 HYBC_RELATIONS_MODELS=1` reruns model
//! 509 alone). Every violation is
//! printed with its reproducer: the model text, the options, the expected and the got values.

mod dd;
mod exact;
mod generate;
mod model;

use std::fmt::Write as _;
use std::time::{Duration, Instant};

use hybc::{Method, Model, SimOptions};

use exact::{Outcome, Reference};
use model::{GenModel, Variant};

/// One way of running: a method, landing on events or the method's default, with or without
/// gradients.
#[derive(Clone, Copy, Debug)]
pub struct Config {
    pub method: Method,
    pub land: bool,
    pub grad: bool,
}

impl Config {
    fn flags(&self) -> String {
        let method = match self.method {
            Method::Auto => "auto",
            Method::Dopri5 => "dopri5",
            Method::Dop853 => "dop853",
            Method::Rodas5p => "rodas5p",
            Method::Rodas4 => "rodas4",
        };
        format!(
            "--method {method}{}{}",
            if self.land { " --land-events" } else { "" },
            if self.grad { " --grad all" } else { "" }
        )
    }
}

const METHODS: [Method; 5] = [Method::Auto, Method::Dopri5, Method::Dop853, Method::Rodas5p, Method::Rodas4];

/// Every stepper, with and without `--land-events`, with gradients; and every stepper without
/// gradients (whose values must not depend on whether gradients are asked for).
pub fn configs() -> Vec<Config> {
    let mut out = Vec::new();
    for method in METHODS {
        out.push(Config { method, land: false, grad: true });
        out.push(Config { method, land: true, grad: true });
        out.push(Config { method, land: false, grad: false });
    }
    out
}

/// The tolerances of the harness's runs.
const RTOL: f64 = 1e-8;
const ATOL: f64 = 1e-10;

/// What a run gave, in the reference's terms.
#[derive(Clone, Debug)]
struct Got {
    /// (event name, time, time gradient per parameter: NaN where none is reported).
    events: Vec<(String, f64, Vec<f64>)>,
    state: Vec<f64>,
    /// `dstate[i][j]`: NaN where none is reported.
    dstate: Vec<Vec<f64>>,
    stopped: String,
    warnings: usize,
}

fn run(g: &GenModel, v: &Variant, c: Config) -> Result<Got, String> {
    run_at(g, v, c, RTOL, ATOL)
}

/// Model `g` in variant `v`, compiled with gradients for every parameter when `c` asks, run
/// under `c` at the given tolerances; with the options it ran with.
fn simulate(
    g: &GenModel,
    v: &Variant,
    c: Config,
    rtol: f64,
    atol: f64,
) -> Result<(hybc::Run, SimOptions), String> {
    let model = Model::parse(&g.text(v)).map_err(|e| format!("does not parse: {e}"))?;
    let names: Vec<String> = (0..g.params.len()).map(|j| format!("p{j}")).collect();
    let grad: Vec<&str> = if c.grad { names.iter().map(String::as_str).collect() } else { Vec::new() };
    let compiled = model.compile(&grad).map_err(|e| format!("does not compile: {e}"))?;
    let opts = SimOptions {
        t_start: v.shift,
        t_end: g.t_end + v.shift,
        rtol,
        atol,
        method: c.method,
        land_events: if c.land { Some(true) } else { None },
        // A generated state nothing reads is a running cost, outside the error test by default
        // (with a warning where its error exceeds the tolerance): the harness judges every state
        // against the tolerance, so every state is under the test.
        quadrature_error_control: true,
        ..SimOptions::default()
    };
    let run = compiled.simulate(&compiled.params(), &opts).map_err(|e| format!("does not run: {e}"))?;
    Ok((run, opts))
}

fn run_at(g: &GenModel, v: &Variant, c: Config, rtol: f64, atol: f64) -> Result<Got, String> {
    let (r, _) = simulate(g, v, c, rtol, atol)?;
    let names: Vec<String> = (0..g.params.len()).map(|j| format!("p{j}")).collect();
    let stopped = match r.stopped_by() {
        hybc::StopReason::TEnd => "t_end".to_string(),
        hybc::StopReason::Event { name, .. } => name.to_string(),
        other => return Err(format!("stopped early: {other:?}")),
    };
    let stop = stopped != "t_end";
    let n = g.init.len();
    let warnings = r.warnings().len();
    let mut got = Got { events: Vec::new(), state: Vec::new(), dstate: Vec::new(), stopped, warnings };
    for e in r.events() {
        if &*e.name == "split" {
            continue;
        }
        let dt = match (&e.dtime, c.grad) {
            (Some(d), true) => d.clone(),
            _ => vec![f64::NAN; g.params.len()],
        };
        got.events.push((e.name.to_string(), e.time - v.shift, dt));
    }
    for i in 0..n {
        let x = GenModel::state_name(i);
        got.state.push(r.state(&x).unwrap_or(f64::NAN));
        let row = names
            .iter()
            .map(|p| {
                if !c.grad {
                    return f64::NAN;
                }
                let d = if stop { r.dstate_total(&x, p) } else { r.dstate(&x, p) };
                d.unwrap_or(f64::NAN)
            })
            .collect();
        got.dstate.push(row);
    }
    Ok(got)
}

/// The gradient relation: every derivative a run reports agrees with central differences of the
/// same compiled model re-run at `p +/- h` (`hybc::gradcheck`, with its own truncation and noise
/// estimates and its tolerance for the run's `rtol`), and its events do not change with the step
/// size. `Err` names the first failing parameter and its worst comparison.
fn gradient_check(g: &GenModel, c: Config) -> Result<(), String> {
    let (run, opts) = simulate(g, &Variant::default(), Config { grad: true, ..c }, RTOL, ATOL)?;
    let compiled = run.compiled();
    let p = compiled.params().values().to_vec();
    let check = hybc::gradcheck::check(
        compiled.native(),
        &p,
        &opts,
        run.result(),
        &hybc::gradcheck::CheckOptions::for_rtol(RTOL),
    )
    .map_err(|e| format!("the check does not run: {e}"))?;
    if let Some(f) = check.failures().next() {
        return Err(format!("gradient check: {} fails: {:?}", f.name, f.worst));
    }
    if !check.events.is_consistent() {
        return Err(format!("gradient check: the events change with the step size: {:?}", check.events));
    }
    Ok(())
}

/// The adjoint relation: with `--sens adjoint` every derivative the run reports equals, to
/// round-off, the forward sensitivities of the same run with the sensitivities out of the error
/// test (both differentiate the same steps; docs/accuracy.md, "The adjoint against the forward
/// sensitivities"). `Ok(None)` when the adjoint carried the run, `Ok(Some(why))` when it computed
/// forward sensitivities instead (what it does not carry yet, its warning).
fn adjoint_relation(g: &GenModel, c: Config) -> Result<Option<String>, String> {
    let v = Variant::default();
    let c = Config { grad: true, ..c };
    let model = Model::parse(&g.text(&v)).map_err(|e| format!("does not parse: {e}"))?;
    let names: Vec<String> = (0..g.params.len()).map(|j| format!("p{j}")).collect();
    let compiled = model.compile(&names).map_err(|e| format!("does not compile: {e}"))?;
    let (_, opts) = simulate(g, &v, c, RTOL, ATOL)?;
    let opts = SimOptions { sens_error_control: false, ..opts };
    let run = |sens| {
        compiled
            .simulate(&compiled.params(), &SimOptions { sens, ..opts.clone() })
            .map_err(|e| format!("does not run: {e}"))
    };
    let (forward, adjoint) = (run(hybc::Sens::Forward)?, run(hybc::Sens::Adjoint)?);
    let not_carried = (adjoint.result().stats.sens != Some(hybc::Sens::Adjoint)).then(|| {
        let said =
            adjoint.warnings().iter().map(|w| w.to_string()).find(|w| w.contains("adjoint does not carry"));
        // A model without parameters has no gradient to compute either way.
        said.unwrap_or_else(|| "no parameter".to_string())
    });
    // Every derivative of the report, forward and adjoint, NaN where none exists.
    let rows = |r: &hybc::Run| -> Vec<f64> {
        let res = r.result();
        let fin = &res.final_state;
        let mut out: Vec<f64> = res.events.iter().flat_map(|e| e.dtime.clone().unwrap_or_default()).collect();
        for d in [&fin.dstate, &fin.doutputs, &fin.dstate_total, &fin.doutputs_total].into_iter().flatten() {
            out.extend(d);
        }
        out
    };
    let (f, a) = (rows(&forward), rows(&adjoint));
    if f.len() != a.len() {
        return Err(format!("adjoint: {} derivatives reported, forward {}", a.len(), f.len()));
    }
    let scale = f.iter().filter(|x| x.is_finite()).fold(0.0f64, |m, x| m.max(x.abs()));
    for (k, (x, y)) in f.iter().zip(&a).enumerate() {
        let both_missing = x.is_nan() && y.is_nan();
        let within = (x - y).abs() <= 1e-10 * x.abs().max(1e-3 * scale).max(1e-300);
        if !both_missing && !within {
            return Err(format!("adjoint: derivative {k} is {y:e}, forward {x:e} (scale {scale:e})"));
        }
    }
    Ok(not_carried)
}

/// The tolerances of the run that stands in for the reference of a model whose guards are not
/// all polynomial: 1e4 times tighter than the runs it judges, so its own error is a negligible
/// part of their tolerance.
const TIGHT: (f64, f64) = (1e-12, 1e-14);

/// A reference from a tight run (DOP853 landing on every event, [`TIGHT`]) of a model whose guards
/// are not all polynomial, or why it cannot judge: the run stopped early, it or the same run at
/// the harness's tolerances warned (near-grazing,
/// near a breakpoint: an edge within the judged runs' accuracy), reported a derivative as not
/// existing, or has instants closer than [`exact::SEPARATION`] of the span to each other or to
/// `t_end`.
fn tight_reference(g: &GenModel) -> Result<Reference, String> {
    let c = Config { method: Method::Dop853, land: true, grad: true };
    let got = run_at(g, &Variant::default(), c, TIGHT.0, TIGHT.1)?;
    // A crossing near grazing is judged at the tolerances of the runs judged, not the tight one's:
    // one at the harness's tolerances must not warn either.
    let judged = run(g, &Variant::default(), c)?;
    if got.warnings > 0 || judged.warnings > 0 {
        return Err("a run warns (an edge within the tolerances)".into());
    }
    let sep = exact::SEPARATION * g.t_end.max(1.0);
    let mut times: Vec<f64> = got.events.iter().map(|e| e.1).collect();
    times.push(g.t_end);
    if times.windows(2).any(|w| w[1] - w[0] < sep) {
        return Err("instants within a tolerance of each other or of t_end".into());
    }
    let dual = |v: f64, d: &[f64]| -> Result<dd::Dual, String> {
        if d.iter().any(|x| !x.is_finite()) {
            return Err("a derivative does not exist".into());
        }
        Ok(dd::Dual { v: dd::Dd::new(v), d: d.iter().map(|&x| dd::Dd::new(x)).collect() })
    };
    let index = |name: &str| g.events.iter().position(|e| e.name == name).expect("a generated event");
    let mut events = Vec::new();
    for (name, t, dt) in &got.events {
        events.push((index(name), dual(*t, dt)?));
    }
    let final_state =
        got.state.iter().zip(&got.dstate).map(|(&x, d)| dual(x, d)).collect::<Result<_, _>>()?;
    Ok(Reference {
        event_grad: vec![true; events.len()],
        events,
        final_state,
        final_mode: 0,
        stopped: (got.stopped != "t_end").then(|| index(&got.stopped)),
        end_cusp: false,
    })
}

/// How far a value may be from its reference in units of the run's tolerance
/// `rtol |reference| + atol`: the error a local error control at `rtol` lets through over a
/// whole run (one step's error bound times the amplification of the flow and the events),
/// measured on the generated models: `HYBC_RELATIONS=full` prints the largest ratio seen per
/// quantity (docs/accuracy.md).
pub const K_VALUE: f64 = 1e3;
/// The same for gradients (sensitivities are error-controlled at the same tolerances).
pub const K_GRAD: f64 = 1e3;

#[derive(Default, Debug)]
struct Worst {
    value: f64,
    time: f64,
    grad: f64,
    dtime: f64,
}

impl Worst {
    fn merge(&mut self, o: &Worst) {
        self.value = self.value.max(o.value);
        self.time = self.time.max(o.time);
        self.grad = self.grad.max(o.grad);
        self.dtime = self.dtime.max(o.dtime);
    }
}

/// A discrepancy with what it was measured against.
#[derive(Clone, Debug)]
pub struct Violation {
    pub model: u64,
    pub what: String,
    pub flags: String,
    pub text: String,
}

impl std::fmt::Display for Violation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "model {} ({}): {}", self.model, self.flags, self.what)?;
        write!(f, "{}", self.text)
    }
}

/// The ratio of an error to the tolerance `tol` (rtol, atol) of a value of size `scale`.
fn ratio(got: f64, want: f64, scale: f64, tol: (f64, f64)) -> f64 {
    if got.is_nan() != want.is_nan() {
        return f64::INFINITY;
    }
    if got.is_nan() {
        return 0.0;
    }
    (got - want).abs() / (tol.0 * scale.abs() + tol.1)
}

/// Compares a run with the reference, in units of the run's tolerance `tol`; returns what
/// disagrees.
fn compare(
    want: &Reference,
    got: &Got,
    c: Config,
    g: &GenModel,
    tol: (f64, f64),
    worst: &mut Worst,
) -> Vec<String> {
    let mut bad = Vec::new();
    let names: Vec<&str> = want.events.iter().map(|(e, _)| g.events[*e].name.as_str()).collect();
    let got_names: Vec<&str> = got.events.iter().map(|(n, _, _)| n.as_str()).collect();
    if names != got_names {
        let times: Vec<f64> = got.events.iter().map(|e| e.1).collect();
        let want_times: Vec<f64> = want.events.iter().map(|(_, t)| t.v.f64()).collect();
        bad.push(format!("events {got_names:?} at {times:?}, expected {names:?} at {want_times:?}"));
        return bad;
    }
    let stopped = want.stopped.map_or("t_end".to_string(), |e| g.events[e].name.clone());
    if stopped != got.stopped {
        bad.push(format!("stopped by {}, expected {stopped}", got.stopped));
    }
    let span = g.t_end;
    for (k, ((_, t), (name, gt, gdt))) in want.events.iter().zip(&got.events).enumerate() {
        let r = ratio(*gt, t.v.f64(), span.max(t.v.f64().abs()), tol);
        worst.time = worst.time.max(r);
        if r > K_VALUE {
            bad.push(format!(
                "{name} #{k} at t = {gt:.17e}, expected {:.17e} ({r:.1} tolerances)",
                t.v.f64()
            ));
        }
        if c.grad && want.gradients_judged() {
            let dt = t.gradient();
            let scale = dt.iter().fold(0.0f64, |a, x| a.max(x.abs()));
            for (j, (&w, &h)) in dt.iter().zip(gdt).enumerate() {
                let r = ratio(h, w, scale.max(1.0), tol);
                worst.dtime = worst.dtime.max(r);
                if r > K_GRAD {
                    bad.push(format!("d{name}#{k}/dp{j} = {h:e}, expected {w:e} ({r:.1} tolerances)"));
                }
            }
        }
    }
    for (i, x) in want.final_state.iter().enumerate() {
        let (w, h) = (x.v.f64(), got.state[i]);
        let r = ratio(h, w, w.abs().max(1.0), tol);
        worst.value = worst.value.max(r);
        if r > K_VALUE {
            bad.push(format!("x{i} = {h:.17e}, expected {w:.17e} ({r:.1} tolerances)"));
        }
        if c.grad && want.gradients_judged() {
            let dx = x.gradient();
            let scale = dx.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            for (j, (&w, &h)) in dx.iter().zip(&got.dstate[i]).enumerate() {
                let r = ratio(h, w, scale.max(1.0), tol);
                worst.grad = worst.grad.max(r);
                if r > K_GRAD {
                    bad.push(format!("dx{i}/dp{j} = {h:e}, expected {w:e} ({r:.1} tolerances)"));
                }
            }
        }
    }
    bad
}

/// The tolerances of the convergence relation, each 100 times tighter than the one before; the
/// middle one is the harness's.
const LADDER: [(f64, f64); 3] = [(1e-6, 1e-8), (RTOL, ATOL), (1e-10, 1e-12)];

/// The largest error of a run's final values against the reference, relative to each value's
/// size (at least 1).
fn final_error(want: &Reference, got: &Got) -> f64 {
    want.final_state
        .iter()
        .zip(&got.state)
        .map(|(w, &h)| (h - w.v.f64()).abs() / w.v.f64().abs().max(1.0))
        .fold(0.0, f64::max)
}

/// The convergence relation under `c`: at every tolerance of [`LADDER`] the run agrees with the
/// reference within [`K_VALUE`] of that tolerance (the same events, values and gradients), and the
/// error shrinks with the tolerance: where the loosest run's error is more than the tightest
/// tolerance allows, the tightest run's is at most a tenth of it (a hundredth of the tolerance
/// would be proportionality; a tenth leaves room for the error control's own slack).
fn convergence(g: &GenModel, want: &Reference, c: Config, worst: &mut Worst) -> Vec<String> {
    let mut bad = Vec::new();
    let mut errors = Vec::new();
    for tol in [LADDER[0], LADDER[2]] {
        match run_at(g, &Variant::default(), c, tol.0, tol.1) {
            Ok(got) => {
                for what in compare(want, &got, c, g, tol, worst) {
                    bad.push(format!("at rtol {:e}: {what}", tol.0));
                }
                errors.push(final_error(want, &got));
            }
            Err(why) => bad.push(format!("at rtol {:e}: {why}", tol.0)),
        }
    }
    if let [loose, tight] = errors[..] {
        let allowed = K_VALUE * (LADDER[2].0 + LADDER[2].1);
        if loose > allowed && tight > loose / 10.0 {
            bad.push(format!(
                "the error does not shrink with the tolerance: {loose:e} at rtol {:e}, {tight:e} at rtol {:e}",
                LADDER[0].0, LADDER[2].0
            ));
        }
    }
    bad
}

/// Where a run reports that a derivative does not exist, one-sided differences of the final value
/// must disagree: a cusp. With `D(h) = (f(p+h) - f(p))/h - (f(p) - f(p-h))/h`, a cusp keeps `D`
/// as `h` shrinks (the jump of the derivative), a smooth value has `D(h)` of order `h`: the cusp
/// is confirmed when `D(h/4)` is more than half of `D(h)` and clear of the runs' noise (runs at
/// [`TIGHT`], `h = 1e-4 max(|p|, 1)`). Returns `Ok(None)` when nothing is reported missing.
fn missing_derivative_confirmed(g: &GenModel, c: Config, got: &Got) -> Result<Option<String>, String> {
    let Some((i, j)) = got
        .dstate
        .iter()
        .enumerate()
        .find_map(|(i, row)| row.iter().position(|d| d.is_nan()).map(|j| (i, j)))
    else {
        return Ok(None);
    };
    let at = |dp: f64| -> Result<f64, String> {
        let mut moved = g.clone();
        moved.params[j] += dp;
        let r = run_at(&moved, &Variant::default(), Config { grad: false, ..c }, TIGHT.0, TIGHT.1)?;
        Ok(r.state[i])
    };
    let f0 = at(0.0)?;
    let jump = |h: f64| -> Result<f64, String> { Ok((at(h)? - f0) / h - (f0 - at(-h)?) / h) };
    let h = 1e-4 * g.params[j].abs().max(1.0);
    let (d1, d4) = (jump(h)?, jump(h / 4.0)?);
    let noise = 1e3 * TIGHT.0 * f0.abs().max(1.0) / (h / 4.0);
    if d4.abs() > 0.5 * d1.abs() && d4.abs() > noise {
        Ok(Some(format!("dx{i}/dp{j}: confirmed, the one-sided derivatives differ by {d4:e}")))
    } else {
        Err(format!(
            "dx{i}/dp{j} is reported not to exist, but one-sided differences agree (D(h) = {d1:e}, D(h/4) = {d4:e}, h = {h:e})"
        ))
    }
}

/// The variants of a model each relation runs, with the shift of its reference.
fn variants(g: &GenModel, index: u64) -> Vec<(&'static str, Variant)> {
    let mut out = vec![
        ("shift 1e6", Variant { shift: 1e6, ..Variant::default() }),
        ("shift 1e-3", Variant { shift: 1e-3, ..Variant::default() }),
        ("bystander 1e10", Variant { bystander: Some(1e10), ..Variant::default() }),
        ("bystander 1e-10", Variant { bystander: Some(1e-10), ..Variant::default() }),
    ];
    if g.uses_time() {
        out.push(("clock for t", Variant { clock: true, ..Variant::default() }));
    }
    if g.events.len() > 1 {
        let mut order: Vec<usize> = (0..g.events.len()).collect();
        order.rotate_left(1 + (index as usize % (g.events.len() - 1)));
        out.push(("events reordered", Variant { order: Some(order), ..Variant::default() }));
    }
    out.push(("mode split", Variant { split: Some(g.t_end * 0.37), ..Variant::default() }));
    out
}

/// The result of a harness run.
#[derive(Default)]
pub struct Summary {
    pub models: usize,
    /// Models whose gradients the reference does not judge (`Reference::gradients_judged`).
    pub not_judged: usize,
    /// Models with a guard no polynomial describes, judged against a tight run of their own.
    pub relations_only: usize,
    /// The index of the last model drawn.
    pub last_index: u64,
    pub ambiguous: usize,
    pub runs: usize,
    pub violations: Vec<Violation>,
    /// Derivatives reported not to exist that one-sided differences confirm as cusps.
    pub cusps_confirmed: usize,
    /// Models whose run the adjoint carried, and those it left to forward sensitivities by why.
    pub adjoint: (usize, std::collections::BTreeMap<String, usize>),
    worst: Worst,
}

/// Checks models `first..` of `seed` until `count` clean models (or `budget`) are done.
pub fn harness(seed: u64, first: u64, count: usize, budget: Duration, configs: &[Config]) -> Summary {
    let started = Instant::now();
    let mut s = Summary::default();
    let mut index = first;
    while s.models < count && started.elapsed() < budget {
        let g = generate::model(seed, index);
        index += 1;
        let want = match exact::reference(&g, 0.0) {
            Outcome::Clean(r) => r,
            Outcome::NotPolynomial => match tight_reference(&g) {
                Ok(r) => {
                    s.relations_only += 1;
                    r
                }
                Err(why) => {
                    if std::env::var_os("HYBC_RELATIONS_WHY").is_some() {
                        println!("model {}: drawn again: {why}", index - 1);
                    }
                    s.ambiguous += 1;
                    continue;
                }
            },
            Outcome::Ambiguous(why) => {
                if std::env::var_os("HYBC_RELATIONS_WHY").is_some() {
                    println!("model {}: drawn again: {why}", index - 1);
                }
                s.ambiguous += 1;
                continue;
            }
        };
        s.models += 1;
        // The worst ratios of the models that keep every relation (a violation's is not a
        // measure of the tolerance).
        let mut worst = Worst::default();
        let violations_before = s.violations.len();
        s.last_index = index - 1;
        s.not_judged += usize::from(!want.gradients_judged());
        let mut report = |c: Config, variant: &str, what: String| {
            let mut text = g.text(&Variant::default());
            let _ = writeln!(text, "# seed {seed}, model {}, variant: {variant}", index - 1);
            s.violations.push(Violation { model: index - 1, what, flags: c.flags(), text });
        };
        let mut base_runs = Vec::new();
        for &c in configs {
            s.runs += 1;
            match run(&g, &Variant::default(), c) {
                Ok(got) => {
                    for what in compare(&want, &got, c, &g, (RTOL, ATOL), &mut worst) {
                        report(c, "none", what);
                    }
                    base_runs.push(Some(got));
                }
                Err(why) => {
                    report(c, "none", why);
                    base_runs.push(None);
                }
            }
        }
        // Every derivative reported not to exist is a cusp (the first such of each run).
        for (k, got) in base_runs.iter().enumerate() {
            let Some(got) = got.as_ref().filter(|_| configs[k].grad) else { continue };
            match missing_derivative_confirmed(&g, configs[k], got) {
                Ok(None) => {}
                Ok(Some(_)) => s.cusps_confirmed += 1,
                Err(why) => report(configs[k], "one-sided differences", why),
            }
        }
        // Convergence, under one configuration.
        let c = configs[(index as usize + 1) % configs.len()];
        s.runs += 2;
        for what in convergence(&g, &want, c, &mut worst) {
            report(c, "convergence", what);
        }
        // The gradients against differences of the run itself, under one configuration.
        let c = configs[index as usize % configs.len()];
        if c.grad {
            s.runs += 1;
            if let Err(why) = gradient_check(&g, c) {
                report(c, "gradient check", why);
            }
        }
        // The adjoint against the forward sensitivities, under one configuration.
        let c = configs[(index as usize + 2) % configs.len()];
        s.runs += 2;
        match adjoint_relation(&g, c) {
            Ok(None) => s.adjoint.0 += 1,
            Ok(Some(why)) => *s.adjoint.1.entry(why).or_default() += 1,
            Err(why) => report(c, "adjoint", why),
        }
        // Each relation under one configuration, cycling through them from model to model.
        for (k, (name, v)) in variants(&g, index).into_iter().enumerate() {
            let c = configs[(index as usize + k) % configs.len()];
            s.runs += 1;
            match run(&g, &v, c) {
                Ok(got) => {
                    for what in compare(&want, &got, c, &g, (RTOL, ATOL), &mut worst) {
                        report(c, name, what);
                    }
                }
                Err(why) => report(c, name, why),
            }
        }
        if s.violations.len() == violations_before {
            s.worst.merge(&worst);
        }
    }
    s
}

fn env<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// The seed CI checks.
const CI_SEED: u64 = 20261128;
/// How many clean models CI checks (59 s in the test build on the 2-core VM, with another build
/// sharing it).
const CI_MODELS: usize = 300;

/// Violations the full run found at [`CI_SEED`] that are not fixed yet, by model index, each
/// with its class, named by its symptom where the cause is not yet pinned down (the reproducers:
/// `HYBC_RELATIONS=full HYBC_RELATIONS_FIRST=N HYBC_RELATIONS_MODELS=1 cargo test --release
/// --test it relations -- --nocapture`). They belong to the event issue; the test fails on any
/// violation not listed here and on any listed model that no longer violates, so the list stays
/// true as they are fixed. None since model 779 (a stiff top under a time shift of 1e6, whose 2,578 events each fired up
/// to a spacing of `t` late) is applied at its crossings (docs/language.md rule 1, the lateness).
const KNOWN: &[(u64, &str)] = &[];

#[test]
fn generated_models_keep_every_relation_under_every_stepper() {
    let full = std::env::var("HYBC_RELATIONS").is_ok_and(|v| v == "full");
    let seed = env("HYBC_RELATIONS_SEED", CI_SEED);
    let count = env("HYBC_RELATIONS_MODELS", if full { 1000 } else { CI_MODELS });
    let budget = Duration::from_secs(env("HYBC_RELATIONS_SECONDS", if full { 1800 } else { 120 }));
    let first = env("HYBC_RELATIONS_FIRST", 0u64);
    let s = harness(seed, first, count, budget, &configs());
    let known = |m: u64| if seed == CI_SEED { KNOWN.iter().find(|k| k.0 == m).map(|k| k.1) } else { None };
    let unknown: Vec<&Violation> = s.violations.iter().filter(|v| known(v.model).is_none()).collect();
    let mut violating: Vec<u64> = s.violations.iter().map(|v| v.model).collect();
    violating.dedup();
    println!(
        "relations: seed {seed}, {} models ({} against a tight run, {} drawn again as ambiguous, {} with \
         gradients not judged, {} derivatives reported missing and confirmed as cusps), \
         {} runs, {} violations in {} models ({} of them known); worst in tolerances where every relation holds: values {:.1}, \
         times {:.1}, gradients {:.1}, time gradients {:.1}; the adjoint carried {} models and left {} to forward mode ({:?})",
        s.models,
        s.relations_only,
        s.ambiguous,
        s.not_judged,
        s.cusps_confirmed,
        s.runs,
        s.violations.len(),
        violating.len(),
        violating.iter().filter(|&&m| known(m).is_some()).count(),
        s.worst.value,
        s.worst.time,
        s.worst.grad,
        s.worst.dtime,
        s.adjoint.0,
        s.adjoint.1.values().sum::<usize>(),
        s.adjoint.1
    );
    // Each violation's line, then the reproducers of the first few models.
    for v in &s.violations {
        println!(
            "model {} ({}): {}{}",
            v.model,
            v.flags,
            v.what,
            known(v.model).map_or(String::new(), |k| format!(" [known: {k}]"))
        );
    }
    let mut shown = Vec::new();
    for v in &s.violations {
        if !shown.contains(&v.model) && shown.len() < 8 {
            shown.push(v.model);
            println!("\n{v}");
        }
    }
    assert!(s.models >= count.min(20), "only {} models in the budget", s.models);
    assert!(unknown.is_empty(), "{} violations (printed above)", unknown.len());
    if seed == CI_SEED && first == 0 {
        let last = s.last_index;
        let fixed: Vec<u64> =
            KNOWN.iter().map(|k| k.0).filter(|&m| m <= last && !violating.contains(&m)).collect();
        assert!(fixed.is_empty(), "known violations of models {fixed:?} are gone: take them off KNOWN");
    }
}

/// The one-sided check itself, from both sides: it confirms a derivative that does not exist and
/// refuses one that does. `x0 = (t - 1)^2` (a chain `x0, x1` under `der(x1) = 2`) touches the
/// guard `x0 <= p0` at `p0 = 0`: for `p0 > 0` the event fires and `x1 := 0` stops the chain's
/// slope; for `p0 < 0` it never fires. The final `x0` jumps with `p0`: no derivative. With the
/// guard moved clear (`p0 = -0.5`, no event), `x0(T)` does not depend on `p0` at all: a derivative
/// reported missing there is refused.
#[test]
fn the_one_sided_check_confirms_a_cusp_and_refuses_a_smooth_value() {
    use model::{Coef, Dir, Event, Lhs, Reset, Top};
    let touching = |p0: f64| GenModel {
        params: vec![p0],
        init: vec![Coef::c(1.0), Coef::c(-2.0)],
        chains: vec![vec![0, 1]],
        tops: vec![vec![Top { a: Coef::c(2.0), b: 0.0 }]],
        switches: vec![None],
        damping: vec![0.0],
        kinked: vec![false],
        events: vec![Event {
            name: "e0".into(),
            mode: None,
            lhs: Lhs::Lin(vec![(0, 1.0)]),
            dir: Dir::Falling,
            rhs: Coef::p(1.0, 0),
            cond: None,
            resets: vec![Reset { state: 1, a: Coef::c(0.0), b: Coef::c(0.0) }],
            to: None,
            stop: false,
        }],
        t_end: 2.0,
    };
    let c = Config { method: Method::Dop853, land: false, grad: true };
    let missing = |x: f64| Got {
        events: Vec::new(),
        state: vec![x, 0.0],
        dstate: vec![vec![f64::NAN], vec![0.0]],
        stopped: "t_end".into(),
        warnings: 0,
    };
    let confirmed = missing_derivative_confirmed(&touching(0.0), c, &missing(0.0));
    assert!(matches!(confirmed, Ok(Some(_))), "{confirmed:?}");
    let refused = missing_derivative_confirmed(&touching(-0.5), c, &missing(1.0));
    assert!(refused.is_err(), "{refused:?}");
}
