//! The flags several commands share: the integrator's (`SimFlags`, flattened into `run`, `sweep`,
//! `fit`, `sobol`, `periodic` and `optimize`), `--set`, the parameter lists of `--grad` and
//! `--free`, and the checks of counts and positive numbers other flags use. The integrator flags
//! only fill an [`api::SimOverrides`](crate::SimOverrides); the library checks it (one set of
//! checks for every front end, Python's keywords included).

use clap::ValueEnum;

use crate::sema::ParamIdx;
use crate::sim::{Method, Sens, SimOptions};
use crate::{Model, ParamError, Params, SimOverrides, Spelling};

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(crate) enum MethodArg {
    /// DOP853 when rtol < 1e-7, else Dormand-Prince 5(4); switches to Rodas5P while the flow is
    /// stiff (and back), each stretch reported.
    Auto,
    Dopri5,
    Dop853,
    /// Rosenbrock Rodas5P (stiff flows; compiles the flow's Jacobians on first use).
    Rodas5p,
    /// Rosenbrock Rodas4 (stiff flows).
    Rodas4,
}

impl From<MethodArg> for Method {
    fn from(arg: MethodArg) -> Method {
        match arg {
            MethodArg::Auto => Method::Auto,
            MethodArg::Dopri5 => Method::Dopri5,
            MethodArg::Dop853 => Method::Dop853,
            MethodArg::Rodas5p => Method::Rodas5p,
            MethodArg::Rodas4 => Method::Rodas4,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(crate) enum SensArg {
    /// One sensitivity column per differentiated parameter, under the error control.
    Forward,
    /// The discrete adjoint: one backward pass over the recorded run for the quantities
    /// reported; its cost does not grow with the parameters.
    Adjoint,
    /// The adjoint when the quantities reported are far fewer than the parameters.
    Auto,
}

impl From<SensArg> for Sens {
    fn from(arg: SensArg) -> Sens {
        match arg {
            SensArg::Forward => Sens::Forward,
            SensArg::Adjoint => Sens::Adjoint,
            SensArg::Auto => Sens::Auto,
        }
    }
}

/// The integrator flags every command that runs a model shares.
#[derive(Debug, clap::Args)]
pub(crate) struct SimFlags {
    /// Start time (default 0). Times are absolute: time events, input knots and every `t` in the
    /// model keep their values, so a later start skips what comes before it.
    #[arg(long, value_name = "T", allow_negative_numbers = true)]
    t_start: Option<f64>,
    /// End time (default: the model's `simulate t_end`, else 10).
    #[arg(long, value_name = "T")]
    t_end: Option<f64>,
    /// Relative tolerance (default: the model's, else 1e-8).
    #[arg(long)]
    rtol: Option<f64>,
    /// Absolute tolerance (default: the model's, else 1e-10).
    #[arg(long)]
    atol: Option<f64>,
    /// Integration method.
    #[arg(long, value_enum, default_value = "auto")]
    method: MethodArg,
    /// Stop (as Zeno behaviour) after this many events.
    #[arg(long, default_value_t = SimOptions::default().max_events)]
    max_events: usize,
    /// Stop with a fault after this many attempted steps (accepted and rejected).
    #[arg(long, default_value_t = SimOptions::default().max_steps)]
    max_steps: usize,
    /// A crossing is grazing (no time gradient) when |g''| delta / d^2 reaches this, with d the
    /// crossing speed, g'' the guard's curvature and delta its accuracy at the tolerances; near-grazing
    /// (gradient kept, with a warning) when it reaches its square.
    #[arg(long, default_value_t = SimOptions::default().graze_tol)]
    graze_tol: f64,
    /// Largest step size (default: none).
    #[arg(long, value_name = "H")]
    h_max: Option<f64>,
    /// Leave the sensitivities out of the step-size error control (faster, gradients less
    /// accurate).
    #[arg(long)]
    no_sens_error_control: bool,
    /// Put running costs (states that nothing but outputs reads, such as `der(effort) = u^2`)
    /// under the step-size error control. By default they take no part in it (as CVODES'
    /// quadratures), and a run warns when one's own error exceeded the tolerance on a step.
    #[arg(long, overrides_with = "no_quadrature_error_control")]
    quadrature_error_control: bool,
    /// Leave running costs out of the step-size error control: the default, accepted so that
    /// scripts written for earlier builds (where control was the default) keep working.
    #[arg(long, hide = true, overrides_with = "quadrature_error_control")]
    no_quadrature_error_control: bool,
    /// Land a step on every event instant, with every method (the Rosenbrock methods do by
    /// default, the explicit pairs where stability holds the step): the pre-event state, its
    /// sensitivities and the event time from a step end under the error control, not from the
    /// dense output; one more step attempt per event.
    #[arg(long)]
    land_events: bool,
    /// How gradients are computed: forward sensitivities, the discrete adjoint (the derivative of
    /// the steps a run with --no-sens-error-control takes), or whichever is cheaper (docs/cli.md,
    /// gradients). Default: forward for run and periodic; auto for sweep, fit and optimize (sobol
    /// differentiates nothing).
    #[arg(long, value_enum)]
    sens: Option<SensArg>,
}

/// The flag that sets each [`SimOverrides::OPTIONS`] entry (`None`: no flag, the option is the
/// library's only). A switch is spelled by what it changes from the default. Tested against the
/// commands' flags and against the options, so that a new option gets a flag (and a keyword in
/// Python: python/tests).
#[cfg(test)]
pub(crate) const FLAG_OF_OPTION: [(&str, Option<&str>); 16] = [
    ("t_end", Some("--t-end")),
    ("rtol", Some("--rtol")),
    ("atol", Some("--atol")),
    ("max_events", Some("--max-events")),
    ("max_steps", Some("--max-steps")),
    ("method", Some("--method")),
    ("graze_tol", Some("--graze-tol")),
    ("sens_error_control", Some("--no-sens-error-control")),
    ("quadrature_error_control", Some("--quadrature-error-control")),
    ("land_events", Some("--land-events")),
    ("h_max", Some("--h-max")),
    ("t_start", Some("--t-start")),
    ("linear_solver", None),
    // `hybc run` only, as `simulate(at=...)` is Python's.
    ("at", Some("--at")),
    ("sens", Some("--sens")),
    // `hybc run` only, as `simulate(of=...)` is Python's.
    ("of", Some("--of")),
];

impl SimFlags {
    /// What the flags set; the rest is the model's.
    pub(crate) fn overrides(&self) -> SimOverrides {
        SimOverrides {
            t_start: self.t_start,
            t_end: self.t_end,
            rtol: self.rtol,
            atol: self.atol,
            method: Some(self.method.into()),
            max_events: Some(self.max_events),
            max_steps: Some(self.max_steps),
            graze_tol: Some(self.graze_tol),
            h_max: self.h_max,
            sens_error_control: self.no_sens_error_control.then_some(false),
            quadrature_error_control: self.quadrature_error_control.then_some(true),
            land_events: self.land_events.then_some(true),
            linear_solver: None,
            at: None,
            sens: self.sens.map(Into::into),
            of: None,
        }
    }
}

/// Simulation options: the flags over the model's `simulate` line over the run defaults
/// (`Model::sim_options`), checked by the library; no trajectory, no sample times.
pub(crate) fn sim_options(model: &Model, flags: &SimFlags) -> Result<SimOptions, String> {
    flags.overrides().apply(&model.sim_options(), Spelling::Flag).map_err(|e| e.message)
}

/// [`sim_options`] for `sweep`, `fit` and `optimize`, whose gradients default to the cheaper mode
/// (`Model::analysis_sim_options`).
pub(crate) fn analysis_sim_options(model: &Model, flags: &SimFlags) -> Result<SimOptions, String> {
    flags.overrides().apply(&model.analysis_sim_options(), Spelling::Flag).map_err(|e| e.message)
}

/// Parameter values: the defaults with every `--set P=VALUE` applied and range-checked; a
/// parameter set twice is a usage error (the second value would silently win). A vector
/// parameter takes all its values at once, `--set u=0,0.5,1` (exactly as many as it has
/// elements), or one element, `--set u[3]=1`.
pub(crate) fn parameter_values(model: &Model, sets: &[String]) -> Result<Params, String> {
    let mut params = model.params();
    let mut seen = std::collections::HashSet::new();
    let number = |name: &str, text: &str| {
        crate::number::parse_number(text.trim()).map_err(|e| match e {
            crate::number::NumberError::TooSmall { .. } => format!("--set {name}: {e}"),
            _ => format!("--set: `{}` is not a finite number", text.trim()),
        })
    };
    for s in sets {
        let Some((name, value)) = s.split_once('=') else {
            return Err(format!("--set: expected P=VALUE, found `{s}`"));
        };
        let name = name.trim();
        if let Some(v) = model.vector(name) {
            let values: Vec<f64> =
                value.split(',').map(|text| number(name, text)).collect::<Result<_, _>>()?;
            if values.len() != v.len as usize {
                return Err(format!(
                    "--set {name}: expected {} comma-separated values, one per element of `{name}`, found {}",
                    v.len,
                    values.len()
                ));
            }
            if let Some(p) = v.elements().find(|p| !seen.insert(*p)) {
                let element = &model.checked().params[p.0 as usize].name;
                return Err(format!(
                    "--set: `{element}` is set twice (`--set {name}=...` sets every element)"
                ));
            }
            params.set_vector(name, &values).map_err(|e| format!("--set: {e}"))?;
            continue;
        }
        let idx = model.param_index(name).map_err(|e| format!("--set: {e}"))?;
        if !seen.insert(idx) {
            let whole = name.split_once('[').map(|(v, _)| format!(" (`--set {v}=...` sets every element)"));
            return Err(format!("--set: `{name}` is set twice{}", whole.unwrap_or_default()));
        }
        let value = number(name, value)?;
        params.set(name, value).map_err(|e| format!("--set: {e}"))?;
    }
    Ok(params)
}

/// Parses a comma-separated list of parameter names, or `all`, for the flag `flag`
/// ([`Model::param_list`]: a vector parameter's name stands for all its elements, in order;
/// `u[3]` for one).
pub(crate) fn parse_param_list(model: &Model, list: &str, flag: &str) -> Result<Vec<ParamIdx>, String> {
    if list.trim() == "all" {
        return Ok((0..model.checked().params.len()).map(|i| ParamIdx(i as u32)).collect());
    }
    let names: Vec<&str> = list.split(',').map(str::trim).filter(|n| !n.is_empty()).collect();
    model.param_list(&names).map_err(|e| match e {
        ParamError::Duplicate { name } => format!("{flag}: `{name}` is named twice"),
        e => format!("{flag}: {e}"),
    })
}

/// `value` if it is at most `cap`, else a usage error naming the flag.
pub(crate) fn at_most(flag: &str, value: usize, cap: usize) -> Result<usize, String> {
    crate::limits::count(flag, value, 0, cap).map_err(|e| e.to_string())
}

/// `v` if it is a finite number above 0, else a usage error naming the flag (the library's
/// wording, Python's too).
pub(crate) use crate::positive_number as positive;

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use clap::CommandFactory as _;

    use super::*;

    /// Every long flag of `hybc COMMAND`.
    fn flags(command: &str) -> BTreeSet<String> {
        let cli = super::super::Cli::command();
        let sub = cli.find_subcommand(command).expect("a command");
        sub.get_arguments().filter_map(|a| a.get_long().map(|l| format!("--{l}"))).collect()
    }

    #[test]
    fn every_simulation_option_has_its_flag_and_every_command_that_runs_takes_them() {
        // Destructured whole, so that a new field does not compile until it is listed here and in
        // `FLAG_OF_OPTION` (and given a keyword in Python).
        let SimOverrides {
            t_start: _,
            t_end: _,
            rtol: _,
            atol: _,
            method: _,
            max_events: _,
            max_steps: _,
            graze_tol: _,
            h_max: _,
            sens_error_control: _,
            quadrature_error_control: _,
            land_events: _,
            linear_solver: _,
            at: _,
            sens: _,
            of: _,
        } = SimOverrides::default();
        let listed: Vec<&str> = FLAG_OF_OPTION.iter().map(|(option, _)| *option).collect();
        assert_eq!(listed, SimOverrides::OPTIONS);
        for command in ["run", "sweep", "fit", "sobol", "periodic", "optimize"] {
            let flags = flags(command);
            for (option, flag) in FLAG_OF_OPTION {
                let Some(flag) = flag else { continue };
                let expected = command == "run" || !matches!(option, "at" | "of");
                assert_eq!(flags.contains(flag), expected, "hybc {command} {flag} ({option})");
            }
        }
    }

    #[test]
    fn the_method_flag_takes_the_librarys_method_names() {
        let names: Vec<String> = MethodArg::value_variants()
            .iter()
            .filter_map(|m| m.to_possible_value())
            .map(|v| v.get_name().into())
            .collect();
        let library: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
        assert_eq!(names, library);
        for arg in MethodArg::value_variants() {
            let name = arg.to_possible_value().unwrap().get_name().to_string();
            assert_eq!(Method::from(*arg).name(), name);
        }
    }
}
