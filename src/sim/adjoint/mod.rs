//! Stage 5 (sim): gradients by the discrete adjoint: the transpose of the forward sensitivities'
//! own recursion, so its cost does not grow with the number of parameters (docs/design.md, "The
//! adjoint").
//!
//! A run is recorded once, without sensitivity columns (`plain.rs`: the steps of a forward run
//! whose error test leaves the sensitivities out), on a [`Tape`]: each step's start, size and how
//! it ended, each event's state before it. [`Recorded::gradient`] then walks the tape backward
//! (`backward.rs`), one pass per quantity, and equals the forward sensitivities of that run to
//! round-off. Where forward mode says a derivative does not exist (a grazing crossing, a reset
//! onto a guard, a flow switch at another event's instant) it says the same, per parameter
//! (`exist.rs`). What the backward pass does not carry yet (an event on knots that a parameter
//! may move apart from them) is named in [`AdjointError::Unsupported`] rather than approximated.
//! Samples at `--at` times are branches off the tape (`SampleAt`), seeded where the backward walk
//! reaches them.
//!
//! Memory: the tape keeps a few scalars per step, the start state (`n` numbers) only at
//! checkpoints ([`Checkpoints`]: by default about `2 sqrt(steps)` of them), and `2n` per event
//! (the forward run's `max_steps` and `max_events` bound it); the backward pass recomputes the
//! states between checkpoints (`replay.rs`), then each step's stages.

mod backward;
mod exist;
mod plain;
mod replay;
mod row;

use super::recorder::{Point, PointKind, Recorder, TapeEntry, TapeSample, TapeStep};
use super::result::{SimError, SimResult, StopReason};
use super::run::Runner;
use super::system::HybridSystem;
use super::SimOptions;
use backward::{
    jump_backward, knot_backward, step_backward, switch_backward, Jump, Scratch, Step, StepEnd, Switch,
};
pub(crate) use plain::WithoutSens;
use replay::Replay;

/// Which steps' start states the tape keeps (the others are recomputed in the backward pass
/// from the checkpoint before them: bit for bit the same states, so the same gradients).
///
/// A step is always a checkpoint where the one before it is not a plain step it follows on from
/// exactly (the run's first step, a step after an event, a flow switch, an input knot, a landed
/// or interpolated end, a restart of the stepper); otherwise every `K`-th step of such a chain is.
/// Docs/design.md, "Checkpoints of the adjoint tape", has the choice and its cost.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Checkpoints {
    /// `K = ceil(sqrt(j))` at the run's `j`-th step: about `2 sqrt(steps)` checkpoints and at
    /// most `sqrt(steps)` recomputed states held at once, for one recomputed step per step.
    #[default]
    Sqrt,
    /// Every `K`-th step of a chain (`Every(1)`: every step's, the full tape; 0 counts as 1).
    Every(usize),
}

impl Checkpoints {
    /// The longest segment (a checkpoint and the steps recomputed from it) at the `j`-th step.
    fn interval(self, j: usize) -> usize {
        match self {
            Checkpoints::Sqrt => (j as f64).sqrt().ceil() as usize,
            Checkpoints::Every(k) => k,
        }
        .max(1)
    }
}

/// The offset of a state the tape did not keep.
const NOT_KEPT: usize = usize::MAX;

/// `Sens::Auto` takes the adjoint when the quantities reported (rows) are fewer than this
/// fraction of the differentiated parameters: measured, a backward row costs 0.45 to 4 plain
/// runs and a forward column 0.05 to 1.1, and the adjoint pays 1.4 to 6 plain runs more; the
/// break-even lies between 3 and 19 parameters a row (`examples/sens_rule`, docs/design.md,
/// "`--sens auto`").
pub const AUTO_ROWS_PER_PARAM: f64 = 0.2;

/// Whether `Sens::Auto` takes the adjoint for `rows` quantities and `params` parameters.
pub fn prefers_adjoint(rows: usize, params: usize) -> bool {
    (rows as f64) < AUTO_ROWS_PER_PARAM * params as f64
}

/// Why a gradient cannot be had by the adjoint.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum AdjointError {
    /// The run holds a piece the backward pass does not carry yet.
    #[error("the adjoint does not carry {0} yet: use forward sensitivities")]
    Unsupported(&'static str),
    /// The run did not end at `t_end` or at a stop event.
    #[error("the run ended by {0}: no gradient")]
    Ended(String),
    /// A seed of the wrong length, or an event index past the run's events.
    #[error("adjoint seed: {0}")]
    Seed(String),
}

/// One recorded piece.
#[derive(Clone, Copy, Debug)]
enum Piece {
    Step {
        at: StepAt,
        end: StepEnd,
    },
    Jump {
        event: usize,
        t: f64,
        mode_before: usize,
        mode_after: usize,
        x: usize,
        velocity: Option<usize>,
        cascade: bool,
        first_of_instant: bool,
        on_knots: bool,
    },
    Switch {
        event: usize,
        t: f64,
        mode: usize,
        x: usize,
        pre: (f64, usize),
        post: (f64, usize),
    },
    Knot {
        /// `Tape::knot_sets[sets.0..sets.1]`.
        sets: (usize, usize),
        mode: usize,
        t: f64,
        jump: usize,
    },
    Drift {
        dt: f64,
        mode: usize,
        t: f64,
        x: usize,
    },
    /// No sensitivity survives this point (a flow switch at another event's instant).
    Void,
    /// `TapeEntry::KnotsMet`, its knot sets in `Tape::knot_sets` (old, then new).
    KnotsMet {
        t: f64,
        event: usize,
        x: usize,
        old: (usize, (usize, usize), bool),
        new: Option<(usize, (usize, usize), bool)>,
    },
}

/// A step's primal values, its start state at `x` in the tape's store ([`NOT_KEPT`]: recomputed
/// from the checkpoint before it); at a checkpoint the next steps are recomputed from, `f0` is its
/// first stage's derivative there.
#[derive(Clone, Copy, Debug)]
struct StepAt {
    pair: super::method::stepper::TapePair,
    t0: f64,
    h: f64,
    ceiling: f64,
    mode: usize,
    x: usize,
    f0: usize,
}

