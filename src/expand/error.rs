//! What flattening refuses, with the loop values it was refused at.

use crate::diag::Diagnostic;
use crate::syntax::Span;

/// One refusal of `expand`: the problem, the span it is about, the reference it stands in and
/// the values of the enclosing loop variables, outermost first.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{}{problem}", at_prefix(at))]
pub struct ExpandError {
    /// What is wrong.
    pub problem: Problem,
    /// Where it stands in the source (the caret).
    pub span: Span,
    /// The reference or declaration it stands in (`x[i + 5]`), quoted in the message.
    pub within: Option<Span>,
    /// The loop variables' values there, outermost first.
    pub at: Vec<(String, i64)>,
}

fn at_prefix(at: &[(String, i64)]) -> String {
    if at.is_empty() {
        return String::new();
    }
    let values: Vec<String> = at.iter().map(|(n, v)| format!("{n} = {v}")).collect();
    format!("at `{}`: ", values.join(", "))
}

/// A declaration's head as quoted: `der(v[i]) = ` -> `der(v[i])`, `event low[i] when` ->
/// `event low[i]`, `v[i] :=` -> `v[i]`.
fn trim_head(text: &str) -> &str {
    let text = text.trim();
    let text = text.strip_suffix(":=").or_else(|| text.strip_suffix('=')).unwrap_or(text).trim_end();
    text.strip_suffix("when").map_or(text, str::trim_end)
}

/// The text of a declaration's head as a message quotes it (`der(v[i])`), if it is short and on
/// one line.
pub fn quote_head(source: &str, within: Span) -> Option<&str> {
    source
        .get(within.start..within.end)
        .map(trim_head)
        .filter(|text| !text.is_empty() && !text.contains(['\n', '\r']) && text.len() <= 80)
}

/// `2000000` as `2,000,000`.
fn thousands(n: usize) -> String {
    let digits = n.to_string();
    let mut out = String::new();
    for (k, c) in digits.chars().enumerate() {
        if k > 0 && (digits.len() - k).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// The ranges of an array, `x[0 .. 7]` or `T[0 .. 3][0 .. 7]`.
fn ranges(array: &str, extent: &[i64]) -> String {
    let dims: String = extent.iter().map(|n| format!("[0 .. {}]", n - 1)).collect();
    format!("{array}{dims}")
}

/// The kinds of refusal.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Problem {
    /// An index outside the declared elements.
    #[error("index {index} is outside `{}`", ranges(array, extent))]
    OutOfRange {
        /// The array.
        array: String,
        /// The index's value.
        index: i64,
        /// One past the largest index of each dimension.
        extent: Vec<i64>,
    },
    /// An array indexed with the wrong number of indices.
    #[error("`{array}` takes {dims} index(es), found {found}")]
    IndexCount {
        /// The array.
        array: String,
        /// Its dimensions.
        dims: usize,
        /// The indices written.
        found: usize,
    },
    /// A number with a fraction (or beyond 2^53) where an integer is needed.
    #[error("{value} is not an integer")]
    NotInteger {
        /// The number.
        value: f64,
    },
    /// A declared name that is not a compile-time integer, read in index arithmetic.
    #[error("`{name}` is {kind}, not a compile-time integer")]
    NotConstant {
        /// The name.
        name: String,
        /// What it is (`a state`).
        kind: &'static str,
    },
    /// A name that is neither a `const` nor a loop variable, read in index arithmetic.
    #[error("unknown const `{name}`")]
    UnknownConst {
        /// The name.
        name: String,
    },
    /// An integer result beyond `i64`.
    #[error("integer overflow")]
    Overflow,
    /// `/ 0`, `div(a, 0)`, `mod(a, 0)`.
    #[error("division by zero")]
    DivideByZero,
    /// `a / b` with a remainder.
    #[error("`{a} / {b}` is not an integer")]
    InexactDivision {
        /// The dividend.
        a: i64,
        /// The divisor.
        b: i64,
    },
    /// `a ^ b` with `b < 0`.
    #[error("a negative power is not an integer")]
    NegativePower,
    /// `min`, `max`, `div`, `mod` with other than two arguments.
    #[error("`{func}` takes 2 arguments in an index, found {found}")]
    IndexArity {
        /// The function.
        func: String,
        /// The arguments written.
        found: usize,
    },
    /// Something other than integer arithmetic in an index.
    #[error("{what} is not index arithmetic")]
    NotIndexArithmetic {
        /// What was found.
        what: String,
    },
    /// A loop, a reduction or the whole model past the cap on the flattened size.
    #[error(
        "{what}: the flattened model would exceed {} items and expression nodes",
        thousands(super::MAX_FLAT_SIZE)
    )]
    TooLarge {
        /// What overflowed (`a loop of 1000000000 iterations`).
        what: String,
    },
    /// An array length below 1.
    #[error("length {len} of `{name}` is not positive")]
    BadLength {
        /// The array.
        name: String,
        /// The length.
        len: i64,
    },
    /// An element declared with a negative index.
    #[error("element `{name}` index {index} is negative")]
    NegativeElement {
        /// The array.
        name: String,
        /// The index.
        index: i64,
    },
    /// A scalar indexed.
    #[error("`{name}` is {kind}, not an array")]
    NotAnArray {
        /// The name.
        name: String,
        /// What it is.
        kind: &'static str,
    },
    /// An array read whole where a number is needed.
    #[error("`{name}` is an array, read here as a number")]
    ArrayAsScalar {
        /// The array.
        name: String,
    },
    /// A `const` or loop variable named as something declared or as an enclosing loop variable.
    #[error("`{name}` is already {what}")]
    Shadows {
        /// The name.
        name: String,
        /// What it already is.
        what: &'static str,
    },
    /// An array declared with different numbers of indices, or both whole and by elements.
    #[error("`{name}` is declared both {first} and {second}")]
    MixedDeclaration {
        /// The array.
        name: String,
        /// The first kind of declaration.
        first: String,
        /// The second.
        second: String,
    },
    /// `dot(x, w)` of two arrays of different lengths.
    #[error("`dot` of `{a}` ({len_a} elements) and `{b}` ({len_b} elements)")]
    Lengths {
        /// The first array.
        a: String,
        /// Its length.
        len_a: i64,
        /// The second.
        b: String,
        /// Its length.
        len_b: i64,
    },
}

