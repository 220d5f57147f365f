//! One `hybc.jax.function`: a compiled model with the parameters that are inputs, the values
//! that are outputs and the number of event slots, and how a batch of points is run into the
//! flat output buffers XLA hands over. Safe Rust; `handler.rs` supplies the slices.
//!
//! Per point (every buffer row-major, leading batch dimensions flattened into `b`):
//! `p[b, j]` in; `values[b, i]`, `times[b, k]`, `n_events[b]`, `status[b]` out, and with
//! Jacobians `dvalues[b, i, j]`, `dtimes[b, k, j]`. With sample times (`at=`), the values are the
//! C columns at the end, then the same C columns at each of the T sample times (`1 + T` blocks of
//! C: `i = (1 + s) C + c` for sample `s`), so the handler and its buffers do not change. Unfired event slots hold NaN times and zero
//! time derivatives (a pad is a constant, so a masked loss gets no NaN through them); a derivative
//! that does not exist (grazing) is NaN, and so is every final value of a run that did not reach
//! `t_end` (see `status.rs`).
//!
//! Reverse mode (`jax.grad`, `jax.vjp`, `jax.jacrev`) calls [`Function::pull_back_batch`]: per
//! point, a cotangent of the values and of the event times in, the parameters' cotangent
//! `dvalues^T ct_values + dtimes^T ct_times` out, computed by the discrete adjoint
//! (`hybc::sim::adjoint`: the run recorded without sensitivities, then one backward pass for
//! every cotangent at that point) where it carries the run, else from the forward Jacobians.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

use rayon::prelude::*;

use super::status;
use hybc::sim::adjoint::{self, SampleSeed, Seed};
use hybc::sim::{EventRecord, SimOptions, SimResult, SystemInfo};
use hybc::{Sens, StopReason};

/// What a value column reads: an output or a state at the end, or the time of one firing of the
/// events of a name (an event family's element counts its own firings: `low[1]#2`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Selector {
    Output(usize),
    State(usize),
    /// `EVENT#K`: the `occurrence`-th firing (from 1) of the events named as `event` is.
    EventTime {
        event: usize,
        occurrence: usize,
    },
    /// `EVENT#last`: the last firing of the events named as `event` is.
    LastFiring {
        event: usize,
    },
}

/// A compiled model with options checked and simulators kept for reuse: one for values only
/// (compiled without gradients, so plain calls pay no sensitivities) and one for values with
/// Jacobians (compiled with gradients with respect to the inputs, in input order).
pub struct Engine {
    compiled: hybc::Compiled,
    opts: SimOptions,
    /// Simulators not in use. A call takes one per worker and gives it back, so steady state
    /// allocates no scratch buffers; at most one per thread that ever ran a point is kept.
    idle: Mutex<Vec<hybc::Simulator>>,
}

impl Engine {
    /// Checks the options by building the first simulator.
    pub fn new(compiled: hybc::Compiled, opts: SimOptions) -> Result<Engine, hybc::Error> {
        let first = compiled.simulator(&opts)?;
        Ok(Engine { compiled, opts, idle: Mutex::new(vec![first]) })
    }

    fn take(&self) -> Result<hybc::Simulator, hybc::Error> {
        let idle = self.idle.lock().unwrap_or_else(|p| p.into_inner()).pop();
        match idle {
            Some(sim) => Ok(sim),
            None => self.compiled.simulator(&self.opts),
        }
    }

    fn give_back(&self, sim: hybc::Simulator) {
        self.idle.lock().unwrap_or_else(|p| p.into_inner()).push(sim);
    }

    fn n_grad(&self) -> usize {
        self.compiled.info().n_grad()
    }
}

/// A worker's simulator and parameter vector, the simulator returned to its engine when the
/// worker is done (also when a point panics).
struct Worker<'a> {
    engine: &'a Engine,
    sim: Option<hybc::Simulator>,
    p: Vec<f64>,
}

