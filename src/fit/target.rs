//! What a fit aims at: a number a run reports (an output or a state at the final time, or the time
//! of the K-th firing of an event) and the value it should take. Parses the command line's
//! `NAME=VALUE[@WEIGHT]` form against a model's names; knows nothing of the solver.

use crate::sim::SystemInfo;

/// A number one simulation run reports, which a target fixes (and `hybc sobol --output`
/// reads). Spelled one way everywhere: `NAME` (an output or a state at the final time), `EVENT#K`
/// (the K-th firing), `EVENT#last` (the last firing), `NAME@TIME` (an output or a state at a given
/// time, from the run's samples at `SimOptions::at`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Observable {
    /// An output at the final time (index into `SystemInfo::output_names`).
    Output(usize),
    /// A state at the final time (index into `SystemInfo::state_names`).
    State(usize),
    /// The time of the `occurrence`-th firing (1-based) of any event named `name`; the name, not
    /// an event id, because events of different modes may share a name and the user counts
    /// firings of the name.
    EventTime {
        /// An event with the name (the first declared).
        name_event: usize,
        /// Which firing, from 1.
        occurrence: usize,
    },
    /// The time of the last firing of any event named as `name_event` is.
    LastFiring {
        /// An event with the name (the first declared).
        name_event: usize,
    },
    /// An output (`output: true`) or a state at time `time`.
    At {
        /// Whether `index` is an output's (else a state's).
        output: bool,
        /// The output's or state's index.
        index: usize,
        /// The time.
        time: f64,
    },
}

impl Observable {
    /// Parses `NAME` (an output or a state; prefix `output:` or `state:` when a name is both),
    /// `EVENT#K`, `EVENT#last` or `NAME@TIME` against the names in `info`.
    pub fn parse(name: &str, info: &SystemInfo) -> Result<Observable, TargetError> {
        parse_observable(name.trim(), name, info)
    }

    /// The time at which the run must sample it, for `NAME@TIME`.
    pub fn sample_time(&self) -> Option<f64> {
        match *self {
            Observable::At { time, .. } => Some(time),
            _ => None,
        }
    }

    /// The name as the user writes it (`energy`, `touchdown#2`, `touchdown#last`, `y@1.5`).
    pub fn label(&self, info: &SystemInfo) -> String {
        match *self {
            Observable::Output(i) => info.output_names[i].clone(),
            Observable::State(i) => info.state_names[i].clone(),
            Observable::EventTime { name_event, occurrence } => {
                format!("{}#{occurrence}", info.events[name_event].name)
            }
            Observable::LastFiring { name_event } => format!("{}#last", info.events[name_event].name),
            Observable::At { output, index, time } => {
                let names = if output { &info.output_names } else { &info.state_names };
                format!("{}@{time}", names[index])
            }
        }
    }
}

/// The sample times a set of observables needs, ascending and without repeats (for
/// `SimOptions::at`).
pub fn sample_times<'o>(observables: impl IntoIterator<Item = &'o Observable>) -> Vec<f64> {
    let mut times: Vec<f64> = observables.into_iter().filter_map(Observable::sample_time).collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    times
}

/// [`Observable::parse`] of `name`, with `text` (the whole flag value) in the messages.
fn parse_observable(name: &str, text: &str, info: &SystemInfo) -> Result<Observable, TargetError> {
    if let Some((value, time)) = name.split_once('@') {
        let time = crate::number::parse_number(time.trim())
            .map_err(|_| TargetError::BadTime { text: text.to_string() })?;
        return match named_value(value.trim(), info)? {
            Observable::Output(index) => Ok(Observable::At { output: true, index, time }),
            Observable::State(index) => Ok(Observable::At { output: false, index, time }),
            _ => unreachable!("named_value gives an output or a state"),
        };
    }
    match name.split_once('#') {
        Some((event, k)) if k.trim() == "last" => match event_time(event.trim(), "1", text, info)? {
            Observable::EventTime { name_event, .. } => Ok(Observable::LastFiring { name_event }),
            _ => unreachable!("event_time gives an event time"),
        },
        Some((event, k)) => event_time(event.trim(), k.trim(), text, info),
        None => named_value(name, info),
    }
}

/// One residual: `weight * (observed - value)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Target {
    /// What is compared.
    pub observable: Observable,
    /// The goal (or the measured value).
    pub value: f64,
    /// Multiplies the residual (the inverse of a standard deviation, in a weighted fit).
    pub weight: f64,
    /// A measurement (`--data`), not an equation: its residual is the measurement's error, so
    /// the fit converges at the least-squares minimum without meeting it.
    pub observed: bool,
}

