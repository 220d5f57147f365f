//! Stage 5 (sim): sampling at given times, beside the recorder: the values (and the outputs'
//! derivatives) at `SimOptions::at` as the run passes them, and the dense-output samples a
//! [`Recorder`] asks for ([`Recorder::next_grid_time`]), both read off the interpolant of the step
//! that passes them or at the current point; once the run is over, the times it did not reach
//! and which samples sit on or near an event instant. The integrator says when (a step's
//! interpolant, an instant's far side, the start, the stop); this file says what is taken.

use super::event::jump::dot_nonzero;
use super::method::stepper::Interpolant;
use super::recorder::{Point, PointKind, Recorder};
use super::result::{EventRecord, Samples};
use super::system::HybridSystem;

/// The output Jacobians `(y_x, y_p, y_t)` at one point (`k * n`, `k * m`, `k`).
pub(crate) type OutputJac = (Vec<f64>, Vec<f64>, Vec<f64>);

/// The samples of one run at `SimOptions::at`, taken as the run passes their times.
pub(crate) struct Sampler<'a, S: HybridSystem + ?Sized> {
    sys: &'a S,
    p: &'a [f64],
    /// The times asked for, ascending; the next one due is `taken.len()`.
    at: &'a [f64],
    taken: Samples,
    /// States, parameters with gradients, outputs.
    shape: (usize, usize, usize),
}

impl<'a, S: HybridSystem + ?Sized> Sampler<'a, S> {
    pub fn new(sys: &'a S, p: &'a [f64], at: &'a [f64]) -> Self {
        let info = sys.info();
        let shape = (info.n_states(), info.n_grad(), info.n_outputs());
        Sampler { sys, p, at, taken: Samples::with_capacity(shape, at.len()), shape }
    }

    /// The next time of `at` not yet taken.
    pub fn next_time(&self) -> Option<f64> {
        self.at.get(self.taken.len()).copied()
    }

    /// How many times of `at` were taken so far (the next row's index).
    pub fn taken(&self) -> usize {
        self.taken.len()
    }

    /// The time of row `row` of `at`.
    pub fn time(&self, row: usize) -> f64 {
        self.at[row]
    }

    /// Whether the next time of `at` is at most `t` (before `t` when `strict`).
    pub fn due(&self, t: f64, strict: bool) -> bool {
        self.at.get(self.taken.len()).is_some_and(|&ts| ts < t || (!strict && ts == t))
    }

    /// Whether `recorder` or `at` wants a sample from the dense output of the step ending at
    /// `t_seg_end`.
    pub fn wanted<R: Recorder>(&self, recorder: &R, t_seg_end: f64) -> bool {
        recorder.next_grid_time().is_some_and(|ts| ts <= t_seg_end) || self.due(t_seg_end, false)
    }

    /// The recorder's samples up to `t_seg_end` from the dense output of the step just attempted
    /// (in `mode`), through the scratch `(outputs, z)`.
    pub fn record_dense<R: Recorder, I: Interpolant>(
        &self,
        recorder: &mut R,
        (outputs, z): &mut (Vec<f64>, Vec<f64>),
        dense: &I,
        mode: usize,
        t_seg_end: f64,
    ) {
        let n = self.shape.0;
        while let Some(ts) = recorder.next_grid_time().filter(|&ts| ts <= t_seg_end) {
            dense.eval(ts, z);
            self.sys.outputs(ts, &z[..n], self.p, outputs);
            let point = Point { kind: PointKind::Grid, t: ts, mode, x: &z[..n], s: &z[n..], outputs };
            recorder.record(&point);
        }
    }

    /// The recorder's samples due at the current point `(t, z)` itself (the start of the run).
    pub fn record_here<R: Recorder>(
        &self,
        recorder: &mut R,
        outputs: &mut [f64],
        t: f64,
        mode: usize,
        z: &[f64],
    ) {
        let n = self.shape.0;
        while let Some(ts) = recorder.next_grid_time().filter(|&ts| ts <= t) {
            self.sys.outputs(ts, &z[..n], self.p, outputs);
            let (x, s) = z.split_at(n);
            let point = Point { kind: PointKind::Grid, t: ts, mode, x, s, outputs };
            recorder.record(&point);
        }
    }