impl Drop for Worker<'_> {
    fn drop(&mut self) {
        if let Some(sim) = self.sim.take() {
            self.engine.give_back(sim);
        }
    }
}

/// The output slices of one call, each `batch * width` long.
pub struct Outputs<'a> {
    pub values: &'a mut [f64],
    pub times: &'a mut [f64],
    pub n_events: &'a mut [i32],
    pub status: &'a mut [i32],
    /// `(dvalues, dtimes)` when the call asks for Jacobians.
    pub jacobians: Option<(&'a mut [f64], &'a mut [f64])>,
}

/// One point's slots in the output buffers.
struct Slots<'a> {
    values: &'a mut [f64],
    times: &'a mut [f64],
    n_events: &'a mut i32,
    status: &'a mut i32,
    jacobians: Option<(&'a mut [f64], &'a mut [f64])>,
}

/// An input parameter.
pub struct Input {
    /// Its index in the model's parameter vector.
    pub index: usize,
    pub name: String,
    /// Its declared range.
    pub range: Option<(f64, f64)>,
}

pub struct Function {
    /// The model's name, for messages.
    pub model_name: String,
    /// The input parameters, in input order.
    inputs: Vec<Input>,
    /// Their names, for messages.
    input_names: Vec<String>,
    /// Every parameter's value where it is not an input (defaults with the caller's overrides).
    base: Vec<f64>,
    columns: Vec<Selector>,
    /// The number of sample times (`SimOptions::at`, the same in both engines).
    samples: usize,
    events: usize,
    plain: Engine,
    with_jacobians: Engine,
    /// Whether reverse mode takes the adjoint (else it transposes the forward Jacobians).
    by_adjoint: bool,
    counts: Counts,
}

/// How many points each kind of native work ran: what the tests read (through
/// `_hybc.jax_counts`) to check that reverse mode runs no forward sensitivities.
#[derive(Debug, Default)]
pub struct Counts {
    /// Runs without sensitivities (the values).
    pub plain: AtomicU64,
    /// Runs with forward sensitivities (forward mode, or reverse mode's fallback).
    pub forward: AtomicU64,
    /// Points whose cotangents the adjoint pulled back.
    pub adjoint: AtomicU64,
    /// Runs recorded for the adjoint, each followed by one backward pass (consecutive points at
    /// the same inputs share one).
    pub recorded: AtomicU64,
    /// Points whose cotangents were pulled back through the forward Jacobians (the adjoint does
    /// not carry the run, or was not asked for).
    pub transposed: AtomicU64,
}

impl Counts {
    fn add(counter: &AtomicU64, n: usize) {
        counter.fetch_add(n as u64, Ordering::Relaxed);
    }

    /// `(name, count)` of each counter.
    pub fn snapshot(&self) -> [(&'static str, u64); 5] {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        [
            ("plain", get(&self.plain)),
            ("forward", get(&self.forward)),
            ("adjoint", get(&self.adjoint)),
            ("recorded", get(&self.recorded)),
            ("transposed", get(&self.transposed)),
        ]
    }
}

/// One point of a reverse-mode call: its cotangents in, its parameters' cotangent out.
struct Pull<'a> {
    ct_values: &'a [f64],
    ct_times: &'a [f64],
    pbar: &'a mut [f64],
}

/// Batches up to this size run on the calling thread: a thread hand-off costs more than a point
/// of a small model.
const SERIAL_BATCH: usize = 4;

