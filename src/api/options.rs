//! The simulation options every front end takes, checked once. A front end only fills a
//! [`SimOverrides`] (the command line from its flags, Python from its keywords) and names how it
//! spells an option ([`Spelling`]); [`SimOverrides::apply`] lays it over the model's options with
//! the one set of checks, so `hybc run --rtol=-1` and `simulate(rtol=-1)` are refused with the
//! same words, each naming the option as its user wrote it.

use crate::fit::Observable;
use crate::limits;
use crate::sim::{GradientsOf, LinearSolver, Method, Sens, SimOptions, SystemInfo, MAX_SAMPLED_ROWS};

/// How a front end spells an option in its messages: `--t-start` on the command line, `t_start`
/// in Python (the library's own name, a [`SimOptions`] field).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Spelling {
    /// A command-line flag: `--` and the name with dashes.
    Flag,
    /// A keyword argument: the name as it is.
    Keyword,
}

impl Spelling {
    /// `option` (a [`SimOverrides::OPTIONS`] name) as this front end writes it.
    pub fn of(self, option: &str) -> String {
        match self {
            Spelling::Flag => format!("--{}", option.replace('_', "-")),
            Spelling::Keyword => option.to_string(),
        }
    }
}

/// A simulation option refused, with the message that names it in the front end's spelling.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct OptionError {
    /// The option's library name (one of [`SimOverrides::OPTIONS`]).
    pub option: &'static str,
    /// The whole message: `--rtol: expected a positive number, found -1`.
    pub message: String,
}

/// Every simulation option a front end can set; `None` keeps the model's value (its `simulate`
/// line over [`SimOptions::default`]). Only [`Self::apply`] checks the values.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SimOverrides {
    /// The start time.
    pub t_start: Option<f64>,
    /// The end time.
    pub t_end: Option<f64>,
    /// The relative tolerance.
    pub rtol: Option<f64>,
    /// The absolute tolerance.
    pub atol: Option<f64>,
    /// The integration method.
    pub method: Option<Method>,
    /// The most events before the run stops.
    pub max_events: Option<usize>,
    /// The most step attempts before the run stops with a fault.
    pub max_steps: Option<usize>,
    /// The grazing threshold (`|g''| delta / d^2`).
    pub graze_tol: Option<f64>,
    /// The largest step size.
    pub h_max: Option<f64>,
    /// Whether the sensitivities take part in the step-size error control.
    pub sens_error_control: Option<bool>,
    /// Whether running costs take part in it.
    pub quadrature_error_control: Option<bool>,
    /// `Some(true)`: every method lands a step on each event; `Some(false)`: none does.
    pub land_events: Option<bool>,
    /// Library only (tests and measurements): no front end exposes it.
    pub linear_solver: Option<LinearSolver>,
    /// The sample times (`hybc run --at`, `simulate(at=...)`): ascending, within the run's span
    /// (checked by `apply`, against the span it sets).
    pub at: Option<Vec<f64>>,
    /// How gradients are computed (`--sens`, `sens=`).
    pub sens: Option<Sens>,
    /// The quantities whose gradients are wanted (`hybc run --of`, `simulate(of=...)`), as the
    /// user names them: `NAME` (a state or an output), `EVENT#K`, `EVENT#last`, `NAME@TIME`.
    /// Resolved against a compiled model's names by [`Self::gradients_of`], not by `apply`.
    pub of: Option<Vec<String>>,
}

impl SimOverrides {
    /// The options' names, as [`SimOptions`] spells them, in the order a front end lists them
    /// (Python's message for an unknown keyword). A test holds each front end to this list.
    pub const OPTIONS: [&'static str; 16] = [
        "t_end",
        "rtol",
        "atol",
        "max_events",
        "max_steps",
        "method",
        "graze_tol",
        "sens_error_control",
        "quadrature_error_control",
        "land_events",
        "h_max",
        "t_start",
        "linear_solver",
        "at",
        "sens",
        "of",
    ];

