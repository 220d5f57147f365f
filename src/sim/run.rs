//! Stage 5 (sim): a run from start to end. [`Runner`] checks a model's shape and the options
//! once and keeps the scratch buffers between runs; [`run`] is one run with a fresh one. Each run
//! is a loop over `Integrator::step` with the trajectory recorder the options ask for.

use super::adjoint;
use super::breakpoints::Breakpoints;
use super::event::detect::Detector;
use super::event::jump::Jump;
use super::integrator::{Integrator, StepOutcome, Workspace};
use super::knots::Knots;
use super::method::auto::Auto;
use super::method::rk::Rk;
use super::method::rosenbrock::Rosenbrock;
use super::method::row_tableau::{RODAS4, RODAS5P};
use super::method::stepper::Stepper;
use super::method::tableau::{DOP853, DOPRI5};
use super::options::{Method, Sens, SimOptions, TrajectoryRequest};
use super::recorder::{Recorder, TrajectoryRecorder};
use super::result::{EventRecord, SimError, SimResult, SimWarning, StopReason};
use super::system::{HybridSystem, SystemInfo};

/// The smallest relative tolerance accepted: ten times the spacing of floating-point numbers
/// near 1. Below it the error estimates are round-off and no step can meet the tolerance (a run
/// at rtol 1e-16 stopped on a step size underflow at its first step).
pub const MIN_RTOL: f64 = 10.0 * f64::EPSILON;

/// Simulates `sys` with parameters `p` (all of them, `n_params` long) from `opts.t_start` to
/// `opts.t_end`. Bad input (parameter length, an inconsistent model shape, invalid options) is an
/// error; runtime faults, Zeno behaviour and stop events end the run with everything computed so
/// far and say why in [`SimResult::stopped_by`].
///
/// Shorthand for [`Runner::new`] followed by one [`Runner::run`]; to run one model many
/// times (sweeps, fits, finite differences) keep a `Runner`, which allocates its scratch
/// buffers once.
pub fn run<S: HybridSystem + ?Sized>(sys: &S, p: &[f64], opts: &SimOptions) -> Result<SimResult, SimError> {
    check_params(sys.info(), p)?;
    Runner::new(sys, opts)?.run(p)
}

/// A model and options checked once, with the stepper's, interpolant's, detector's and jump's
/// scratch buffers kept between runs: a run then allocates only what its result holds.
/// Runs are independent: the same parameters give bit-for-bit the same result, whatever ran
/// before. One `Runner` per thread (it is `Send` when the system is `Sync`).
pub struct Runner<H: SystemRef> {
    sys: H,
    opts: SimOptions,
    work: Work,
}

/// The scratch of a run with the stepper the options chose. The stepper is a type parameter of
/// the integrator, chosen once per run here, so the explicit methods' step loop is the same
/// machine code as before there was a choice (no dispatch per call).
enum Work {
    Explicit(Workspace<Rk>),
    Rosenbrock(Workspace<Rosenbrock>),
    /// Boxed: both steppers make it the largest by far.
    Auto(Box<Workspace<Auto>>),
}

