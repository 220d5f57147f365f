//! Fits to time series (`hybc fit --data obs.csv`): a CSV of measurements becomes one target per
//! value (`NAME@TIME`, weighted by `1 / sigma`), and a finished fit gets the statistics of a
//! least-squares estimate: the residuals per observed name and the parameters' standard errors
//! from the Jacobian (the inverse Fisher information). No IO: the caller reads the file.

use nalgebra::DMatrix;

use super::target::{Observable, Target};
use crate::sim::SystemInfo;

/// The most measurements a data file may hold (one target, one residual and one Jacobian row
/// each: 10^6 measurements of 10 free parameters are 80 MB of Jacobian).
pub const MAX_OBSERVATIONS: usize = 1_000_000;

/// A data file that cannot be read as measurements of the model.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DataError {
    /// No line at all.
    #[error("{file}: the file is empty; expected a header line with a `time` column")]
    Empty {
        /// The file's name, as messages give it.
        file: String,
    },
    /// No `time` column.
    #[error("{file}:1: no `time` column in the header (columns: {columns})")]
    NoTime {
        /// The file's name, as messages give it.
        file: String,
        /// The columns there are.
        columns: String,
    },
    /// A column that is no output or state of the model.
    #[error("{file}:1: column `{name}` is not an output or a state of the model{hint} (outputs: {outputs}; states: {states})")]
    UnknownColumn {
        /// The file's name, as messages give it.
        file: String,
        /// The column's name.
        name: String,
        /// ` (did you mean ..?)`, or empty.
        hint: String,
        /// The model's outputs.
        outputs: String,
        /// The model's states.
        states: String,
    },
    /// A column named twice.
    #[error("{file}:1: column `{name}` appears twice")]
    Repeated {
        /// The file's name, as messages give it.
        file: String,
        /// The column's name.
        name: String,
    },
    /// A `sigma_NAME` column without its `NAME` column.
    #[error("{file}:1: `sigma_{name}` has no column `{name}` to weigh")]
    LoneSigma {
        /// The file's name, as messages give it.
        file: String,
        /// The name it would weigh.
        name: String,
    },
    /// A row with another number of cells than the header.
    #[error("{file}:{line}: expected {expected} cells as in the header, found {found}")]
    Cells {
        /// The file's name, as messages give it.
        file: String,
        /// The line (1-based, the header line 1).
        line: usize,
        /// The header's cells.
        expected: usize,
        /// The row's.
        found: usize,
    },
    /// A cell that is not a finite number.
    #[error("{file}:{line}: column `{column}`: `{text}` is not a finite number")]
    NotANumber {
        /// The file's name, as messages give it.
        file: String,
        /// The line (1-based, the header line 1).
        line: usize,
        /// The column's name.
        column: String,
        /// The cell as written.
        text: String,
    },
    /// A standard deviation that is not positive.
    #[error("{file}:{line}: column `{column}`: a standard deviation must be positive, found {text}")]
    BadSigma {
        /// The file's name, as messages give it.
        file: String,
        /// The line (1-based, the header line 1).
        line: usize,
        /// The column's name.
        column: String,
        /// The cell as written.
        text: String,
    },
    /// A row without its time.
    #[error("{file}:{line}: a row needs its time")]
    NoTimeValue {
        /// The file's name, as messages give it.
        file: String,
        /// The line (1-based, the header line 1).
        line: usize,
    },
    /// More measurements than `MAX_FIT_TARGETS`-like caps allow.
    #[error("{file}: more than {cap} measurements")]
    TooMany {
        /// The file's name, as messages give it.
        file: String,
        /// The most a fit takes.
        cap: usize,
    },
    /// A measurement's time outside the run's span: no run reaches it.
    #[error("{file}:{line}: time {t} is {side} = {bound}: the run goes from t_start = {t_start} to t_end = {t_end}")]
    TimeOutside {
        /// The file's name, as messages give it.
        file: String,
        /// The line (1-based, the header line 1).
        line: usize,
        /// The time.
        t: f64,
        /// `before t_start` or `after t_end`.
        side: &'static str,
        /// The end it is past.
        bound: f64,
        /// The run's start.
        t_start: f64,
        /// The run's end.
        t_end: f64,
    },
    /// A file whose value cells are all empty.
    #[error("{file}: no measurements (every value cell is empty)")]
    Nothing {
        /// The file's name, as messages give it.
        file: String,
    },
}