    /// The samples of `at` up to `t_seg_end` (before it when `before_instant`: a sample at an
    /// event instant is taken after the events), from the dense output of the step just
    /// attempted, in `mode`.
    pub fn take_dense<I: Interpolant>(
        &mut self,
        jac: &mut OutputJac,
        dense: &I,
        mode: usize,
        t_seg_end: f64,
        before_instant: bool,
    ) {
        while self.due(t_seg_end, before_instant) {
            let ts = self.at[self.taken.len()];
            let (z, _, _) = self.taken.push(ts, mode);
            dense.eval(ts, z);
            self.fill_outputs(jac);
        }
    }

    /// The samples of `at` due at the current point `(t, z)` (after an instant's events, or
    /// where the run stops).
    pub fn take_here(&mut self, jac: &mut OutputJac, t: f64, mode: usize, z: &[f64]) {
        while self.due(t, false) {
            let ts = self.at[self.taken.len()];
            let (row, _, _) = self.taken.push(ts, mode);
            row.copy_from_slice(z);
            self.fill_outputs(jac);
        }
    }

    /// Fills the outputs of the sample just pushed, and their derivatives `y_x S + y_p` at that
    /// fixed time, from its state and sensitivities.
    fn fill_outputs(&mut self, jac: &mut OutputJac) {
        let (n, m, k) = self.shape;
        let row = self.taken.len() - 1;
        let (z, outputs, doutputs) = self.taken.row_mut(row);
        let (x, s) = z.split_at(n);
        let ts = self.at[row];
        self.sys.outputs(ts, x, self.p, outputs);
        if m > 0 {
            let (yx, yp, yt) = &mut *jac;
            self.sys.output_jac(ts, x, self.p, yx, yp, yt);
            output_sens_into((n, m, k), jac, s, None, doutputs);
        }
    }

    /// The samples of the run that stopped after `events`, completed ([`complete`]).
    pub fn finish(self, events: &[EventRecord]) -> Samples {
        let mut taken = self.taken;
        complete(&mut taken, self.at, events);
        taken
    }
}

/// `y_x S_j + y_p_j` (`+ y_t dt_j` for totals), column per parameter, for `k` outputs of `n`
/// states and `m` parameters, from the output Jacobians `(y_x, y_p, y_t)`.
pub(crate) fn output_sens(
    shape: (usize, usize, usize),
    jac: &OutputJac,
    sens: &[f64],
    dte: Option<&[f64]>,
) -> Vec<f64> {
    let mut out = vec![0.0; shape.2 * shape.1];
    output_sens_into(shape, jac, sens, dte, &mut out);
    out
}

/// [`output_sens`] into `out` (k * m).
fn output_sens_into(
    (n, m, k): (usize, usize, usize),
    (yx, yp, yt): &OutputJac,
    sens: &[f64],
    dte: Option<&[f64]>,
    out: &mut [f64],
) {
    for j in 0..m {
        for i in 0..k {
            let row = &yx[i * n..(i + 1) * n];
            let mut v = yp[j * k + i];
            v += dot_nonzero(row, &sens[j * n..(j + 1) * n]);
            if let Some(d) = dte {
                if yt[i] != 0.0 {
                    v += yt[i] * d[j];
                }
            }
            out[j * k + i] = v;
        }
    }
}

/// Completes the samples taken (`taken`, in time order, a prefix of `at`): the times after the
/// run's stop get a sample that says so (values NaN, no derivatives), and each sample notes
/// whether it is at an event instant (taken after it) and the nearest event within whose time
/// resolution it lies.
fn complete(taken: &mut Samples, at: &[f64], events: &[EventRecord]) {
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
