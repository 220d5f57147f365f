//! Running costs (quadrature states: read by no flow, guard, condition or other state's reset)
//! left out of the step-size error test (`SimOptions::quadrature_error_control` off,
//! `--no-quadrature-error-control`; CVODES' default for its quadratures, not hybc's): a model with
//! one then takes exactly the steps of the same model without it, however wild its integrand,
//! and the integral is computed from those steps, not under its own control, so an integrand
//! faster than the dynamics comes out wrong. With the control on (the default) it is right.

use hybc::Model;

/// A run with the running costs out of the error test.
fn steps(text: &str, grad: &[&str]) -> (usize, hybc::Run) {
    steps_with(text, grad, false)
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
}