/// One run in progress with the stepper the options chose (see [`Runner::integrator`]).
pub enum Driver<'a, S: HybridSystem + ?Sized, R: Recorder> {
    /// A forced explicit pair.
    Explicit(Integrator<'a, S, R, Rk>),
    /// A forced Rosenbrock method.
    Rosenbrock(Integrator<'a, S, R, Rosenbrock>),
    /// `--method auto`.
    Auto(Integrator<'a, S, R, Auto>),
}

impl<S: HybridSystem + ?Sized, R: Recorder> Driver<'_, S, R> {
    /// [`Integrator::step`].
    pub fn step(&mut self) -> StepOutcome {
        match self {
            Driver::Explicit(it) => it.step(),
            Driver::Rosenbrock(it) => it.step(),
            Driver::Auto(it) => it.step(),
        }
    }

    /// [`Integrator::t`].
    pub fn t(&self) -> f64 {
        match self {
            Driver::Explicit(it) => it.t(),
            Driver::Rosenbrock(it) => it.t(),
            Driver::Auto(it) => it.t(),
        }
    }

    /// [`Integrator::state`].
    pub fn state(&self) -> &[f64] {
        match self {
            Driver::Explicit(it) => it.state(),
            Driver::Rosenbrock(it) => it.state(),
            Driver::Auto(it) => it.state(),
        }
    }

    /// [`Integrator::events`].
    pub fn events(&self) -> &[EventRecord] {
        match self {
            Driver::Explicit(it) => it.events(),
            Driver::Rosenbrock(it) => it.events(),
            Driver::Auto(it) => it.events(),
        }
    }

    /// [`Integrator::finish`].
    pub fn finish(self, stopped_by: StopReason) -> SimResult {
        match self {
            Driver::Explicit(it) => it.finish(stopped_by),
            Driver::Rosenbrock(it) => it.finish(stopped_by),
            Driver::Auto(it) => it.finish(stopped_by),
        }
    }
}

/// The scratch of a run, for any stepper.
struct ShapedWork<'a, St> {
    stepper: St,
    info: &'a SystemInfo,
    n: usize,
    m: usize,
    k: usize,
    nz: usize,
}

impl<St: Stepper> ShapedWork<'_, St> {
    fn build(self) -> Workspace<St> {
        let ShapedWork { stepper, info, n, m, k, nz } = self;
        Workspace {
            stepper,
            det: Detector::new(info, n, m),
            jump: Jump::new(n, m),
            breakpoints: Breakpoints::default(),
            knots: Knots::new(n, m, info.modes.len()),
            knot_sets: Vec::new(),
            z: vec![0.0; nz],
            fired: Vec::new(),
            output_jac: (vec![0.0; k * n], vec![0.0; k * m], vec![0.0; k]),
            x_sides: (vec![0.0; n], vec![0.0; n]),
            switch_flow: (vec![0.0; n], vec![0.0; n]),
            record_buf: (vec![0.0; k], vec![0.0; nz]),
            before: (vec![0.0; n], Vec::new()),
            z_start: vec![0.0; nz],
            instant_dte: vec![0.0; m],
            landed_velocity: (Vec::new(), Vec::new()),
            void: vec![false; n * m],
            reset_onto: Vec::new(),
            reset_onto_guard: Vec::new(),
            onto_guard_dte: Vec::new(),
            onto_guard_grad: (vec![0.0; n], vec![0.0; m]),
            lateness: (vec![0.0; n], vec![0.0; n * m], vec![0.0; n], vec![0.0; m]),
            lateness_guards: (Vec::new(), Vec::new()),
        }
    }
}

/// A run from start to end on any stepper.
fn run_to_end<S: HybridSystem + ?Sized, R: Recorder, St: Stepper>(
    mut it: Integrator<'_, S, R, St>,
) -> SimResult {
    loop {
        if let StepOutcome::Done(stop) = it.step() {
            return it.finish(stop);
        }
    }
}

/// What a [`Runner`] holds its model by: a reference, an `Arc`, a `Box`, anything that
/// dereferences to a [`HybridSystem`]. An owned handle (`Arc<CompiledModel>`) makes an owned
/// simulator that a thread or a Python object can keep.
pub trait SystemRef {
    /// The system referred to.
    type System: HybridSystem + ?Sized;
    /// The system.
    fn system(&self) -> &Self::System;
}

impl<D: std::ops::Deref> SystemRef for D
where
    D::Target: HybridSystem,
{
    type System = D::Target;
    fn system(&self) -> &D::Target {
        self
    }
}

impl<H: SystemRef> std::fmt::Debug for Runner<H> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Runner").field("opts", &self.opts).finish_non_exhaustive()
    }
}