/// The measurements of `text` (a CSV file's contents, named `file` in messages) as targets: a
/// `time` column, one column per observed output or state, optional `sigma_NAME` columns (the
/// measurement's standard deviation: the weight is `1 / sigma`; 1 without). An empty cell is a
/// missing value. Cells are separated by commas; surrounding spaces are ignored.
/// Measurements read from a data file: one observed target per value cell.
#[derive(Clone, Debug)]
pub struct Data {
    /// One target per value cell: `NAME@TIME=VALUE`, weighted by `1 / sigma`.
    pub targets: Vec<Target>,
    /// Whether every value column has its `sigma_` column: the weighted residuals are then in
    /// units of the measurements' standard deviations (see [`standard_errors`]).
    pub sigma_known: bool,
}

/// The measurements of `text` (a CSV file's contents, named `file` in messages) as targets:
/// see [`Data`]; refused with the line and column at fault. Every time must lie within the run's
/// span `(t_start, t_end)`. A leading UTF-8 byte-order mark (as spreadsheets write one) is not
/// part of the first column's name; any other invisible character in a name is shown as
/// `<U+XXXX>` in the messages.
pub fn parse_data(text: &str, file: &str, info: &SystemInfo, span: (f64, f64)) -> Result<Data, DataError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let Some((_, header)) = lines.next() else {
        return Err(DataError::Empty { file: file.to_string() });
    };
    let columns: Vec<&str> = header.split(',').map(str::trim).collect();
    let time = columns
        .iter()
        .position(|c| *c == "time")
        .ok_or_else(|| DataError::NoTime { file: file.to_string(), columns: shown(&columns.join(", ")) })?;
    // Per column: what it holds.
    enum Column {
        Time,
        Value { output: bool, index: usize, sigma: Option<usize> },
        Sigma,
    }
    let mut kinds: Vec<Column> = Vec::with_capacity(columns.len());
    for (c, name) in columns.iter().enumerate() {
        if columns[..c].contains(name) {
            return Err(DataError::Repeated { file: file.to_string(), name: shown(name) });
        }
        if c == time {
            kinds.push(Column::Time);
        } else if let Some(of) = name.strip_prefix("sigma_") {
            if !columns.contains(&of) {
                return Err(DataError::LoneSigma { file: file.to_string(), name: shown(of) });
            }
            kinds.push(Column::Sigma);
        } else {
            let (output, index) = match Observable::parse(name, info) {
                Ok(Observable::Output(i)) => (true, i),
                Ok(Observable::State(i)) => (false, i),
                _ => return Err(unknown(file, name, info)),
            };
            let sigma = columns.iter().position(|c| c.strip_prefix("sigma_") == Some(name));
            kinds.push(Column::Value { output, index, sigma });
        }
    }
    let number = |line: usize, column: &str, cell: &str| -> Result<f64, DataError> {
        crate::number::parse_number(cell).map_err(|_| DataError::NotANumber {
            file: file.to_string(),
            line,
            column: column.to_string(),
            text: cell.to_string(),
        })
    };
    let mut targets = Vec::new();
    for (index, row) in lines {
        let line = index + 1;
        let cells: Vec<&str> = row.split(',').map(str::trim).collect();
        if cells.len() != columns.len() {
            return Err(DataError::Cells {
                file: file.to_string(),
                line,
                expected: columns.len(),
                found: cells.len(),
            });
        }
        if cells[time].is_empty() {
            return Err(DataError::NoTimeValue { file: file.to_string(), line });
        }
        let t = number(line, "time", cells[time])?;
        let (t_start, t_end) = span;
        if t < t_start || t > t_end {
            let (side, bound) =
                if t < t_start { ("before t_start", t_start) } else { ("after t_end", t_end) };
            return Err(DataError::TimeOutside {
                file: file.to_string(),
                line,
                t,
                side,
                bound,
                t_start,
                t_end,
            });
        }
        for (c, kind) in kinds.iter().enumerate() {
            let Column::Value { output, index, sigma } = *kind else { continue };
            if cells[c].is_empty() {
                continue;
            }
            let value = number(line, columns[c], cells[c])?;
            let weight = match sigma.map(|s| (s, cells[s])) {
                None | Some((_, "")) => 1.0,
                Some((s, text)) => {
                    let sd = number(line, columns[s], text)?;
                    if sd <= 0.0 {
                        let (file, column, text) =
                            (file.to_string(), columns[s].to_string(), text.to_string());
                        return Err(DataError::BadSigma { file, line, column, text });
                    }
                    1.0 / sd
                }
            };
            if targets.len() == MAX_OBSERVATIONS {
                return Err(DataError::TooMany { file: file.to_string(), cap: MAX_OBSERVATIONS });
            }
            let observable = Observable::At { output, index, time: t };
            targets.push(Target { observable, value, weight, observed: true });
        }
    }
    if targets.is_empty() {
        return Err(DataError::Nothing { file: file.to_string() });
    }
    let sigma_known = kinds.iter().all(|k| !matches!(k, Column::Value { sigma: None, .. }));
    Ok(Data { targets, sigma_known })
}

