//! hybc: a compiler for hybrid dynamical models with exact gradients through events.
//!
//! The front door ([`Model`], [`Compiled`], [`Params`], [`Run`], [`Error`]):
//!
//! ```no_run
//! use hybc::{Error, Model};
//!
//! fn main() -> Result<(), Error> {
//!     let model = Model::from_file("models/ball.hyb")?;
//!     let compiled = model.compile(&["e", "h0"])?;
//!     let mut params = model.params();
//!     params.set("e", 0.9)?;
//!     let run = compiled.simulate(&params, &model.sim_options())?;
//!     println!("{:?} {:?}", run.output("energy"), run.doutput("energy", "e"));
//!     Ok(())
//! }
//! ```
//!
//! Pipeline behind it: `syntax` (text -> AST) -> `sema` (AST -> checked model) -> `expr` (model
//! functions and their symbolic derivatives as a DAG) -> `codegen` (DAG -> native kernels) ->
//! `sim` (event-locating integrator with sensitivities).
//!
//! Cargo features: `cli` (the `hybc` command: clap, indicatif; implies `plot`) and `plot` (SVG and
//! PNG figures: plotters), both on by default. Without them the library needs neither.

// All `unsafe` is in `codegen` (calling the JIT's code) and in `sim::method::sums`, the stage
// sums (a CPU feature dispatch and checked-once block loads); each allows it where it stands.
#![deny(unsafe_code)]

mod api;
#[cfg(feature = "cli")]
pub mod cli;
pub mod codegen;
pub mod diag;
pub mod expr;
pub mod fit;
pub mod gradcheck;
pub mod limits;
pub mod lower;
pub mod number;
pub mod optimize;
pub mod periodic;
#[cfg(feature = "plot")]
pub mod plot;
pub mod report;
pub mod sema;
pub mod sim;
pub mod sobol;
mod stack;
pub mod status;
pub mod sweep;
pub mod syntax;

pub use api::{
    method_named, positive_number, time_span, Compiled, Error, FitFailure, FitRequest, GradCheckRequest,
    Model, ModelError, OptimizeFailure, OptimizeRequest, OptionError, ParamError, Params, PeriodicRequest,
    Run, SimOverrides, Simulator, SobolFailure, SobolRequest, Spelling, SweepRequest, VaryPriorError,
    MAX_MODEL_BYTES,
};
pub use sim::{Method, SimOptions, StopReason, TrajectoryRequest};

use diag::Diagnostic;

/// Everything the front end can reject in a model text.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FrontendError {
    #[error(transparent)]
    Parse(#[from] syntax::ParseError),
    #[error("{} error(s) in the model", .0.len())]
    Check(Vec<sema::CheckError>),
}

impl FrontendError {
    /// The errors as diagnostics, in source order.
    pub fn diagnostics(&self, source: &str) -> Vec<Diagnostic> {
        match self {
            FrontendError::Parse(e) => vec![Diagnostic {
                message: e.message.clone(),
                span: e.span,
                label: format!("expected {}", e.expected),
                notes: Vec::new(),
            }],
            FrontendError::Check(errors) => errors.iter().map(|e| e.to_diagnostic(source)).collect(),
        }
    }

    /// The errors rendered against the source, with `file_name` in every location.
    pub fn render(&self, file_name: &str, source: &str) -> String {
        diag::render(file_name, source, &self.diagnostics(source))
    }
}

/// Parses and checks a model text.
pub fn check_source(source: &str) -> Result<sema::Model, FrontendError> {
    let file = syntax::parse(source)?;
    sema::check(&file).map_err(FrontendError::Check)
}
