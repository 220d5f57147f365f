//! Runs of models written out in a test: compile, set options, simulate, read the event times.
//! A test body run under [`with_method`] integrates with that method wherever it takes its
//! options from here ([`run`], [`options`]) and does not choose a method itself: the event
//! tests run so with every stepper ([`every_test_with`]). Under [`with_adjoint_check`] every
//! [`run`] with gradients is also run by the adjoint and by forward sensitivities out of the
//! error test (the same steps), and the two must agree (`check_adjoint`).

use std::cell::Cell;

use hybc::sim::{Method, SimResult};
use hybc::{Model, Run, Sens, SimOptions};

thread_local! {
    static METHOD: Cell<Option<Method>> = const { Cell::new(None) };
    static LAND: Cell<Option<bool>> = const { Cell::new(None) };
    /// Under [`with_adjoint_check`]: the runs checked, and of those the adjoint carried.
    static ADJOINT: Cell<Option<(usize, usize)>> = const { Cell::new(None) };
}

/// The model's `simulate` options, with the method of an enclosing [`with_method`].
pub fn options(model: &Model) -> SimOptions {
    let mut o = model.sim_options();
    if let Some(method) = METHOD.get() {
        o.method = method;
    }
    if let Some(land) = LAND.get() {
        o.land_events = Some(land);
    }
    o
}

/// Runs `body` with `method` as the method of [`options`] and [`run`] on this thread.
pub fn with_method<T>(method: Method, body: impl FnOnce() -> T) -> T {
    let before = METHOD.replace(Some(method));
    let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(body));
    METHOD.set(before);
    out.unwrap_or_else(|e| std::panic::resume_unwind(e))
}

/// [`every_test_with`], with `SimOptions::land_events` forced to `land` as well.
pub fn every_test_landing(method: Method, land: bool, tests: &[(&str, fn())]) -> Vec<String> {
    let before = LAND.replace(Some(land));
    let failed = every_test_with(method, tests).into_iter().map(|f| format!("{f} landing {land}")).collect();
    LAND.set(before);
    failed
}

/// Runs every test of `tests` under `method`; returns the names of those that failed (each
/// failure's message is printed as it happens).
pub fn every_test_with(method: Method, tests: &[(&str, fn())]) -> Vec<String> {
    let mut failed = Vec::new();
    for (name, test) in tests {
        if with_method(method, || std::panic::catch_unwind(test)).is_err() {
            failed.push(format!("{name} ({method:?})"));
        }
    }
    failed
}

/// Compiles `text` with gradients for `grad` and runs it at its defaults with `opts` over the
/// model's `simulate` line.
pub fn run(text: &str, grad: &[&str], opts: impl FnOnce(&mut SimOptions)) -> Run {
    let model = Model::parse(text).unwrap_or_else(|e| panic!("{e}"));
    let compiled = model.compile(grad).expect("compiles");
    let mut o = options(&model);
    opts(&mut o);
    if ADJOINT.get().is_some() && !grad.is_empty() {
        check_adjoint(&compiled, &model.params(), &o);
    }
    compiled.simulate(&model.params(), &o).expect("valid options")
}

/// Runs `body` with every [`run`] with gradients checked by [`check_adjoint`]; returns how many
/// runs were checked and how many of them the adjoint carried (the others it leaves to forward
/// mode by name, which the check confirms).
pub fn with_adjoint_check(body: impl FnOnce()) -> (usize, usize) {
    let before = ADJOINT.replace(Some((0, 0)));
    let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(body));
    let counts = ADJOINT.replace(before).expect("set above");
    out.unwrap_or_else(|e| std::panic::resume_unwind(e));
    counts
}

/// The run with `--sens adjoint` against the run with forward sensitivities out of the error
/// test (`sens_error_control` off: the same steps, so the same derivative computed two ways):
/// every event time's and final value's derivative equal to 1e-10 of its size (or of a
/// thousandth of the run's largest derivative, for one that cancels to near zero), the same
/// entries not existing, or the adjoint's run is the forward one with the warning that names
/// what it does not carry: on the event rules' runs, only a run that ended early (stuck), which
/// has no gradient at `t_end` by either mode.
pub fn check_adjoint(compiled: &hybc::Compiled, params: &hybc::Params, o: &SimOptions) {
    let same_steps = SimOptions { sens: Sens::Forward, sens_error_control: false, ..o.clone() };
    let by_adjoint = SimOptions { sens: Sens::Adjoint, ..same_steps.clone() };
    let (Ok(forward), Ok(adjoint)) =
        (compiled.simulate(params, &same_steps), compiled.simulate(params, &by_adjoint))
    else {
        return;
    };
    let (checked, carried) = ADJOINT.get().unwrap_or_default();
    let took_adjoint = adjoint.result().stats.sens == Some(Sens::Adjoint);
    ADJOINT.set(Some((checked + 1, carried + usize::from(took_adjoint))));
    if !took_adjoint {
        let said = adjoint.warnings().iter().map(|w| w.to_string()).collect::<Vec<_>>();
        // A run that ended early has no gradient by either mode; otherwise the refusal is named.
        let early = !matches!(
            adjoint.result().stopped_by,
            hybc::sim::StopReason::TEnd | hybc::sim::StopReason::Event { .. }
        );
        // What the adjoint leaves to forward mode inside a run is refused by name; the event
        // rules' runs hold none of it (a grazing crossing, a reset onto a guard and a switch at
        // an event's instant are carried), so only a run that ended early may be left.
        assert!(early && said.iter().any(|w| w.contains("adjoint does not carry")), "{said:?}");
        return;
    }
    let (f, a) = (derivatives(forward.result()), derivatives(adjoint.result()));
    assert_eq!(f.len(), a.len(), "the same quantities in both modes");
    let largest = f.iter().filter(|x| x.is_finite()).fold(0.0f64, |m, x| m.max(x.abs()));
    for (i, (x, y)) in f.iter().zip(&a).enumerate() {
        if x.is_nan() || y.is_nan() {
            assert!(x.is_nan() && y.is_nan(), "derivative {i}: forward {x}, adjoint {y}: existence differs");
            continue;
        }
        let tol = 1e-10 * x.abs().max(1e-3 * largest).max(f64::MIN_POSITIVE);
        assert!((x - y).abs() <= tol, "derivative {i}: forward {x}, adjoint {y} (tolerance {tol:e})");
    }
}

/// Every derivative a run reports, in one order: each event's time gradient, then the final
/// states' and outputs'.
fn derivatives(r: &SimResult) -> Vec<f64> {
    let mut all: Vec<f64> = r.events.iter().flat_map(|e| e.dtime.clone().unwrap_or_default()).collect();
    let fin = &r.final_state;
    for d in [&fin.dstate, &fin.doutputs] {
        all.extend(d.clone().unwrap_or_default());
    }
    all
}

/// The times of a run's events, in order.
pub fn times(r: &Run) -> Vec<f64> {
    r.events().iter().map(|e| e.time).collect()
}

/// The names of a run's events, in order.
pub fn names(r: &Run) -> Vec<String> {
    r.events().iter().map(|e| e.name.to_string()).collect()
}
