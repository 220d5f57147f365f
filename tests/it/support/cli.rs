//! Test helper shared by the tests that drive the `hybc` binary: run it from the repository root
//! (so `models/...` paths work) and capture everything it prints.

use std::process::{Command, Output};

/// Runs this build's `hybc` with `args` from the repository root.
pub fn hybc(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hybc"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("hybc runs")
}