/// A sample of `SimOptions::at` on the tape: its row in the run's samples, the point it is
/// taken at (`point`: before the piece of that index, after the one before it), and, for a
/// sample read off a step, that step (the piece at `point`, whose start state the branch leaves
/// from) as the sample read it: its dense output at a time, or its end retaken to the sample's
/// time. Kept beside the pieces, so that samples never break a chain of steps recomputed from
/// one checkpoint.
#[derive(Clone, Copy, Debug)]
struct SampleAt {
    row: usize,
    point: usize,
    branch: Option<(StepAt, StepEnd)>,
}

/// The tape's view of the chain of steps it is recording: whether the next step may be
/// recomputed from the last checkpoint.
#[derive(Debug, Default)]
struct Chain {
    /// The last piece is a step with a whole end (`StepEnd::End`); `x1`/`f1` hold its end and
    /// end derivative.
    open: bool,
    x1: Vec<f64>,
    f1: Vec<f64>,
    /// The current segment's checkpoint (a piece index), its start derivative while not yet
    /// kept (`f0_kept` false), and its length in steps.
    checkpoint: usize,
    f0: Vec<f64>,
    f0_kept: bool,
    len: usize,
    /// Steps recorded so far.
    steps: usize,
}

/// Bit for bit equal (a `-0.0` is not `0.0` here: the recomputation must be the same
/// arithmetic).
fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// What [`Tape::existence_marks`] counts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ExistenceMarks {
    /// Grazing crossings (events and flow switches).
    pub grazes: usize,
    /// Events whose guard a reset put the state on.
    pub onto_guard: usize,
    /// Flow switches that grazed with a jump vanishing with their speed.
    pub benign: usize,
    /// Flow switches at another event's instant (every sensitivity voided).
    pub voids: usize,
}

/// The adjoint tape: a [`Recorder`] that keeps the pieces of a run for the backward pass.
#[derive(Debug, Default)]
pub struct Tape {
    pieces: Vec<Piece>,
    /// States, `n` at a time, at the offsets the pieces name.
    store: Vec<f64>,
    unsupported: Option<&'static str>,
    /// What the tape says of the existence of some pieces' derivatives (`exist.rs`), by piece,
    /// in order.
    marks: Vec<(usize, exist::Mark)>,
    /// The samples of `SimOptions::at`, in the order they were taken.
    samples: Vec<SampleAt>,
    /// The knot sets of the `Piece::Knot`s.
    knot_sets: Vec<(f64, u32)>,
    /// The factorisation the run's Rosenbrock steps used (the backward pass recomputes them
    /// with it).
    solver: super::LinearSolver,
    /// Which steps' start states are kept.
    checkpoints: Checkpoints,
    chain: Chain,
}

impl Tape {
    fn keep(&mut self, x: &[f64]) -> usize {
        let at = self.store.len();
        self.store.extend_from_slice(x);
        at
    }

    /// The step `s`, ended as `end`, about to be pushed as the next piece: its start state
    /// kept at a checkpoint, else left to the backward pass to recompute.
    fn step_at(&mut self, s: &TapeStep<'_>, end: StepEnd) -> StepAt {
        let mut at = StepAt {
            pair: s.pair,
            t0: s.t0,
            h: s.h,
            ceiling: s.ceiling,
            mode: s.mode,
            x: NOT_KEPT,
            f0: NOT_KEPT,
        };
        if self.checkpoints == Checkpoints::Every(1) || self.checkpoints == Checkpoints::Every(0) {
            // The full tape: nothing to recompute, nothing to check.
            at.x = self.keep(s.x0);
            return at;
        }
        let chain = &mut self.chain;
        chain.steps += 1;
        // Recomputable from the step before only where this step starts from exactly its end,
        // with its end derivative as the first stage (no restart, no jump, no cut between).
        let follows = chain.open && same_bits(s.x0, &chain.x1) && same_bits(s.f0, &chain.f1);
        let index = self.pieces.len();
        if follows && chain.len < self.checkpoints.interval(chain.steps) {
            chain.len += 1;
            if !chain.f0_kept {
                // The checkpoint's first stage, which the recomputation starts from.
                let f0 = std::mem::take(&mut chain.f0);
                let offset = self.keep(&f0);
                self.chain.f0 = f0;
                self.chain.f0_kept = true;
                if let Some(Piece::Step { at, .. }) = self.pieces.get_mut(self.chain.checkpoint) {
                    at.f0 = offset;
                }
            }
        } else {
            at.x = self.keep(s.x0);
            let chain = &mut self.chain;
            chain.checkpoint = index;
            chain.len = 1;
            chain.f0.clear();
            chain.f0.extend_from_slice(s.f0);
            chain.f0_kept = false;
        }
        let chain = &mut self.chain;
        chain.open = matches!(end, StepEnd::End);
        if chain.open {
            chain.x1.clear();
            chain.x1.extend_from_slice(s.x1);
            chain.f1.clear();
            chain.f1.extend_from_slice(s.f1);
        }
        at
    }

    /// The sample at `row` taken as `from` says: at the current end of the tape, or as a branch
    /// from the start of the step last told (`taped`) or told next.
    fn sample(&mut self, row: usize, from: TapeSample) {
        let branch = |pair, t0, h, ceiling, mode, end| {
            let at = StepAt { pair, t0, h, ceiling, mode, x: NOT_KEPT, f0: NOT_KEPT };
            Some((at, end))
        };
        let (point, branch) = match from {
            TapeSample::Here => (self.pieces.len(), None),
            TapeSample::Dense { pair, t0, h, ceiling, mode, t, taped } => {
                let point = self.pieces.len().saturating_sub(usize::from(taped));
                (point, branch(pair, t0, h, ceiling, mode, StepEnd::Dense(t)))
            }
            TapeSample::Landed { pair, t0, h, ceiling, mode, taped } => {
                let point = self.pieces.len().saturating_sub(usize::from(taped));
                (point, branch(pair, t0, h, ceiling, mode, StepEnd::End))
            }
        };
        self.samples.push(SampleAt { row, point, branch });
    }

