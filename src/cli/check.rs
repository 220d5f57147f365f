//! `hybc check FILE`: validate a model and print the door's summary of it (`Model::summary`).

use std::process::ExitCode;

use super::{load_model, ModelArg};

#[derive(Debug, clap::Args)]
pub struct CheckArgs {
    #[command(flatten)]
    model: ModelArg,
}

pub fn run(args: &CheckArgs) -> ExitCode {
    match load_model(&args.model.file) {
        Ok(model) => {
            eprint!("{}", model.warnings());
            super::print_out(&model.summary());
            ExitCode::SUCCESS
        }
        Err(code) => code,
    }
}
