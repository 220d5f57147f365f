//! Semantic errors. Each carries the span it is about; `to_diagnostic` words it for the user.

use crate::diag::Diagnostic;
use crate::syntax::Span;

/// Everything the checker can refuse in a parsed model, each with the span it is about;
/// [`CheckError::to_diagnostic`] words it for the user.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CheckError {
    /// A refusal of the flattening of arrays and loops (`crate::expand`).
    #[error("{0}")]
    Expand(Box<crate::expand::ExpandError>),
    /// An error in an item unrolled from a loop, with the loop values of the first unrolled item
    /// where it arose and the declaration it stands in.
    #[error("at `{}`: {error}", at.iter().map(|(n, v)| format!("{n} = {v}")).collect::<Vec<_>>().join(", "))]
    InLoop {
        /// The error.
        error: Box<CheckError>,
        /// The loop variables' values, outermost first.
        at: Vec<(String, i64)>,
        /// The declaration's head (`der(x[i]) = `), quoted in the message.
        within: Span,
    },
    /// A name declared in no enclosing scope.
    #[error("unknown name `{name}`")]
    UnknownName {
        /// The name, as written.
        name: String,
        /// Where it stands in the source.
        span: Span,
        /// The closest known name, if one is close.
        suggestion: Option<String>,
    },
    /// A call of a function hybc does not have.
    #[error("unknown function `{name}`")]
    UnknownFunction {
        /// The name, as written.
        name: String,
        /// Where it stands in the source.
        span: Span,
        /// The closest known name, if one is close.
        suggestion: Option<String>,
    },
    /// A `-> MODE` target that names no mode.
    #[error("unknown mode `{name}`")]
    UnknownMode {
        /// The name, as written.
        name: String,
        /// Where it stands in the source.
        span: Span,
        /// The closest known name, if one is close.
        suggestion: Option<String>,
    },
    /// A name declared twice in one scope, or shadowing an enclosing one.
    #[error("`{name}` is declared twice")]
    Duplicate {
        /// The name, as written.
        name: String,
        /// What kind of declaration it is (`parameter`, `state`, `let`, ...).
        what: &'static str,
        /// Where it stands in the source.
        span: Span,
        /// Where the first one stands.
        first: Span,
    },
    /// A built-in name (`t`, a function) declared.
    #[error("`{name}` is a built-in name and cannot be declared")]
    Reserved {
        /// The name, as written.
        name: String,
        /// Where it stands in the source.
        span: Span,
    },
    /// A name used as another kind of thing than it is (a parameter reset, ...).
    #[error("`{name}` is a {found}, expected a {expected}")]
    WrongKind {
        /// The name, as written.
        name: String,
        /// What the name is.
        found: &'static str,
        /// What the place needs.
        expected: &'static str,
        /// Where it stands in the source.
        span: Span,
    },
    /// A state without a flow in a mode.
    #[error("state `{state}` has no flow equation in mode `{mode}`")]
    MissingFlow {
        /// The state's name.
        state: String,
        /// The mode's name.
        mode: String,
        /// Where it stands in the source.
        span: Span,
    },
    /// Two flows for one state in one mode.
    #[error("state `{state}` has two flow equations in mode `{mode}`")]
    DuplicateFlow {
        /// The state's name.
        state: String,
        /// The mode's name.
        mode: String,
        /// Where it stands in the source.
        span: Span,
        /// Where the first one stands.
        first: Span,
    },
    /// One state reset twice by one event.
    #[error("state `{state}` is reset twice in event `{event}`")]
    DoubleReset {
        /// The state's name.
        state: String,
        /// The event's name.
        event: String,
        /// Where it stands in the source.
        span: Span,
        /// Where the first one stands.
        first: Span,
    },
    /// Modes, none marked `initial`.
    #[error("the model has modes but none is marked `initial`")]
    NoInitialMode {
        /// Where it stands in the source.
        span: Span,
    },
    /// A second mode marked `initial`.
    #[error("more than one mode is marked `initial`")]
    SecondInitialMode {
        /// The second mode's name.
        name: String,
        /// Where it stands in the source.
        span: Span,
        /// Where the first one stands.
        first: Span,
    },
    /// A `let` that depends on itself.
    #[error("`let {name}` depends on itself")]
    LetCycle {
        /// The name, as written.
        name: String,
        /// The chain of `let`s back to it, `a -> b -> a`.
        path: String,
        /// Where it stands in the source.
        span: Span,
    },
    /// A `let` nested deeper than `MAX_EXPR_DEPTH`.
    #[error("`let {name}` nests expressions {depth} levels deep")]
    TooDeep {
        /// The name, as written.
        name: String,
        /// How deep it nests.
        depth: usize,
        /// Where it stands in the source.
        span: Span,
    },
    /// A function called with the wrong number of arguments.
    #[error("`{func}` takes {expected} argument{}, found {found}", if *expected == 1 { "" } else { "s" })]
    Arity {
        /// The function's name.
        func: String,
        /// The arguments it takes.
        expected: usize,
        /// The arguments given.
        found: usize,
        /// Where it stands in the source.
        span: Span,
    },
    /// A declared range that leaves out the parameter's default.
    #[error("the range of `{name}` excludes its default {default}")]
    RangeExcludesDefault {
        /// The name, as written.
        name: String,
        /// The default value.
        default: f64,
        /// The range's lower end.
        lo: f64,
        /// The range's upper end.
        hi: f64,
        /// Where it stands in the source.
        span: Span,
    },
    /// A range whose lower end is not below its upper end.
    #[error("empty range [{lo}, {hi}]")]
    EmptyRange {
        /// The range's lower end.
        lo: f64,
        /// The range's upper end.
        hi: f64,
        /// Where it stands in the source.
        span: Span,
    },
    /// An initial value that reads `t`, a state or an input.
    #[error("initial value of `{state}` depends on {what}")]
    InitNotConstant {
        /// The state whose initial value it is.
        state: String,
        /// What it reads: `time `t``, `state `x``, an input.
        what: String,
        /// Where it stands in the source.
        span: Span,
    },
    /// A model without states.
    #[error("model `{name}` has no states")]
    EmptyModel {
        /// The model's name.
        name: String,
        /// Where it stands in the source.
        span: Span,
    },
    /// A setting given twice on the `simulate` line.
    #[error("`{name}` is set twice on the `simulate` line")]
    DuplicateSetting {
        /// The setting.
        name: String,
        /// Where it stands in the source.
        span: Span,
        /// Where the first one stands.
        first: Span,
    },
    /// A `simulate` setting hybc does not have.
    #[error("unknown simulate setting `{name}`")]
    UnknownSetting {
        /// The setting.
        name: String,
        /// Where it stands in the source.
        span: Span,
    },
    /// A `simulate` setting outside its range.
    #[error("`{name} = {value}` is out of range")]
    BadSetting {
        /// The setting.
        name: String,
        /// The value given.
        value: f64,
        /// What it takes, in words (`a positive number`).
        expected: &'static str,
        /// Where it stands in the source.
        span: Span,
    },
    /// A guard that jumps where an `if` or `sign` in it switches (an event needs a continuous guard).
    #[error("the guard of event `{event}` jumps where an `if` or `sign` in it switches")]
    DiscontinuousGuard {
        /// The event's name.
        event: String,
        /// Where it stands in the source.
        span: Span,
    },
    /// A vector parameter whose length is not a whole number from 1 up.
    #[error("vector parameter `{name}` has length {len}")]
    BadVectorLength {
        /// The vector's name.
        name: String,
        /// The length as written.
        len: String,
        /// Where it stands in the source.
        span: Span,
    },
    /// More parameters than `MAX_PARAMS`.
    #[error("the model declares more than {} parameters", super::model::MAX_PARAMS)]
    TooManyParams {
        /// Where it stands in the source.
        span: Span,
    },
    /// An element index past the vector's end.
    #[error("index {index} is out of range for `{name}`, a vector of {len}")]
    IndexOutOfRange {
        /// The vector's name.
        name: String,
        /// The index given.
        index: f64,
        /// The vector's length.
        len: u32,
        /// Where it stands in the source.
        span: Span,
    },
    /// An element index that is not an integer literal.
    #[error("the index of `{name}` must be an integer literal")]
    BadIndex {
        /// The vector's name.
        name: String,
        /// The vector's length.
        len: u32,
        /// Where it stands in the source.
        span: Span,
    },
    /// A vector parameter used where one number is meant.
    #[error("`{name}` is a vector of {len} parameters")]
    VectorAsScalar {
        /// The vector's name.
        name: String,
        /// The vector's length.
        len: u32,
        /// Where it stands in the source.
        span: Span,
    },
    /// A vector function (`sum`, `dot`, `pwl`, `pwc`) given something that is not a vector parameter.
    #[error("`{func}` takes vector parameters")]
    NotAVector {
        /// The function's name.
        func: &'static str,
        /// Where it stands in the source.
        span: Span,
    },
    /// An input whose first argument is not `t`.
    #[error("the first argument of `{func}` must be `t`")]
    InputTime {
        /// The function's name.
        func: &'static str,
        /// Where it stands in the source.
        span: Span,
    },
    /// An input whose knot window reads `t`, a state or another input.
    #[error("the knot window of `{func}` depends on {what}")]
    InputWindow {
        /// The function's name.
        func: &'static str,
        /// What it reads: `time `t``, `state `x``, an input.
        what: String,
        /// Where it stands in the source.
        span: Span,
    },
    /// A `pwl` input over fewer than 2 knots.
    #[error("`pwl` needs at least 2 knots, `{name}` has {len}")]
    InputTooShort {
        /// The vector's name.
        name: String,
        /// The vector's length.
        len: u32,
        /// Where it stands in the source.
        span: Span,
    },
    /// A guard that reads a `pwc` input (it would jump at the input's knots).
    #[error("the guard of event `{event}` jumps at the knots of a `pwc` input")]
    PwcInGuard {
        /// The event's name.
        event: String,
        /// Where it stands in the source.
        span: Span,
    },
    /// `dot` of two vectors of different lengths.
    #[error("`dot` of vectors of different lengths: `{a}` has {len_a}, `{b}` has {len_b}")]
    VectorLengths {
        /// The first vector's name.
        a: String,
        /// Its length.
        len_a: u32,
        /// The second vector's name.
        b: String,
        /// Its length.
        len_b: u32,
        /// Where it stands in the source.
        span: Span,
    },
}