    /// `base` (usually [`Model::sim_options`](super::Model::sim_options)) with these values laid
    /// over it, each checked: tolerances, `graze_tol` and `h_max` positive (`rtol` below 1), the
    /// span by [`time_span`], the counts by [`limits::count`], at most
    /// [`MAX_SAMPLED_ROWS`] sample times. The first refusal is returned, named in `spelling`.
    pub fn apply(&self, base: &SimOptions, spelling: Spelling) -> Result<SimOptions, OptionError> {
        let refuse = |option: &'static str| move |message: String| OptionError { option, message };
        let positive =
            |option: &'static str, v: f64| positive_number(&spelling.of(option), v).map_err(refuse(option));
        let count = |option: &'static str, v: usize, max: usize| {
            limits::count(&spelling.of(option), v, 1, max).map_err(|e| refuse(option)(e.to_string()))
        };
        let rtol = positive("rtol", self.rtol.unwrap_or(base.rtol))?;
        if rtol >= 1.0 {
            return Err(refuse("rtol")(format!(
                "{}: expected a number below 1, found {rtol}",
                spelling.of("rtol")
            )));
        }
        let names = (spelling.of("t_start"), spelling.of("t_end"));
        let (t_start, t_end) = time_span(self.t_start, self.t_end, base, (&names.0, &names.1))
            // A span is refused by its end unless the start itself is not finite.
            .map_err(|message| {
                let option = if message.starts_with(&names.0) { "t_start" } else { "t_end" };
                OptionError { option, message }
            })?;
        let atol = positive("atol", self.atol.unwrap_or(base.atol))?;
        // 0 events would still fire the first event (the cap is checked after each instant), so it
        // is refused rather than reported as 1.
        let max_steps = count("max_steps", self.max_steps.unwrap_or(base.max_steps), limits::MAX_STEPS)?;
        let max_events = count("max_events", self.max_events.unwrap_or(base.max_events), limits::MAX_EVENTS)?;
        let graze_tol = positive("graze_tol", self.graze_tol.unwrap_or(base.graze_tol))?;
        let h_max = match self.h_max {
            None => base.h_max,
            Some(h) => positive("h_max", h)?,
        };
        let at = match &self.at {
            None => base.at.clone(),
            Some(times) if times.len() as f64 > MAX_SAMPLED_ROWS => {
                let message =
                    format!("{}: {} times, at most {MAX_SAMPLED_ROWS:.0}", spelling.of("at"), times.len());
                return Err(refuse("at")(message));
            }
            Some(times) => {
                sample_times_within(times, t_start, t_end, &spelling.of("at")).map_err(refuse("at"))?;
                times.clone()
            }
        };
        Ok(SimOptions {
            t_start,
            t_end,
            rtol,
            atol,
            method: self.method.unwrap_or(base.method),
            max_events,
            max_steps,
            graze_tol,
            sens_error_control: self.sens_error_control.unwrap_or(base.sens_error_control),
            quadrature_error_control: self.quadrature_error_control.unwrap_or(base.quadrature_error_control),
            h_max,
            land_events: self.land_events.or(base.land_events),
            linear_solver: self.linear_solver.unwrap_or(base.linear_solver),
            trajectory: base.trajectory,
            at,
            sens: self.sens.unwrap_or(base.sens),
            of: base.of.clone(),
        })
    }

    /// Sets `opts.of` from [`Self::of`], the names resolved against `info` (a compiled model's)
    /// as every analysis spells a quantity ([`Observable`]); a `NAME@TIME` adds its time to
    /// `opts.at` (the sample it reads), checked against the run's span. Nothing when `of` is
    /// unset; an empty list asks for no gradient at all.
    pub fn gradients_of(
        &self,
        info: &SystemInfo,
        opts: &mut SimOptions,
        spelling: Spelling,
    ) -> Result<(), OptionError> {
        let Some(names) = &self.of else { return Ok(()) };
        let flag = spelling.of("of");
        let refuse = |message: String| OptionError { option: "of", message };
        let mut of = GradientsOf::default();
        let names: Vec<String> = names.iter().flat_map(|n| whole_array(n, info)).collect();
        for name in &names {
            match Observable::parse(name, info).map_err(|e| refuse(format!("{flag}: {e}")))? {
                Observable::State(i) => of.states.push(i),
                Observable::Output(i) => of.outputs.push(i),
                Observable::EventTime { name_event, occurrence } => {
                    of.firings.push((name_event, Some(occurrence)))
                }
                Observable::LastFiring { name_event } => of.firings.push((name_event, None)),
                Observable::At { output, index, time } => {
                    sample_times_within(&[time], opts.t_start, opts.t_end, &flag).map_err(refuse)?;
                    of.samples.push((output, index, time));
                    if !opts.at.contains(&time) {
                        let at = opts.at.partition_point(|&t| t < time);
                        opts.at.insert(at, time);
                    }
                }
            }
        }
        if opts.at.len() as f64 > MAX_SAMPLED_ROWS {
            return Err(refuse(format!(
                "{flag}: {} sample times, at most {MAX_SAMPLED_ROWS:.0}",
                opts.at.len()
            )));
        }
        opts.of = Some(of);
        Ok(())
    }
}