/// Makes `sys`'s forward sensitivities ready when it has any (`HybridSystem::prepare_sensitivities`:
/// once; afterwards a load and a compare).
fn ready_for_sensitivities<S: HybridSystem + ?Sized>(sys: &S) -> Result<(), SimError> {
    if sys.info().n_grad() == 0 {
        return Ok(());
    }
    sys.prepare_sensitivities().map_err(|reason| SimError::NoSensitivities { reason })
}

/// The states left out of the step-size error test: the quadrature states (running costs that
/// nothing but outputs reads; `SystemInfo::quadrature`), their sensitivities with them, unless
/// every state is one (then the error test needs them all). Empty: none.
fn error_test_exclusions(info: &SystemInfo) -> Vec<bool> {
    let q = &info.quadrature;
    if q.len() != info.n_states() || q.iter().all(|&b| b) || !q.iter().any(|&b| b) {
        return Vec::new();
    }
    q.clone()
}

impl<H: SystemRef> Runner<H> {
    /// Checks the model's shape and the options (an `Err` for an inconsistent shape or an
    /// invalid option) and allocates the scratch buffers.
    pub fn new(sys: H, opts: &SimOptions) -> Result<Self, SimError> {
        let info = sys.system().info();
        validate(info, opts)?;
        let (n, m) = (info.n_states(), info.n_grad());
        // A run by the adjoint carries no sensitivities: a large model's forward kernel is
        // compiled only where a run may take them (`Self::run_with` when it falls back).
        if opts.sens == Sens::Forward {
            ready_for_sensitivities(sys.system())?;
        }
        let nz = n * (1 + m);
        let method = opts.method.resolve(opts.rtol);
        let n_err = if opts.sens_error_control { nz } else { n };
        let k = info.n_outputs();
        let excluded = if opts.quadrature_error_control { Vec::new() } else { error_test_exclusions(info) };
        let work = match method {
            // The explicit pair `resolve` picks, with Rodas5P to switch to (`auto`).
            _ if opts.method == Method::Auto => {
                let tab = if method == Method::Dop853 { &DOP853 } else { &DOPRI5 };
                let rk = Rk::new(tab, nz, n, n_err, opts.rtol, opts.atol).with_excluded(excluded.clone());
                let row = Rosenbrock::new(&RODAS5P, nz, n, n_err, opts.rtol, opts.atol)
                    .with_linear_solver(opts.linear_solver)
                    .with_excluded(excluded);
                let stepper = Auto::new(method, rk, row, nz, n);
                Work::Auto(Box::new(ShapedWork { stepper, info, n, m, k, nz }.build()))
            }
            Method::Rodas5p | Method::Rodas4 => {
                let tab = if method == Method::Rodas5p { &RODAS5P } else { &RODAS4 };
                let method = tab.name;
                sys.system()
                    .prepare_jacobians()
                    .map_err(|reason| SimError::NoJacobians { method, reason })?;
                let stepper = Rosenbrock::new(tab, nz, n, n_err, opts.rtol, opts.atol)
                    .with_linear_solver(opts.linear_solver)
                    .with_excluded(excluded);
                Work::Rosenbrock(ShapedWork { stepper, info, n, m, k, nz }.build())
            }
            Method::Auto | Method::Dopri5 | Method::Dop853 => {
                let tab = if method == Method::Dop853 { &DOP853 } else { &DOPRI5 };
                let stepper = Rk::new(tab, nz, n, n_err, opts.rtol, opts.atol).with_excluded(excluded);
                Work::Explicit(ShapedWork { stepper, info, n, m, k, nz }.build())
            }
        };
        Ok(Runner { sys, opts: opts.clone(), work })
    }

    /// Simulates with parameters `p` (all of them, `n_params` long; an `Err` otherwise).
    pub fn run(&mut self, p: &[f64]) -> Result<SimResult, SimError> {
        let mut recorder = TrajectoryRecorder::new(self.opts.trajectory, self.opts.t_start);
        let mut result = self.run_with(p, &mut recorder)?;
        result.trajectory = recorder.into_rows();
        Ok(result)
    }

