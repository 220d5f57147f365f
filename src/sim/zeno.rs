//! Stage 5 (sim): Zeno behaviour, events that accumulate: when a run counts as Zeno and where the
//! events accumulate. Reads the run's event record only; knows nothing of steps or guards.

use super::result::{EventRecord, StopReason};

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
    let k = events.len();
    if k < SHRINKING_INTERVALS + 2 {
        return None;
    }
    let shrinking = events[k - SHRINKING_INTERVALS - 2..].windows(3).all(|w| {
        let (d1, d2) = (w[1].time - w[0].time, w[2].time - w[1].time);
        d2 > 0.0 && d2 < d1
    });
    let t_star = accumulation(events)?;
    let last = events[k - 1].time;
    (shrinking && t_star - last <= ACCUMULATION_RESOLUTION * t_star.abs().max(1.0)).then(|| stop(events))
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

/// Geometric extrapolation of the last two inter-event intervals: with ratio `r = d2 / d1 < 1`
/// the remaining intervals sum to `d2 r / (1 - r)`.
pub(crate) fn accumulation(events: &[EventRecord]) -> Option<f64> {
    let k = events.len();
    if k < 3 {
        return None;
    }
    let (ta, tb, tc) = (events[k - 3].time, events[k - 2].time, events[k - 1].time);
    let (d1, d2) = (tb - ta, tc - tb);
    if d1 <= 0.0 || d2 <= 0.0 {
        return Some(tc);
    }
    let r = d2 / d1;
    (r < 1.0).then(|| tc + d2 * r / (1.0 - r))
}
