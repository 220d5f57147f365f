//! Stage 5 (sim): the samples of `SimOptions::at` once a run is over: the times it did not reach,
//! and which samples sit on or near an event instant. Reads the run's records only.

use super::result::{EventRecord, Samples};

/// Completes the samples taken (`taken`, in time order, a prefix of `at`): the times after the
/// run's stop get a sample that says so (values NaN, no derivatives), and each sample notes
/// whether it is at an event instant (taken after it) and the nearest event within whose time
/// resolution it lies.
pub(crate) fn complete(taken: &mut Samples, at: &[f64], events: &[EventRecord]) {
    let reached = taken.len().min(at.len());
    for &time in &at[reached..] {
        taken.push_unreached(time);
    }
    // Both lists are in time order: one pass with a window of the events near each sample.
    let mut first = 0;
    for row in 0..reached {
        let t = taken.times()[row];
        // Events are in time order: skip those whose resolution ends before `t`, stop at the
        // first whose resolution starts after it.
        while first < events.len() && events[first].time + events[first].resolution < t {
            first += 1;
        }
        let mut nearest: Option<(usize, f64)> = None;
        let mut after_events = false;
        for (index, e) in events.iter().enumerate().skip(first) {
            let gap = (e.time - t).abs();
            if e.time - e.resolution > t {
                break;
            }
            if e.time == t {
                after_events = true;
            }
            if (gap <= e.resolution.max(0.0) || e.time == t) && nearest.is_none_or(|(_, g)| gap < g) {
                nearest = Some((index, gap));
            }
        }
        taken.mark(row, after_events, nearest.map(|(index, _)| index));
    }
}