/// A `--target` text that does not name a target of the model.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TargetError {
    #[error(
        "expected NAME=VALUE, NAME@TIME=VALUE, EVENT#K=TIME or EVENT#last=TIME, each with an optional \
         @WEIGHT after the value, found `{text}`"
    )]
    /// Not one of the shapes a target takes.
    Malformed {
        /// The target as written.
        text: String,
    },
    /// A `NAME@TIME` whose time the run does not reach (`reason` says why: before `t_start`,
    /// after `t_end`).
    #[error("`{text}`: {reason}")]
    TimeOutside {
        /// The target as written.
        text: String,
        /// Why: `time 3 is after t_end = 2.5: the run goes from ...`.
        reason: String,
    },
    /// A goal that is not a finite number.
    #[error("`{text}` is not a finite number")]
    NotANumber {
        /// The goal as written.
        text: String,
    },
    /// A goal a double cannot hold (`1e-400` would round to 0).
    #[error(transparent)]
    Unrepresentable(crate::number::NumberError),
    /// A weight that is not a positive finite number.
    #[error("weight `{text}` must be a positive finite number")]
    BadWeight {
        /// The weight as written.
        text: String,
    },
    #[error(
        "in `{text}`: the firing number K of EVENT#K must be a whole number from 1 (1 is the first firing), or `last`"
    )]
    /// A firing number K that is neither a whole number from 1 nor `last`.
    BadOccurrence {
        /// The target as written.
        text: String,
    },
    /// A time of NAME@TIME that is not a finite number.
    #[error("in `{text}`: the time of NAME@TIME must be a finite number")]
    BadTime {
        /// The target as written.
        text: String,
    },
    /// No event of that name.
    #[error("model has no event `{name}`{hint}; its events are {known}")]
    UnknownEvent {
        /// The name given.
        name: String,
        /// ` (did you mean ..?)`, or empty.
        hint: String,
        /// The model's events.
        known: String,
    },
    /// No output or state of that name.
    #[error("model has no output or state `{name}`{hint}; its outputs are {outputs}, its states {states}")]
    UnknownName {
        /// The name given.
        name: String,
        /// ` (did you mean ..?)`, or empty.
        hint: String,
        /// The model's outputs.
        outputs: String,
        /// The model's states.
        states: String,
    },
    /// A name that is an output and a state.
    #[error("`{name}` is both an output and a state; write `output:{name}` or `state:{name}`")]
    Ambiguous {
        /// The name.
        name: String,
    },
}

impl Target {
    /// Parses `NAME=VALUE`, `NAME=VALUE@WEIGHT` or `EVENT#K=TIME[@WEIGHT]` against the names in
    /// `info`. `NAME` is an output or a state (prefix `output:` or `state:` when a name is both).
    pub fn parse(text: &str, info: &SystemInfo) -> Result<Target, TargetError> {
        let malformed = || TargetError::Malformed { text: text.to_string() };
        let (name, rhs) = text.split_once('=').ok_or_else(malformed)?;
        let name = name.trim();
        let (value, weight) = match rhs.split_once('@') {
            Some((v, w)) => (v.trim(), Some(w.trim())),
            None => (rhs.trim(), None),
        };
        if name.is_empty() || value.is_empty() {
            return Err(malformed());
        }
        let value = crate::number::parse_number(value).map_err(|e| match e {
            crate::number::NumberError::TooSmall { .. } => TargetError::Unrepresentable(e),
            _ => TargetError::NotANumber { text: value.to_string() },
        })?;
        let weight = match weight {
            None => 1.0,
            Some(w) => finite(w)
                .filter(|w| *w > 0.0)
                .ok_or_else(|| TargetError::BadWeight { text: w.to_string() })?,
        };
        let observable = parse_observable(name, text, info)?;
        Ok(Target { observable, value, weight, observed: false })
    }

    /// The target's name as the user writes it (`energy`, `touchdown#2`, `y@1.5`).
    pub fn label(&self, info: &SystemInfo) -> String {
        self.observable.label(info)
    }
}

fn finite(text: &str) -> Option<f64> {
    // A weight that rounds to 0 or overflows is not the number written.
    crate::number::parse_number(text).ok()
}

fn event_time(name: &str, k: &str, text: &str, info: &SystemInfo) -> Result<Observable, TargetError> {
    let occurrence: usize = k
        .parse()
        .ok()
        .filter(|k| *k >= 1)
        .ok_or_else(|| TargetError::BadOccurrence { text: text.to_string() })?;
    // Flow switches are not events of the run's record, so they cannot be targets.
    let declared = || info.events.iter().enumerate().filter(|(_, e)| !e.implicit);
    let names: Vec<&str> = declared().map(|(_, e)| &*e.name).collect();
    match declared().find(|(_, e)| &*e.name == name) {
        Some((name_event, _)) => Ok(Observable::EventTime { name_event, occurrence }),
        None => Err(TargetError::UnknownEvent {
            name: name.to_string(),
            hint: hint(name, &names),
            known: list(&names),
        }),
    }
}

fn named_value(name: &str, info: &SystemInfo) -> Result<Observable, TargetError> {
    let find = |names: &[String], n: &str| names.iter().position(|x| x == n);
    if let Some(n) = name.strip_prefix("output:") {
        if let Some(i) = find(&info.output_names, n) {
            return Ok(Observable::Output(i));
        }
    } else if let Some(n) = name.strip_prefix("state:") {
        if let Some(i) = find(&info.state_names, n) {
            return Ok(Observable::State(i));
        }
    } else {
        match (find(&info.output_names, name), find(&info.state_names, name)) {
            (Some(_), Some(_)) => return Err(TargetError::Ambiguous { name: name.to_string() }),
            (Some(i), None) => return Ok(Observable::Output(i)),
            (None, Some(i)) => return Ok(Observable::State(i)),
            (None, None) => {}
        }
    }
    let outputs: Vec<&str> = info.output_names.iter().map(String::as_str).collect();
    let states: Vec<&str> = info.state_names.iter().map(String::as_str).collect();
    let all: Vec<&str> = outputs.iter().chain(&states).copied().collect();
    Err(TargetError::UnknownName {
        name: name.to_string(),
        hint: hint(name, &all),
        outputs: list(&outputs),
        states: list(&states),
    })
}

fn hint(name: &str, names: &[&str]) -> String {
    crate::sema::closest_name(name, names.iter().copied())
        .map(|s| format!(" (did you mean `{s}`?)"))
        .unwrap_or_default()
}

fn list(names: &[&str]) -> String {
    if names.is_empty() {
        "none".to_string()
    } else {
        names.join(", ")
    }
}