impl CheckError {
    /// The span the error is about.
    pub fn span(&self) -> Span {
        use CheckError::*;
        match self {
            UnknownName { span, .. }
            | UnknownFunction { span, .. }
            | UnknownMode { span, .. }
            | Duplicate { span, .. }
            | Reserved { span, .. }
            | WrongKind { span, .. }
            | MissingFlow { span, .. }
            | DuplicateFlow { span, .. }
            | DoubleReset { span, .. }
            | NoInitialMode { span }
            | SecondInitialMode { span, .. }
            | LetCycle { span, .. }
            | TooDeep { span, .. }
            | Arity { span, .. }
            | RangeExcludesDefault { span, .. }
            | EmptyRange { span, .. }
            | InitNotConstant { span, .. }
            | EmptyModel { span, .. }
            | DuplicateSetting { span, .. }
            | UnknownSetting { span, .. }
            | BadSetting { span, .. }
            | DiscontinuousGuard { span, .. }
            | BadVectorLength { span, .. }
            | TooManyParams { span }
            | IndexOutOfRange { span, .. }
            | BadIndex { span, .. }
            | VectorAsScalar { span, .. }
            | NotAVector { span, .. }
            | VectorLengths { span, .. }
            | InputTime { span, .. }
            | InputWindow { span, .. }
            | InputTooShort { span, .. }
            | PwcInGuard { span, .. } => *span,
            Expand(e) => e.span,
            InLoop { error, .. } => error.span(),
        }
    }

