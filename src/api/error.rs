//! The front door's one error type, joining the stages' errors.

use std::path::PathBuf;

use super::FrontendError;
use super::{FitFailure, OptimizeFailure, SobolFailure};
use crate::codegen::CodegenError;
use crate::periodic::PeriodicError;
use crate::sim::SimError;
use crate::sweep::SweepError;

/// Everything the library's front door can refuse. The messages are complete sentences for a
/// user: a model error renders its diagnostics (file:line:column, the line, a caret).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The model text has syntax or semantic errors.
    #[error("{0}")]
    Model(#[from] ModelError),
    /// An SBML document the importer refused (`Model::from_sbml`).
    #[error("{0}")]
    Import(#[from] super::ImportError),
    /// A model file could not be read.
    #[error("cannot read `{}`", path.display())]
    Read {
        /// The path as given.
        path: PathBuf,
        /// Why it could not be read.
        #[source]
        source: std::io::Error,
    },
    /// A model file is larger than [`MAX_MODEL_BYTES`](super::MAX_MODEL_BYTES).
    #[error("`{}` is larger than {limit} bytes; model files are limited to that size", path.display())]
    TooLarge {
        /// The path as given.
        path: PathBuf,
        /// The most a model file may have, in bytes.
        limit: u64,
    },
    /// A parameter name or value was refused.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// The model could not be compiled to native code.
    #[error("could not compile model `{model}`")]
    Compile {
        /// The model's name.
        model: String,
        /// What the code generator refused.
        #[source]
        source: CodegenError,
    },
    /// The simulation options, or the parameter vector's length, were refused before running.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// A fit gave no report ([`FitRequest`](super::FitRequest)).
    #[error(transparent)]
    Fit(#[from] FitFailure),
    /// An optimisation gave no report ([`OptimizeRequest`](super::OptimizeRequest)).
    #[error(transparent)]
    Optimize(#[from] OptimizeFailure),
    /// No periodic orbit found, or the request refused ([`PeriodicRequest`](super::PeriodicRequest)).
    #[error(transparent)]
    Periodic(#[from] PeriodicError),
    /// A Sobol' analysis gave no report ([`SobolRequest`](super::SobolRequest)).
    #[error(transparent)]
    Sobol(#[from] SobolFailure),
    /// A sweep could not run or write its rows ([`SweepRequest`](super::SweepRequest)).
    #[error(transparent)]
    Sweep(#[from] SweepError),
}

/// A model text that does not parse or check, with its diagnostics rendered against the source.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{rendered}")]
pub struct ModelError {
    /// The errors as the stages found them, in source order.
    pub errors: FrontendError,
    /// The diagnostics rendered as text (file:line:column, the line, a caret), one after another.
    pub rendered: String,
}

/// A parameter name or value that a model refuses.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ParamError {
    #[error("model `{model}` has no parameter `{name}`{}; its parameters are {}",
        hint.as_ref().map(|h| format!(" (did you mean `{h}`?)")).unwrap_or_default(), known.join(", "))]
    /// A name that is no parameter of the model.
    Unknown {
        /// The model's name.
        model: String,
        /// The name given.
        name: String,
        /// The closest parameter's name, if one is close.
        hint: Option<String>,
        /// The model's parameters (a vector once, `u[0] .. u[20]`).
        known: Vec<String>,
    },
    /// A value that is not a finite number.
    #[error("{name} = {value} is not a finite number")]
    NotFinite {
        /// The parameter.
        name: String,
        /// The value given.
        value: f64,
    },
    /// A value outside the parameter's declared range.
    #[error("{name} = {value} is outside its range [{lo}, {hi}]")]
    OutOfRange {
        /// The parameter.
        name: String,
        /// The value given.
        value: f64,
        /// The range's lower end.
        lo: f64,
        /// The range's upper end.
        hi: f64,
    },
    /// A parameter named twice (directly, or through its vector).
    #[error("parameter `{name}` is named twice")]
    Duplicate {
        /// The parameter.
        name: String,
    },
    /// A vector parameter named where one scalar is meant (`set("u", 1.0)`).
    #[error("`{name}` is a vector of {len} parameters; name one element, `{name}[0]` .. `{name}[{}]`", len.saturating_sub(1))]
    IsVector {
        /// The vector's name.
        name: String,
        /// Its number of elements.
        len: u32,
    },
    /// A vector's values of the wrong count.
    #[error("`{name}` is a vector of {len} parameters, but {found} value{} given", if *found == 1 { " was" } else { "s were" })]
    VectorLength {
        /// The vector's name.
        name: String,
        /// Its number of elements.
        len: u32,
        /// The values given.
        found: usize,
    },
    /// Vector values for a name that is not a vector parameter.
    #[error("model `{model}` has no vector parameter `{name}`")]
    NotAVector {
        /// The model's name.
        model: String,
        /// The name given.
        name: String,
    },
    /// Parameter values of another model.
    #[error("the parameter values are for model `{found}`, not `{expected}`")]
    OtherModel {
        /// The model run.
        expected: String,
        /// The model the values are for.
        found: String,
    },
}