    /// How many step start states it keeps (the checkpoints).
    pub fn kept_states(&self) -> usize {
        self.pieces.iter().filter(|p| matches!(p, Piece::Step { at, .. } if at.x != NOT_KEPT)).count()
    }

    /// How many numbers its store holds (states at checkpoints and jumps, first-stage
    /// derivatives at checkpoints steps are recomputed from).
    pub fn stored_numbers(&self) -> usize {
        self.store.len()
    }

    /// How many of its pieces forward mode gives no derivative through, by kind: grazing
    /// crossings, events a reset put on their guard, flow switches that grazed with a jump
    /// vanishing with their speed (their derivative exists), and flow switches at another
    /// event's instant (`exist.rs`).
    pub fn existence_marks(&self) -> ExistenceMarks {
        let mut marks = ExistenceMarks::default();
        for (_, mark) in &self.marks {
            match mark {
                exist::Mark::Graze => marks.grazes += 1,
                exist::Mark::OntoGuard => marks.onto_guard += 1,
                exist::Mark::Benign(_) => marks.benign += 1,
            }
        }
        marks.voids = self.pieces.iter().filter(|p| matches!(p, Piece::Void)).count();
        marks
    }

    /// How many steps it holds.
    pub fn steps(&self) -> usize {
        self.pieces.iter().filter(|p| matches!(p, Piece::Step { .. })).count()
    }

    /// How many pieces (steps and events) the tape holds.
    pub fn len(&self) -> usize {
        self.pieces.len()
    }

    /// Whether it holds none.
    pub fn is_empty(&self) -> bool {
        self.pieces.is_empty()
    }

    /// The memory the tape holds, in bytes.
    pub fn bytes(&self) -> usize {
        self.pieces.capacity() * std::mem::size_of::<Piece>()
            + self.store.capacity() * 8
            + self.samples.capacity() * std::mem::size_of::<SampleAt>()
            + self.knot_sets.capacity() * std::mem::size_of::<(f64, u32)>()
    }
}

