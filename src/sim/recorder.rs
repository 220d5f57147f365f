//! Stage 5 (sim): what a run records besides its result, through an observer: the
//! [`Recorder`] is told of the start, every accepted step, both sides of every event group and
//! the dense-output samples it asks for. The built-in [`TrajectoryRecorder`] keeps rows for
//! `SimOptions::trajectory`; other recorders (a plot feed, an adjoint tape) implement the trait.

use super::method::stepper::TapePair;
use super::options::TrajectoryRequest;
use super::result::TrajectoryRow;

/// Where a recorded point comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PointKind {
    /// The initial point.
    Start,
    /// The end of an accepted step.
    Step,
    /// The state at an event instant, before the group fires.
    BeforeEvents,
    /// The state after an event group.
    AfterEvents,
    /// A time asked for through [`Recorder::next_grid_time`], from the dense output.
    Grid,
}

/// One point of the trajectory. `s` holds the sensitivities, column per parameter.
#[derive(Clone, Copy, Debug)]
pub struct Point<'a> {
    /// Where it comes from.
    pub kind: PointKind,
    /// The time.
    pub t: f64,
    /// The mode (index).
    pub mode: usize,
    /// The states.
    pub x: &'a [f64],
    /// The sensitivities (n * m).
    pub s: &'a [f64],
    /// The outputs.
    pub outputs: &'a [f64],
}

/// An observer of a run.
pub trait Recorder {
    /// Whether the recorder wants anything; when false the integrator does no recording work at
    /// all (no outputs computed, no dense output built for samples).
    fn is_active(&self) -> bool {
        true
    }
    /// Whether points of this kind are wanted (grid points excepted: see `next_grid_time`).
    fn wants(&self, kind: PointKind) -> bool;
    /// The next time at which a sample from the dense output is wanted, if any. Each
    /// [`PointKind::Grid`] point recorded moves it on.
    fn next_grid_time(&self) -> Option<f64> {
        None
    }
    /// Takes one point the recorder wants.
    fn record(&mut self, point: &Point<'_>);
    /// Whether the recorder keeps an adjoint tape (`sim/adjoint/`): the integrator then tells
    /// [`Self::tape`] of every step and jump the sensitivities are carried through, and measures
    /// what a run with sensitivities measures (a landed instant's velocity), so that the run
    /// takes the steps a run with sensitivities left out of the error test takes.
    fn keeps_tape(&self) -> bool {
        false
    }
    /// Takes one piece of the run for the adjoint's backward pass (only when [`Self::keeps_tape`]).
    fn tape(&mut self, entry: &TapeEntry<'_>) {
        let _ = entry;
    }
}

/// A step (of an explicit pair or a Rosenbrock method) as the adjoint tape records it: from `(t0, x0)` of size `h` in
/// `mode`, the flow read at `ceiling` at the latest (a step ending on an input knot).
#[derive(Clone, Copy, Debug)]
pub struct TapeStep<'a> {
    /// The method.
    pub pair: TapePair,
    /// Its start.
    pub t0: f64,
    /// Its size.
    pub h: f64,
    /// The latest time the flow is read at.
    pub ceiling: f64,
    /// The mode it integrates.
    pub mode: usize,
    /// The states at its start.
    pub x0: &'a [f64],
    /// The derivative its first stage took at the start (the step before's end derivative, or
    /// a restart's): the tape keeps it where it recomputes steps from a checkpoint.
    pub f0: &'a [f64],
    /// The states at the end of the attempt it is (before any cut).
    pub x1: &'a [f64],
    /// The derivative at that end (what the next step takes as its first stage if the stepper
    /// carries it on).
    pub f1: &'a [f64],
}

/// A mode, its knot sets at an instant (`(time, set)`, as the breakpoints list them) and whether
/// the flow jumps there (`TapeEntry::KnotsMet`).
pub type KnotsOfMode<'a> = (usize, &'a [(f64, u32)], bool);

/// How a sample of `SimOptions::at` was read, for the adjoint tape. A sample read off a step is
/// a branch from the step's start: `taped` says whether that step is the last one told to the
/// tape (a step cut at an event instant is told before its samples are taken) or the next one.
#[derive(Clone, Copy, Debug)]
pub enum TapeSample {
    /// The current point itself (the state after an instant's events, on a knot, at the stop).
    Here,
    /// The dense output of the step from `t0` of size `h` (the attempt the step's interpolant
    /// was built from) read at `t`.
    Dense {
        /// The method.
        pair: TapePair,
        /// The step's start.
        t0: f64,
        /// The attempt's size.
        h: f64,
        /// The latest time the flow is read at.
        ceiling: f64,
        /// The mode.
        mode: usize,
        /// The time read.
        t: f64,
        /// The step is the last one on the tape (else the next).
        taped: bool,
    },
    /// The end of the step from `t0` retaken with size `h` to end on the sample's time
    /// (`Stepper::land`).
    Landed {
        /// The method.
        pair: TapePair,
        /// The step's start.
        t0: f64,
        /// The retaken size.
        h: f64,
        /// The latest time the flow is read at.
        ceiling: f64,
        /// The mode.
        mode: usize,
        /// The step is the last one on the tape (else the next).
        taped: bool,
    },
}

