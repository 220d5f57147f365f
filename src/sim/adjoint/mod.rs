//! Stage 5 (sim): gradients by the discrete adjoint: the transpose of the forward sensitivities'
//! own recursion, so its cost does not grow with the number of parameters (docs/design.md, "The
//! adjoint").
//!
//! A run is recorded once, without sensitivity columns (`plain.rs`: the steps of a forward run
//! whose error test leaves the sensitivities out), on a [`Tape`]: each step's start, size and how
//! it ended, each event's state before it. [`Recorded::gradient`] then walks the tape backward
//! (`backward.rs`), one pass per quantity, and equals the forward sensitivities of that run to
//! round-off. What the backward pass does not carry yet (a Rosenbrock step, a flow switch, a
//! `pwc` knot, an event on a knot or cascading at another's instant, a grazing crossing, samples
//! at `--at` times) is named in [`AdjointError::Unsupported`] rather than approximated.
//!
//! Memory: the tape keeps `n` numbers per step and `2n` per event (the forward run's
//! `max_steps` and `max_events` bound it); the backward pass recomputes each step's stages.

mod backward;
mod plain;

use super::recorder::{Point, PointKind, Recorder, TapeEntry, TapeStep};
use super::result::{SimError, SimResult, StopReason};
use super::run::Runner;
use super::system::HybridSystem;
use super::SimOptions;
use backward::{
    jump_backward, knot_backward, step_backward, switch_backward, Jump, Scratch, Step, StepEnd, Switch,
};
pub(crate) use plain::WithoutSens;

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
    Step { at: StepAt, end: StepEnd },
    Jump { event: usize, t: f64, mode_before: usize, mode_after: usize, x: usize, velocity: Option<usize> },
    Switch { event: usize, t: f64, mode: usize, x: usize, pre: (f64, usize), post: (f64, usize) },
    Knot { set: usize, t: f64, jump: usize },
}

/// A step's primal values, its start state at `x` in the tape's store.
#[derive(Clone, Copy, Debug)]
struct StepAt {
    pair: super::method::stepper::TapePair,
    t0: f64,
    h: f64,
    ceiling: f64,
    mode: usize,
    x: usize,
}

/// The adjoint tape: a [`Recorder`] that keeps the pieces of a run for the backward pass.
#[derive(Debug, Default)]
pub struct Tape {
    pieces: Vec<Piece>,
    /// States, `n` at a time, at the offsets the pieces name.
    store: Vec<f64>,
    unsupported: Option<&'static str>,
}

impl Tape {
    fn keep(&mut self, x: &[f64]) -> usize {
        let at = self.store.len();
        self.store.extend_from_slice(x);
        at
    }

