//! Stage 4: expression DAG -> Cranelift IR -> native kernels behind a safe `CompiledModel`.
//! All `unsafe` in hybc lives in this module. Knows no syntax, no spans and no integrator: it
//! consumes `expr::ModelFunctions` and implements `sim::HybridSystem`.
//!
//! Code map: `plan` decides what each kernel computes and checks every index (no Cranelift);
//! `stiff` plans the Rosenbrock kernels (Jacobians, second derivatives), compiled on demand;
//! `translate` turns a plan into IR, one `translate_*` method per node kind; `runtime` holds the host
//! wrappers for transcendental functions; `compiled` owns the JIT module and calls the kernels.

#[allow(unsafe_code)]
mod compiled;
mod plan;
mod runtime;
mod stiff;
#[cfg(test)]
mod tests;
mod translate;

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
    /// Better code, slower to compile; its compile time grows faster than linearly with the
    /// size of one kernel (measured: a 1000-state chain's fused sensitivity kernel, 4000
    /// outputs, takes 1.7-2.4 s against 0.11-0.15 s with `SinglePass`).
    Backtracking,
    /// Linear compile time; slower code (1.3x to 2.7x on the chains measured below).
    SinglePass,
    /// `Backtracking` unless the largest kernel part exceeds [`AUTO_REGALLOC_LIMIT`] operations
    /// or one part computes more than [`AUTO_REGALLOC_NODE_LIMIT`] expression nodes, then
    /// `SinglePass`: big models stay quick to compile, small ones get the better code.
    Auto,
}

/// Size of the largest kernel part (output entries plus sensitivity products) above which
/// [`RegAlloc::Auto`] switches to the single-pass allocator. Since kernels are cut into parts of
/// at most [`MAX_PART_SIZE`], this only happens for a single entry with more than this many
/// sensitivity products. Measured before kernels were cut into parts, on chain models (the
/// benchmarks' generated model, all parameters differentiated, release build; size of the fused
/// sensitivity kernel in brackets), compile time and ns per fused-kernel call, backtracking
/// against single-pass:
/// - 100 states (997): 10 ms / 191 ns against 3 ms / 511 ns: backtracking's code is 2.7x faster;
/// - 150 states (1497): 41 ms / 588 ns against 6 ms / 790 ns: 7x the compile time for 1.3x;
/// - 300 states (2997): 78 ms / 2950 ns against 8 ms / 1577 ns: backtracking loses both ways.
///
/// So the switch sits between 100 and 150 states; the shipped models' kernels have under 100.
pub const AUTO_REGALLOC_LIMIT: usize = 1200;

/// Most expression nodes one kernel part may compute before [`RegAlloc::Auto`] switches to the
/// single-pass allocator, whatever the part's size: cutting into parts bounds the writes, not
/// the expression of one write. A chain of `n` `let`s that square their predecessor
/// (`stress_models::squaring_lets`) is one flow entry whose sensitivity kernel computes `7 n`
/// nodes and keeps every link of the chain live until the derivative's end; with the
/// backtracking allocator its compile time was quadratic (release build: 1.9 s at n = 5,000, 36 s
/// at 20,000), with the single-pass one 0.06 s and 0.34 s. Parts of the models measured above
/// (cut at [`MAX_PART_SIZE`]) compute a few thousand nodes (3,502 for 1000 states reading one
/// shared sum), so they keep the backtracking allocator.
pub const AUTO_REGALLOC_NODE_LIMIT: usize = 10_000;

/// Default [`CompileOptions::max_part_size`]. The backtracking allocator's compile time grows
/// faster than linearly with the size of one function, so big kernels are cut into parts of at
/// most this size, each compiled on its own, behind one driver function that calls them.
/// Measured on chain models (`PART=N RA=auto cargo run --release --example jit_parts`): compile
/// time at 10, 100 and 1000 states; ns per call of the 100-state fused sensitivity kernel (997 in
/// size) and of the 1000-state one:
/// - no parts: 0.72 / 10.9 / 27.6 ms, 194 ns, 5.9 us (at 1000 states `Auto` switched to the
///   single-pass allocator; backtracking on the whole kernel took 718 ms);
/// - 1000: 0.85 / 11.5 / 102 ms, 202 ns, 4.3 us;
/// - 500: 0.73 / 9.6 / 78 ms, 204 ns, 4.8 us: 73-96 us of compile time per state at every size;
/// - 350: 0.78 / 8.5 / 69 ms, 310-840 ns (erratic), 4.7 us;
/// - 100: 0.99 / 6.5 / 57 ms, 398 ns, 4.5 us: parts recompute the subexpressions they share.
pub const MAX_PART_SIZE: usize = 500;

