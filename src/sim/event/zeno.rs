//! Stage 5 (sim): Zeno behaviour, events that accumulate: when a run counts as Zeno and where the
//! events accumulate. Reads the run's event record only; knows nothing of steps or guards.

use crate::sim::result::{EventRecord, StopReason};

/// Intervals between the last events that must each shrink before a run counts as
/// accumulating without a bounce too small to resolve.
const SHRINKING_INTERVALS: usize = 10;
/// Accumulation is reported once the estimated remaining time to the accumulation point is below
/// this fraction of `max(|t*|, 1)`: closer events than that are not told apart from one instant
/// by an f64 time plus the location tolerance.
const ACCUMULATION_RESOLUTION: f64 = 1e-9;

/// Zeno detected from the event times alone: the last [`SHRINKING_INTERVALS`] intervals each
/// shorter than the one before, and the extrapolated accumulation point closer than
/// [`ACCUMULATION_RESOLUTION`] (relative). Events at one instant (a cascade) are not Zeno, nor
/// are many events over a long time (that is `max_events`).
pub(crate) fn accumulating(events: &[EventRecord]) -> Option<StopReason> {
    let mut instants = [0.0; SHRINKING_INTERVALS + 2];
    if last_instants(events, &mut instants) < instants.len() {
        return None;
    }
    let shrinking = instants.windows(3).all(|w| {
        let (d1, d2) = (w[1] - w[0], w[2] - w[1]);
        d2 > 0.0 && d2 < d1
    });
    let t_star = accumulation(events)?;
    let last = instants[instants.len() - 1];
    (shrinking && t_star - last <= ACCUMULATION_RESOLUTION * t_star.abs().max(1.0)).then(|| stop(events))
}

/// Fills `out` with the times of the last `out.len()` distinct instants, in time order (several
/// events at one instant are one instant: a bounce that also counts is still one bounce).
/// Returns how many there were (fewer than `out.len()` leaves the front of `out` unset).
fn last_instants(events: &[EventRecord], out: &mut [f64]) -> usize {
    let mut found = 0;
    let mut previous = f64::NAN;
    for e in events.iter().rev() {
        if found == out.len() {
            break;
        }
        if e.time != previous {
            found += 1;
            out[out.len() - found] = e.time;
            previous = e.time;
        }
    }
    found
}

/// The Zeno stop at the last event, with the accumulation point estimated from the last
/// inter-event intervals (`TEnd` when nothing fired).
pub(crate) fn stop(events: &[EventRecord]) -> StopReason {
    match events.last() {
        Some(last) => StopReason::Zeno {
            time: last.time,
            event: last.event,
            count: events.len(),
            accumulation: accumulation(events),
        },
        None => StopReason::TEnd,
    }
}

/// Geometric extrapolation of the last two intervals between distinct instants: with ratio `r = d2 / d1 < 1`
/// the remaining intervals sum to `d2 r / (1 - r)`.
pub(crate) fn accumulation(events: &[EventRecord]) -> Option<f64> {
    let mut t = [0.0; 3];
    if last_instants(events, &mut t) < 3 {
        return events.last().map(|e| e.time).filter(|_| events.len() >= 3);
    }
    let (d1, d2) = (t[1] - t[0], t[2] - t[1]);
    let r = d2 / d1;
    (r < 1.0).then(|| t[2] + d2 * r / (1.0 - r))
}