impl Recorder for Tape {
    fn is_active(&self) -> bool {
        false
    }
    fn wants(&self, _kind: PointKind) -> bool {
        false
    }
    fn record(&mut self, _point: &Point<'_>) {}
    fn keeps_tape(&self) -> bool {
        true
    }
    fn tape(&mut self, entry: &TapeEntry<'_>) {
        if let TapeEntry::Sample { row, from } = *entry {
            self.sample(row, from);
            return;
        }
        // Any piece but a step breaks the chain of steps recomputed from one checkpoint.
        if !matches!(entry, TapeEntry::Step(_) | TapeEntry::Landed(..) | TapeEntry::Dense(..)) {
            self.chain.open = false;
        }
        let piece = match *entry {
            TapeEntry::Step(ref s) => Piece::Step { at: self.step_at(s, StepEnd::End), end: StepEnd::End },
            TapeEntry::Landed(ref s, dt) => {
                let end = StepEnd::Landed(dt);
                Piece::Step { at: self.step_at(s, end), end }
            }
            TapeEntry::Dense(ref s, t) => {
                let end = StepEnd::Dense(t);
                Piece::Step { at: self.step_at(s, end), end }
            }
            TapeEntry::Jump {
                event,
                t,
                mode_before,
                mode_after,
                x,
                velocity,
                cascade,
                first_of_instant,
                on_knots,
            } => {
                let x = self.keep(x);
                let velocity = velocity.map(|v| self.keep(v));
                Piece::Jump {
                    event,
                    t,
                    mode_before,
                    mode_after,
                    x,
                    velocity,
                    cascade,
                    first_of_instant,
                    on_knots,
                }
            }
            TapeEntry::Switch { event, t, mode, x, pre, post } => {
                let x = self.keep(x);
                let pre = (pre.0, self.keep(pre.1));
                let post = (post.0, self.keep(post.1));
                Piece::Switch { event, t, mode, x, pre, post }
            }
            TapeEntry::Knot { sets, mode, t, jump } => {
                let start = self.knot_sets.len();
                self.knot_sets.extend_from_slice(sets);
                Piece::Knot { sets: (start, self.knot_sets.len()), mode, t, jump: self.keep(jump) }
            }
            TapeEntry::Drift { dt, mode, t, x } => Piece::Drift { dt, mode, t, x: self.keep(x) },
            TapeEntry::VoidAll => Piece::Void,
            // Marks of the piece just recorded.
            TapeEntry::Grazed | TapeEntry::OntoGuard | TapeEntry::BenignGraze(_) => {
                let Some(last) = self.pieces.len().checked_sub(1) else { return };
                let mark = match *entry {
                    TapeEntry::Grazed => exist::Mark::Graze,
                    TapeEntry::OntoGuard => exist::Mark::OntoGuard,
                    TapeEntry::BenignGraze(c) => exist::Mark::Benign(self.keep(c)),
                    _ => unreachable!("a mark"),
                };
                self.marks.push((last, mark));
                return;
            }
            TapeEntry::KnotsMet { t, event, x, old, new } => {
                let mut sets = |s: &[(f64, u32)]| {
                    let start = self.knot_sets.len();
                    self.knot_sets.extend_from_slice(s);
                    (start, self.knot_sets.len())
                };
                let old = (old.0, sets(old.1), old.2);
                let new = new.map(|new| (new.0, sets(new.1), new.2));
                Piece::KnotsMet { t, event, x: self.keep(x), old, new }
            }
            TapeEntry::Sample { .. } => unreachable!("taken above"),
            TapeEntry::Unsupported(what) => {
                self.unsupported.get_or_insert(what);
                return;
            }
        };
        self.pieces.push(piece);
    }
}

/// What a gradient is taken of: `sum_i state_i x_i + sum_i outputs_i y_i` at the run's end plus
/// `sum weight t_K` over the event times `event_times` (`(K, weight)`, `K` an index into the
/// run's events), plus the weighted values of samples of `SimOptions::at` (`samples`). Empty
/// `state`/`outputs`: zero.
#[derive(Clone, Debug, Default)]
pub struct Seed {
    /// Weights of the final states (`n`, or empty).
    pub state: Vec<f64>,
    /// Weights of the final outputs (`k`, or empty).
    pub outputs: Vec<f64>,
    /// Weights of event times.
    pub event_times: Vec<(usize, f64)>,
    /// Weights of the values at samples of `SimOptions::at`.
    pub samples: Vec<SampleSeed>,
    /// At a stop event: the total derivative of the final values (carried to the stop's time,
    /// `FinalState::dstate_total`) rather than `dstate`.
    pub total: bool,
    /// Events fired at `t_end`: the final values before them (`SimResult::end_cusp`, the other
    /// side of the cusp) rather than after.
    pub before_end_events: bool,
}

/// The weights of one sample's values in a [`Seed`]: `sum_i state_i x_i(t_s) + sum_i outputs_i
/// y_i(t_s)` at the sample of row `row` of `SimResult::samples` (a time the run reached). Empty
/// `state`/`outputs`: zero.
#[derive(Clone, Debug, Default)]
pub struct SampleSeed {
    /// The sample's row.
    pub row: usize,
    /// Weights of its states (`n`, or empty).
    pub state: Vec<f64>,
    /// Weights of its outputs (`k`, or empty).
    pub outputs: Vec<f64>,
}

/// A run recorded for the adjoint: its result (values, events; no gradients) and its tape.
#[derive(Debug)]
pub struct Recorded {
    /// The run's result, as a run without gradients reports it.
    pub result: SimResult,
    /// Its tape.
    pub tape: Tape,
}

/// Runs `sys` at `p` under `opts` (sensitivities out of the error test whatever `opts` says)
/// without sensitivity columns, keeping the tape (checkpoints by the default rule,
/// [`Checkpoints::Sqrt`]).
pub fn record<S: HybridSystem + ?Sized>(sys: &S, p: &[f64], opts: &SimOptions) -> Result<Recorded, SimError> {
    record_with(sys, p, opts, Checkpoints::default())
}

/// [`record`], keeping the step start states `checkpoints` says.
pub fn record_with<S: HybridSystem + ?Sized>(
    sys: &S,
    p: &[f64],
    opts: &SimOptions,
    checkpoints: Checkpoints,
) -> Result<Recorded, SimError> {
    let plain = WithoutSens::new(sys);
    let mut opts = opts.clone();
    opts.sens_error_control = false;
    opts.trajectory = super::TrajectoryRequest::None;
    let mut tape = Tape { solver: opts.linear_solver, checkpoints, ..Tape::default() };
    let result = Runner::new(&plain, &opts)?.run_forward_with(p, &mut tape)?;
    Ok(Recorded { result, tape })
}

/// A run's result with the gradients of every quantity it reports (event times, final states and
/// outputs, their total derivatives at a stop event) by the adjoint: `Ok(Err(why))` where the
/// adjoint does not carry the run, or (`auto`) is not the cheaper; the caller then runs forward.
pub(crate) fn run_by_adjoint<S: HybridSystem + ?Sized>(
    sys: &S,
    p: &[f64],
    opts: &SimOptions,
    auto: bool,
) -> Result<Result<SimResult, AdjointError>, SimError> {
    let info = sys.info();
    let (n, m, k) = (info.n_states(), info.n_grad(), info.n_outputs());
    // The final states and outputs asked for are rows whatever the run does (events and a stop
    // only add rows): where they alone outweigh the parameters, `auto` is forward before any
    // recording run, so choosing costs nothing where forward mode wins anyway.
    // The quantities asked for (`SimOptions::of`; all by default), a backward pass each.
    let of = opts.of.as_ref();
    let states_wanted: Vec<bool> = (0..n).map(|i| of.is_none_or(|o| o.state(i))).collect();
    let outputs_wanted: Vec<bool> = (0..k).map(|i| of.is_none_or(|o| o.output(i))).collect();
    let finals_wanted = states_wanted.iter().chain(&outputs_wanted).filter(|&&w| w).count();
    if auto && !prefers_adjoint(finals_wanted, m) {
        return Ok(Err(AdjointError::Unsupported("(auto) a run with more quantities than parameters")));
    }
    let recorded = record(sys, p, opts)?;
    let result = &recorded.result;
    let at_stop = matches!(result.stopped_by, StopReason::Event { .. });
    let names: Vec<&str> = result.events.iter().map(|e| &*e.name).collect();
    let events_wanted = of.map_or_else(|| vec![true; names.len()], |o| o.events(info, &names));
    let unit = |len: usize, i: usize| {
        let mut w = vec![0.0; len];
        w[i] = 1.0;
        w
    };
    let mut seeds: Vec<Seed> = (0..names.len())
        .filter(|&e| events_wanted[e])
        .map(|e| Seed { event_times: vec![(e, 1.0)], ..Seed::default() })
        .collect();
    let finals = |seeds: &mut Vec<Seed>, total: bool, before_end_events: bool| {
        for i in (0..n).filter(|&i| states_wanted[i]) {
            seeds.push(Seed { state: unit(n, i), total, before_end_events, ..Seed::default() });
        }
        for i in (0..k).filter(|&i| outputs_wanted[i]) {
            seeds.push(Seed { outputs: unit(k, i), total, before_end_events, ..Seed::default() });
        }
    };
    finals(&mut seeds, false, false);
    if at_stop {
        finals(&mut seeds, true, false);
    }
    if result.end_cusp.is_some() {
        finals(&mut seeds, false, true);
    }
    // The values at the samples of `--at` the run reached, a row each asked for.
    let mut sample_rows = Vec::new();
    for (row, sample) in result.samples.iter().enumerate().filter(|(_, s)| s.reached) {
        for (output, count) in [(false, n), (true, k)] {
            for i in (0..count).filter(|&i| of.is_none_or(|o| o.sample(output, i, sample.time))) {
                let w = SampleSeed {
                    row,
                    state: if output { Vec::new() } else { unit(n, i) },
                    outputs: if output { unit(k, i) } else { Vec::new() },
                };
                seeds.push(Seed { samples: vec![w], ..Seed::default() });
                sample_rows.push((row, output, i));
            }
        }
    }
    if auto && !prefers_adjoint(seeds.len(), m) {
        return Ok(Err(AdjointError::Unsupported("(auto) a run with more quantities than parameters")));
    }
    let rows = match recorded.gradients(sys, p, &seeds) {
        Ok(rows) => rows,
        Err(e) => return Ok(Err(e)),
    };
    let mut result = recorded.result;
    let mut rows = rows.into_iter();
    for (event, wanted) in result.events.iter_mut().zip(&events_wanted) {
        event.dtime = if *wanted { rows.next().and_then(existing) } else { None };
    }
    // Column per parameter: entry `j * count + i` is quantity `i`'s derivative by `j`, NaN for
    // a quantity not asked for.
    let mut columns = |wanted: &[bool]| -> Vec<f64> {
        let count = wanted.len();
        let mut a = vec![f64::NAN; count * m];
        for i in (0..count).filter(|&i| wanted[i]) {
            let row = rows.next().expect("a row per seed");
            for j in 0..m {
                a[j * count + i] = row[j];
            }
        }
        a
    };
    let fin = &mut result.final_state;
    fin.dstate = existing(columns(&states_wanted));
    fin.doutputs = existing(columns(&outputs_wanted));
    if at_stop {
        fin.dstate_total = existing(columns(&states_wanted));
        fin.doutputs_total = existing(columns(&outputs_wanted));
    }
    if let Some(cusp) = &mut result.end_cusp {
        cusp.dstate = existing(columns(&states_wanted));
        cusp.doutputs = existing(columns(&outputs_wanted));
    }
    result.samples.widen(m);
    for (row, output, i) in sample_rows {
        let d = rows.next().expect("a row per seed");
        result.samples.set_derivatives(row, output, i, &d);
    }
    result.stats.sens = Some(super::Sens::Adjoint);
    Ok(Ok(result))
}

impl Recorded {
    /// The gradient (one entry per differentiated parameter of `sys`, in its order) of the
    /// quantity `seed` names, by one backward pass over the tape.
    pub fn gradient<S: HybridSystem + ?Sized>(
        &self,
        sys: &S,
        p: &[f64],
        seed: &Seed,
    ) -> Result<Vec<f64>, AdjointError> {
        Ok(self.gradients(sys, p, std::slice::from_ref(seed))?.remove(0))
    }