/// `x` or `x@T` for an array of states or outputs (`x` itself no state or output, but `x[0]`, `x[1]`,
/// .. are): each element, in the model's order; any other name as it is. A list of gradients
/// takes a whole array where it takes its elements (docs/cli.md).
fn whole_array(name: &str, info: &SystemInfo) -> Vec<String> {
    let (value, at) = name.split_once('@').map_or((name.trim(), None), |(v, t)| (v.trim(), Some(t)));
    let is_element = |n: &str| {
        n.strip_prefix(value)
            .is_some_and(|rest| rest.starts_with('[') && rest.ends_with(']') && !rest.contains('#'))
    };
    let names = info.state_names.iter().chain(&info.output_names);
    if value.is_empty() || value.contains(['[', '#']) || names.clone().any(|n| n == value) {
        return vec![name.to_string()];
    }
    let elements: Vec<String> = names
        .filter(|n| is_element(n))
        .map(|n| at.map_or_else(|| n.clone(), |t| format!("{n}@{t}")))
        .collect();
    if elements.is_empty() {
        vec![name.to_string()]
    } else {
        elements
    }
}

/// `Ok` if `times` ascend (repeats allowed) within `[t_start, t_end]`; else the refusal naming
/// the first time at fault and why: before `t_start`, after `t_end`, or before the time ahead of
/// it. `name` is the option as the front end spells it.
pub fn sample_times_within(times: &[f64], t_start: f64, t_end: f64, name: &str) -> Result<(), String> {
    let span = format!("the run goes from t_start = {t_start} to t_end = {t_end}");
    let mut previous: Option<f64> = None;
    for &t in times {
        if !t.is_finite() {
            return Err(format!("{name}: time {t} is not a finite number"));
        }
        if t < t_start {
            return Err(format!("{name}: time {t} is before t_start = {t_start}: {span}"));
        }
        if t > t_end {
            return Err(format!("{name}: time {t} is after t_end = {t_end}: {span}"));
        }
        if let Some(p) = previous.filter(|&p| t < p) {
            return Err(format!("{name}: the times must ascend, but {t} comes after {p}"));
        }
        previous = Some(t);
    }
    Ok(())
}

/// The gradient mode named `name` (`forward`, `adjoint`, `auto`), for a front end that reads it
/// as text.
pub fn sens_named(name: &str, spelling: Spelling) -> Result<Sens, OptionError> {
    Sens::ALL.into_iter().find(|s| s.name() == name).ok_or_else(|| OptionError {
        option: "sens",
        message: format!(
            "{}: expected \"forward\", \"adjoint\" or \"auto\", found {name:?}",
            spelling.of("sens")
        ),
    })
}

