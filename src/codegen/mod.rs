//! Stage 4: expression DAG -> Cranelift IR -> native kernels behind a safe `CompiledModel`.
//! All `unsafe` in hybc lives in this module. Knows no syntax, no spans and no integrator: it
//! consumes `expr::ModelFunctions` and implements `sim::HybridSystem`.
//!
//! Code map: `plan` decides what each kernel computes and checks every index (no Cranelift);
//! `lower` turns a plan into IR, one `translate_*` method per node kind; `runtime` holds the host
//! wrappers for transcendental functions; `compiled` owns the JIT module and calls the kernels.

mod compiled;
mod lower;
mod plan;
mod runtime;

pub use compiled::CompiledModel;

use crate::expr::ModelFunctions;
use crate::sim::SystemInfo;

/// Compiles `funcs` to native code; shorthand for [`CompiledModel::compile`].
pub fn compile(
    funcs: &ModelFunctions,
    info: SystemInfo,
    opts: &CompileOptions,
) -> Result<CompiledModel, CodegenError> {
    CompiledModel::compile(funcs, info, opts)
}

/// Cranelift's optimisation level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum OptLevel {
    /// Fastest compilation, no mid-end optimisation.
    None,
    /// E-graph optimisation of the generated code.
    Speed,
    /// Like `Speed`, also reducing code size.
    SpeedAndSize,
}

/// Cranelift's register allocator.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RegAlloc {
    /// Better code, slower to compile.
    Backtracking,
    /// About three times faster to compile, 1.2-1.5x slower code (CRANELIFT.md).
    SinglePass,
}

/// How kernels are compiled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CompileOptions {
    pub opt_level: OptLevel,
    /// Run Cranelift's IR verifier on every kernel (catches codegen bugs, costs 20-30%).
    pub verifier: bool,
    pub regalloc: RegAlloc,
}

impl Default for CompileOptions {
    /// Kernels run millions of times per simulation and compile in well under a millisecond
    /// each, so run-time speed wins: `Speed` with the backtracking allocator. The verifier stays
    /// on in debug builds only, where catching a codegen bug matters more than compile time.
    fn default() -> Self {
        CompileOptions {
            opt_level: OptLevel::Speed,
            verifier: cfg!(debug_assertions),
            regalloc: RegAlloc::Backtracking,
        }
    }
}

/// Why a model could not be compiled to native code.
#[derive(Debug, thiserror::Error)]
pub enum CodegenError {
    #[error("host machine is not supported by cranelift: {reason}")]
    UnsupportedHost { reason: &'static str },
    #[error("invalid cranelift setting")]
    Setting(#[source] cranelift_codegen::settings::SetError),
    #[error("cranelift could not build the target description")]
    Target(#[source] cranelift_codegen::CodegenError),
    #[error("cranelift failed on kernel `{kernel}`")]
    Module {
        kernel: String,
        #[source]
        source: Box<cranelift_module::ModuleError>,
    },
    #[error("{what} has {found} entries, expected {expected}")]
    ShapeMismatch { what: String, expected: usize, found: usize },
    #[error("{what} index {index} out of range for length {len}")]
    IndexOutOfRange { what: String, index: usize, len: usize },
    #[error("{what} entries are not strictly ascending at position {position}")]
    UnsortedSparse { what: String, position: usize },
    #[error("parameter {param} is listed twice among the gradient parameters")]
    DuplicateGradParam { param: usize },
    #[error("expression {id} is not in the store of {len} nodes")]
    UnknownExpr { id: u32, len: usize },
    #[error("{what} entry {index} would never be written")]
    Unwritten { what: String, index: usize },
    #[error("{what} is too large for a kernel ({len} entries)")]
    TooLarge { what: String, len: usize },
    #[error("internal codegen error: {reason}")]
    Internal { reason: &'static str },
}