    fn step_at(&mut self, s: &TapeStep<'_>) -> StepAt {
        let x = self.keep(s.x0);
        StepAt { pair: s.pair, t0: s.t0, h: s.h, ceiling: s.ceiling, mode: s.mode, x }
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
        self.pieces.capacity() * std::mem::size_of::<Piece>() + self.store.capacity() * 8
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
        let piece = match entry {
            TapeEntry::Step(s) => Piece::Step { at: self.step_at(s), end: StepEnd::End },
            TapeEntry::Landed(s, dt) => Piece::Step { at: self.step_at(s), end: StepEnd::Landed(*dt) },
            TapeEntry::Dense(s, t) => Piece::Step { at: self.step_at(s), end: StepEnd::Dense(*t) },
            &TapeEntry::Jump { event, t, mode_before, mode_after, x, velocity } => {
                let x = self.keep(x);
                let velocity = velocity.map(|v| self.keep(v));
                Piece::Jump { event, t, mode_before, mode_after, x, velocity }
            }
            &TapeEntry::Switch { event, t, mode, x, pre, post } => {
                let x = self.keep(x);
                let pre = (pre.0, self.keep(pre.1));
                let post = (post.0, self.keep(post.1));
                Piece::Switch { event, t, mode, x, pre, post }
            }
            &TapeEntry::Knot { set, t, jump } => Piece::Knot { set, t, jump: self.keep(jump) },
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
/// run's events). Empty `state`/`outputs`: zero.
#[derive(Clone, Debug, Default)]
pub struct Seed {
    /// Weights of the final states (`n`, or empty).
    pub state: Vec<f64>,
    /// Weights of the final outputs (`k`, or empty).
    pub outputs: Vec<f64>,
    /// Weights of event times.
    pub event_times: Vec<(usize, f64)>,
    /// At a stop event: the total derivative of the final values (carried to the stop's time,
    /// `FinalState::dstate_total`) rather than `dstate`.
    pub total: bool,
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
/// without sensitivity columns, keeping the tape.
pub fn record<S: HybridSystem + ?Sized>(sys: &S, p: &[f64], opts: &SimOptions) -> Result<Recorded, SimError> {
    let plain = WithoutSens::new(sys);
    let mut opts = opts.clone();
    opts.sens_error_control = false;
    opts.trajectory = super::TrajectoryRequest::None;
    let mut tape = Tape::default();
    if !opts.at.is_empty() {
        tape.unsupported = Some("samples at given times (--at)");
    }
    let result = Runner::new(&plain, &opts)?.run_with(p, &mut tape)?;
    Ok(Recorded { result, tape })
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
        if let Some(what) = self.tape.unsupported {
            return Err(AdjointError::Unsupported(what));
        }
        let info = sys.info();
        let (n, m, k) = (info.n_states(), info.n_grad(), info.n_outputs());
        let fin = &self.result.final_state;
        let stop_total = match &self.result.stopped_by {
            StopReason::TEnd => false,
            StopReason::Event { .. } => seed.total,
            other => return Err(AdjointError::Ended(format!("{other:?}"))),
        };
        if !(seed.state.is_empty() || seed.state.len() == n)
            || !(seed.outputs.is_empty() || seed.outputs.len() == k)
        {
            return Err(AdjointError::Seed(format!("{n} state and {k} output weights expected")));
        }
        let events = self.result.events.len();
        if let Some(&(bad, _)) = seed.event_times.iter().find(|&&(e, _)| e >= events) {
            return Err(AdjointError::Seed(format!("event {bad} of a run with {events}")));
        }
        let mut lam = vec![0.0; n];
        let mut pbar = vec![0.0; m];
        lam.iter_mut().zip(&seed.state).for_each(|(l, w)| *l = *w);
        // The outputs at the end: y_x^T ybar into the state's cotangent, y_p^T ybar into the
        // parameters', y_t . ybar into the stop's time when the total derivative is asked for.
        let mut end_time_bar = 0.0;
        if !seed.outputs.is_empty() {
            let (mut yx, mut yp, mut yt) = (vec![0.0; k * n], vec![0.0; k * m], vec![0.0; k]);
            sys.output_jac(fin.time, &fin.state, p, &mut yx, &mut yp, &mut yt);
            for (i, &w) in seed.outputs.iter().enumerate() {
                for c in 0..n {
                    lam[c] += w * yx[i * n + c];
                }
                for j in 0..m {
                    pbar[j] += w * yp[j * k + i];
                }
                end_time_bar += w * yt[i];
            }
        }
        let mut time_bars = vec![0.0; events];
        for &(e, w) in &seed.event_times {
            time_bars[e] += w;
        }
        let mut scratch = Scratch::default();
        let mut event = events;
        let store = &self.tape.store;
        let last_jump = self.tape.pieces.iter().rposition(|p| matches!(p, Piece::Jump { .. }));
        for (index, piece) in self.tape.pieces.iter().enumerate().rev() {
            match *piece {
                Piece::Step { at, end } => {
                    let step = Step {
                        pair: at.pair,
                        t0: at.t0,
                        h: at.h,
                        ceiling: at.ceiling,
                        mode: at.mode,
                        x0: &store[at.x..at.x + n],
                        end,
                    };
                    step_backward(sys, p, &step, &mut lam, &mut pbar, &mut scratch);
                }
                Piece::Jump { event: ev, t, mode_before, mode_after, x, velocity } => {
                    event -= 1;
                    let is_stop_end = stop_total && Some(index) == last_jump;
                    let jump = Jump {
                        event: ev,
                        t,
                        mode_before,
                        mode_after,
                        x: &store[x..x + n],
                        velocity: velocity.map(|v| &store[v..v + n]),
                    };
                    let time_bar = time_bars[event] + if is_stop_end { end_time_bar } else { 0.0 };
                    jump_backward(sys, p, &jump, time_bar, is_stop_end, &mut lam, &mut pbar);
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
                    switch_backward(sys, p, &switch, &mut lam, &mut pbar);
                }
                Piece::Knot { set, t, jump } => {
                    knot_backward(sys, p, set, t, &store[jump..jump + n], &lam, &mut pbar)
                }
            }
        }
        // The initial state's own dependence on the parameters.
        let mut s0 = vec![0.0; n * m];
        sys.initial_sens(p, &mut s0);
        for (j, pb) in pbar.iter_mut().enumerate() {
            *pb += (0..n).map(|i| s0[j * n + i] * lam[i]).sum::<f64>();
        }
        Ok(pbar)
    }
}
