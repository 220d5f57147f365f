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

// All `unsafe` is in `codegen` (calling the JIT's code), in `sim::method::sums`, the stage sums
// (a CPU feature dispatch and checked-once block loads), and in `sim::fp_mode` (the
// floating-point control register); each allows it where it stands.
#![deny(unsafe_code)]
// Every public item says what it is: the library is used from outside (the CLI, Python, tests).
#![warn(missing_docs)]

mod api;
#[cfg(feature = "cli")]
pub mod cli;
pub mod codegen;
pub mod diag;
pub mod expand;
pub mod expr;
pub mod fit;
pub mod gradcheck;
pub mod interval;
pub mod limits;
pub mod lower;
pub mod number;
pub mod optimize;
pub mod periodic;
#[cfg(feature = "plot")]
pub mod plot;
pub mod report;
pub mod sbml;
pub mod sema;
pub mod sim;
pub mod sobol;
mod stack;
pub mod status;
pub mod sweep;
pub mod syntax;

pub use api::{
    check_source, import_sbml, import_sbml_file, is_sbml_path, method_named, positive_number, sens_named,
    time_span, Compiled, Error, FitFailure, FitRequest, FrontendError, GradCheckRequest, ImportError, Model,
    ModelError, OptimizeFailure, OptimizeRequest, OptionError, ParamError, Params, PeriodicRequest, Run,
    SimOverrides, Simulator, SobolFailure, SobolRequest, Spelling, SweepRequest, VaryPriorError,
    MAX_MODEL_BYTES,
};
pub use sim::{Method, Sens, SimOptions, StopReason, TrajectoryRequest};
