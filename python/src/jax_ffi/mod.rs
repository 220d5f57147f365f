//! `hybc.jax`'s native half: an XLA FFI handler in plain Rust against XLA's C API
//! (`xla/ffi/api/c_api.h`, shipped inside jaxlib; no C++ toolchain and no jaxlib at build time).
//!
//! Code map: `abi` (the C structs mirrored, the only place that knows their layout), `handler`
//! (the `extern "C"` entry point: metadata, decoding buffers and attributes, errors, panics;
//! the only unsafe code besides `abi`), `function` (a function's configuration and how a batch
//! runs, in parallel, into the output slices), `status` (the status codes), `registry` (the
//! process-wide table of functions the handle attribute selects), `py` (what `hybc/jax.py` calls).

mod abi;
mod function;
mod handler;
mod py;
mod registry;
mod status;

use pyo3::prelude::*;

/// Adds the module's functions to `hybc._hybc`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(py::jax_handler_address, m)?)?;
    m.add_function(wrap_pyfunction!(py::jax_register, m)?)?;
    m.add_function(wrap_pyfunction!(py::jax_counts, m)?)?;
    Ok(())
}
