//! Running costs (quadrature states: read by no flow, guard, condition or other state's reset)
//! left out of the step-size error test's norm (the default, as CVODES' quadratures;
//! `SimOptions::quadrature_error_control` puts them back): a model with a cost its steps resolve
//! takes exactly the steps of the same model without it; a cost they do not resolve (its own
//! scaled error above 1) rejects the step, so its integral is never left less accurate than the
//! tolerance. Below a floor of step size the run goes on with it and says so
//! (`SimWarning::CostUnresolved`).

use hybc::sim::SimWarning;
use hybc::Model;

/// A run with the model's default options (the running costs out of the error test).
fn steps(text: &str, grad: &[&str]) -> (usize, hybc::Run) {
    let model = Model::parse(text).expect("parses");
    assert!(!model.sim_options().quadrature_error_control, "off by default");
    steps_with(text, grad, false)
}

/// The running-cost warnings of a run: (state, steps, worst ratio).
fn cost_warnings(run: &hybc::Run) -> Vec<(String, usize, f64)> {
    run.result()
        .warnings
        .iter()
        .filter_map(|w| match w {
            SimWarning::CostUnresolved { state, steps, worst, .. } => {
                Some((state.to_string(), *steps, *worst))
            }
            _ => None,
        })
        .collect()
}

fn steps_with(text: &str, grad: &[&str], quadrature_error_control: bool) -> (usize, hybc::Run) {
    let model = Model::parse(text).expect("parses");
    let compiled = model.compile(grad).expect("compiles");
    let opts = hybc::SimOptions { quadrature_error_control, ..model.sim_options() };
    let run = compiled.simulate(&compiled.params(), &opts).expect("runs");
    (run.result().stats.steps, run)
}

const BASE: &str = "model decay\nparam k = 1\nstate x = 1\nder(x) = -k * x\n\
                    event kick when x <= 0.3 {\n    x := 1\n}\nsimulate t_end = 5, rtol = 1e-8, atol = 1e-10\n";

#[test]
fn a_running_cost_its_steps_do_not_resolve_rejects_them_and_comes_out_right() {
    // The cost's integrand oscillates 50 times faster than x decays: the decay's steps do not
    // resolve it (the integral of this positive integrand came out negative from them).
    let with_cost = BASE.replace(
        "der(x) = -k * x\n",
        "der(x) = -k * x\nstate cost = 0\nder(cost) = 1e3 * sin(50 * t)^2 * x^2\noutput c = cost\n",
    );
    let reference =
        steps_with(&with_cost.replace("rtol = 1e-8, atol = 1e-10", "rtol = 1e-12, atol = 1e-14"), &[], true)
            .1;
    let want = reference.output("c").unwrap();
    assert!(want > 0.0);
    for grad in [&[][..], &["k"][..]] {
        let (plain, _) = steps(BASE, grad);
        let (costed, run) = steps(&with_cost, grad);
        // Its own error test takes the steps it needs: more than the decay alone, fewer than
        // under the full control (where it also weighs in the states' norm), and no warning.
        assert!(costed > 10 * plain, "grad {grad:?}: {costed} vs {plain} steps");
        assert!(cost_warnings(&run).is_empty(), "{:?}", cost_warnings(&run));
        let got = run.output("c").unwrap();
        assert!((got - want).abs() < 1e-6 * want, "grad {grad:?}: {got} vs {want}");
    }
    let (controlled_steps, controlled) = steps_with(&with_cost, &[], true);
    assert!(cost_warnings(&controlled).is_empty());
    assert!((controlled.output("c").unwrap() - want).abs() < 1e-6 * want);
    assert!(controlled_steps > 10 * steps(BASE, &[]).0, "{controlled_steps} steps");
    // A state the cost's integrand is read by (here: by a guard) is no running cost: it drives
    // the steps as before.
    let guarded = with_cost.replace("event kick when x <= 0.3", "event kick when x + 1e-9 * cost <= 0.3");
    let (plain, _) = steps(BASE, &[]);
    let (driven, _) = steps(&guarded, &[]);
    assert!(driven > 3 * plain, "{driven} vs {plain} steps");
}