/// The method named `name` (`auto`, `dopri5`, `dop853`, `rodas5p`, `rodas4`: the command line's
/// and JSON's spelling), for a front end that reads it as text.
pub fn method_named(name: &str, spelling: Spelling) -> Result<Method, OptionError> {
    Method::ALL.into_iter().find(|m| m.name() == name).ok_or_else(|| {
        let names: Vec<String> = Method::ALL.iter().map(|m| format!("{:?}", m.name())).collect();
        let (last, first) = names.split_last().expect("there are methods");
        OptionError {
            option: "method",
            message: format!(
                "{}: expected {} or {last}, found {name:?}",
                spelling.of("method"),
                first.join(", ")
            ),
        }
    })
}

/// `v` if it is a finite number above 0, else the refusal every front end words alike:
/// `NAME: expected a positive number, found V`, `name` spelled as the front end spells it.
pub fn positive_number(name: &str, v: f64) -> Result<f64, String> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{name}: expected a positive number, found {v}"))
    }
}

/// The start and end of a run: `t_start` (default: `base.t_start`) any finite time, `t_end`
/// (default: `base.t_end`) a finite time after it. Times are absolute: time events, input knots
/// and every `t` in the model keep their values whatever the start (docs/language.md, "Time").
/// `names` are the front end's spellings of the two options, for the message.
pub fn time_span(
    t_start: Option<f64>,
    t_end: Option<f64>,
    base: &SimOptions,
    names: (&str, &str),
) -> Result<(f64, f64), String> {
    let (start_name, end_name) = names;
    let start = t_start.unwrap_or(base.t_start);
    if !start.is_finite() {
        return Err(format!("{start_name}: expected a finite number, found {start}"));
    }
    let end = t_end.unwrap_or(base.t_end);
    if !end.is_finite() {
        return Err(format!("{end_name}: expected a finite number, found {end}"));
    }
    if end <= start {
        let whose = if t_end.is_some() { "" } else { " (the model's end time)" };
        return Err(format!("{end_name}: expected a time after {start_name} = {start}, found {end}{whose}"));
    }
    Ok((start, end))
}

#[cfg(test)]
mod tests {
    use super::*;

    const NAMES: (&str, &str) = ("--t-start", "--t-end");

    #[test]
    fn a_span_starts_anywhere_finite_and_ends_after_its_start() {
        let base = SimOptions { t_end: 2.5, ..SimOptions::default() };
        assert_eq!(time_span(None, None, &base, NAMES), Ok((0.0, 2.5)));
        assert_eq!(time_span(Some(-3.0), Some(-1.0), &base, NAMES), Ok((-3.0, -1.0)));
        assert_eq!(time_span(Some(1e6), Some(1e6 + 2.5), &base, NAMES), Ok((1e6, 1e6 + 2.5)));
    }

    #[test]
    fn a_span_that_is_empty_reversed_or_not_finite_is_refused_by_name() {
        let base = SimOptions { t_end: 2.5, ..SimOptions::default() };
        let err = time_span(Some(5.0), None, &base, NAMES).unwrap_err();
        assert_eq!(err, "--t-end: expected a time after --t-start = 5, found 2.5 (the model's end time)");
        let err = time_span(Some(1.0), Some(1.0), &base, ("t_start", "t_end")).unwrap_err();
        assert_eq!(err, "t_end: expected a time after t_start = 1, found 1");
        assert!(time_span(Some(f64::NAN), None, &base, NAMES)
            .unwrap_err()
            .starts_with("--t-start: expected a finite"));
        assert!(time_span(None, Some(f64::INFINITY), &base, NAMES)
            .unwrap_err()
            .starts_with("--t-end: expected a finite"));
    }

    #[test]
    fn sample_times_on_the_spans_ends_and_repeated_are_taken() {
        let base = SimOptions { t_start: -1.0, t_end: 2.5, ..SimOptions::default() };
        let at = vec![-1.0, 0.0, 0.0, 2.5];
        let applied =
            SimOverrides { at: Some(at.clone()), ..Default::default() }.apply(&base, Spelling::Flag);
        assert_eq!(applied.map(|o| o.at), Ok(at));
        // Just past either end is refused.
        assert!(sample_times_within(&[2.5 + 1e-15 * 4.0], -1.0, 2.5, "--at").is_err());
        assert!(sample_times_within(&[-1.0 - 1e-15], -1.0, 2.5, "--at").is_err());
    }

