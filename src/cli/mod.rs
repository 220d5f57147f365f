//! The command line: arguments, files and printing. Every failure becomes a message on stderr and
//! an exit code (0 success, 1 model or run errors, 2 usage errors); nothing here panics on input.

mod check;
mod derive;
mod fit;
mod import;
mod optimize;
mod options;
mod output;
mod periodic;
mod run;
mod samples;
mod sobol;
mod sweep;
mod trajectory;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use crate::sema::ParamIdx;

/// hybc: a compiler for hybrid dynamical models with exact gradients through events.
#[derive(Debug, Parser)]
#[command(name = "hybc", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Check a model and print a summary of it.
    Check(check::CheckArgs),
    /// Translate an SBML model (Level 2 or 3) into a readable .hyb model.
    Import(import::ImportArgs),
    /// Print the symbolic derivatives of every model function.
    Derive(derive::DeriveArgs),
    /// Simulate a model; report events, final state, outputs and their gradients.
    Run(run::RunArgs),
    /// Fit parameters to targets on outputs, states and event times (least squares).
    Fit(fit::FitArgs),
    /// Run a model at many parameter points in parallel; one CSV or JSON row per point.
    Sweep(sweep::SweepArgs),
    /// Sobol' indices (first order, total, optionally second order) of outputs over parameter
    /// priors, from a Saltelli design; bootstrap intervals.
    Sobol(sobol::SobolArgs),
    /// A periodic orbit through events: the initial values a run returns to right after a section
    /// event, and the orbit's Floquet multipliers (stability).
    Periodic(periodic::PeriodicArgs),
    /// Minimise an output, state, event time or parameter subject to constraints on such
    /// quantities, with exact gradients through events (SLSQP); several seeded starts in parallel.
    Optimize(optimize::OptimizeArgs),
}

/// Exit codes, as documented in docs/cli.md.
pub const EXIT_MODEL_ERROR: u8 = 1;
/// A usage error: a bad flag, an unreadable file.
pub const EXIT_USAGE_ERROR: u8 = 2;
/// The simulation stopped early (Zeno behaviour or a runtime fault); what it computed is printed.
pub const EXIT_SIM_STOPPED: u8 = 3;
/// The command ran but its goal was not met: `hybc run --check-grad` found a derivative that
/// disagrees with its central difference, or `hybc fit` did not converge.
pub const EXIT_GOAL_NOT_MET: u8 = 4;
/// `hybc run --check-grad` failed nothing but could not judge a derivative: its finite
/// differences neither confirm nor refute it.
pub const EXIT_CANNOT_JUDGE: u8 = 5;

/// Runs the command line: parses the arguments, runs the command, returns its exit code.
pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            // clap prints help/version to stdout (exit 0) and usage errors to stderr (exit 2).
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() { EXIT_USAGE_ERROR } else { 0 });
        }
    };
    match cli.command {
        Command::Check(args) => check::run(&args),
        Command::Import(args) => import::run(&args),
        Command::Derive(args) => derive::run(&args),
        Command::Run(args) => run::run(&args),
        Command::Fit(args) => fit::run(&args),
        Command::Sweep(args) => sweep::run(&args),
        Command::Sobol(args) => sobol::run(&args),
        Command::Periodic(args) => periodic::run(&args),
        Command::Optimize(args) => optimize::run(&args),
    }
}

/// A model file read and checked through the front door, or the exit code after its errors were
/// printed (diagnostics for a bad model, a usage error for an unreadable file).
pub(crate) fn load_model(path: &Path) -> Result<crate::Model, ExitCode> {
    match crate::Model::from_file(path) {
        Ok(model) => Ok(model),
        Err(crate::Error::Model(e)) => {
            eprint!("{e}");
            Err(ExitCode::from(EXIT_MODEL_ERROR))
        }
        Err(crate::Error::Import(e)) => {
            eprint!("{e}");
            Err(ExitCode::from(EXIT_MODEL_ERROR))
        }
        Err(e) => {
            eprintln!("error: {}", error_chain(&e));
            Err(ExitCode::from(EXIT_USAGE_ERROR))
        }
    }
}

/// An error and its sources, joined by `: ` (`cannot read `x.hyb`: No such file or directory`).
pub(crate) fn error_chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        text.push_str(&format!(": {s}"));
        source = s.source();
    }
    text
}

/// Compiles `model` with gradients for `grad`, or prints why not and returns exit code 1.
pub(crate) fn compile_model(model: &crate::Model, grad: &[ParamIdx]) -> Result<crate::Compiled, ExitCode> {
    model.compile_params(grad).map_err(|e| {
        eprintln!("error: {}", error_chain(&e));
        ExitCode::from(EXIT_MODEL_ERROR)
    })
}

#[derive(Debug, Clone, clap::Args)]
pub(crate) struct ModelArg {
    /// The model file (.hyb, or SBML as .xml or .sbml).
    pub file: PathBuf,
}

/// Prints a usage error (a bad flag value) and returns its exit code.
pub(crate) fn usage_error(message: &str) -> ExitCode {
    eprintln!("error: {message}");
    ExitCode::from(EXIT_USAGE_ERROR)
}

/// Writes `text` to stdout. A closed pipe (`hybc run ... | head`) is not an error worth a panic:
/// the reader has what it wanted.
pub(crate) fn print_out(text: &str) {
    print_to(output::Stream::Stdout, text);
}

/// Writes `text` to `stream`, as [`print_out`] does to stdout.
pub(crate) fn print_to(stream: output::Stream, text: &str) {
    output::write_to(stream, |out| std::io::Write::write_all(out, text.as_bytes()));
}

/// A `fmt::Write` over an `io::Write`, keeping the IO error that `fmt::Error` cannot carry.
pub(crate) struct FmtIo<'w, W: std::io::Write + ?Sized> {
    inner: &'w mut W,
    error: Option<std::io::Error>,
}

impl<'w, W: std::io::Write + ?Sized> FmtIo<'w, W> {
    pub(crate) fn new(inner: &'w mut W) -> Self {
        FmtIo { inner, error: None }
    }

    /// The outcome of a formatted write through this adapter, as an IO result.
    pub(crate) fn result(self, written: std::fmt::Result) -> std::io::Result<()> {
        match (self.error, written) {
            (Some(e), _) => Err(e),
            (None, Ok(())) => Ok(()),
            (None, Err(_)) => Err(std::io::Error::other("formatting failed")),
        }
    }
}

impl<W: std::io::Write + ?Sized> std::fmt::Write for FmtIo<'_, W> {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        self.inner.write_all(s.as_bytes()).map_err(|e| {
            self.error = Some(e);
            std::fmt::Error
        })
    }
}
