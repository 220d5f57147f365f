//! Semantic errors. Each carries the span it is about; `to_diagnostic` words it for the user.

use crate::diag::Diagnostic;
use crate::syntax::Span;

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CheckError {
    #[error("unknown name `{name}`")]
    UnknownName { name: String, span: Span, suggestion: Option<String> },
    #[error("unknown function `{name}`")]
    UnknownFunction { name: String, span: Span, suggestion: Option<String> },
    #[error("unknown mode `{name}`")]
    UnknownMode { name: String, span: Span, suggestion: Option<String> },
    #[error("`{name}` is declared twice")]
    Duplicate { name: String, what: &'static str, span: Span, first: Span },
    #[error("`{name}` is a built-in name and cannot be declared")]
    Reserved { name: String, span: Span },
    #[error("`{name}` is a {found}, expected a {expected}")]
    WrongKind { name: String, found: &'static str, expected: &'static str, span: Span },
    #[error("state `{state}` has no flow equation in mode `{mode}`")]
    MissingFlow { state: String, mode: String, span: Span },
    #[error("state `{state}` has two flow equations in mode `{mode}`")]
    DuplicateFlow { state: String, mode: String, span: Span, first: Span },
    #[error("state `{state}` is reset twice in event `{event}`")]
    DoubleReset { state: String, event: String, span: Span, first: Span },
    #[error("the model has modes but none is marked `initial`")]
    NoInitialMode { span: Span },
    #[error("more than one mode is marked `initial`")]
    SecondInitialMode { name: String, span: Span, first: Span },
    #[error("`let {name}` depends on itself")]
    LetCycle { name: String, path: String, span: Span },
    #[error("`let {name}` nests expressions {depth} levels deep")]
    TooDeep { name: String, depth: usize, span: Span },
    #[error("`{func}` takes {expected} argument{}, found {found}", if *expected == 1 { "" } else { "s" })]
    Arity { func: String, expected: usize, found: usize, span: Span },
    #[error("the range of `{name}` excludes its default {default}")]
    RangeExcludesDefault { name: String, default: f64, lo: f64, hi: f64, span: Span },
    #[error("empty range [{lo}, {hi}]")]
    EmptyRange { lo: f64, hi: f64, span: Span },
    #[error("initial value of `{state}` depends on {what}")]
    InitNotConstant { state: String, what: String, span: Span },
    #[error("model `{name}` has no states")]
    EmptyModel { name: String, span: Span },
    #[error("`{name}` is set twice on the `simulate` line")]
    DuplicateSetting { name: String, span: Span, first: Span },
    #[error("unknown simulate setting `{name}`")]
    UnknownSetting { name: String, span: Span },
    #[error("`{name} = {value}` is out of range")]
    BadSetting { name: String, value: f64, expected: &'static str, span: Span },
    #[error("the guard of event `{event}` jumps where an `if` or `sign` in it switches")]
    DiscontinuousGuard { event: String, span: Span },
    #[error("vector parameter `{name}` has length {len}")]
    BadVectorLength { name: String, len: String, span: Span },
    #[error("the model declares more than {} parameters", super::model::MAX_PARAMS)]
    TooManyParams { span: Span },
    #[error("index {index} is out of range for `{name}`, a vector of {len}")]
    IndexOutOfRange { name: String, index: f64, len: u32, span: Span },
    #[error("the index of `{name}` must be an integer literal")]
    BadIndex { name: String, len: u32, span: Span },
    #[error("`{name}` is a vector of {len} parameters")]
    VectorAsScalar { name: String, len: u32, span: Span },
    #[error("`{func}` takes vector parameters")]
    NotAVector { func: &'static str, span: Span },
    #[error("the first argument of `{func}` must be `t`")]
    InputTime { func: &'static str, span: Span },
    #[error("the knot window of `{func}` depends on {what}")]
    InputWindow { func: &'static str, what: String, span: Span },
    #[error("`pwl` needs at least 2 knots, `{name}` has {len}")]
    InputTooShort { name: String, len: u32, span: Span },
    #[error("the guard of event `{event}` jumps at the knots of a `pwc` input")]
    PwcInGuard { event: String, span: Span },
    #[error("`dot` of vectors of different lengths: `{a}` has {len_a}, `{b}` has {len_b}")]
    VectorLengths { a: String, len_a: u32, b: String, len_b: u32, span: Span },
}

impl CheckError {
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
