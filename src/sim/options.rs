//! Stage 5 (sim): what a caller can ask of one simulation run. Plain data with a `Default`;
//! knows nothing of models, tableaux or the step loop.

use serde::Serialize;

/// Which method integrates the flow: an explicit Runge-Kutta pair, or a Rosenbrock method for
/// stiff flows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Starts with DOP853 when `rtol < 1e-7` (high accuracy pays for its 12 stages),
    /// Dormand-Prince 5(4) otherwise, and switches to Rodas5P while the flow is stiff and back
    /// when it is not, by stiffness estimates with hysteresis (`sim::auto`); the stretches are in
    /// `SimResult::methods`.
    Auto,
    /// Dormand-Prince 5(4), 7 stages (FSAL), 4th-order dense output.
    Dopri5,
    /// Hairer's DOP853, 8th order with 5th/3rd-order error estimators and 7th-order dense output.
    Dop853,
    /// Steinebach's Rodas5P: Rosenbrock, 5th order with a 4th-order embedded estimate and
    /// 4th-order dense output, stiffly accurate and L-stable; for stiff flows.
    Rodas5p,
    /// Hairer and Wanner's Rodas4: Rosenbrock, 4th order (3rd-order estimate and dense output),
    /// stiffly accurate and L-stable.
    Rodas4,
}

impl Method {
    /// Every method, in the order the command line lists them.
    pub const ALL: [Method; 5] =
        [Method::Auto, Method::Dopri5, Method::Dop853, Method::Rodas5p, Method::Rodas4];

    /// The method's name as the command line, Python and JSON spell it (`dopri5`, `rodas5p`, ..).
    pub fn name(self) -> &'static str {
        match self {
            Method::Auto => "auto",
            Method::Dopri5 => "dopri5",
            Method::Dop853 => "dop853",
            Method::Rodas5p => "rodas5p",
            Method::Rodas4 => "rodas4",
        }
    }

    /// The explicit pair `Auto` starts with at tolerance `rtol` (a named method stands for
    /// itself).
    pub fn resolve(self, rtol: f64) -> Method {
        match self {
            Method::Auto if rtol < 1e-7 => Method::Dop853,
            Method::Auto => Method::Dopri5,
            other => other,
        }
    }

    /// Whether the method is a Rosenbrock method (needs the flow's Jacobian).
    pub fn is_rosenbrock(self) -> bool {
        matches!(self, Method::Rodas5p | Method::Rodas4)
    }
}

/// Which rows the result's trajectory holds.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub enum TrajectoryRequest {
    /// No trajectory (the fast path: nothing is allocated per step).
    None,
    /// The start, every accepted step end, both sides of every event, and the end.
    Steps,
    /// Every multiple of this interval from the start, taken from the dense output.
    Every(f64),
}

/// How a run's gradients are computed (`hybc run --sens`, docs/cli.md): the report is the same
/// whichever ran.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Sens {
    /// Forward sensitivities: one column per differentiated parameter, integrated with the states
    /// (under the error control unless `sens_error_control` is off).
    Forward,
    /// The discrete adjoint (`sim::adjoint`): the run recorded without sensitivities, then one
    /// backward pass for the quantities reported; equal to the forward sensitivities of a run with
    /// `sens_error_control` off. Where it does not carry a run yet, the forward sensitivities are
    /// computed instead, with a warning.
    Adjoint,
    /// The adjoint when it is the cheaper (`sim::adjoint::prefers_adjoint`), else forward.
    Auto,
}

impl Sens {
    /// Every mode, in the order the command line lists them.
    pub const ALL: [Sens; 3] = [Sens::Forward, Sens::Adjoint, Sens::Auto];

    /// Its name on the command line and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Sens::Forward => "forward",
            Sens::Adjoint => "adjoint",
            Sens::Auto => "auto",
        }
    }
}

/// The quantities whose gradients a run reports (`hybc run --of`, Python's `of=`): with
/// [`SimOptions::of`] set, every other quantity keeps its value and has no gradient (the report
/// leaves it out; in the result its entries are NaN), in either mode, and the adjoint runs one
/// backward pass per quantity named, so it costs what they are. Indices into the system's names.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct GradientsOf {
    /// States: at the final time, their total derivatives after a stop event, and the side
    /// without the events at `t_end`.
    pub states: Vec<usize>,
    /// Outputs, likewise.
    pub outputs: Vec<usize>,
    /// Event times, by name: `(an event with the name, Some(k))` is the `k`-th firing of any
    /// event of that name (from 1), `(.., None)` the last one.
    pub firings: Vec<(usize, Option<usize>)>,
    /// Values at a sample time of `SimOptions::at`: `(whether an output, its index, the time)`.
    pub samples: Vec<(bool, usize, f64)>,
}

impl GradientsOf {
    /// Whether state `i`'s gradients are asked for.
    pub fn state(&self, i: usize) -> bool {
        self.states.contains(&i)
    }

    /// Whether output `i`'s gradients are asked for.
    pub fn output(&self, i: usize) -> bool {
        self.outputs.contains(&i)
    }

    /// Whether the gradient of a sample's value is asked for: an output's (`output`) or a
    /// state's `index` at `time`.
    pub fn sample(&self, output: bool, index: usize, time: f64) -> bool {
        self.samples.contains(&(output, index, time))
    }

