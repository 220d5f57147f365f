//! `hybc run --at TIMES [--samples-out FILE.csv]`: the values of every output and state with their
//! derivatives at given times, from the dense output (`SimOptions::at`, `SimResult::samples`).
//! Parses the times and writes the samples as CSV; the table and the JSON `samples` field are the
//! report's.
//!
//! CSV columns: time, reached, after_events, near_event (the index of an event within whose time
//! resolution the sample lies, or empty), the outputs, the states, then with gradients
//! `d<output>/d<param>` and `d<state>/d<param>`.

use std::io::{self, Write};
use std::path::Path;

use crate::report::RunReport;
use crate::sim::MAX_SAMPLED_ROWS;
use crate::sweep::points::linspace;

/// Parses `--at`: `LO:HI:N` (N >= 2 evenly spaced times, both ends included) or `T1,T2,...`
/// (ascending). At most `MAX_SAMPLED_ROWS` times; their order and range are checked with the run's
/// options.
pub(crate) fn parse_at(text: &str) -> Result<Vec<f64>, String> {
    let bad = |what: &str| {
        format!("--at `{text}`: {what}; expected LO:HI:N (N >= 2 evenly spaced times) or T1,T2,...")
    };
    let number = |s: &str| {
        crate::number::parse_number(s.trim())
            .map_err(|_| bad(&format!("`{}` is not a finite number", s.trim())))
    };
    let parts: Vec<&str> = text.split(':').collect();
    match parts.as_slice() {
        [lo, hi, n] => {
            let (lo, hi) = (number(lo)?, number(hi)?);
            let n: usize = n.trim().parse().map_err(|_| bad("N is not a whole number"))?;
            if n < 2 || n as f64 > MAX_SAMPLED_ROWS {
                return Err(bad(&format!("N must be from 2 to {MAX_SAMPLED_ROWS:.0}")));
            }
            if lo >= hi {
                return Err(bad("LO must be below HI"));
            }
            Ok(linspace(lo, hi, n))
        }
        [list] => {
            let times = list.split(',').map(number).collect::<Result<Vec<f64>, String>>()?;
            if times.len() as f64 > MAX_SAMPLED_ROWS {
                return Err(bad(&format!("at most {MAX_SAMPLED_ROWS:.0} times")));
            }
            Ok(times)
        }
        _ => Err(bad("a range needs its count")),
    }
}

/// Writes the report's samples to `path` as CSV (`-`: standard output).
pub(crate) fn write_csv(path: &Path, report: &RunReport) -> Result<(), String> {
    let fail = |e: io::Error| format!("--samples-out: cannot write `{}`: {e}", path.display());
    let mut out = super::output::create(path).map_err(fail)?;
    super::output::closed_pipe_is_done(path, write_rows(&mut out, report)).map_err(fail)
}

fn write_rows(out: &mut dyn Write, report: &RunReport) -> io::Result<()> {
    let info = report.info();
    let grad: Vec<&str> = info.grad_params.iter().map(|&j| info.param_names[j].as_str()).collect();
    let names: Vec<&String> = info.output_names.iter().chain(&info.state_names).collect();
    let mut head = vec!["time".to_string(), "reached".into(), "after_events".into(), "near_event".into()];
    head.extend(names.iter().map(|n| n.to_string()));
    for p in &grad {
        head.extend(names.iter().map(|n| format!("d{n}/d{p}")));
    }
    writeln!(out, "{}", head.join(","))?;
    let (k, n) = (info.n_outputs(), info.n_states());
    for s in report.result().samples.iter() {
        let mut row = vec![
            format!("{:e}", s.time),
            s.reached.to_string(),
            s.after_events.to_string(),
            s.near_event.map(|e| e.to_string()).unwrap_or_default(),
        ];
        row.extend(s.outputs.iter().chain(s.state).map(|v| value(*v)));
        for j in 0..grad.len() {
            let d = |a: Option<&[f64]>, len: usize, i: usize| a.map_or(f64::NAN, |a| a[j * len + i]);
            row.extend((0..k).map(|i| value(d(s.doutputs, k, i))));
            row.extend((0..n).map(|i| value(d(s.dstate, n, i))));
        }
        writeln!(out, "{}", row.join(","))?;
    }
    out.flush()
}

/// A value as a CSV cell: shortest round-trip form, empty where it does not exist (NaN).
fn value(v: f64) -> String {
    if v.is_nan() {
        String::new()
    } else {
        format!("{v:e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_come_as_a_range_with_a_count_or_a_list() {
        assert_eq!(parse_at("0:1:5").unwrap(), vec![0.0, 0.25, 0.5, 0.75, 1.0]);
        assert_eq!(parse_at("0.1, 0.2,3").unwrap(), vec![0.1, 0.2, 3.0]);
        for bad in ["0:1", "0:1:1", "1:0:3", "0:1:x", "a,b", "0:1:2:3", "0:1:2000001"] {
            let e = parse_at(bad).unwrap_err();
            assert!(e.starts_with(&format!("--at `{bad}`")), "{e}");
        }
    }
}
