//! Gradient check: the event sequence of the nominal run against a re-run at a tenth of the
//! tolerances with capped steps. Differences of the same detector at the same steps cannot see a
//! crossing the detector missed or invented; a run with other steps can. Knows `sim` results and
//! options; does not run anything itself.

use serde::Serialize;

use crate::report::num;
use crate::sim::{EventRecord, SimOptions, SimResult, StopReason, SystemInfo};

/// The re-run's tolerances are the run's divided by this.
pub const TIGHTER: f64 = 10.0;

/// The re-run takes at most this many steps' worth of the span per step:
/// `h_max = span / 10_000`. Every guard is then looked at, at each step's end and at its interior
/// samples, at least ten thousand times over the run, whatever sizes the error control would
/// allow. Why so many: where the solution is a low-degree polynomial the error control takes
/// steps as long as the cap, and a guard that crosses twice within one step shows no sign change;
/// with `span / 100` a run of 100 s re-ran with 1 s steps and missed, as the run did, the three
/// crossings 0.1 s apart of `x = (t - 1)(t - 1.1)(t - 1.2)` (the check passed a run that found 1
/// of 3 events). Crossings closer than about `span / 10_000` can still be missed by both runs.
pub const STEPS_PER_SPAN: f64 = 10_000.0;

/// The outcome of the event-sequence check.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EventCheck {
    /// The re-run's options.
    pub rtol: f64,
    /// The re-run's absolute tolerance.
    pub atol: f64,
    /// The re-run's largest step.
    pub h_max: f64,
    /// Event times that differ by at most this are the same crossing: `sqrt(rtol) * span`.
    pub time_tol: f64,
    /// Events in the run and in the re-run.
    pub events: [usize; 2],
    /// How each ended (`t_end`, a stop event's name, `zeno`, ...).
    pub stopped_by: [String; 2],
    /// How many events were compared (position by position).
    pub compared: usize,
    /// Where the sequences differ: the check then fails.
    pub difference: Option<String>,
    /// What was not compared, and why.
    pub notes: Vec<String>,
}

impl EventCheck {
    /// Whether the two runs' events agree (within `time_tol`), as compared.
    pub fn is_consistent(&self) -> bool {
        self.difference.is_none()
    }
}

/// The options of the re-run: a tenth of the tolerances, steps capped at `span / 10_000` (or the
/// run's own cap if smaller), no trajectory.
pub fn rerun_options(opts: &SimOptions) -> SimOptions {
    let span = (opts.t_end - opts.t_start).abs();
    SimOptions {
        rtol: opts.rtol / TIGHTER,
        atol: opts.atol / TIGHTER,
        h_max: opts.h_max.min(span / STEPS_PER_SPAN),
        ..opts.clone()
    }
}

/// Compares the run's events with the re-run's, position by position: the same event, at times
/// within `time_tol`. Not compared: events from the first grazing crossing on (whether a tangent
/// crossing happens is not decided at any tolerance), and after a run that ended early, the events
/// one run has and the other has not (where a Zeno run stops depends on the tolerances). An extra
/// event within `time_tol` of the end of the runs is noted, not a difference (it is at `t_end`
/// within the integration error).
pub fn compare(
    info: &SystemInfo,
    run: &SimResult,
    rerun: &SimResult,
    opts: &SimOptions,
    rerun_opts: &SimOptions,
) -> EventCheck {
    let span = (opts.t_end - opts.t_start).abs();
    let mut check = EventCheck {
        rtol: rerun_opts.rtol,
        atol: rerun_opts.atol,
        h_max: rerun_opts.h_max,
        time_tol: opts.rtol.sqrt() * span,
        events: [run.events.len(), rerun.events.len()],
        stopped_by: [run.stopped_by.name().to_string(), rerun.stopped_by.name().to_string()],
        compared: 0,
        difference: None,
        notes: Vec::new(),
    };
    let (a, b) = (&run.events, &rerun.events);
    let graze = a.iter().chain(b).filter(|e| e.grazing).map(|e| e.index).min();
    let common = a.len().min(b.len()).min(graze.unwrap_or(usize::MAX));
    for k in 0..common {
        let (x, y) = (&a[k], &b[k]);
        if x.event != y.event {
            check.difference = Some(format!(
                "event #{k} is `{}` at t = {} in the run but `{}` at t = {} in the re-run",
                x.name,
                num(x.time),
                y.name,
                num(y.time)
            ));
            return check;
        }
        if (x.time - y.time).abs() > check.time_tol {
            check.difference = Some(format!(
                "event #{k} (`{}`) is at t = {} in the run but at t = {} in the re-run, {:.1e} apart",
                x.name,
                num(x.time),
                num(y.time),
                (x.time - y.time).abs()
            ));
            return check;
        }
        check.compared += 1;
    }
    if let Some(g) = graze.filter(|&g| g < a.len().max(b.len())) {
        check.notes.push(format!(
            "events from #{g} on follow a grazing crossing and are not compared: whether a tangent \
             crossing happens is not decided at any tolerance"
        ));
        return check;
    }
    if !run.stopped_by.is_complete() {
        check.notes.push(format!(
            "the run ended early ({}): only the events both runs have are compared",
            run.stopped_by.name()
        ));
        return check;
    }
    if !rerun.stopped_by.is_complete() {
        let why = rerun.stopped_by.describe(info, &rerun.events, &rerun.final_state).unwrap_or_default();
        check.difference = Some(format!("the run reached its end but the re-run ended early: {why}"));
        return check;
    }
    let (longer, which) = if a.len() > b.len() { (a, "run") } else { (b, "re-run") };
    let extra = &longer[common..];
    let end = run.final_state.time.max(rerun.final_state.time);
    if extra.iter().all(|e| (e.time - end).abs() <= check.time_tol) {
        if let Some(e) = extra.first() {
            check.notes.push(format!(
                "only the {which} has event `{}` at t = {}, within {:.1e} of the end: not a difference",
                e.name,
                num(e.time),
                check.time_tol
            ));
        }
    } else {
        check.difference = Some(extra_events(a.len(), b.len(), which, extra));
        return check;
    }
    if !same_end(&run.stopped_by, &rerun.stopped_by) && extra.is_empty() {
        check.difference = Some(format!(
            "the run ended by `{}`, the re-run by `{}`",
            check.stopped_by[0], check.stopped_by[1]
        ));
    }
    check
}

fn extra_events(n_run: usize, n_rerun: usize, which: &str, extra: &[EventRecord]) -> String {
    let first = &extra[0];
    format!(
        "the run has {n_run} events, the re-run {n_rerun}: only the {which} has event #{} (`{}` at t = {}){}",
        first.index,
        first.name,
        num(first.time),
        if extra.len() > 1 { format!(" and {} more", extra.len() - 1) } else { String::new() }
    )
}

/// Whether two runs ended the same way (the same kind of stop; the same stop event).
pub(super) fn same_end(a: &StopReason, b: &StopReason) -> bool {
    match (a, b) {
        (StopReason::Event { event: x, .. }, StopReason::Event { event: y, .. }) => x == y,
        _ => std::mem::discriminant(a) == std::mem::discriminant(b),
    }
}