    /// [`Self::run`] with another recorder (the result's `trajectory` is then `None`).
    ///
    /// With `SimOptions::sens` asking for the adjoint and a recorder that records nothing, the
    /// gradients are the adjoint's (`sim::adjoint`); where it does not carry the run, or
    /// (`auto`) is not the cheaper, the run is the forward one (with a warning when the adjoint
    /// was asked for by name).
    pub fn run_with<R: Recorder>(&mut self, p: &[f64], recorder: &mut R) -> Result<SimResult, SimError> {
        let sys = self.sys.system();
        check_params(sys.info(), p)?;
        let m = sys.info().n_grad();
        let by_adjoint = self.opts.sens != Sens::Forward && m > 0 && !recorder.is_active();
        let mut fell_back = None;
        if by_adjoint {
            match adjoint::run_by_adjoint(sys, p, &self.opts, self.opts.sens == Sens::Auto)? {
                Ok(mut result) => {
                    if let Some(of) = &self.opts.of {
                        result.keep_gradients_of(of, sys.info());
                    }
                    return Ok(result);
                }
                Err(e) if self.opts.sens == Sens::Adjoint => fell_back = Some(e),
                Err(_) => {}
            }
        }
        ready_for_sensitivities(sys)?;
        let mut result = self.run_forward(p, recorder);
        if m > 0 {
            result.stats.sens = Some(Sens::Forward);
        }
        let what = match fell_back {
            Some(adjoint::AdjointError::Unsupported(what)) => Some(what),
            Some(adjoint::AdjointError::Ended(_)) => Some("a run that ends before t_end but by a stop event"),
            Some(adjoint::AdjointError::Seed(_)) | None => None,
        };
        if let Some(what) = what {
            result.warnings.push(SimWarning::AdjointNotCarried { what });
        }
        if let (Some(of), true) = (&self.opts.of, m > 0) {
            result.keep_gradients_of(of, self.sys.system().info());
        }
        Ok(result)
    }

    /// A run with forward sensitivities whatever `SimOptions::sens` says (checked parameters).
    fn run_forward<R: Recorder>(&mut self, p: &[f64], recorder: &mut R) -> SimResult {
        let sys = self.sys.system();
        match &mut self.work {
            Work::Explicit(w) => run_to_end(Integrator::new(sys, p, &self.opts, w, recorder)),
            Work::Rosenbrock(w) => run_to_end(Integrator::new(sys, p, &self.opts, w, recorder)),
            Work::Auto(w) => run_to_end(Integrator::new(sys, p, &self.opts, &mut **w, recorder)),
        }
    }

    /// [`Self::run_with`] with forward sensitivities whatever `SimOptions::sens` says: the
    /// adjoint's own recording run.
    pub(crate) fn run_forward_with<R: Recorder>(
        &mut self,
        p: &[f64],
        recorder: &mut R,
    ) -> Result<SimResult, SimError> {
        check_params(self.sys.system().info(), p)?;
        ready_for_sensitivities(self.sys.system())?;
        Ok(self.run_forward(p, recorder))
    }

    /// A run at `p` to drive step by step: [`Integrator::step`] until it says `Done`, then
    /// [`Integrator::finish`].
    pub fn integrator<'s, R: Recorder>(
        &'s mut self,
        p: &'s [f64],
        recorder: &'s mut R,
    ) -> Result<Driver<'s, H::System, R>, SimError> {
        let sys = self.sys.system();
        check_params(sys.info(), p)?;
        ready_for_sensitivities(sys)?;
        Ok(match &mut self.work {
            Work::Explicit(w) => Driver::Explicit(Integrator::new(sys, p, &self.opts, w, recorder)),
            Work::Rosenbrock(w) => Driver::Rosenbrock(Integrator::new(sys, p, &self.opts, w, recorder)),
            Work::Auto(w) => Driver::Auto(Integrator::new(sys, p, &self.opts, &mut **w, recorder)),
        })
    }

    /// The checked options every run takes.
    pub fn options(&self) -> &SimOptions {
        &self.opts
    }

    /// The model this simulator runs.
    pub fn system(&self) -> &H::System {
        self.sys.system()
    }

    /// The handle the model is held by (for `Runner<&S>`, the reference itself).
    pub fn handle(&self) -> &H {
        &self.sys
    }
}

