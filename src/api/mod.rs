//! The library's front door: text in, runs out, with one set of defaults.
//!
//! ```text
//! Model::parse(text) --compile(grad)--> Compiled --simulate(params, opts)--> Run
//!                                           \--simulator(opts)--> Simulator (reused, owned)
//! ```
//!
//! Every type here is owned and cheap to clone (the checked model and the native code are shared
//! through `Arc`s), so a `Compiled` can move into a thread, a thread pool or a Python object.
//! This module only composes the stages (`syntax`, `sema`, `lower`, `codegen`, `sim`); it adds no
//! numerics of its own. The CLI, sweeps, fits and gradient checks go through it.

mod compiled;
mod error;
mod frontend;
mod import;
mod model;
mod options;
mod params;
mod request;
mod run;
mod summary;

pub use compiled::{Compiled, Simulator};
pub use error::{Error, ModelError, ParamError};
pub use frontend::{check_source, FrontendError};
pub use import::{import_sbml, import_sbml_file, is_sbml_path, ImportError};
pub use model::{Model, MAX_MODEL_BYTES};
pub use options::{
    method_named, positive_number, sens_named, time_span, OptionError, SimOverrides, Spelling,
};
pub use params::Params;
pub use request::fit::{FitFailure, FitRequest};
pub use request::gradcheck::GradCheckRequest;
pub use request::optimize::{OptimizeFailure, OptimizeRequest};
pub use request::periodic::PeriodicRequest;
pub use request::sobol::{SobolFailure, SobolRequest, VaryPriorError};
pub use request::sweep::SweepRequest;
pub use run::Run;
