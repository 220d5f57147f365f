//! Stage 5 (sim): breakpoints, the times the integrator lands on exactly: a step that would pass
//! one is clipped to end on it. `t_end` is always the last; time events join it, and each mode's
//! input knots (`pwl`, `pwc`), which are breakpoints of that mode only: a queue per mode, in time
//! order, that the run passes through once (a control of 10,000 knots costs a cursor, not a
//! search). Also what a run's result says of events on or near breakpoints (a cusp at `t_end`,
//! derivatives that hold only on one side). Knows nothing of models' functions or methods.

use std::sync::Arc;

use super::result::{EventRecord, SimWarning};
use super::system::{GuardShape, SystemInfo};

/// Sorted times to land on, consumed in order as the run passes them.
#[derive(Clone, Debug, Default)]
pub(crate) struct Breakpoints {
    times: Vec<f64>,
    next: usize,
    /// Per mode: its input knots as `(time, knot set)`, in time order, and the first one the
    /// run has not passed.
    knots: Vec<Vec<(f64, u32)>>,
    knot_next: Vec<usize>,
}

impl Breakpoints {
    /// Starts a run in a system of `modes` modes: forgets the times of an earlier run and lands
    /// on `t_end` last.
    pub fn reset(&mut self, t_end: f64, modes: usize) {
        self.times.clear();
        self.times.push(t_end);
        self.next = 0;
        self.knots.resize_with(modes, Vec::new);
        self.knots.iter_mut().for_each(Vec::clear);
        self.knot_next.clear();
        self.knot_next.resize(modes, 0);
    }

    /// Adds a time to land on (before `sort`).
    pub fn add(&mut self, t: f64) {
        self.times.push(t);
    }

    /// Adds a knot of knot set `set` at `t`, a breakpoint of `mode` (before `sort`).
    pub fn add_knot(&mut self, mode: usize, t: f64, set: u32) {
        self.knots[mode].push((t, set));
    }

    /// Orders the times after the last `add`.
    pub fn sort(&mut self) {
        self.times.sort_by(f64::total_cmp);
        self.times.dedup();
        for knots in &mut self.knots {
            knots.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        }
    }

    /// The first breakpoint of `mode` strictly after `t` (`t_end` itself when `t` is at or past
    /// it). The ones at or before `t` are consumed.
    pub fn next_after(&mut self, t: f64, mode: usize) -> f64 {
        while self.next + 1 < self.times.len() && self.times[self.next] <= t {
            self.next += 1;
        }
        let time = self.times[self.next];
        match self.knot_after(t, mode) {
            Some(knot) => knot.min(time),
            None => time,
        }
    }

    /// The first breakpoint of `mode` strictly after `t`, as [`Self::next_after`] but consuming
    /// nothing: a step that ends at `t` has not crossed the knots there yet.
    pub fn peek_after(&self, t: f64, mode: usize) -> f64 {
        let later = |times: &[f64]| times.iter().copied().find(|&b| b > t);
        let time = later(&self.times[self.next..]).unwrap_or(self.times[self.times.len() - 1]);
        let knot = match (self.knots.get(mode), self.knot_next.get(mode)) {
            (Some(knots), Some(&next)) => knots[next..].iter().map(|k| k.0).find(|&k| k > t),
            _ => None,
        };
        knot.map_or(time, |k| k.min(time))
    }

    /// The first knot of `mode` strictly after `t`; the ones at or before `t` are consumed.
    pub fn knot_after(&mut self, t: f64, mode: usize) -> Option<f64> {
        let (knots, next) = (self.knots.get(mode)?, self.knot_next.get_mut(mode)?);
        while *next < knots.len() && knots[*next].0 <= t {
            *next += 1;
        }
        knots.get(*next).map(|k| k.0)
    }

    /// The knots of `mode` at `t` exactly, `(time, knot set)`, not consumed (the ones before `t`
    /// are).
    pub fn knots_at(&mut self, t: f64, mode: usize) -> &[(f64, u32)] {
        let (Some(knots), Some(next)) = (self.knots.get(mode), self.knot_next.get_mut(mode)) else {
            return &[];
        };
        while *next < knots.len() && knots[*next].0 < t {
            *next += 1;
        }
        let count = knots[*next..].iter().take_while(|k| k.0 == t).count();
        &knots[*next..*next + count]
    }
}

/// Events this close to a breakpoint, relative to `max(|t|, 1)`, are flagged: their derivatives
/// hold only while parameter changes keep them on their side of it.
const NEAR_BREAKPOINT: f64 = 1e-9;

/// Whether `t` is on the breakpoint `at` to round-off (16 spacings of `t`, as the guards'
/// round-off of rule 11: an event at `t_end` is located a few spacings before it when round-off
/// in the state puts the guard across early): there the event is on the breakpoint itself, a cusp.
pub(crate) fn on_breakpoint(t: f64, at: f64) -> bool {
    (at - t).abs() <= 16.0 * super::spacing(at)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn knots_are_a_queue_per_mode_and_a_step_ending_on_one_leaves_it_to_be_crossed() {
        let mut b = Breakpoints::default();
        b.reset(10.0, 2);
        b.add(5.0);
        for (t, set) in [(3.0, 0), (1.0, 0), (2.0, 1), (2.0, 0)] {
            b.add_knot(0, t, set);
        }
        b.add_knot(1, 4.0, 2);
        b.sort();
        // Each mode sees its own knots among the shared times.
        assert_eq!(b.next_after(0.0, 0), 1.0);
        assert_eq!(b.next_after(0.0, 1), 4.0);
        // A step that ended on the knot at 1 has not crossed it: looking ahead consumes nothing.
        assert_eq!(b.peek_after(1.0, 0), 2.0);
        assert_eq!(b.knots_at(1.0, 0), &[(1.0, 0)]);
        // The next step from 1 passes it; two knot sets at one time are met together.
        assert_eq!(b.next_after(1.0, 0), 2.0);
        assert_eq!(b.knots_at(2.0, 0), &[(2.0, 0), (2.0, 1)]);
        assert_eq!(b.next_after(3.0, 0), 5.0);
        assert!(b.knots_at(3.5, 0).is_empty());
        assert_eq!(b.next_after(5.0, 0), 10.0);
        assert_eq!(b.next_after(12.0, 1), 10.0);
    }
}