fn check_params(info: &SystemInfo, p: &[f64]) -> Result<(), SimError> {
    if p.len() != info.n_params() {
        return Err(SimError::ParamLength { expected: info.n_params(), got: p.len() });
    }
    Ok(())
}

fn validate(info: &SystemInfo, opts: &SimOptions) -> Result<(), SimError> {
    let bad_index = |what, index: usize, count: usize| {
        if index < count {
            Ok(())
        } else {
            Err(SimError::BadIndex { what, index, count })
        }
    };
    bad_index("initial mode", info.initial_mode, info.modes.len())?;
    for mode in &info.modes {
        for &ev in &mode.events {
            bad_index("event", ev, info.events.len())?;
        }
    }
    for ev in &info.events {
        if let Some(target) = ev.target_mode {
            bad_index("target mode", target, info.modes.len())?;
        }
    }
    for &gp in &info.grad_params {
        bad_index("grad parameter", gp, info.n_params())?;
    }
    if opts.rtol.is_finite() && opts.rtol > 0.0 && opts.rtol < MIN_RTOL {
        return Err(SimError::ToleranceTooSmall { rtol: opts.rtol, floor: MIN_RTOL });
    }
    // `max_events = 0` is refused: the cap is checked after an instant's events, so a run would
    // still fire one and report the cap as 1.
    let checks: [(&'static str, f64, bool); 7] = [
        ("max_events", opts.max_events as f64, opts.max_events >= 1),
        ("t_start", opts.t_start, opts.t_start.is_finite()),
        ("t_end", opts.t_end, opts.t_end.is_finite() && opts.t_end >= opts.t_start),
        ("rtol", opts.rtol, opts.rtol.is_finite() && opts.rtol > 0.0),
        ("atol", opts.atol, opts.atol.is_finite() && opts.atol >= 0.0),
        ("graze_tol", opts.graze_tol, opts.graze_tol >= 0.0),
        ("h_max", opts.h_max, opts.h_max > 0.0),
    ];
    for (name, value, ok) in checks {
        if !ok {
            return Err(SimError::InvalidOption { name, value });
        }
    }
    if let TrajectoryRequest::Every(dt) = opts.trajectory {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(SimError::InvalidOption { name: "trajectory sample interval", value: dt });
        }
        let rows = ((opts.t_end - opts.t_start) / dt).floor() + 1.0;
        if rows > MAX_SAMPLED_ROWS {
            let (t_start, t_end, cap) = (opts.t_start, opts.t_end, MAX_SAMPLED_ROWS);
            return Err(SimError::TooManyRows { dt, t_start, t_end, rows, cap });
        }
    }
    if opts.at.len() as f64 > MAX_SAMPLED_ROWS {
        return Err(SimError::InvalidOption {
            name: "number of sample times (at most 1e6)",
            value: opts.at.len() as f64,
        });
    }
    let mut previous = opts.t_start;
    for &t in &opts.at {
        if !(t >= previous && t <= opts.t_end) {
            return Err(SimError::SampleTime { t, t_start: opts.t_start, t_end: opts.t_end, previous });
        }
        previous = t;
    }
    Ok(())
}

/// The most rows a sampled trajectory kept in memory may have (checked before the run: the ball
/// sampled every 1e-8 s would be 2.5e8 rows, several GB). `hybc run --trajectory` writes its rows
/// out as they are recorded instead, with its own, larger cap.
pub const MAX_SAMPLED_ROWS: f64 = 1e6;
