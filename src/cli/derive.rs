//! `hybc derive FILE [--wrt P,...] [--mode M] [--only NAMES]`: print every symbolic derivative of a
//! model, or those of some states, events and outputs.

use std::process::ExitCode;

use super::options::parse_param_list;
use super::{load_model, usage_error, ModelArg};

#[derive(Debug, clap::Args)]
pub struct DeriveArgs {
    #[command(flatten)]
    model: ModelArg,
    /// Parameters to differentiate with respect to: `P1,P2,...` or `all` (the default).
    #[arg(long, value_name = "P1,P2|all", default_value = "all")]
    wrt: String,
    /// Show only this mode (top-level events are always shown).
    #[arg(long, value_name = "MODE")]
    mode: Option<String>,
    /// Show only these states, events and outputs: names (`v[3]`, `low[3]`, `ke`), whole arrays
    /// and families (`v`, `low`), or ranges of elements, inclusive (`low[2..5]`, `T[1][0..2]`).
    #[arg(long, value_name = "N1,N2,..", value_delimiter = ',')]
    only: Option<Vec<String>>,
}

pub fn run(args: &DeriveArgs) -> ExitCode {
    let model = match load_model(&args.model.file) {
        Ok(model) => model,
        Err(code) => return code,
    };
    let wrt = match parse_param_list(&model, &args.wrt, "--wrt") {
        Ok(wrt) => wrt,
        Err(message) => return usage_error(&message),
    };
    let checked = model.checked();
    let mode = match &args.mode {
        None => None,
        Some(name) => match checked.mode_index(name) {
            Some(m) => Some(m),
            None => {
                let names: Vec<&str> = checked.modes.iter().map(|m| m.name.as_str()).collect();
                return usage_error(&format!(
                    "--mode: model `{}` has no mode `{name}`; its modes are {}",
                    checked.name,
                    names.join(", ")
                ));
            }
        },
    };
    let text = match &args.only {
        None => model.derivatives(&wrt, mode),
        Some(names) => {
            let names: Vec<&str> = names.iter().map(String::as_str).collect();
            match model.derivatives_only(&wrt, mode, &names) {
                Ok(text) => text,
                Err(message) => return usage_error(&message),
            }
        }
    };
    super::print_out(&text);
    ExitCode::SUCCESS
}