impl ExpandError {
    /// The error as a diagnostic: the message names the reference it stands in (`in `x[i + 5]``)
    /// and the loop values; the label says what was expected under the caret.
    pub fn to_diagnostic(&self, source: &str) -> Diagnostic {
        let quoted = self
            .within
            .and_then(|w| quote_head(source, w))
            .map(|text| format!("in `{text}` "))
            .unwrap_or_default();
        let message = if quoted.is_empty() { self.to_string() } else { format!("{quoted}{self}") };
        let (label, notes): (String, Vec<String>) = match &self.problem {
            Problem::OutOfRange { extent, .. } => {
                (format!("expected an index from 0 to {}", extent.last().map_or(0, |n| n - 1)), vec![])
            }
            Problem::IndexCount { dims, .. } => (format!("expected {dims} index(es)"), vec![]),
            Problem::NotInteger { .. }
            | Problem::NotConstant { .. }
            | Problem::UnknownConst { .. }
            | Problem::InexactDivision { .. }
            | Problem::NegativePower
            | Problem::IndexArity { .. }
            | Problem::NotIndexArithmetic { .. } => (
                "expected an integer expression of numbers, loop variables and `const`s".to_string(),
                vec!["index arithmetic: `+ - *`, exact `/`, `^`, `div`, `mod`, `min`, `max`".to_string()],
            ),
            Problem::Overflow | Problem::DivideByZero => {
                ("expected an integer within 64 bits".to_string(), vec![])
            }
            Problem::TooLarge { .. } => (
                "expected a smaller model".to_string(),
                vec![format!(
                    "the cap is {} items and expression nodes after unrolling",
                    thousands(super::MAX_FLAT_SIZE)
                )],
            ),
            Problem::BadLength { .. } => ("expected a length of at least 1".to_string(), vec![]),
            Problem::NegativeElement { .. } => ("expected an index of at least 0".to_string(), vec![]),
            Problem::NotAnArray { .. } => ("expected the name of an array".to_string(), vec![]),
            Problem::ArrayAsScalar { name } => {
                (format!("expected a number: index it (`{name}[k]`) or use `sum({name})`"), vec![])
            }
            Problem::Shadows { .. } => ("expected a new name".to_string(), vec![]),
            Problem::MixedDeclaration { .. } => {
                ("expected every declaration of an array alike".to_string(), vec![])
            }
            Problem::Lengths { .. } => ("expected two arrays of the same length".to_string(), vec![]),
        };
        Diagnostic { message, span: self.span, label, notes }
    }
}
