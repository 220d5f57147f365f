//! Stage 5 (sim): Zeno behaviour, events that accumulate: when a run counts as Zeno and where the
//! events accumulate (docs/language.md rule 10). Reads the run's event record only; knows nothing
//! of steps or guards.
//!
//! The rule is about the sequence of intervals `d_k` between distinct instants, not about a
//! window of `t`: events accumulate when the `d_k` shrink summably. A finite record cannot prove
//! that, so the run follows the sequence until what is left of it is below the accuracy of the
//! event times (the remaining sum, estimated from the fitted decay, cannot hold an event that
//! could be told apart from the accumulation point), or until `max_events`, where the record is
//! judged: Zeno when its decay is summable (geometric, or like `k^-p` with `p` at least
//! [`SUMMABLE_EXPONENT`]), `max_events` otherwise.
//!
//! Why a fit with an offset: a decay like `C (k + k0)^-p` has ratios `d_{k+1} / d_k` that tend
//! to 1, so the geometric extrapolation of the last intervals underestimates what is left by a
//! factor `(p - 1) / p` and never decides; the offset `k0` (how many events came before the
//! sequence took its shape) is unknown, so it is fitted too, from three intervals a lag apart.

use crate::sim::result::{Accumulation, Decay, EventRecord, StopReason};

/// Intervals between the last events that must each shrink before accumulation is judged.
const SHRINKING_INTERVALS: usize = 10;
/// The smallest decay exponent judged summable: `k^-1` (which never accumulates) fits as 1.0,
/// `k^-2` as 2.0; between them a record of 10,000 events cannot tell slow accumulation from
/// none.
pub(crate) const SUMMABLE_EXPONENT: f64 = 1.5;
/// The intervals of a judged record must shrink at least this much over the fit's span: constant
/// intervals with round-off in them are not a decay.
const MIN_SHRINK: f64 = 2.0;
/// Spacings of `t` below which two instants are not told apart (as the guards' round-off of rule
/// 11): the floor of the event times' accuracy.
const TIME_SPACINGS: f64 = 16.0;

/// Watches the event record for accumulation as events fire. The cheap test (the last
/// [`SHRINKING_INTERVALS`] intervals shrink, and their geometric tail is below the events'
/// accuracy) runs at every round of events; the fit that confirms it reads the whole shrinking
/// run, so after a fit that does not confirm, the next waits until the record has doubled
/// (linear work in all).
#[derive(Debug, Default)]
pub(crate) struct Watch {
    next_fit: usize,
}

impl Watch {
    /// After a round of events: the Zeno stop when the events accumulate beyond resolution.
    pub(crate) fn accumulating(&mut self, events: &[EventRecord]) -> Option<StopReason> {
        let mut instants = [0.0; SHRINKING_INTERVALS + 2];
        if last_instants(events, &mut instants) < instants.len() {
            return None;
        }
        let shrinking = instants.windows(3).all(|w| {
            let (d1, d2) = (w[1] - w[0], w[2] - w[1]);
            d2 > 0.0 && d2 < d1
        });
        if !shrinking {
            return None;
        }
        let last = instants[instants.len() - 1];
        let d_last = last - instants[instants.len() - 2];
        let d_first = instants[1] - instants[0];
        let r = (d_last / d_first).powf(1.0 / (SHRINKING_INTERVALS as f64));
        let accuracy = accuracy_at_last(events);
        if d_last * r / (1.0 - r) > accuracy || events.len() < self.next_fit {
            return None;
        }
        let fit = fit(&distinct_instants(events));
        match fit {
            Some(f) if f.estimate - last <= accuracy => Some(zeno_stop(events, Some(f))),
            _ => {
                self.next_fit = 2 * events.len();
                None
            }
        }
    }
}

/// The stop at `max_events`: Zeno when the record's intervals shrink summably (with the
/// accumulation point estimated), `MaxEvents` otherwise.
pub(crate) fn at_max_events(events: &[EventRecord], time: f64) -> StopReason {
    match fit(&distinct_instants(events)) {
        Some(f) if f.summable() => zeno_stop(events, Some(f)),
        _ => StopReason::MaxEvents { time, count: events.len() },
    }
}

/// The Zeno stop at the last event when a bounce was too small to resolve, with the accumulation
/// point estimated from the intervals (`TEnd` when nothing fired).
pub(crate) fn stop(events: &[EventRecord]) -> StopReason {
    let instants = distinct_instants(events);
    let fit = fit(&instants).or_else(|| last_two(&instants));
    zeno_stop(events, fit)
}

fn zeno_stop(events: &[EventRecord], accumulation: Option<Accumulation>) -> StopReason {
    match events.last() {
        Some(last) => {
            StopReason::Zeno { time: last.time, event: last.event, count: events.len(), accumulation }
        }
        None => StopReason::TEnd,
    }
}