    /// The gradients of several quantities in one backward pass: each step's stages are
    /// recomputed once for all of them.
    pub fn gradients<S: HybridSystem + ?Sized>(
        &self,
        sys: &S,
        p: &[f64],
        seeds: &[Seed],
    ) -> Result<Vec<Vec<f64>>, AdjointError> {
        if let Some(what) = self.tape.unsupported {
            return Err(AdjointError::Unsupported(what));
        }
        let info = sys.info();
        let (n, m, k) = (info.n_states(), info.n_grad(), info.n_outputs());
        let fin = &self.result.final_state;
        let at_stop = match &self.result.stopped_by {
            StopReason::TEnd => false,
            StopReason::Event { .. } => true,
            other => return Err(AdjointError::Ended(format!("{other:?}"))),
        };
        let events = self.result.events.len();
        for seed in seeds {
            if !(seed.state.is_empty() || seed.state.len() == n)
                || !(seed.outputs.is_empty() || seed.outputs.len() == k)
            {
                return Err(AdjointError::Seed(format!("{n} state and {k} output weights expected")));
            }
            if let Some(&(bad, _)) = seed.event_times.iter().find(|&&(e, _)| e >= events) {
                return Err(AdjointError::Seed(format!("event {bad} of a run with {events}")));
            }
            for s in &seed.samples {
                if !self.result.samples.get(s.row).is_some_and(|row| row.reached) {
                    return Err(AdjointError::Seed(format!(
                        "sample {} is not a time the run reached",
                        s.row
                    )));
                }
                if !(s.state.is_empty() || s.state.len() == n)
                    || !(s.outputs.is_empty() || s.outputs.len() == k)
                {
                    return Err(AdjointError::Seed(format!("{n} state and {k} output weights expected")));
                }
            }
        }
        let rows = seeds.len();
        if m == 0 || rows == 0 {
            return Ok(vec![Vec::new(); rows]);
        }
        self.check_knots_met(sys, p)?;
        // The seeds' rows, then the auxiliary rows of the events whose time's derivative may not
        // exist (`exist.rs`): `all` in every piece's transpose.
        let plan = exist::Plan::new(&self.tape);
        let all = rows + plan.auxes();
        let mut voids = exist::Voids::new(all);
        let mut lams = vec![0.0; all * n];
        let mut pbars = vec![0.0; all * m];
        let mut end_time_bars = vec![0.0; rows];
        if seeds.iter().any(|s| s.before_end_events) && self.result.end_cusp.is_none() {
            return Err(AdjointError::Seed("no event fired at t_end".into()));
        }
        let (mut yx, mut yp, mut yt) = (vec![0.0; k * n], vec![0.0; k * m], vec![0.0; k]);
        for (r, seed) in seeds.iter().enumerate() {
            if !seed.outputs.is_empty() {
                // The outputs where the seed reads them: after the run, or before its events
                // at `t_end`.
                let state = match (&self.result.end_cusp, seed.before_end_events) {
                    (Some(cusp), true) => &cusp.state,
                    _ => &fin.state,
                };
                sys.output_jac(fin.time, state, p, &mut yx, &mut yp, &mut yt);
            }
            let (lam, pbar) = (&mut lams[r * n..(r + 1) * n], &mut pbars[r * m..(r + 1) * m]);
            lam.iter_mut().zip(&seed.state).for_each(|(l, w)| *l = *w);
            // The outputs at the end: y_x^T ybar into the state's cotangent, y_p^T ybar into
            // the parameters', y_t . ybar into the stop's time when the total derivative is
            // asked for.
            for (i, &w) in seed.outputs.iter().enumerate() {
                for (c, l) in lam.iter_mut().enumerate() {
                    *l += w * yx[i * n + c];
                }
                for (j, pb) in pbar.iter_mut().enumerate() {
                    *pb += w * yp[j * k + i];
                }
                end_time_bars[r] += w * yt[i];
            }
        }
        let mut scratch = Scratch::default();
        scratch.row.solver = self.tape.solver;
        // A drift's cotangent times `dt`, and `f_x^T` of it.
        let mut drift = (vec![0.0; n], vec![0.0; n]);
        // Per row: the cotangent of the current instant's `dt/dp` gathered from the events that
        // cascade from its first event (they take its `dt/dp`), handed to that event.
        let mut pending = vec![0.0; all];
        // Whether a cascade's share in `pending` was not zero (a sum can cancel where forward
        // mode's NaN does not).
        let mut pending_touched = vec![false; all];
        let mut event = events;
        let store = &self.tape.store;
        let last_jump = self.tape.pieces.iter().rposition(|p| matches!(p, Piece::Jump { .. }));
        // The pieces after the last step: the instant at the end. A row before the events at
        // `t_end` starts below them (they still count for the event indices).
        let last_step = self.tape.pieces.iter().rposition(|p| matches!(p, Piece::Step { .. }));
        let skips = |r: usize, index: usize| {
            seeds.get(r).is_some_and(|s| s.before_end_events) && last_step.is_none_or(|s| index > s)
        };
        let pieces = &self.tape.pieces;
        let mut replay = Replay::new(self.tape.solver);
        // Made on the first segment recomputed: a tape of checkpoints only never needs it.
        let mut plain = None;
        let mut samples = SampleCotangents::new(self, seeds, sys, p, &mut pbars);
        // The samples taken at the run's end.
        samples.inject(sys, p, pieces.len(), None, &mut lams, &mut pbars, &mut scratch)?;
        for (index, piece) in pieces.iter().enumerate().rev() {
            match *piece {
                Piece::Step { at, end } => {
                    let x0 = if at.x != NOT_KEPT {
                        &store[at.x..at.x + n]
                    } else {
                        if replay.state(index, n).is_none() {
                            // The segment this step ends: from its checkpoint (the last step
                            // before it whose start was kept; only steps lie between) to here.
                            let steps = segment(pieces, index);
                            let first = index + 1 - steps.len();
                            let c = steps[0];
                            replay.run(
                                plain.get_or_insert_with(|| WithoutSens::new(sys)),
                                p,
                                first + 1,
                                &steps,
                                &store[c.x..c.x + n],
                                &store[c.f0..c.f0 + n],
                            );
                        }
                        replay.state(index, n).expect("the segment's states were just recomputed")
                    };
                    let step = Step {
                        pair: at.pair,
                        t0: at.t0,
                        h: at.h,
                        ceiling: at.ceiling,
                        mode: at.mode,
                        x0,
                        end,
                    };
                    step_backward(sys, p, &step, &mut lams, &mut pbars, &mut scratch);
                    // The samples taken at the step's start, and read off it.
                    samples.inject(sys, p, index, Some(&step), &mut lams, &mut pbars, &mut scratch)?;
                    continue;
                }
                Piece::Jump {
                    event: ev,
                    t,
                    mode_before,
                    mode_after,
                    x,
                    velocity,
                    cascade,
                    first_of_instant,
                    on_knots,
                } => {
                    event -= 1;
                    let jump = Jump {
                        event: ev,
                        t,
                        t_flow: if on_knots { t.next_down() } else { t },
                        mode_before,
                        mode_after,
                        x: &store[x..x + n],
                        velocity: velocity.map(|v| &store[v..v + n]),
                    };
                    let mark = plan.mark(index);
                    for r in (0..all).filter(|&r| !skips(r, index)) {
                        let seed = seeds.get(r);
                        let is_stop_end =
                            at_stop && seed.is_some_and(|s| s.total) && Some(index) == last_jump;
                        let mut time_bar = seed.map_or(0.0, |s| {
                            s.event_times.iter().filter(|e| e.0 == event).map(|e| e.1).sum::<f64>()
                        });
                        if is_stop_end {
                            time_bar += end_time_bars[r];
                        }
                        let mut touched = false;
                        if first_of_instant {
                            time_bar += std::mem::take(&mut pending[r]);
                            touched = std::mem::take(&mut pending_touched[r]);
                        }
                        let (lam, pbar) = (&mut lams[r * n..(r + 1) * n], &mut pbars[r * m..(r + 1) * m]);
                        match mark {
                            // Its time's derivative is not carried: the reset's own transpose
                            // (`given`: nothing through the guard) and its time's cotangent `u`.
                            Some((exist::Mark::Graze | exist::Mark::OntoGuard, voiders)) => {
                                let u = jump_backward(sys, p, &jump, time_bar, is_stop_end, true, lam, pbar);
                                if u != 0.0 || touched {
                                    voids.add(r, voiders);
                                }
                            }
                            _ => {
                                let dte_bar =
                                    jump_backward(sys, p, &jump, time_bar, is_stop_end, cascade, lam, pbar);
                                if cascade {
                                    pending[r] += dte_bar;
                                    pending_touched[r] |= dte_bar != 0.0;
                                }
                            }
                        }
                    }
                    for a in plan.seeded_at(index) {
                        let r = rows + a;
                        let (lam, pbar) = (&mut lams[r * n..(r + 1) * n], &mut pbars[r * m..(r + 1) * m]);
                        exist::seed_guard(sys, p, ev, t, jump.x, lam, pbar);
                    }
                }
                Piece::Switch { event: ev, t, mode, x, pre, post } => {
                    let switch = Switch {
                        event: ev,
                        t,
                        mode,
                        x: &store[x..x + n],
                        pre: (pre.0, &store[pre.1..pre.1 + n]),
                        post: (post.0, &store[post.1..post.1 + n]),
                    };
                    let mark = plan.mark(index);
                    for r in (0..all).filter(|&r| !skips(r, index)) {
                        let (lam, pbar) = (&mut lams[r * n..(r + 1) * n], &mut pbars[r * m..(r + 1) * m]);
                        match mark {
                            Some((exist::Mark::Benign(c), _)) => {
                                exist::benign_backward(sys, p, &switch, &store[c..c + n], lam, pbar)
                            }
                            Some((_, voiders)) => {
                                if exist::switch_time_bar(sys, p, &switch, lam) != 0.0 {
                                    voids.add(r, voiders);
                                }
                            }
                            None => switch_backward(sys, p, &switch, lam, pbar),
                        }
                    }
                    for a in plan.seeded_at(index) {
                        let r = rows + a;
                        let (lam, pbar) = (&mut lams[r * n..(r + 1) * n], &mut pbars[r * m..(r + 1) * m]);
                        exist::seed_guard(sys, p, ev, t, switch.x, lam, pbar);
                    }
                }
                Piece::Void => {
                    for r in (0..all).filter(|&r| !skips(r, index)) {
                        if lams[r * n..(r + 1) * n].iter().any(|&l| l != 0.0) {
                            voids.void_all(r);
                        }
                    }
                }
                Piece::Drift { dt, mode, t, x } => {
                    // `S+ = S + dt (f_x S + f_p)` at `x`: `lam += dt f_x^T lam`, `pbar += dt f_p^T lam`.
                    let x = &store[x..x + n];
                    let (w, gx) = (&mut drift.0, &mut drift.1);
                    for r in (0..all).filter(|&r| !skips(r, index)) {
                        let (lam, pbar) = (&mut lams[r * n..(r + 1) * n], &mut pbars[r * m..(r + 1) * m]);
                        for (w, l) in w.iter_mut().zip(lam.iter()) {
                            *w = dt * l;
                        }
                        sys.flow_vjp_add(mode, t, x, w, p, gx, pbar);
                        for (l, g) in lam.iter_mut().zip(gx.iter()) {
                            *l += g;
                        }
                    }
                }
                Piece::KnotsMet { .. } => {}
                Piece::Knot { sets, mode, t, jump } => {
                    let sets = &self.tape.knot_sets[sets.0..sets.1];
                    for r in (0..all).filter(|&r| !skips(r, index)) {
                        let (lam, pbar) = (&lams[r * n..(r + 1) * n], &mut pbars[r * m..(r + 1) * m]);
                        knot_backward(sys, p, sets, mode, t, &store[jump..jump + n], lam, pbar);
                    }
                }
            }
            samples.inject(sys, p, index, None, &mut lams, &mut pbars, &mut scratch)?;
        }
        // The initial state's own dependence on the parameters.
        let mut s0 = vec![0.0; n * m];
        sys.initial_sens(p, &mut s0);
        for r in 0..all {
            let (lam, pbar) = (&lams[r * n..(r + 1) * n], &mut pbars[r * m..(r + 1) * m]);
            for (j, pb) in pbar.iter_mut().enumerate() {
                *pb += (0..n).map(|i| s0[j * n + i] * lam[i]).sum::<f64>();
            }
        }
        voids.resolve(rows, m, &mut pbars);
        Ok(pbars[..rows * m].chunks_exact(m).map(<[f64]>::to_vec).collect())
    }
}

/// A gradient where some entry exists: forward mode reports one whose every entry is NaN (no
/// derivative exists) as none.
fn existing(d: Vec<f64>) -> Option<Vec<f64>> {
    (d.is_empty() || d.iter().any(|v| !v.is_nan())).then_some(d)
}

impl Recorded {
    /// Refuses a run with an instant on input knots where the flow jumps that a parameter may
    /// move apart from the knots (forward mode's `knot_order` and `void_apart` then find
    /// derivatives that do not exist on one side, which the backward pass does not carry): the
    /// instant must be a time event's whose time moves with every parameter exactly as the
    /// knots where the flow jumps do (`same`, as forward mode compares them), else it is
    /// refused. A state event's time moves with the state's sensitivities, which the backward
    /// pass does not have: refused.
    fn check_knots_met<S: HybridSystem + ?Sized>(&self, sys: &S, p: &[f64]) -> Result<(), AdjointError> {
        use super::event::jump::same;
        let info = sys.info();
        let (n, m) = (info.n_states(), info.n_grad());
        let refused =
            "an event on an input knot where the flow jumps that a parameter may move apart from it";
        for piece in &self.tape.pieces {
            let Piece::KnotsMet { t, event, x, old, new } = *piece else { continue };
            if info.events[event].guard != super::system::GuardShape::Time {
                return Err(AdjointError::Unsupported(refused));
            }
            // A time guard: `g_x = 0`, so `dt_e/dp = -g_p / g_t`.
            let (mut gx, mut gp) = (vec![0.0; n], vec![0.0; m]);
            let gt = sys.guard_grad(event, t, &self.tape.store[x..x + n], p, &mut gx, &mut gp);
            let a: Vec<f64> = gp.iter().map(|&g| if g == 0.0 { 0.0 } else { -g / gt }).collect();
            let (mut sp, mut dt) = (vec![0.0; m], vec![0.0; m]);
            for (mode, sets, jumps) in std::iter::once(old).chain(new) {
                if !jumps {
                    continue;
                }
                let sets = &self.tape.knot_sets[sets.0..sets.1];
                super::knots::motion(sys, p, mode, t, sets, &mut sp, &mut dt);
                if a.iter().zip(&dt).any(|(&a, &d)| !(a.is_nan() || same(a, d))) {
                    return Err(AdjointError::Unsupported(refused));
                }
            }
        }
        Ok(())
    }
}

/// The steps of the segment whose last step is the piece `last`: from the checkpoint before it
/// (its start state and start derivative kept) to `last`, all steps (the tape breaks a chain at
/// any other piece).
fn segment(pieces: &[Piece], last: usize) -> Vec<StepAt> {
    let mut steps = Vec::new();
    for piece in pieces[..=last].iter().rev() {
        let Piece::Step { at, .. } = *piece else { unreachable!("a segment holds only steps") };
        steps.push(at);
        if at.x != NOT_KEPT {
            debug_assert!(at.f0 != NOT_KEPT, "a checkpoint steps are recomputed from keeps its f0");
            break;
        }
    }
    steps.reverse();
    steps
}

/// The samples' part of a backward pass: per sample on the tape, the rows whose seeds weigh it
/// and the cotangent of its state there (the states' weights plus `y_x^T` the outputs'; the
/// outputs' `y_p^T` share goes to the parameters at once, as forward mode's `y_x S + y_p`),
/// injected where the walk reaches the sample's point: into the cotangent there, or, for a
/// sample read off a step, through that step's dense output or retaken end into the cotangent
/// of its start.
struct SampleCotangents<'t> {
    taken: &'t [SampleAt],
    /// Per sample on the tape, `(row, cotangent of its state)`.
    bars: Vec<Vec<(usize, Vec<f64>)>>,
    /// The samples not yet injected are `taken[..next]` (the walk goes backward).
    next: usize,
    /// Scratch for a branch: its rows' cotangents and parameter shares.
    lams: Vec<f64>,
    pbars: Vec<f64>,
    /// States and differentiated parameters.
    n: usize,
    m: usize,
}

