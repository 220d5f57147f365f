//! Helpers shared by the test modules.

pub mod cli;
pub mod expr;
pub mod hand_functions;
pub mod hand_systems;
pub mod knots;
pub mod measured;
pub mod models;
pub mod printed;
pub mod reference;
pub mod runs;

use proptest::test_runner::{Config, FailurePersistence, FileFailurePersistence};

/// Proptest's settings for this crate with `cases` random cases. A failing case is kept next to
/// the test's source file as `<file>.proptest-regressions` (`tests/it/expr_props.rs` ->
/// `tests/it/expr_props.proptest-regressions`) and re-run first from then on. Proptest's default
/// (`SourceParallel`) would put it in `tests/proptest-regressions/expr_props.txt`, beside this
/// crate, since `tests/it` has a `main.rs`. `PROPTEST_DISABLE_FAILURE_PERSISTENCE` still turns
/// persistence off.
pub fn proptest_config(cases: u32) -> Config {
    let default = Config::default();
    let failure_persistence = default.failure_persistence.as_ref().map(|_| {
        Box::new(FileFailurePersistence::WithSource("proptest-regressions")) as Box<dyn FailurePersistence>
    });
    Config { cases, failure_persistence, ..default }
}

/// The generated chain models (workload W5 among them), shared with the benches.
#[path = "../../../benches/support/chain.rs"]
pub mod chain;

/// Particles in a box written with arrays, and their closed form, shared with the benches.
#[path = "../../../benches/support/particle_box.rs"]
pub mod particle_box;

/// `run`, made with `opts`, passes `hybc::gradcheck` at `opts.rtol`: every reported derivative
/// against central differences of re-runs of its compiled model with the same options.
pub fn assert_gradients_check(run: &hybc::Run, opts: &hybc::SimOptions) {
    let compiled = run.compiled();
    let p = compiled.params().values().to_vec();
    let check = hybc::gradcheck::check(
        compiled.native(),
        &p,
        opts,
        run.result(),
        &hybc::gradcheck::CheckOptions::for_rtol(opts.rtol),
    )
    .expect("checks");
    assert!(check.passed(), "{check:#?}");
}
