//! Runs of models written out in a test: compile, set options, simulate, read the event times.
//! A test body run under [`with_method`] integrates with that method wherever it takes its
//! options from here ([`run`], [`options`]) and does not choose a method itself: the event
//! tests run so with every stepper ([`every_test_with`]).

use std::cell::Cell;

use hybc::sim::Method;
use hybc::{Model, Run, SimOptions};

thread_local! {
    static METHOD: Cell<Option<Method>> = const { Cell::new(None) };
    static LAND: Cell<Option<bool>> = const { Cell::new(None) };
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
    compiled.simulate(&model.params(), &o).expect("valid options")
}

/// The times of a run's events, in order.
pub fn times(r: &Run) -> Vec<f64> {
    r.events().iter().map(|e| e.time).collect()
}

/// The names of a run's events, in order.
pub fn names(r: &Run) -> Vec<String> {
    r.events().iter().map(|e| e.name.to_string()).collect()
}