/// `text` with every character a terminal would not show as itself written `<U+XXXX>`.
fn shown(text: &str) -> String {
    use crate::syntax::chars::{escaped, is_invisible};
    text.chars().map(|c| if is_invisible(c) { escaped(c) } else { c.to_string() }).collect()
}

fn unknown(file: &str, name: &str, info: &SystemInfo) -> DataError {
    let outputs: Vec<&str> = info.output_names.iter().map(String::as_str).collect();
    let states: Vec<&str> = info.state_names.iter().map(String::as_str).collect();
    let hint = crate::sema::closest_name(name, outputs.iter().chain(&states).copied())
        .map(|s| format!(" (did you mean `{s}`?)"))
        .unwrap_or_default();
    let list = |v: &[&str]| if v.is_empty() { "none".to_string() } else { v.join(", ") };
    DataError::UnknownColumn {
        file: file.to_string(),
        name: shown(name),
        hint,
        outputs: list(&outputs),
        states: list(&states),
    }
}

/// The standard error of each free parameter at a least-squares estimate with the weighted
/// Jacobian `jacobian` (observations x free) and residuals `residuals`: the square roots of the
/// diagonal of `s^2 (J^T J)^-1`. With measured standard deviations (`sigma_known`) the weighted
/// residuals are in units of them and `s^2 = 1`; without, `s^2` is the residual variance
/// `sum r^2 / (N - P)`. `None` where `J^T J` is singular or there are no more observations than
/// parameters.
pub fn standard_errors(jacobian: &DMatrix<f64>, residuals: &[f64], sigma_known: bool) -> Option<Vec<f64>> {
    let (n, p) = jacobian.shape();
    if n <= p {
        return None;
    }
    let fisher = jacobian.transpose() * jacobian;
    let covariance = fisher.try_inverse()?;
    let s2 = if sigma_known { 1.0 } else { residuals.iter().map(|r| r * r).sum::<f64>() / (n - p) as f64 };
    let se: Vec<f64> = (0..p).map(|j| (s2 * covariance[(j, j)]).sqrt()).collect();
    se.iter().all(|v| v.is_finite()).then_some(se)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_straight_line_has_the_textbook_standard_errors() {
        // y = a + b x at x = 0, 1, 2, 3 with residuals r: the slope's variance is s^2 / Sxx with
        // Sxx = 5 and s^2 = sum r^2 / 2; the intercept's s^2 (1/4 + 2.25 / 5).
        let j = DMatrix::from_row_slice(4, 2, &[1.0, 0.0, 1.0, 1.0, 1.0, 2.0, 1.0, 3.0]);
        let r = [0.1, -0.2, 0.15, -0.05];
        let s2 = r.iter().map(|v| v * v).sum::<f64>() / 2.0;
        let se = standard_errors(&j, &r, false).unwrap();
        assert!((se[1] - (s2 / 5.0).sqrt()).abs() < 1e-15);
        assert!((se[0] - (s2 * (0.25 + 2.25 / 5.0)).sqrt()).abs() < 1e-15);
        // Known sigmas: s^2 = 1. Too few observations, or a singular J^T J: none.
        assert!((standard_errors(&j, &r, true).unwrap()[1] - (1.0f64 / 5.0).sqrt()).abs() < 1e-15);
        assert!(
            standard_errors(&DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 1.0]), &r[..2], false).is_none()
        );
        assert!(standard_errors(
            &DMatrix::from_row_slice(3, 2, &[1.0, 2.0, 1.0, 2.0, 1.0, 2.0]),
            &r[..3],
            false
        )
        .is_none());
    }
}
