//! `hybc._hybc`: the native half of the Python package `hybc` (python/hybc/ is the other half).
//!
//! Code map: `errors` (the exception classes and how library errors map onto them), `model`
//! (a checked model and its per-gradient-set compile cache), `options` (keyword arguments to
//! `SimOptions`), `run` (one run's result as Python values and NumPy arrays), `sweep` (many points
//! in parallel, the columns of `hybc sweep`), `sobol` (Sobol' indices: the library's design and
//! estimators, a shard of rows at a time), `fit` (`Model.fit`: the library's whole fit, the report
//! as JSON), `optimize` (`Model.optimize`, the same for `hybc optimize`), `periodic` (`Model.periodic`, the
//! same for `hybc periodic`). Every call that integrates releases the GIL.
//!
//! Where the JAX primitive plugs in (branch `jax`): a module `jax_ffi` declared below next to the
//! others, registered by one line in [`_hybc`]; it reaches compiled models through
//! [`model::Model::compiled`] (cached per gradient set, `Send + Sync + 'static`).

mod errors;
mod fit;
mod jax_ffi;
mod model;
mod optimize;
mod options;
mod periodic;
mod run;
mod sobol;
mod sweep;

use pyo3::prelude::*;

#[pymodule]
fn _hybc(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    m.add_class::<model::Model>()?;
    m.add_class::<run::Run>()?;
    m.add_function(wrap_pyfunction!(sobol::sobol_analyze, m)?)?;
    m.add_function(wrap_pyfunction!(fit::fit_report, m)?)?;
    m.add_function(wrap_pyfunction!(optimize::optimize_report, m)?)?;
    m.add_function(wrap_pyfunction!(optimize::optimize_merge, m)?)?;
    m.add_function(wrap_pyfunction!(periodic::periodic_report, m)?)?;
    jax_ffi::register(m)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