/// One piece of a run as the adjoint tape sees it: the primal values the backward pass
/// recomputes the piece from. States are the `n` states, without sensitivities.
#[derive(Clone, Copy, Debug)]
pub enum TapeEntry<'a> {
    /// A whole step.
    Step(TapeStep<'a>),
    /// A step cut at an event instant: the state there read off its dense output at this time.
    Dense(TapeStep<'a>, f64),
    /// A step retaken to end on an event instant (the step's `h` is the retaken one), its end
    /// moved on by this `dt` along its end derivative: `z = z_end + dt F(z_end)`.
    Landed(TapeStep<'a>, f64),
    /// Event `event` applied at `t` to the state `x`, from `mode_before` to `mode_after`;
    /// `velocity`: the trajectory's measured velocity where it replaced the flow in the crossing
    /// speed.
    Jump {
        /// The event.
        event: usize,
        /// Its instant.
        t: f64,
        /// The mode it fired in.
        mode_before: usize,
        /// The mode after it.
        mode_after: usize,
        /// The state before it.
        x: &'a [f64],
        /// The measured velocity, where it replaced the flow.
        velocity: Option<&'a [f64]>,
        /// It cascades from the instant's first event: its `dt/dp` is that event's.
        cascade: bool,
        /// It is the instant's first event (whose `dt/dp` later cascades take).
        first_of_instant: bool,
        /// The instant is on input knots: the flows on both sides are read on the knots'
        /// earlier side (at `t.next_down()`), and the knots are crossed after it.
        on_knots: bool,
    },
    /// The flow switch `event` crossed at `t` in `mode` at the state `x`, its flow read before
    /// it at `pre` and past it at `post` (the state stays; the sensitivities jump by
    /// `(f- - f+) dt/dp`).
    Switch {
        /// The switch (an implicit event).
        event: usize,
        /// Its instant.
        t: f64,
        /// The mode.
        mode: usize,
        /// The state at the instant.
        x: &'a [f64],
        /// A time and state just before the switch.
        pre: (f64, &'a [f64]),
        /// A time and state just past it.
        post: (f64, &'a [f64]),
    },
    /// The `pwc` knots of the knot sets `sets` (those of `mode` among them whose input jumps)
    /// crossed at `t`, where the flow jumps by `jump` (`f- - f+`): the sensitivities jump by
    /// `jump dt_k/dp` (`dt_k/dp` the knots' common motion, `knots::motion`).
    Knot {
        /// The knot sets met at `t` (`(time, set)`, as the breakpoints list them).
        sets: &'a [(f64, u32)],
        /// The mode the knots are crossed in.
        mode: usize,
        /// The knot's time.
        t: f64,
        /// The flow's jump there.
        jump: &'a [f64],
    },
    /// The state at `t` moved by `dt` along the flow of `mode` at `x`, its sensitivities by
    /// `dt (f_x S + f_p)` there (`dt` a constant): an event's lateness carried to its crossing
    /// and back (`Integrator::move_to_crossing`).
    Drift {
        /// How far along the flow (negative: back).
        dt: f64,
        /// The mode whose flow.
        mode: usize,
        /// The instant.
        t: f64,
        /// The state it moved from.
        x: &'a [f64],
    },
    /// The crossing of the piece just recorded (a `Jump` or a `Switch`) grazed: its time's
    /// derivative does not exist for the parameters that move its guard (`g_x S + g_p != 0`),
    /// nor does what depends on it.
    Grazed,
    /// The `Jump` just recorded is an event whose guard a reset put the state on (rule 7): its
    /// time's derivative does not exist for the parameters that move its guard or its instant.
    OntoGuard,
    /// The `Switch` just recorded grazed with a flow jump that vanishes with the crossing speed:
    /// its saltation is `-c (g_x S + g_p)` with this limit `c` of `J / d` (n).
    BenignGraze(&'a [f64]),
    /// No sensitivity survives this point (a flow switch at another event's instant).
    VoidAll,
    /// The sample of `SimOptions::at` at row `row` of the run's samples, taken as `from` says.
    Sample {
        /// Its row in `SimResult::samples`.
        row: usize,
        /// How it was read.
        from: TapeSample,
    },
    /// The events of the instant at `t` met input knots where the flow jumps: in the mode they
    /// were met in (`old`: the mode, the knot sets there, whether the flow jumps) and the mode
    /// after them (`new`, crossed after them, `None` at a stop). Forward mode finds the
    /// derivatives by a parameter that moves the instant and the knots apart not to exist
    /// (`Jump::knot_order`); the backward pass refuses a run where a parameter may do so (the
    /// recorded run, without parameters, cannot tell).
    KnotsMet {
        /// The instant.
        t: f64,
        /// The instant's first event (whose time derivative the instant takes).
        event: usize,
        /// The state it fired at.
        x: &'a [f64],
        /// The mode the events were met in, its knot sets at `t`, whether the flow jumps there.
        old: KnotsOfMode<'a>,
        /// The same for the mode after them, crossed after them.
        new: Option<KnotsOfMode<'a>>,
    },
    /// Something the backward pass does not carry (yet): named for the refusal.
    Unsupported(&'static str),
}

/// Records nothing.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoRecorder;

impl Recorder for NoRecorder {
    fn is_active(&self) -> bool {
        false
    }
    fn wants(&self, _kind: PointKind) -> bool {
        false
    }
    fn record(&mut self, _point: &Point<'_>) {}
}

/// The rows of [`TrajectoryRequest`]: every step (the start, every accepted step end, both sides
/// of every event group), or samples every `dt` from the start on the dense output.
#[derive(Clone, Debug)]
pub struct TrajectoryRecorder {
    schedule: RowSchedule,
    rows: Vec<TrajectoryRow>,
}

impl TrajectoryRecorder {
    /// Keeps the rows `request` asks for, from `t_start`.
    pub fn new(request: TrajectoryRequest, t_start: f64) -> TrajectoryRecorder {
        TrajectoryRecorder { schedule: RowSchedule::new(request, t_start), rows: Vec::new() }
    }

    /// The rows recorded, `None` when no trajectory was asked for.
    pub fn into_rows(self) -> Option<Vec<TrajectoryRow>> {
        self.schedule.is_active().then_some(self.rows)
    }
}

/// Which points a [`TrajectoryRequest`] keeps and where its next sample falls: one definition for
/// every recorder of those rows (kept here, written to a file by `hybc run --trajectory`).
#[derive(Clone, Copy, Debug)]
pub struct RowSchedule {
    request: TrajectoryRequest,
    t_start: f64,
    grid_rows: usize,
}

impl RowSchedule {
    /// The rows `request` asks for, from `t_start`.
    pub fn new(request: TrajectoryRequest, t_start: f64) -> RowSchedule {
        RowSchedule { request, t_start, grid_rows: 0 }
    }

    /// Whether any row is wanted.
    pub fn is_active(&self) -> bool {
        self.request != TrajectoryRequest::None
    }

    /// Whether points of `kind` are wanted (the grid points by `next_grid_time`).
    pub fn wants(&self, kind: PointKind) -> bool {
        match self.request {
            TrajectoryRequest::None => false,
            TrajectoryRequest::Steps => kind != PointKind::Grid,
            TrajectoryRequest::Every(_) => kind == PointKind::Grid,
        }
    }

    /// Samples fall at `t_start + k dt`, counted rather than summed so that they do not drift.
    pub fn next_grid_time(&self) -> Option<f64> {
        match self.request {
            TrajectoryRequest::Every(dt) => Some(self.t_start + self.grid_rows as f64 * dt),
            _ => None,
        }
    }

    /// Notes that a point of `kind` was recorded.
    pub fn recorded(&mut self, kind: PointKind) {
        if kind == PointKind::Grid {
            self.grid_rows += 1;
        }
    }
}

impl Recorder for TrajectoryRecorder {
    fn is_active(&self) -> bool {
        self.schedule.is_active()
    }

    fn wants(&self, kind: PointKind) -> bool {
        self.schedule.wants(kind)
    }

    fn next_grid_time(&self) -> Option<f64> {
        self.schedule.next_grid_time()
    }

    fn record(&mut self, p: &Point<'_>) {
        self.schedule.recorded(p.kind);
        self.rows.push(TrajectoryRow {
            t: p.t,
            mode: p.mode,
            x: p.x.to_vec(),
            s: p.s.to_vec(),
            outputs: p.outputs.to_vec(),
        });
    }
}
