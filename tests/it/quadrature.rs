//! Running costs (quadrature states: read by no flow, guard, condition or other state's reset)
//! left out of the step-size error test (the default, as CVODES' quadratures;
//! `SimOptions::quadrature_error_control` puts them back): a model with one takes exactly the
//! steps of the same model without it, however wild its integrand, and the integral is computed
//! from those steps, so an integrand faster than the dynamics comes out wrong, and the run says
//! so (`SimWarning::CostUnresolved`). With the control on it is right.

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
fn a_running_cost_takes_no_part_in_the_step_size() {
    // The cost's integrand oscillates 50 times faster than x decays: under the error test it
    // would need hundreds of steps.
    let with_cost = BASE.replace(
        "der(x) = -k * x\n",
        "der(x) = -k * x\nstate cost = 0\nder(cost) = 1e3 * sin(50 * t)^2 * x^2\noutput c = cost\n",
    );
    for grad in [&[][..], &["k"][..]] {
        let (plain, _) = steps(BASE, grad);
        let (costed, _) = steps(&with_cost, grad);
        assert_eq!(plain, costed, "grad {grad:?}");
    }
    // Those steps do not resolve sin(50 t)^2: the integral of a positive integrand comes out
    // wrong (negative, even). Under the error control it is right: against a run at rtol 1e-12.
    let (_, loose) = steps(&with_cost, &[]);
    let (controlled_steps, controlled) = steps_with(&with_cost, &[], true);
    let reference =
        steps_with(&with_cost.replace("rtol = 1e-8, atol = 1e-10", "rtol = 1e-12, atol = 1e-14"), &[], true)
            .1;
    let want = reference.output("c").unwrap();
    assert!(want > 0.0);
    assert!((loose.output("c").unwrap() - want).abs() > 1.0, "uncontrolled {}", loose.output("c").unwrap());
    // Not silently: the run names the cost and counts the steps that did not resolve it.
    let warned = cost_warnings(&loose);
    assert_eq!(warned.len(), 1, "{warned:?}");
    assert_eq!(warned[0].0, "cost");
    assert!(warned[0].1 >= 1 && warned[0].2 > 1.0, "{warned:?}");
    assert!(loose.result().warnings.iter().any(|w| w.to_string().contains("--quadrature-error-control")));
    // Under the control nothing is out of the test, so nothing to warn about.
    assert!(cost_warnings(&controlled).is_empty());
    assert!(
        (controlled.output("c").unwrap() - want).abs() < 1e-6 * want,
        "{} vs {want}",
        controlled.output("c").unwrap()
    );
    assert!(controlled_steps > 10 * steps(BASE, &[]).0, "{controlled_steps} steps");
    // A state the cost's integrand is read by (here: by a guard) is no running cost: it drives
    // the steps as before.
    let guarded = with_cost.replace("event kick when x <= 0.3", "event kick when x + 1e-9 * cost <= 0.3");
    let (plain, _) = steps(BASE, &[]);
    let (driven, _) = steps(&guarded, &[]);
    assert!(driven > 3 * plain, "{driven} vs {plain} steps");
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
    // tolerances, with its gradient, and no warning is given.
    let with_cost = BASE
        .replace("der(x) = -k * x\n", "der(x) = -k * x\nstate cost = 0\nder(cost) = x^2\noutput c = cost\n");
    let (plain, _) = steps(BASE, &["k"]);
    let (costed, run) = steps(&with_cost, &["k"]);
    assert_eq!(plain, costed);
    assert!(cost_warnings(&run).is_empty(), "{:?}", cost_warnings(&run));
    let reference = steps_with(
        &with_cost.replace("rtol = 1e-8, atol = 1e-10", "rtol = 1e-12, atol = 1e-14"),
        &["k"],
        true,
    )
    .1;
    let (got, want) = (run.output("c").unwrap(), reference.output("c").unwrap());
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