impl Function {
    /// `plain` must be compiled without gradients and `with_jacobians` with gradients with
    /// respect to the inputs, in order; both run forward sensitivities whatever their options'
    /// `sens` says, and `reverse` chooses how reverse mode pulls cotangents back (`Auto`: the
    /// adjoint when `hybc::sim::adjoint::prefers_adjoint` says one row is cheaper by it).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        model_name: String,
        inputs: Vec<Input>,
        base: Vec<f64>,
        columns: Vec<Selector>,
        events: usize,
        plain: Engine,
        with_jacobians: Engine,
        reverse: Sens,
    ) -> Function {
        assert_eq!(with_jacobians.n_grad(), inputs.len(), "Jacobian engine compiled for the inputs");
        debug_assert!(plain.opts.sens == Sens::Forward && with_jacobians.opts.sens == Sens::Forward);
        let input_names = inputs.iter().map(|i| i.name.clone()).collect();
        let samples = plain.opts.at.len();
        let by_adjoint = match reverse {
            Sens::Forward => false,
            Sens::Adjoint => true,
            Sens::Auto => adjoint::prefers_adjoint(1, inputs.len()),
        };
        Function {
            model_name,
            inputs,
            input_names,
            base,
            columns,
            samples,
            events,
            plain,
            with_jacobians,
            by_adjoint,
            counts: Counts::default(),
        }
    }

    /// The points each kind of native work ran so far.
    pub fn counts(&self) -> &Counts {
        &self.counts
    }

    pub fn n_inputs(&self) -> usize {
        self.inputs.len()
    }

    /// The value columns at the end and at each sample time.
    pub fn n_values(&self) -> usize {
        self.columns.len() * (1 + self.samples)
    }

    pub fn n_event_slots(&self) -> usize {
        self.events
    }

    pub fn input_names(&self) -> &[String] {
        &self.input_names
    }

    /// Runs `batch` points (`p` is `batch * n_inputs` long) into `out`, in parallel for batches
    /// larger than a few points. The slice lengths must match (the handler checks them against the
    /// buffers' shapes first).
    pub fn run_batch(&self, p: &[f64], batch: usize, out: Outputs<'_>) {
        let (m, k, n) = (self.n_inputs(), self.events, self.n_values());
        debug_assert_eq!(p.len(), batch * m);
        let Outputs { values, times, n_events, status, jacobians } = out;
        let engine = if jacobians.is_some() { &self.with_jacobians } else { &self.plain };
        let counter = if jacobians.is_some() { &self.counts.forward } else { &self.counts.plain };
        Counts::add(counter, batch);
        let mut slots: Vec<Slots<'_>> = Vec::with_capacity(batch);
        let mut values = values.chunks_mut(n.max(1));
        let mut times = times.chunks_mut(k.max(1));
        let (mut dvalues, mut dtimes) = match jacobians {
            Some((dv, dt)) => (Some(dv.chunks_mut((n * m).max(1))), Some(dt.chunks_mut((k * m).max(1)))),
            None => (None, None),
        };
        for (n_events, status) in n_events.iter_mut().zip(status.iter_mut()) {
            let jacobians = match (dvalues.as_mut(), dtimes.as_mut()) {
                (Some(dv), Some(dt)) => Some((next_row(dv, n * m), next_row(dt, k * m))),
                _ => None,
            };
            let values = next_row(&mut values, n);
            let times = next_row(&mut times, k);
            slots.push(Slots { values, times, n_events, status, jacobians });
        }
        let worker = || Worker { engine, sim: None, p: self.base.clone() };
        // Point `b`'s inputs (empty when the function has no inputs: then `p` is empty too).
        let inputs_of = |b: usize| &p[b * m..(b + 1) * m];
        if batch <= SERIAL_BATCH {
            let mut w = worker();
            for (b, slot) in slots.into_iter().enumerate() {
                self.run_point(&mut w, inputs_of(b), slot);
            }
        } else {
            slots.into_par_iter().enumerate().for_each_init(worker, |w, (b, slot)| {
                self.run_point(w, inputs_of(b), slot);
            });
        }
    }

    fn run_point(&self, w: &mut Worker<'_>, q: &[f64], slot: Slots<'_>) {
        if !self.set_inputs(w, q) {
            return fill_failed(slot, status::BAD_PARAM);
        }
        match run(w) {
            Some(result) => self.fill(slot, &result),
            None => fill_failed(slot, status::FAULT),
        }
    }

    /// Sets the worker's parameters to the inputs `q`; false (nothing set) when one is not finite
    /// or outside its declared range.
    fn set_inputs(&self, w: &mut Worker<'_>, q: &[f64]) -> bool {
        let in_range = q
            .iter()
            .zip(&self.inputs)
            .all(|(&v, input)| v.is_finite() && input.range.is_none_or(|(lo, hi)| (lo..=hi).contains(&v)));
        if in_range {
            for (input, &v) in self.inputs.iter().zip(q) {
                w.p[input.index] = v;
            }
        }
        in_range
    }

    /// Pulls `batch` points' cotangents back (`p`: `batch * n_inputs`, `ct_values`:
    /// `batch * n_values`, `ct_times`: `batch * n_event_slots`, `pbar`: `batch * n_inputs`).
    /// Consecutive points at the same inputs (the rows of `jax.jacrev`, which broadcasts `p`)
    /// share one run and one backward pass.
    pub fn pull_back_batch(
        &self,
        p: &[f64],
        batch: usize,
        ct_values: &[f64],
        ct_times: &[f64],
        pbar: &mut [f64],
    ) {
        let (m, k, n) = (self.n_inputs(), self.events, self.n_values());
        debug_assert_eq!(p.len(), batch * m);
        let inputs_of = |b: usize| &p[b * m..(b + 1) * m];
        // Groups of consecutive points with bitwise equal inputs: (first point, points).
        let mut groups: Vec<(usize, Vec<Pull<'_>>)> = Vec::new();
        let mut pbars = pbar.chunks_mut(m.max(1));
        for b in 0..batch {
            let pull = Pull {
                ct_values: &ct_values[b * n..(b + 1) * n],
                ct_times: &ct_times[b * k..(b + 1) * k],
                pbar: next_row(&mut pbars, m),
            };
            let same = groups.last().is_some_and(|(first, _)| {
                inputs_of(*first).iter().zip(inputs_of(b)).all(|(a, c)| a.to_bits() == c.to_bits())
            });
            match groups.last_mut() {
                Some((_, pulls)) if same => pulls.push(pull),
                _ => groups.push((b, vec![pull])),
            }
        }
        let worker = || Worker { engine: &self.with_jacobians, sim: None, p: self.base.clone() };
        if groups.len() <= SERIAL_BATCH {
            let mut w = worker();
            for (first, pulls) in groups {
                self.pull_back(&mut w, inputs_of(first), pulls);
            }
        } else {
            groups.into_par_iter().for_each_init(worker, |w, (first, pulls)| {
                self.pull_back(w, inputs_of(first), pulls);
            });
        }
    }

    /// One point's cotangents pulled back: by the adjoint where it carries the run, else through
    /// the forward Jacobians. Either way the result is `dvalues^T ct_values + dtimes^T ct_times`
    /// with a cotangent of exactly 0 contributing nothing (not even a NaN derivative's NaN), and
    /// a pad slot's time derivative 0.
    fn pull_back(&self, w: &mut Worker<'_>, q: &[f64], mut pulls: Vec<Pull<'_>>) {
        if !self.set_inputs(w, q) {
            for pull in &mut pulls {
                pull.pbar.fill(f64::NAN);
            }
            return;
        }
        if self.by_adjoint && self.pull_back_by_adjoint(&w.p, &mut pulls) {
            Counts::add(&self.counts.adjoint, pulls.len());
            return;
        }
        Counts::add(&self.counts.transposed, pulls.len());
        Counts::add(&self.counts.forward, 1);
        let (m, k, n) = (self.n_inputs(), self.events, self.n_values());
        let (mut values, mut times, mut n_events, mut code) = (vec![0.0; n], vec![0.0; k], 0, 0);
        let (mut dv, mut dt) = (vec![0.0; n * m], vec![0.0; k * m]);
        let slot = Slots {
            values: &mut values,
            times: &mut times,
            n_events: &mut n_events,
            status: &mut code,
            jacobians: Some((&mut dv, &mut dt)),
        };
        match run(w) {
            Some(result) => self.fill(slot, &result),
            None => fill_failed(slot, status::FAULT),
        }
        for pull in pulls {
            for (j, pb) in pull.pbar.iter_mut().enumerate() {
                let weighted = |ct: &[f64], d: &[f64]| -> f64 {
                    ct.iter().enumerate().filter(|(_, &c)| c != 0.0).map(|(i, &c)| c * d[i * m + j]).sum()
                };
                *pb = weighted(pull.ct_values, &dv) + weighted(pull.ct_times, &dt);
            }
        }
    }

    /// The adjoint's pull-back of every cotangent at `p` (all the model's parameters): one
    /// recorded run, one backward pass. False where the adjoint does not carry the run, the run
    /// ended early or a pulled-back entry is not finite: the caller then goes through the forward
    /// Jacobians.
    fn pull_back_by_adjoint(&self, p: &[f64], pulls: &mut [Pull<'_>]) -> bool {
        let compiled = &self.with_jacobians.compiled;
        let sys = compiled.system();
        Counts::add(&self.counts.recorded, 1);
        let Ok(recorded) = adjoint::record(sys, p, &self.with_jacobians.opts) else { return false };
        let result = &recorded.result;
        // An event on `t_end` leaves the derivative to forward mode's cusp rule, as
        // `hybc run --sens adjoint` does.
        if !result.stopped_by.is_complete() || result.end_cusp.is_some() {
            return false;
        }
        let info = compiled.info();
        let (n_states, n_outputs) = (info.n_states(), info.n_outputs());
        // The values at a stop event carry the total derivative, as `fill` reads them.
        let total = matches!(result.stopped_by, StopReason::Event { .. });
        let fired = result.events.len();
        let seeds: Option<Vec<Seed>> = pulls
            .iter()
            .map(|pull| {
                let (mut state, mut outputs) = (vec![0.0; n_states], vec![0.0; n_outputs]);
                // A pad (an unfired slot or event column) is a constant: its cotangent goes nowhere.
                let mut event_times: Vec<(usize, f64)> = pull
                    .ct_times
                    .iter()
                    .take(fired)
                    .copied()
                    .enumerate()
                    .filter(|&(_, c)| c != 0.0)
                    .collect();
                for (col, &c) in self.columns.iter().zip(pull.ct_values) {
                    match *col {
                        Selector::Output(i) => outputs[i] += c,
                        Selector::State(i) => state[i] += c,
                        Selector::EventTime { .. } | Selector::LastFiring { .. } => {
                            if let Some(e) = col.firing(info, &result.events).filter(|_| c != 0.0) {
                                event_times.push((e, c));
                            }
                        }
                    }
                }
                // The values at the `at` times: a row of columns per sample, after the end's.
                let c = self.columns.len();
                let samples = pull.ct_values[c..]
                    .chunks(c.max(1))
                    .enumerate()
                    .filter(|(_, cts)| cts.iter().any(|&c| c != 0.0))
                    .map(|(row, cts)| {
                        let (mut state, mut outputs) = (vec![0.0; n_states], vec![0.0; n_outputs]);
                        for (col, &c) in self.columns.iter().zip(cts) {
                            match *col {
                                Selector::Output(i) => outputs[i] += c,
                                Selector::State(i) => state[i] += c,
                                // An event column reads no value at a sample (`fill`): what a
                                // cotangent there means is forward mode's to say.
                                Selector::EventTime { .. } | Selector::LastFiring { .. } => {
                                    return None;
                                }
                            }
                        }
                        Some(SampleSeed { row, state, outputs })
                    })
                    .collect::<Option<Vec<_>>>();
                samples.map(|samples| Seed { state, outputs, event_times, total, samples, ..Seed::default() })
            })
            .collect::<Option<Vec<_>>>();
        // A cotangent on a sample not reached (the run stopped before it) or on an event column
        // of a sample: forward mode's NaN rules apply, through the Jacobians.
        let unreached =
            |seed: &Seed| seed.samples.iter().any(|s| !result.samples.get(s.row).is_some_and(|v| v.reached));
        let Some(seeds) = seeds.filter(|seeds| !seeds.iter().any(unreached)) else { return false };
        let Ok(rows) = recorded.gradients(sys, p, &seeds) else { return false };
        // A non-finite entry: some derivative along the run does not exist (an infinite slope, a
        // grazing time). The backward pass mixes every state's cotangent into every parameter's
        // (0 * inf is NaN), while forward mode keeps existence per quantity: ask it.
        if rows.iter().flatten().any(|v| !v.is_finite()) {
            return false;
        }
        for (pull, row) in pulls.iter_mut().zip(rows) {
            pull.pbar.copy_from_slice(&row);
        }
        true
    }

    fn fill(&self, slot: Slots<'_>, result: &SimResult) {
        // Both engines compile the same model: the names (for non-finite finals) are the same.
        let code = status::of_run(self.plain.compiled.info(), result);
        *slot.status = code;
        *slot.n_events = i32::try_from(result.events.len()).unwrap_or(i32::MAX);
        let (m, k) = (self.n_inputs(), self.events);
        for (t, event) in
            slot.times.iter_mut().zip(result.events.iter().map(Some).chain(std::iter::repeat(None)))
        {
            *t = event.map_or(f64::NAN, |e| e.time);
        }
        let complete = result.stopped_by.is_complete();
        let fin = &result.final_state;
        let c = self.columns.len();
        let info = self.plain.compiled.info();
        let (end_values, sample_values) = slot.values.split_at_mut(c);
        for (v, col) in end_values.iter_mut().zip(&self.columns) {
            *v = match col.firing(info, &result.events) {
                // An event time is read as the slots are, also from a run that ended early.
                Some(e) => result.events[e].time,
                None if col.is_event() => f64::NAN,
                None if complete => col.read(&fin.outputs, &fin.state),
                None => f64::NAN,
            };
        }
        for (row, sample) in sample_values.chunks_mut(c.max(1)).zip(result.samples.iter()) {
            for (v, col) in row.iter_mut().zip(&self.columns) {
                // A time after the run's stop reads NaN (the sample says it was not reached).
                *v = col.read(sample.outputs, sample.state);
            }
        }
        let Some((dvalues, dtimes)) = slot.jacobians else { return };
        // At a `stop` event the final values are taken at a time that moves with the parameters:
        // their derivative is the total one.
        let dstate = fin.dstate_total.as_deref().or(fin.dstate.as_deref());
        let doutputs = fin.doutputs_total.as_deref().or(fin.doutputs.as_deref());
        let (end_rows, sample_rows) = dvalues.split_at_mut(c * m);
        let (n_states, n_outputs) = (fin.state.len(), fin.outputs.len());
        for (i, col) in self.columns.iter().enumerate() {
            let row = &mut end_rows[i * m..(i + 1) * m];
            if col.is_event() {
                // As an event slot: an unfired event's pad is a constant (derivative 0), a time
                // without a derivative (grazing) NaN.
                match col.firing(info, &result.events).map(|e| result.events[e].dtime.as_deref()) {
                    None => row.fill(0.0),
                    Some(Some(d)) => row.copy_from_slice(&d[..m]),
                    Some(None) => row.fill(f64::NAN),
                }
                continue;
            }
            for (j, r) in row.iter_mut().enumerate() {
                let d =
                    if complete { col.derivative(doutputs, dstate, (n_outputs, n_states), j) } else { None };
                *r = d.unwrap_or(f64::NAN);
            }
        }
        // A sample's derivative is at its fixed time (the interpolated sensitivity).
        for (rows, sample) in sample_rows.chunks_mut((c * m).max(1)).zip(result.samples.iter()) {
            for (i, col) in self.columns.iter().enumerate() {
                for j in 0..m {
                    let d = col.derivative(sample.doutputs, sample.dstate, (n_outputs, n_states), j);
                    rows[i * m + j] = d.unwrap_or(f64::NAN);
                }
            }
        }
        for slot_k in 0..k {
            let row = &mut dtimes[slot_k * m..(slot_k + 1) * m];
            match result.events.get(slot_k) {
                None => row.fill(0.0),
                Some(event) => match &event.dtime {
                    Some(d) => row.copy_from_slice(&d[..m]),
                    None => row.fill(f64::NAN),
                },
            }
        }
    }
}

impl Selector {
    /// Whether the column is an event's time (which has no value at the sample times).
    pub fn is_event(self) -> bool {
        matches!(self, Selector::EventTime { .. } | Selector::LastFiring { .. })
    }

    /// The index in `events` (a run's firings) of the firing an event column reads; `None` for a
    /// value column and for an event that fired fewer times. Firings are counted by name, as
    /// `hybc fit`'s `EVENT#K` counts them.
    fn firing(self, info: &SystemInfo, events: &[EventRecord]) -> Option<usize> {
        let named = |event: usize| {
            let name = &info.events[event].name;
            events.iter().enumerate().filter(move |(_, e)| e.name == *name).map(|(i, _)| i)
        };
        match self {
            Selector::EventTime { event, occurrence } => named(event).nth(occurrence - 1),
            Selector::LastFiring { event } => named(event).next_back(),
            Selector::Output(_) | Selector::State(_) => None,
        }
    }

    /// The column's value among `outputs` and `states` (NaN for an event column).
    fn read(self, outputs: &[f64], states: &[f64]) -> f64 {
        match self {
            Selector::Output(i) => outputs[i],
            Selector::State(i) => states[i],
            Selector::EventTime { .. } | Selector::LastFiring { .. } => f64::NAN,
        }
    }

    /// Its derivative with respect to input `j`, from column-per-parameter blocks of the outputs'
    /// (`k` rows) or states' (`n` rows) derivatives; `None` where they do not exist.
    fn derivative(
        self,
        doutputs: Option<&[f64]>,
        dstates: Option<&[f64]>,
        (k, n): (usize, usize),
        j: usize,
    ) -> Option<f64> {
        match self {
            Selector::Output(i) => doutputs.map(|d| d[j * k + i]),
            Selector::State(i) => dstates.map(|d| d[j * n + i]),
            Selector::EventTime { .. } | Selector::LastFiring { .. } => None,
        }
    }
}

/// Runs the worker's simulator (taken from its engine on first use) at its parameters; `None`
/// where no run could start (options were checked when the engine was built, and the parameter
/// vector has the model's length, so never in practice: but never a silent number either).
fn run(w: &mut Worker<'_>) -> Option<SimResult> {
    let mut sim = match w.sim.take() {
        Some(sim) => sim,
        None => w.engine.take().ok()?,
    };
    let result = sim.run_raw(&w.p);
    w.sim = Some(sim);
    result.ok()
}

/// The next `width` values of a row-major buffer; a width of zero gets an empty slice (the
/// buffer is empty then and its chunks iterator yields nothing).
fn next_row<'a>(rows: &mut std::slice::ChunksMut<'a, f64>, width: usize) -> &'a mut [f64] {
    if width == 0 {
        &mut []
    } else {
        rows.next().expect("buffer lengths checked against the batch")
    }
}

/// A point with no run (or a run that could not start): every value and time NaN, no events.
fn fill_failed(slot: Slots<'_>, code: i32) {
    *slot.status = code;
    *slot.n_events = 0;
    slot.values.fill(f64::NAN);
    slot.times.fill(f64::NAN);
    if let Some((dv, dt)) = slot.jacobians {
        dv.fill(f64::NAN);
        // No event fired: the slots are pads.
        dt.fill(0.0);
    }
}
