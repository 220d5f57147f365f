//! Runs of models written out in a test: compile, set options, simulate, read the event times.

use hybc::{Model, Run, SimOptions};

/// Compiles `text` with gradients for `grad` and runs it at its defaults with `opts` over the
/// model's `simulate` line.
pub fn run(text: &str, grad: &[&str], opts: impl FnOnce(&mut SimOptions)) -> Run {
    let model = Model::parse(text).unwrap_or_else(|e| panic!("{e}"));
    let compiled = model.compile(grad).expect("compiles");
    let mut o = model.sim_options();
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