    /// Which of a run's event records (`names[e]`: the name of record `e`'s event, in firing
    /// order) have their time's gradient asked for, by the names of `info`.
    pub fn events(&self, info: &super::SystemInfo, names: &[&str]) -> Vec<bool> {
        let mut wanted = vec![false; names.len()];
        for &(event, firing) in &self.firings {
            let name = &*info.events[event].name;
            let mut of_name = names.iter().enumerate().filter(|(_, n)| **n == name).map(|(e, _)| e);
            let hit = match firing {
                Some(k) => of_name.nth(k.saturating_sub(1)),
                None => of_name.next_back(),
            };
            if let Some(e) = hit {
                wanted[e] = true;
            }
        }
        wanted
    }

    /// How many rows an adjoint runs for it in a run with `events` records, ending at a stop
    /// event (`at_stop`) or with events at `t_end` (`cusp`): what `Sens::Auto` weighs.
    pub fn rows(&self, events: usize, at_stop: bool, cusp: bool) -> usize {
        let finals = self.states.len() + self.outputs.len();
        self.firings.len().min(events)
            + finals * (1 + usize::from(at_stop) + usize::from(cusp))
            + self.samples.len()
    }
}

/// Options of [`run`](super::run). Times are model time; tolerances are per component, applied
/// as `atol + rtol * |x_i|` to states and (by default) to sensitivities.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SimOptions {
    /// Start time of the run.
    pub t_start: f64,
    /// End time; the run stops here unless an event stops it earlier.
    pub t_end: f64,
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance.
    pub atol: f64,
    /// The integration method.
    pub method: Method,
    /// Largest number of events: the run stops with `StopReason::MaxEvents` when it is reached.
    pub max_events: usize,
    /// Largest number of attempted steps (accepted + rejected) before the run stops with a fault
    /// (at most `limits::MAX_STEPS` from the command line and Python).
    pub max_steps: usize,
    /// A crossing is grazing (no time gradient) when its conditioning
    /// `kappa = |g''| delta / d^2` is at least `graze_tol`, and near-grazing (gradient kept, with a
    /// warning) when it is at least `graze_tol^2`: `d` is the crossing speed `g_x f + g_t`, `g''`
    /// the guard's second derivative along the solution and `delta = sum_i |g_x,i| (atol + rtol
    /// |x_i|)` the guard's accuracy at the tolerances (`sim::jump`). A crossing whose speed is
    /// round-off is always grazing.
    pub graze_tol: f64,
    /// Whether sensitivities take part in the step-size error norm. Off is cheaper, but then the
    /// sensitivities' accuracy is only whatever the state's steps give them.
    pub sens_error_control: bool,
    /// Whether running costs (quadrature states, `SystemInfo::quadrature`) take part in the
    /// step-size error norm. Off by default, as CVODES' quadratures: a cost that nothing reads
    /// does not drive the step size; a step on which its own error exceeds the tolerance is
    /// reported (`SimWarning::CostUnresolved`), and on puts it back in the test
    /// (docs/language.md, "Running costs and the step size").
    pub quadrature_error_control: bool,
    /// Optional cap on the step size (infinite by default).
    pub h_max: f64,
    /// Whether a step is retaken to land on each event instant located inside it, so that the
    /// state and sensitivities the events jump from (and the instant, by one Newton correction)
    /// come from a step end under the error control rather than from the dense output: one more
    /// step attempt per event. `None` (the default): the method's own choice
    /// (`Stepper::lands_on_events`: the Rosenbrock methods, whose dense output is of order 3 to
    /// 4, land; the explicit pairs only on a step held by stability, where their dense output is
    /// poor for the fast components, which keeps their speed elsewhere: landing costs the
    /// bouncing ball 36% more evaluations). See docs/accuracy.md.
    pub land_events: Option<bool>,
    /// The factorisation of a Rosenbrock method's `W` (`sim::linsolve`): for models of
    /// [`SPARSE_MIN_STATES`](super::SPARSE_MIN_STATES) states or more whose Jacobian's pattern
    /// is known, the cheapest of the dense, the banded and the sparse LU by operation count;
    /// dense otherwise. Explicit methods ignore it.
    pub linear_solver: super::LinearSolver,
    /// Which trajectory rows the result keeps.
    pub trajectory: TrajectoryRequest,
    /// Times at which every state and output is sampled with its derivatives, from the dense
    /// output (`SimResult::samples`): ascending, within `[t_start, t_end]`. They do not cut the
    /// steps. A sample at an event instant is taken after the instant's events.
    pub at: Vec<f64>,
    /// How gradients are computed.
    pub sens: Sens,
    /// The quantities whose gradients are reported; `None`: every quantity the report holds.
    pub of: Option<GradientsOf>,
}

/// The run defaults, the one set the CLI and the library share: a model's `simulate` line
/// overrides `t_end`, `rtol` and `atol` (`Model::sim_options`), flags override both.
impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            t_start: 0.0,
            t_end: 10.0,
            rtol: 1e-8,
            atol: 1e-10,
            method: Method::Auto,
            max_events: 10_000,
            max_steps: 1_000_000,
            graze_tol: 1e-2,
            sens_error_control: true,
            quadrature_error_control: false,
            h_max: f64::INFINITY,
            land_events: None,
            linear_solver: super::LinearSolver::Auto,
            trajectory: TrajectoryRequest::None,
            at: Vec::new(),
            sens: Sens::Forward,
            of: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Method;

    #[test]
    fn a_methods_name_is_its_json_spelling() {
        for m in Method::ALL {
            assert_eq!(serde_json::to_value(m).unwrap(), m.name());
        }
    }
}