#[test]
fn a_cost_no_step_resolves_is_kept_at_the_floor_and_warned_about() {
    // 1 / sqrt(x) from x = 1e-12 integrates to 2 (1 - 1e-6), but no step near the start resolves
    // it to atol: below the floor of step size the run goes on, its integral is still close,
    // and it says so.
    let text =
        "model sing\nstate x = 1e-12\nstate c = 0\nder(x) = 1\nder(c) = 1 / sqrt(x)\noutput total = c\n\
                simulate t_end = 1, rtol = 1e-8, atol = 1e-10\n";
    let (_, run) = steps(text, &[]);
    let got = run.output("total").unwrap();
    assert!((got - 2.0 * (1.0 - 1e-6)).abs() < 1e-2, "{got}");
    let warned = cost_warnings(&run);
    assert_eq!(warned.len(), 1, "{warned:?}");
    assert_eq!(warned[0].0, "c");
    assert!(run.result().warnings.iter().any(|w| w.to_string().contains("--quadrature-error-control")));
}

#[test]
fn a_model_of_running_costs_alone_keeps_its_error_test() {
    // Every state a quadrature: nothing else controls the steps, so they all stay in the test;
    // the integral of cos over [0, 5] is sin(5) to the tolerance.
    let text = "model q\nstate s = 0\nder(s) = cos(t)\nsimulate t_end = 5, rtol = 1e-10, atol = 1e-12\n";
    let (_, run) = steps(text, &[]);
    let s = run.state("s").unwrap();
    assert!((s - 5f64.sin()).abs() < 1e-9, "{s}");
    assert!(cost_warnings(&run).is_empty());
}

#[test]
fn a_smooth_running_cost_is_resolved_by_the_states_steps_and_not_warned_about() {
    // The other side of the warning: a cost whose integrand is a smooth function of the states
    // (x^2 on the decay with its kicks) is accurate from the states' steps alone, to the
    // tolerances, and no warning is given. Without gradients it takes exactly their steps; with
    // them its sensitivities' own error test may reject a step or two where they start from 0
    // (atol is their scale there): 19 against 20 accepted here, with 2 rejected.
    let with_cost = BASE
        .replace("der(x) = -k * x\n", "der(x) = -k * x\nstate cost = 0\nder(cost) = x^2\noutput c = cost\n");
    assert_eq!(steps(BASE, &[]).0, steps(&with_cost, &[]).0);
    let (plain, _) = steps(BASE, &["k"]);
    let (costed, run) = steps(&with_cost, &["k"]);
    assert!(plain <= costed && costed <= plain + 4, "{plain} vs {costed}");
    assert!(cost_warnings(&run).is_empty(), "{:?}", cost_warnings(&run));
    let reference = steps_with(
        &with_cost.replace("rtol = 1e-8, atol = 1e-10", "rtol = 1e-12, atol = 1e-14"),
        &["k"],
        true,
    )
    .1;
    let (got, want) = (run.output("c").unwrap(), reference.output("c").unwrap());
    assert!((got - want).abs() < 1e-7 * want, "{got} vs {want}");
    let (got, want) = (run.doutput("c", "k").unwrap(), reference.doutput("c", "k").unwrap());
    assert!((got - want).abs() < 1e-7 * want, "{got} vs {want}");
}

#[test]
fn every_shipped_running_cost_is_resolved_without_the_control() {
    // The shipped models with a running cost (the juggler's paddle effort, the compass gait's
    // hip work, the hopper's thrust effort): at their defaults no step leaves a cost unresolved.
    for (file, cost) in [
        ("models/juggler.hyb", "effort"),
        ("models/compass_gait.hyb", "work"),
        ("models/hopper_apex.hyb", "effort"),
    ] {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
        let text = std::fs::read_to_string(&path).expect("shipped model");
        let model = Model::parse(&text).expect("parses");
        assert!(!model.sim_options().quadrature_error_control);
        // The cost is a quadrature state, so it is out of the test (the check is not vacuous).
        let quadrature = hybc::sema::quadrature_states(model.checked());
        let at = model.state_names().position(|s| s == cost).expect("the cost state");
        assert!(quadrature[at], "{file}: {cost}");
        let compiled = model.compile::<&str>(&[]).expect("compiles");
        let run = compiled.simulate(&compiled.params(), &model.sim_options()).expect("runs");
        assert!(cost_warnings(&run).is_empty(), "{file}: {:?}", cost_warnings(&run));
    }
}
