//! Stage 5 (sim): breakpoints, the times the integrator lands on exactly: a step that would pass
//! one is clipped to end on it. `t_end` is always the last; time events and input knots join
//! them. Also what a run's result says of events on or near them (a cusp at `t_end`, derivatives
//! that hold only on one side). Knows nothing of models' functions or methods.

use std::sync::Arc;

use super::result::{EventRecord, SimWarning};
use super::system::{GuardShape, SystemInfo};

/// Sorted times to land on, consumed in order as the run passes them.
#[derive(Clone, Debug, Default)]
pub(crate) struct Breakpoints {
    times: Vec<f64>,
    next: usize,
}

impl Breakpoints {
    /// Starts a run: forgets the times of an earlier run and lands on `t_end` last.
    pub fn reset(&mut self, t_end: f64) {
        self.times.clear();
        self.times.push(t_end);
        self.next = 0;
    }

    /// Adds a time to land on (before `sort`).
    pub fn add(&mut self, t: f64) {
        self.times.push(t);
    }

    /// Orders the times after the last `add`.
    pub fn sort(&mut self) {
        self.times.sort_by(f64::total_cmp);
        self.times.dedup();
    }

    /// The first breakpoint strictly after `t` (`t_end` itself when `t` is at or past it). The
    /// ones at or before `t` are consumed.
    pub fn next_after(&mut self, t: f64) -> f64 {
        while self.next + 1 < self.times.len() && self.times[self.next] <= t {
            self.next += 1;
        }
        self.times[self.next]
    }
}

/// Events this close to a breakpoint, relative to `max(|t|, 1)`, are flagged: their derivatives
/// hold only while parameter changes keep them on their side of it.
const NEAR_BREAKPOINT: f64 = 1e-9;

/// Whether `t` is on the breakpoint `at` to round-off (16 spacings of `t`, as the guards'
/// round-off of rule 11: an event at `t_end` is located a few spacings before it when round-off
/// in the state puts the guard across early): there the event is on the breakpoint itself, a cusp.
pub(crate) fn on_breakpoint(t: f64, at: f64) -> bool {
    (at - t).abs() <= 16.0 * (at.abs().next_up() - at.abs())
}

/// Events within `1e-9 max(|t|, 1)` before `t_end`, or of a time event they are not a time event with: their derivatives
/// hold only while they stay on their side (`SimWarning::NearBreakpoint`). Time events fire on
/// their breakpoint by construction and are not warned about themselves.
pub(crate) fn near_breakpoints(
    info: &SystemInfo,
    events: &[EventRecord],
    t_end: f64,
    warnings: &mut Vec<SimWarning>,
) {
    let near = |a: f64, b: f64| (a - b).abs() <= NEAR_BREAKPOINT * a.abs().max(b.abs()).max(1.0);
    let is_time = |e: &EventRecord| info.events[e.event].guard == GuardShape::Time;
    // Only the events near the end or near a time event matter: scan the neighbours in time.
    for (k, e) in events.iter().enumerate() {
        if is_time(e) {
            continue;
        }
        let mut breakpoint: Option<(Arc<str>, f64)> = None;
        if near(e.time, t_end) {
            breakpoint = Some(("t_end".into(), t_end));
        }
        let neighbours = events[k.saturating_sub(8)..(k + 9).min(events.len())].iter();
        // Not one at the very same instant: a cascade from the time event's reset moves with
        // the instant (rule 7), and a group fires in declaration order either way.
        for other in neighbours.filter(|o| is_time(o) && o.time != e.time && near(o.time, e.time)) {
            if breakpoint.is_none() {
                breakpoint = Some((format!("the time event `{}`", other.name).into(), other.time));
            }
        }
        if let Some((name, at)) = breakpoint {
            let margin = if on_breakpoint(e.time, at) { 0.0 } else { (at - e.time).abs() };
            warnings.push(SimWarning::NearBreakpoint {
                event: e.event,
                name: e.name.clone(),
                time: e.time,
                breakpoint: name,
                margin,
            });
        }
    }
}