/// How kernels are compiled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CompileOptions {
    /// How hard Cranelift optimises.
    pub opt_level: OptLevel,
    /// Run Cranelift's IR verifier on every kernel (catches codegen bugs, costs 20-30%).
    pub verifier: bool,
    /// The register allocator.
    pub regalloc: RegAlloc,
    /// Kernels larger than this (`KernelPlan::size`: output entries plus
    /// sensitivity products) are compiled as several native functions of at most this size,
    /// called in order.
    pub max_part_size: usize,
}

impl Default for CompileOptions {
    /// Kernels run millions of times per simulation, so run-time speed wins where it is cheap:
    /// `Speed` (it cost no measurable compile time over `None` on the ball or a 100-state chain)
    /// and [`RegAlloc::Auto`]. The verifier (10-25% of compile time) stays on in debug builds
    /// only, where catching a codegen bug matters more than compile time. Measured with
    /// `cargo run --example jit_options`; figures in that file's header.
    fn default() -> Self {
        CompileOptions {
            opt_level: OptLevel::Speed,
            verifier: cfg!(debug_assertions),
            regalloc: RegAlloc::Auto,
            max_part_size: MAX_PART_SIZE,
        }
    }
}

/// Why a model could not be compiled to native code.
#[derive(Debug, thiserror::Error)]
pub enum CodegenError {
    /// Cranelift does not support this machine.
    #[error("host machine is not supported by cranelift: {reason}")]
    UnsupportedHost {
        /// Cranelift's reason.
        reason: &'static str,
    },
    /// A Cranelift setting was refused.
    #[error("invalid cranelift setting")]
    Setting(#[source] cranelift_codegen::settings::SetError),
    /// Cranelift could not describe the target.
    #[error("cranelift could not build the target description")]
    Target(#[source] cranelift_codegen::CodegenError),
    /// Cranelift failed on one kernel.
    #[error("cranelift failed on kernel `{kernel}`")]
    Module {
        /// The kernel's name.
        kernel: String,
        /// Cranelift's error.
        #[source]
        source: Box<cranelift_module::ModuleError>,
    },
    /// An array of the plan has another length than the model's shape says.
    #[error("{what} has {found} entries, expected {expected}")]
    ShapeMismatch {
        /// Which array.
        what: String,
        /// The length expected.
        expected: usize,
        /// The length found.
        found: usize,
    },
    /// An index of the plan past its array's end.
    #[error("{what} index {index} out of range for length {len}")]
    IndexOutOfRange {
        /// Which index.
        what: String,
        /// The index.
        index: usize,
        /// The array's length.
        len: usize,
    },
    /// Sparse entries out of order.
    #[error("{what} entries are not strictly ascending at position {position}")]
    UnsortedSparse {
        /// Which array.
        what: String,
        /// The first entry out of order.
        position: usize,
    },
    /// A gradient parameter listed twice.
    #[error("parameter {param} is listed twice among the gradient parameters")]
    DuplicateGradParam {
        /// The parameter.
        param: usize,
    },
    /// An expression id not in the store.
    #[error("expression {id} is not in the store of {len} nodes")]
    UnknownExpr {
        /// The id.
        id: u32,
        /// The store's nodes.
        len: usize,
    },
    /// An output entry no kernel writes.
    #[error("{what} entry {index} would never be written")]
    Unwritten {
        /// Which output.
        what: String,
        /// The entry.
        index: usize,
    },
    /// An array too large for a kernel.
    #[error("{what} is too large for a kernel ({len} entries)")]
    TooLarge {
        /// Which array.
        what: String,
        /// Its entries.
        len: usize,
    },
    /// A bug in the code generator.
    #[error("internal codegen error: {reason}")]
    Internal {
        /// What went wrong.
        reason: &'static str,
    },
}
