//! A model compiled to native code, and the reusable simulator that runs it.

use std::sync::Arc;
use std::time::Instant;

use super::{Error, Model, ParamError, Params, Run};
use crate::codegen::{self, CompileOptions, CompiledModel};
use crate::lower::{lower, system_info};
use crate::sema::ParamIdx;
use crate::sim::{self, HybridSystem as _, SimOptions, SystemInfo};

/// A model compiled with gradients for a fixed set of parameters; every parameter value stays a
/// run-time input. Cloning is cheap (the native code is shared through an `Arc`), and a
/// `Compiled` is `Send + Sync + 'static`: clones can run in any thread.
#[derive(Clone, Debug)]
pub struct Compiled {
    model: Model,
    pub(super) native: Arc<CompiledModel>,
    compile_seconds: f64,
}

impl Compiled {
    pub(crate) fn new(model: Model, grad: &[ParamIdx], opts: &CompileOptions) -> Result<Compiled, Error> {
        let started = Instant::now();
        let checked = model.checked();
        let native = codegen::compile(&lower(checked), system_info(checked, grad), opts)
            .map_err(|source| Error::Compile { model: model.name().to_string(), source })?;
        Ok(Compiled { model, native: Arc::new(native), compile_seconds: started.elapsed().as_secs_f64() })
    }

    /// The model this was compiled from.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The native code, for tests and measurements that reach the kernels. A front end never
    /// needs it: an analysis takes [`Self::system`].
    pub fn native(&self) -> &CompiledModel {
        &self.native
    }

    /// The compiled model as the integrator runs it, for the analysis cores (generic over the
    /// system, so that their tests can hand them a hand-written one). The type is opaque: what
    /// stands behind the door stays there, and the analyses call the native kernels directly.
    pub fn system(&self) -> &(impl sim::HybridSystem + '_) {
        &*self.native
    }

    /// The model's shape as the integrator sees it (names, modes, events, gradient columns).
    pub fn info(&self) -> &SystemInfo {
        self.native.info()
    }

    /// Names of the differentiated parameters, in sensitivity column order.
    pub fn grad_names(&self) -> impl Iterator<Item = &str> {
        let info = self.info();
        info.grad_params.iter().map(|&j| info.param_names[j].as_str())
    }

    /// Seconds spent from the checked model to callable kernels.
    pub fn compile_seconds(&self) -> f64 {
        self.compile_seconds
    }

    /// The parameters at their defaults (as [`Model::params`]).
    pub fn params(&self) -> Params {
        self.model.params()
    }

    /// One run at `params` with `opts`. For many runs keep a [`Self::simulator`].
    pub fn simulate(&self, params: &Params, opts: &SimOptions) -> Result<Run, Error> {
        self.simulator(opts)?.run(params)
    }

    /// A simulator for many runs with the same options: the options are checked and the scratch
    /// buffers allocated once. Owned (it holds a clone of this `Compiled`), so it can live in a
    /// thread or a binding.
    pub fn simulator(&self, opts: &SimOptions) -> Result<Simulator, Error> {
        Ok(Simulator { compiled: self.clone(), sim: sim::Runner::new(Arc::clone(&self.native), opts)? })
    }

    fn check_params(&self, params: &Params) -> Result<(), ParamError> {
        if params.model().same(&self.model) || params.model().checked() == self.model.checked() {
            Ok(())
        } else {
            Err(ParamError::OtherModel {
                expected: self.model.name().to_string(),
                found: params.model().name().to_string(),
            })
        }
    }
}

/// A compiled model with checked options and scratch buffers kept between runs: sweeps, fits,
/// gradient checks and bindings run many points through one. A reused simulator gives bit for bit
/// the result of a fresh one. One per thread (it is `Send`).
#[derive(Debug)]
pub struct Simulator {
    compiled: Compiled,
    sim: sim::Runner<Arc<CompiledModel>>,
}

impl Simulator {
    /// Runs at `params` (values of this simulator's model).
    pub fn run(&mut self, params: &Params) -> Result<Run, Error> {
        self.compiled.check_params(params)?;
        self.run_values(params.values())
    }

    /// Runs at the parameter vector `p` (every parameter, in declaration order).
    pub fn run_values(&mut self, p: &[f64]) -> Result<Run, Error> {
        let started = Instant::now();
        let result = self.sim.run(p)?;
        Ok(self.finished(p, result, started))
    }

    /// Runs at `params` with `recorder` observing the run as it goes (the start, every step,
    /// both sides of every event): a front end writes a long trajectory as it is recorded rather
    /// than keeping it. The run's `trajectory` is then `None`, whatever the options ask.
    pub fn run_with<R: sim::Recorder>(&mut self, params: &Params, recorder: &mut R) -> Result<Run, Error> {
        self.compiled.check_params(params)?;
        let p = params.values();
        let started = Instant::now();
        let result = self.sim.run_with(p, recorder)?;
        Ok(self.finished(p, result, started))
    }

    fn finished(&self, p: &[f64], result: sim::SimResult, started: Instant) -> Run {
        let run_seconds = started.elapsed().as_secs_f64();
        Run::new(self.compiled.clone(), p.to_vec(), self.sim.options().t_end, result, run_seconds)
    }

    /// The raw result at `p`, without names attached (for loops that read a few numbers).
    pub fn run_raw(&mut self, p: &[f64]) -> Result<sim::SimResult, sim::SimError> {
        self.sim.run(p)
    }

    /// The checked options every run of this simulator takes.
    pub fn options(&self) -> &SimOptions {
        self.sim.options()
    }

    /// The compiled model it runs.
    pub fn compiled(&self) -> &Compiled {
        &self.compiled
    }
}