    #[test]
    fn no_overrides_leave_the_base_as_it_is() {
        let base = SimOptions { t_end: 2.5, rtol: 1e-6, land_events: Some(false), ..SimOptions::default() };
        assert_eq!(SimOverrides::default().apply(&base, Spelling::Flag), Ok(base));
    }

    #[test]
    fn every_value_is_checked_once_and_named_in_the_front_ends_spelling() {
        let base = SimOptions::default();
        let refused = |overrides: SimOverrides| {
            let flag = overrides.apply(&base, Spelling::Flag).unwrap_err();
            let keyword = overrides.apply(&base, Spelling::Keyword).unwrap_err();
            // The same words, only the options' names spelled differently.
            let respelled = SimOverrides::OPTIONS
                .iter()
                .fold(flag.message.clone(), |m, o| m.replace(&Spelling::Flag.of(o), o));
            assert_eq!((keyword.option, keyword.message), (flag.option, respelled));
            (flag.option, flag.message)
        };
        let cases = [
            (
                SimOverrides { rtol: Some(-1.0), ..Default::default() },
                "rtol",
                "--rtol: expected a positive number, found -1",
            ),
            (
                SimOverrides { rtol: Some(1.0), ..Default::default() },
                "rtol",
                "--rtol: expected a number below 1, found 1",
            ),
            (
                SimOverrides { atol: Some(0.0), ..Default::default() },
                "atol",
                "--atol: expected a positive number, found 0",
            ),
            (
                SimOverrides { graze_tol: Some(f64::NAN), ..Default::default() },
                "graze_tol",
                "--graze-tol: expected a positive number, found NaN",
            ),
            (
                SimOverrides { h_max: Some(-2.0), ..Default::default() },
                "h_max",
                "--h-max: expected a positive number, found -2",
            ),
            (
                SimOverrides { max_events: Some(0), ..Default::default() },
                "max_events",
                "--max-events: at least 1, found 0",
            ),
            (
                SimOverrides { max_steps: Some(0), ..Default::default() },
                "max_steps",
                "--max-steps: at least 1, found 0",
            ),
            (
                SimOverrides { t_start: Some(f64::INFINITY), ..Default::default() },
                "t_start",
                "--t-start: expected a finite number, found inf",
            ),
            (
                SimOverrides { t_start: Some(3.0), t_end: Some(1.0), ..Default::default() },
                "t_end",
                "--t-end: expected a time after --t-start = 3, found 1",
            ),
            (
                SimOverrides { at: Some(vec![0.0; 1_000_001]), ..Default::default() },
                "at",
                "--at: 1000001 times, at most 1000000",
            ),
            (
                SimOverrides { at: Some(vec![1.0, 3.0]), t_end: Some(2.5), ..Default::default() },
                "at",
                "--at: time 3 is after t_end = 2.5: the run goes from t_start = 0 to t_end = 2.5",
            ),
            (
                SimOverrides { at: Some(vec![-1.0]), t_end: Some(2.5), ..Default::default() },
                "at",
                "--at: time -1 is before t_start = 0: the run goes from t_start = 0 to t_end = 2.5",
            ),
            (
                SimOverrides { at: Some(vec![2.0, 1.0]), t_end: Some(2.5), ..Default::default() },
                "at",
                "--at: the times must ascend, but 1 comes after 2",
            ),
        ];
        for (overrides, option, message) in cases {
            assert_eq!(refused(overrides), (option, message.to_string()));
        }
    }

    #[test]
    fn a_method_is_named_as_the_command_line_spells_it() {
        assert_eq!(method_named("rodas5p", Spelling::Keyword), Ok(Method::Rodas5p));
        let e = method_named("euler", Spelling::Keyword).unwrap_err();
        assert_eq!(
            e.message,
            r#"method: expected "auto", "dopri5", "dop853", "rodas5p" or "rodas4", found "euler""#
        );
    }
}
