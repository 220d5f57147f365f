//! Checks of simulation options that every front end shares, so that `hybc run`'s flags and
//! Python's keywords accept the same values with the same words. A front end passes the names it
//! spells an option with (`--t-start` or `t_start`); the rule lives here once.

use crate::sim::SimOptions;

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
}
