//! What an optimisation aims at, parsed from text against a model's names: the objective (a
//! quantity to minimise) and the constraints (`QUANTITY OP VALUE`, `OP` one of `=`, `<=`, `>=`).
//! A quantity is anything `hybc fit` can target (`crate::fit::Observable`: `NAME`, `EVENT#K`,
//! `EVENT#last`, `NAME@TIME`) or a parameter (`h0`: the lowest drop height that meets the
//! constraints); a path constraint `NAME@LO:HI:N OP VALUE` is N constraints on an even grid of
//! times. Knows names, not runs or solvers.

use crate::fit::{Observable, TargetError};
use crate::sim::SystemInfo;

/// A number the optimiser reads at a parameter point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Quantity {
    /// Read off a run (final value, event time, value at a time).
    Observable(Observable),
    /// A parameter's own value (index into `SystemInfo::param_names`); its gradient is 1 with
    /// respect to itself when free, else 0.
    Param(usize),
}

impl Quantity {
    /// Parses a quantity against the names in `info`: an output, a state, an event time or a
    /// value at a time first (the one parser `hybc fit` uses), else a parameter.
    pub fn parse(text: &str, info: &SystemInfo) -> Result<Quantity, SpecError> {
        match Observable::parse(text, info) {
            Ok(o) => Ok(Quantity::Observable(o)),
            Err(e @ TargetError::UnknownName { .. }) => {
                match info.param_names.iter().position(|p| p == text.trim()) {
                    Some(j) => Ok(Quantity::Param(j)),
                    None => Err(SpecError::Name(e)),
                }
            }
            Err(e) => Err(SpecError::Name(e)),
        }
    }

    /// The name as the user writes it.
    pub fn label(&self, info: &SystemInfo) -> String {
        match self {
            Quantity::Observable(o) => o.label(info),
            Quantity::Param(j) => info.param_names[*j].clone(),
        }
    }
}

/// How a constraint compares its quantity with its value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sense {
    /// `Q = V`.
    Eq,
    /// `Q <= V`.
    Le,
    /// `Q >= V`.
    Ge,
}

impl Sense {
    /// The symbol as written (`=`, `<=`, `>=`).
    pub fn symbol(self) -> &'static str {
        match self {
            Sense::Eq => "=",
            Sense::Le => "<=",
            Sense::Ge => ">=",
        }
    }
}

/// `quantity SENSE value`.
#[derive(Clone, Debug, PartialEq)]
pub struct Constraint {
    /// What is constrained.
    pub quantity: Quantity,
    /// How it compares.
    pub sense: Sense,
    /// The bound.
    pub value: f64,
}

impl Constraint {
    /// How far the quantity's value `v` lies outside the constraint (0 when it holds).
    pub fn violation(&self, v: f64) -> f64 {
        match self.sense {
            Sense::Eq => (v - self.value).abs(),
            Sense::Le => (v - self.value).max(0.0),
            Sense::Ge => (self.value - v).max(0.0),
        }
    }

    /// The constraint as `c(v) <= 0` (inequalities) or `c(v) = 0` (equalities), and `dc/dv`.
    pub fn normalized(&self, v: f64) -> (f64, f64) {
        match self.sense {
            Sense::Eq | Sense::Le => (v - self.value, 1.0),
            Sense::Ge => (self.value - v, -1.0),
        }
    }

    /// `y@1.5 >= 0`.
    pub fn label(&self, info: &SystemInfo) -> String {
        format!("{} {} {}", self.quantity.label(info), self.sense.symbol(), self.value)
    }
}

/// A `--minimize` or `--subject-to` text that does not say what it must.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SpecError {
    /// The quantity is neither an observable of the model nor a parameter.
    #[error("{0} (or a parameter)")]
    Name(TargetError),
    /// No `=`, `<=` or `>=`.
    #[error("expected QUANTITY = VALUE, QUANTITY <= VALUE or QUANTITY >= VALUE, found `{text}`")]
    NoComparison {
        /// The text as written.
        text: String,
    },
    /// A bound that is not a finite number.
    #[error("in `{text}`: `{value}` is not a finite number")]
    BadValue {
        /// The constraint as written.
        text: String,
        /// The bound as written.
        value: String,
    },
    #[error(
        "in `{text}`: a path grid is NAME@LO:HI:N with finite LO < HI and N >= 2 (N at most {max}), found `{grid}`"
    )]
    /// A path grid `LO:HI:N` that is not one (or has more than `max` times).
    BadGrid {
        /// The constraint as written.
        text: String,
        /// The grid as written.
        grid: String,
        /// The most times a path constraint takes.
        max: usize,
    },
    /// A path constraint on something that has no value at a time (an event time, a parameter).
    #[error("in `{text}`: a path constraint NAME@LO:HI:N needs an output or a state as NAME")]
    PathOfNonValue {
        /// The text as written.
        text: String,
    },
}

/// Parses `QUANTITY OP VALUE` (one constraint) or `NAME@LO:HI:N OP VALUE` (one per grid time).
pub fn parse_constraint(text: &str, info: &SystemInfo) -> Result<Vec<Constraint>, SpecError> {
    let (lhs, sense, rhs) =
        split_comparison(text).ok_or_else(|| SpecError::NoComparison { text: text.into() })?;
    let value = crate::number::parse_number(rhs.trim())
        .map_err(|_| SpecError::BadValue { text: text.into(), value: rhs.trim().into() })?;
    let lhs = lhs.trim();
    if lhs.is_empty() {
        return Err(SpecError::NoComparison { text: text.into() });
    }
    // A grid `@LO:HI:N` expands into one `NAME@t` per time; a single `@TIME` is the fit's syntax.
    if let Some((name, grid)) = lhs.split_once('@').filter(|(_, g)| g.contains(':')) {
        let times = parse_grid(grid).ok_or_else(|| SpecError::BadGrid {
            text: text.into(),
            grid: grid.into(),
            max: crate::limits::MAX_CONSTRAINTS,
        })?;
        let (output, index) = match Observable::parse(name, info).map_err(SpecError::Name)? {
            Observable::Output(i) => (true, i),
            Observable::State(i) => (false, i),
            _ => return Err(SpecError::PathOfNonValue { text: text.into() }),
        };
        return Ok(times
            .into_iter()
            .map(|time| Constraint {
                quantity: Quantity::Observable(Observable::At { output, index, time }),
                sense,
                value,
            })
            .collect());
    }
    Ok(vec![Constraint { quantity: Quantity::parse(lhs, info)?, sense, value }])
}

/// `LO:HI:N`, N evenly spaced times with both ends.
fn parse_grid(grid: &str) -> Option<Vec<f64>> {
    let parts: Vec<&str> = grid.split(':').map(str::trim).collect();
    let [lo, hi, n] = parts[..] else { return None };
    let lo = crate::number::parse_number(lo).ok()?;
    let hi = crate::number::parse_number(hi).ok()?;
    let n: usize = n.parse().ok()?;
    if lo >= hi || !(2..=crate::limits::MAX_CONSTRAINTS).contains(&n) {
        return None;
    }
    Some(crate::sweep::linspace(lo, hi, n))
}

/// Splits at the first `<=`, `>=`, `==` or `=`.
fn split_comparison(text: &str) -> Option<(&str, Sense, &str)> {
    for (op, sense) in [("<=", Sense::Le), (">=", Sense::Ge), ("==", Sense::Eq), ("=", Sense::Eq)] {
        if let Some((l, r)) = text.split_once(op) {
            return Some((l, sense, r));
        }
    }
    None
}
