//! Stage 5 (sim): the samples of `SimOptions::at` once a run is over: the times it did not reach,
//! and which samples sit on or near an event instant. Reads the run's records only.

use super::result::{EventRecord, Sample};

/// Completes the samples taken (`taken`, in time order, a prefix of `at`): the times after the
/// run's stop get a sample that says so (values NaN, no derivatives), and each sample notes
/// whether it is at an event instant (taken after it) and the nearest event within whose time
/// resolution it lies. `shape` is (states, differentiated parameters, outputs).
pub(crate) fn complete(
    taken: &mut Vec<Sample>,
    at: &[f64],
    events: &[EventRecord],
    shape: (usize, usize, usize),
) {
    let (n, _, k) = shape;
    for &time in &at[taken.len().min(at.len())..] {
        taken.push(Sample {
            time,
            reached: false,
            mode: 0,
            state: vec![f64::NAN; n],
            dstate: None,
            outputs: vec![f64::NAN; k],
            doutputs: None,
            after_events: false,
            near_event: None,
        });
    }
    // Both lists are in time order: one pass with a window of the events near each sample.
    let mut first = 0;
    for sample in taken.iter_mut().filter(|s| s.reached) {
        let t = sample.time;
        // Events are in time order: skip those whose resolution ends before `t`, stop at the
        // first whose resolution starts after it.
        while first < events.len() && events[first].time + events[first].resolution < t {
            first += 1;
        }
        let mut nearest: Option<(usize, f64)> = None;
        for (index, e) in events.iter().enumerate().skip(first) {
            let gap = (e.time - t).abs();
            if e.time - e.resolution > t {
                break;
            }
            if e.time == t {
                sample.after_events = true;
            }
            if (gap <= e.resolution.max(0.0) || e.time == t) && nearest.is_none_or(|(_, g)| gap < g) {
                nearest = Some((index, gap));
            }
        }
        sample.near_event = nearest.map(|(index, _)| index);
    }
}
