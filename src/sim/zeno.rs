//! Stage 5 (sim): Zeno behaviour, events that accumulate: when a run counts as Zeno and where the
//! events accumulate. Reads the run's event record only; knows nothing of steps or guards.

use super::options::SimOptions;
use super::result::{EventRecord, StopReason};

/// Zeno: `max_events` in total, or `zeno_events` events inside the window
/// `zeno_window * max(|t_end - t_start|, 1)` ending at the last event.
pub(crate) fn check(events: &[EventRecord], opts: &SimOptions) -> Option<StopReason> {
    let count = events.len();
    let last = events.last()?;
    let span = (opts.t_end - opts.t_start).abs().max(1.0);
    let window = opts.zeno_window * span;
    let in_window = events.iter().rev().take_while(|e| e.time >= last.time - window).count();
    let too_many = count >= opts.max_events;
    let crowded = opts.zeno_events > 0 && in_window >= opts.zeno_events;
    if !(too_many || crowded) {
        return None;
    }
    Some(stop(events))
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