impl<'t> SampleCotangents<'t> {
    fn new<S: HybridSystem + ?Sized>(
        recorded: &'t Recorded,
        seeds: &[Seed],
        sys: &S,
        p: &[f64],
        pbars: &mut [f64],
    ) -> SampleCotangents<'t> {
        let info = sys.info();
        let (n, m, k) = (info.n_states(), info.n_grad(), info.n_outputs());
        let taken = &recorded.tape.samples[..];
        let mut bars: Vec<Vec<(usize, Vec<f64>)>> = vec![Vec::new(); taken.len()];
        // The tape's samples by row (a row is taken once).
        let mut on_tape = vec![usize::MAX; recorded.result.samples.len()];
        for (i, s) in taken.iter().enumerate() {
            if let Some(slot) = on_tape.get_mut(s.row) {
                *slot = i;
            }
        }
        let (mut yx, mut yp, mut yt) = (vec![0.0; k * n], vec![0.0; k * m], vec![0.0; k]);
        for (r, seed) in seeds.iter().enumerate() {
            for w in &seed.samples {
                let sample = recorded.result.samples.get(w.row).expect("checked: a reached sample");
                let mut xbar = vec![0.0; n];
                xbar.iter_mut().zip(&w.state).for_each(|(x, w)| *x = *w);
                if !w.outputs.is_empty() {
                    sys.output_jac(sample.time, sample.state, p, &mut yx, &mut yp, &mut yt);
                    let pbar = &mut pbars[r * m..(r + 1) * m];
                    for (i, &wi) in w.outputs.iter().enumerate() {
                        for (c, x) in xbar.iter_mut().enumerate() {
                            *x += wi * yx[i * n + c];
                        }
                        for (j, pb) in pbar.iter_mut().enumerate() {
                            *pb += wi * yp[j * k + i];
                        }
                    }
                }
                match on_tape.get(w.row).copied().filter(|&i| i != usize::MAX) {
                    Some(i) => bars[i].push((r, xbar)),
                    // Checked reached, so taken: a tape without it holds nothing to inject.
                    None => debug_assert!(false, "a reached sample is on the tape"),
                }
            }
        }
        SampleCotangents { taken, bars, next: taken.len(), lams: Vec::new(), pbars: Vec::new(), n, m }
    }

    /// Injects the samples taken at `point` into `lams`/`pbars` (rows of n and m), the walk
    /// being there: `step` is the piece at `point` when it is a step (its start state is the
    /// branch's).
    #[allow(clippy::too_many_arguments)]
    fn inject<S: HybridSystem + ?Sized>(
        &mut self,
        sys: &S,
        p: &[f64],
        point: usize,
        step: Option<&Step<'_>>,
        lams: &mut [f64],
        pbars: &mut [f64],
        scratch: &mut Scratch,
    ) -> Result<(), AdjointError> {
        while self.next > 0 && self.taken[self.next - 1].point >= point {
            self.next -= 1;
            let sample = self.taken[self.next];
            let bars = &self.bars[self.next];
            if bars.is_empty() {
                continue;
            }
            let (n, m) = (self.n, self.m);
            let Some((at, end)) = sample.branch else {
                for (r, xbar) in bars {
                    lams[r * n..(r + 1) * n].iter_mut().zip(xbar).for_each(|(l, x)| *l += x);
                }
                continue;
            };
            let Some(step) = step.filter(|s| s.t0 == at.t0 && s.mode == at.mode) else {
                return Err(AdjointError::Unsupported("a sample read off a step the tape does not hold"));
            };
            let branch = Step {
                pair: at.pair,
                t0: at.t0,
                h: at.h,
                ceiling: at.ceiling,
                mode: at.mode,
                x0: step.x0,
                end,
            };
            self.lams.clear();
            for (_, xbar) in bars {
                self.lams.extend_from_slice(xbar);
            }
            self.pbars.clear();
            self.pbars.resize(bars.len() * m, 0.0);
            step_backward(sys, p, &branch, &mut self.lams, &mut self.pbars, scratch);
            for (b, (r, _)) in bars.iter().enumerate() {
                let (lam, x0bar) = (&mut lams[r * n..(r + 1) * n], &self.lams[b * n..(b + 1) * n]);
                lam.iter_mut().zip(x0bar).for_each(|(l, x)| *l += x);
                let (pbar, share) = (&mut pbars[r * m..(r + 1) * m], &self.pbars[b * m..(b + 1) * m]);
                pbar.iter_mut().zip(share).for_each(|(pb, s)| *pb += s);
            }
        }
        Ok(())
    }
}