/// How well the last instant is known: the largest resolution of its events (guard accuracy
/// over crossing speed), at least [`TIME_SPACINGS`] spacings of `t`.
fn accuracy_at_last(events: &[EventRecord]) -> f64 {
    let Some(last) = events.last() else { return 0.0 };
    let t = last.time.abs();
    let floor = TIME_SPACINGS * (t.next_up() - t);
    events.iter().rev().take_while(|e| e.time == last.time).map(|e| e.resolution).fold(floor, f64::max)
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

/// The distinct instants of the record, in time order.
fn distinct_instants(events: &[EventRecord]) -> Vec<f64> {
    let mut t: Vec<f64> = events.iter().map(|e| e.time).collect();
    t.dedup();
    t
}

/// With fewer intervals than a fit needs: the geometric extrapolation of the last two.
fn last_two(instants: &[f64]) -> Option<Accumulation> {
    let [.., t0, t1, t2] = *instants else { return None };
    let (d1, d2) = (t1 - t0, t2 - t1);
    let r = d2 / d1;
    (d2 > 0.0 && r < 1.0).then(|| {
        let estimate = t2 + d2 * r / (1.0 - r);
        Accumulation { estimate, upper: None, decay: Decay::Geometric { ratio: r } }
    })
}

/// The accumulation point of distinct instants `t` (increasing), from the run of shrinking
/// intervals that ends the record (at least [`SHRINKING_INTERVALS`] + 1 of them): the decay law
/// through its last, middle and first intervals gives the estimate; the same fit over the run's
/// last half, when later, the upper end (a bound as long as the decay does not slow down).
pub(crate) fn fit(t: &[f64]) -> Option<Accumulation> {
    let d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    // The run: each interval shorter than the one before, to the round-off of the times.
    let noise = |k: usize| 4.0 * (t[k + 1].abs().next_up() - t[k + 1].abs());
    let mut start = d.len().checked_sub(1)?;
    while start > 0 && d[start] < d[start - 1] + noise(start) {
        start -= 1;
    }
    let run = &d[start..];
    if run.len() <= SHRINKING_INTERVALS {
        return None;
    }
    let last = *t.last()?;
    let (half, shrink) = law(run, (run.len() - 1) / 2)?;
    let quarter = law(run, (run.len() - 1) / 4).map(|(q, _)| q.tail);
    let upper = quarter.filter(|q| q.is_finite()).map(|q| last + q.max(half.tail));
    // Intervals that shrank too little over the span are not judged a decay.
    let decay = if shrink >= MIN_SHRINK { half.decay } else { Decay::Unclear };
    Some(Accumulation { estimate: last + half.tail, upper, decay })
}

struct Law {
    tail: f64,
    decay: Decay,
}

/// The decay law through the intervals `lag` apart at the end of `run` (`d_n`, `d_{n-L}`,
/// `d_{n-2L}`): `C (k + k0)^-p` with the offset and exponent solved from the two ratios (a
/// geometric law when the ratios are equal or the decay speeds up), and the remaining sum after
/// `d_n` (`d_n sum_j (m / (m + j))^p`, `m = n + k0`; infinite for `p <= 1`).
/// Also returns `d_{n-2L} / d_n`, how much the intervals shrank over the span.
fn law(run: &[f64], lag: usize) -> Option<(Law, f64)> {
    if lag == 0 {
        return None;
    }
    let n = run.len() - 1;
    let (dn, dm, df) = (run[n], run[n - lag], run[n - 2 * lag]);
    let (a, b) = ((dm / dn).ln(), (df / dm).ln());
    if !(dn > 0.0 && a > 0.0 && b > 0.0 && a.is_finite() && b.is_finite()) {
        return None;
    }
    let shrink = df / dn;
    let lag_f = lag as f64;
    let q = b / a;
    if q <= 1.0 {
        let ratio = (-a / lag_f).exp();
        return Some((Law { tail: dn * ratio / (1.0 - ratio), decay: Decay::Geometric { ratio } }, shrink));
    }
    // phi(x) = ln((1 - x) / (1 - 2x)) / -ln(1 - x), x = L / m in (0, 1/2): rises from 1 to
    // infinity; bisect for phi(x) = q.
    let phi = |x: f64| ((-x).ln_1p() - (-2.0 * x).ln_1p()) / -(-x).ln_1p();
    let (mut lo, mut hi) = (0.0f64, 0.5f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if phi(mid) < q {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    // An offset a thousand lags back bends the log-intervals by less than their round-off over
    // the span: the law is geometric as far as the record can tell.
    let x = 0.5 * (lo + hi);
    if x <= 1e-3 {
        let ratio = (-a / lag_f).exp();
        return Some((Law { tail: dn * ratio / (1.0 - ratio), decay: Decay::Geometric { ratio } }, shrink));
    }
    let m = lag_f / x;
    let p = a / -(-x).ln_1p();
    let tail = if p > 1.0 { dn * power_tail(m, p) } else { f64::INFINITY };
    Some((Law { tail, decay: Decay::Power { exponent: p } }, shrink))
}

/// `sum_{j >= 1} (m / (m + j))^p` for `p > 1`: the first terms summed, the rest by
/// Euler-Maclaurin (integral, half the first term, the derivative term), which is then accurate
/// also when the terms fall fast (a geometric-like law, `p / m` not small).
fn power_tail(m: f64, p: f64) -> f64 {
    const SUMMED: usize = 16;
    let f = |j: f64| (-p * (j / m).ln_1p()).exp();
    let explicit: f64 = (1..SUMMED).map(|j| f(j as f64)).sum();
    let j = SUMMED as f64;
    let fj = f(j);
    explicit + (m + j) * fj / (p - 1.0) + 0.5 * fj + p * fj / (12.0 * (m + j))
}

impl Accumulation {
    /// Whether the decay is summable: geometric, or a power of at least [`SUMMABLE_EXPONENT`].
    pub(crate) fn summable(&self) -> bool {
        self.estimate.is_finite()
            && match self.decay {
                Decay::Geometric { ratio } => ratio < 1.0,
                Decay::Power { exponent } => exponent >= SUMMABLE_EXPONENT,
                Decay::Unclear => false,
            }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Instants from intervals `d(k)`, k = 0, 1, ..., starting at `t0`, with the sum of all of
    /// them (the accumulation point) computed far beyond.
    fn instants(t0: f64, count: usize, d: impl Fn(usize) -> f64) -> Vec<f64> {
        let mut t = vec![t0];
        for k in 0..count {
            let next = t[k] + d(k);
            t.push(next);
        }
        t
    }

    #[test]
    fn a_geometric_sequence_is_summable_with_its_exact_accumulation_point() {
        for (t0, r) in [(0.0, 0.5), (0.0, 0.8), (1e6, 0.9), (-3.0, 0.95)] {
            // Down to intervals far above the spacing of t.
            let smallest: f64 = if t0 == 0.0 { 1e-9 } else { 1e-4 };
            let count = (smallest.ln() / f64::ln(r)) as usize;
            let t = instants(t0, count, |k| 0.3 * f64::powi(r, k as i32));
            let f = fit(&t).expect("a fit");
            assert!(f.summable(), "{f:?}");
            let t_star = t0 + 0.3 / (1.0 - r);
            let scale = t_star.abs().max(1.0);
            assert!((f.estimate - t_star).abs() < 1e-12 * scale, "r = {r}: {} vs {t_star}", f.estimate);
            let Decay::Geometric { ratio } = f.decay else { panic!("{f:?}") };
            assert!((ratio - r).abs() < 1e-6, "{ratio} vs {r}");
        }
    }

    #[test]
    fn power_law_intervals_are_summable_above_exponent_one_and_estimate_their_sum() {
        // d_k = (k + k0)^-p: the sum after n is the Hurwitz zeta tail, here summed directly.
        for (p, k0) in [(2.0, 0.0), (2.0, 40.0), (3.0, 5.0), (1.6, 10.0)] {
            let d = |k: usize| (k as f64 + 1.0 + k0).powf(-p);
            let n = 4000;
            let t = instants(0.0, n, d);
            // Beyond N, Euler-Maclaurin: the integral plus half the first term.
            let big = 1_000_000;
            let far = (big as f64 + 1.0 + k0).powf(1.0 - p) / (p - 1.0) + 0.5 * d(big);
            let tail: f64 = (n..big).map(d).sum::<f64>() + far;
            let t_star = t[n] + tail;
            let f = fit(&t).expect("a fit");
            assert!(f.summable(), "p = {p}: {f:?}");
            let Decay::Power { exponent } = f.decay else { panic!("{f:?}") };
            assert!((exponent - p).abs() < 0.02, "p = {p}: fitted {exponent}");
            // Within a hundredth of what was left, and the upper end no earlier than the truth
            // less that hundredth.
            assert!(
                (f.estimate - t_star).abs() < 0.01 * tail,
                "p = {p}: {} vs {t_star} (tail {tail})",
                f.estimate
            );
            assert!(f.upper.expect("an upper end") >= t_star - 0.01 * tail, "{f:?}");
        }
    }

    #[test]
    fn slow_and_constant_intervals_are_not_summable() {
        // 1/k never accumulates, nor does 1/sqrt(k) (a chirp), nor constant intervals with
        // round-off, nor intervals that halve and then settle.
        let harmonic = instants(0.0, 10_000, |k| 1.0 / (k as f64 + 3.0));
        let chirp = instants(0.0, 10_000, |k| 1.0 / (k as f64 + 1.0).sqrt());
        let constant = instants(1e6, 10_000, |k| 2.44e-6 * (1.0 + 1e-9 * ((k * 7919) % 13) as f64));
        let settling = instants(1e6, 10_000, |k| 0.01 * 0.5f64.powi(k.min(12) as i32));
        for (name, t) in
            [("1/k", harmonic), ("1/sqrt(k)", chirp), ("constant", constant), ("settling", settling)]
        {
            assert!(!fit(&t).is_some_and(|f| f.summable()), "{name}: {:?}", fit(&t));
        }
    }
}