    /// The error with what was expected under the caret and any helpful notes.
    pub fn to_diagnostic(&self, source: &str) -> Diagnostic {
        use CheckError::*;
        let line_of = |s: Span| source[..s.start.min(source.len())].matches('\n').count() + 1;
        let did_you_mean = |s: &Option<String>| {
            s.as_ref().map(|s| format!("did you mean `{s}`?")).into_iter().collect::<Vec<_>>()
        };
        let (label, notes) = match self {
            Expand(e) => return e.to_diagnostic(source),
            InLoop { error, within, .. } => {
                let mut d = error.to_diagnostic(source);
                let quoted = crate::expand::quote_head(source, *within);
                d.message = match quoted {
                    Some(text) => format!("in `{text}` {self}"),
                    None => self.to_string(),
                };
                return d;
            }
            UnknownName { suggestion, .. } => {
                ("expected a parameter, state, `let`, `t` or `pi`".to_string(), did_you_mean(suggestion))
            }
            UnknownFunction { suggestion, .. } => {
                ("expected a built-in function".to_string(), did_you_mean(suggestion))
            }
            UnknownMode { suggestion, .. } => {
                ("expected the name of a declared mode".to_string(), did_you_mean(suggestion))
            }
            Duplicate { what, first, .. } => (
                format!("expected a new name; the {what} was first declared on line {}", line_of(*first)),
                vec![],
            ),
            Reserved { .. } => {
                ("expected a name other than `t`, `pi`, `sum`, `dot`, `pwl`, `pwc` or a function name".into(), vec![])
            }
            WrongKind { expected, .. } => (format!("expected a {expected} here"), vec![]),
            MissingFlow { state, .. } => (format!("expected `der({state}) = ...` in this mode"), vec![]),
            DuplicateFlow { first, .. } => (
                format!("expected one flow equation per state; the first is on line {}", line_of(*first)),
                vec![],
            ),
            DoubleReset { first, .. } => (
                format!("expected at most one `:=` per state; the first is on line {}", line_of(*first)),
                vec![],
            ),
            NoInitialMode { .. } => {
                ("expected one mode declared as `initial mode NAME { ... }`".to_string(), vec![])
            }
            SecondInitialMode { first, .. } => (
                format!("expected exactly one initial mode; the first is on line {}", line_of(*first)),
                vec![],
            ),
            LetCycle { path, .. } => (
                "expected a definition that does not refer back to itself".to_string(),
                vec![format!("cycle: {path}")],
            ),
            TooDeep { .. } => (
                format!(
                    "expected at most {} levels, counting through the `let`s it uses",
                    super::model::MAX_EXPR_DEPTH
                ),
                vec!["each `let` that uses another adds the depth of its definition".to_string()],
            ),
            Arity { expected, .. } => (format!("expected {expected} argument(s)"), vec![]),
            RangeExcludesDefault { lo, hi, .. } => {
                (format!("expected a default inside [{lo}, {hi}]"), vec![])
            }
            EmptyRange { .. } => ("expected LO <= HI".to_string(), vec![]),
            InitNotConstant { .. } => {
                ("expected an expression of parameters only (no `t`, no states)".to_string(), vec![])
            }
            EmptyModel { .. } => ("expected at least one `state NAME = ...`".to_string(), vec![]),
            DuplicateSetting { first, .. } => {
                let column = first.start
                    - source[..first.start.min(source.len())].rfind('\n').map_or(0, |i| i + 1)
                    + 1;
                (
                    format!(
                        "expected each setting once; the first is at line {}, column {column}",
                        line_of(*first)
                    ),
                    vec!["one value would silently win over the other".to_string()],
                )
            }
            UnknownSetting { .. } => ("expected `t_end`, `rtol` or `atol`".to_string(), vec![]),
            BadSetting { expected, .. } => (format!("expected {expected}"), vec![]),
            DiscontinuousGuard { .. } => (
                "expected a guard continuous in time and the state".to_string(),
                vec![
                    "a guard that jumps across zero has no crossing to locate and no crossing speed for its \
                     gradient"
                        .to_string(),
                    "split the event, one per branch, each with a condition: \
                     `event e when x - b <= 0 if x > a`"
                        .to_string(),
                ],
            ),
            BadVectorLength { .. } => {
                (format!("expected a length from 1 to {}", super::model::MAX_PARAMS), vec![])
            }
            TooManyParams { .. } => (
                format!(
                    "expected at most {} parameters in all, counting every element of a vector",
                    super::model::MAX_PARAMS
                ),
                vec![],
            ),
            IndexOutOfRange { len, .. } | BadIndex { len, .. } => (
                format!("expected an integer from 0 to {}", len.saturating_sub(1)),
                vec![
                    "an index is a constant: `u[3]`; `sum(u)` and `dot(u, w)` take every element".to_string()
                ],
            ),
            VectorAsScalar { name, .. } => (
                format!("expected a number: index it (`{name}[k]`) or use `sum({name})`, `dot({name}, w)`"),
                vec![],
            ),
            NotAVector { .. } => {
                ("expected the name of a vector parameter (`param u[N] = ...`)".to_string(), vec![])
            }
            VectorLengths { .. } => ("expected two vectors of the same length".to_string(), vec![]),
            InputTime { func, .. } => (
                "expected `t`".to_string(),
                vec![format!("an input is a function of time: `{func}(t, t0, t1, u)`")],
            ),
            InputWindow { .. } => (
                "expected an expression of parameters".to_string(),
                vec!["the knots are fixed for a run: their times are computed from the parameters at its start"
                    .to_string()],
            ),
            InputTooShort { .. } => ("expected a vector of at least 2 elements".to_string(), vec![]),
            PwcInGuard { .. } => (
                "expected a guard continuous in time and the state".to_string(),
                vec!["a `pwc` input jumps at its knots: use `pwl`, or an event per knot time \
                      (`event e when t >= T`)"
                    .to_string()],
            ),
        };
        Diagnostic { message: self.to_string(), span: self.span(), label, notes }
    }
}
