//! Stage 5 (sim): the step-start states a checkpointed tape did not keep, recomputed for the
//! backward pass (docs/design.md, "Checkpoints of the adjoint tape").
//!
//! A segment is a checkpoint step (its start state and start derivative kept) and the steps that
//! followed it on the tape with nothing between them, each starting exactly (bit for bit) where
//! the one before ended, with the derivative that one ended with: the tape checked that when it
//! recorded them (`Tape::step_at`). The segment is recomputed forward by the same steppers on the
//! states alone (`Rk::attempt`, `Rosenbrock::attempt`: the same stage sums, the same
//! factorisations), each step from the last one's end and end derivative, so every recomputed
//! state is the recorded run's, bit for bit.

use super::plain::WithoutSens;
use super::StepAt;
use crate::sim::linalg::linsolve::LinearSolver;
use crate::sim::method::rk::Rk;
use crate::sim::method::rosenbrock::Rosenbrock;
use crate::sim::method::row_tableau::{RODAS4, RODAS5P};
use crate::sim::method::stepper::{Rhs, Stepper, TapePair};
use crate::sim::method::tableau::{DOP853, DOPRI5};
use crate::sim::mode_rhs::rhs_for;
use crate::sim::system::HybridSystem;

/// The recomputed states of one segment, and the steppers that recompute them.
pub(super) struct Replay {
    /// The explicit pair last used, by method and size.
    rk: Option<(TapePair, usize, Rk)>,
    /// The Rosenbrock method last used, by method and size.
    ros: Option<(TapePair, usize, Rosenbrock)>,
    /// The factorisation the recorded run's Rosenbrock steps used.
    solver: LinearSolver,
    /// The start states of the pieces `first..first + count`, `n` each.
    states: Vec<f64>,
    first: usize,
    count: usize,
    /// The state and derivative carried from step to step.
    x: Vec<f64>,
    f: Vec<f64>,
}

impl Replay {
    pub(super) fn new(solver: LinearSolver) -> Replay {
        Replay {
            rk: None,
            ros: None,
            solver,
            states: Vec::new(),
            first: 0,
            count: 0,
            x: Vec::new(),
            f: Vec::new(),
        }
    }

    /// The start state of the step at piece `index`, if the last segment recomputed it.
    pub(super) fn state(&self, index: usize, n: usize) -> Option<&[f64]> {
        let i = index.checked_sub(self.first).filter(|&i| i < self.count)?;
        Some(&self.states[i * n..(i + 1) * n])
    }

    /// Recomputes the steps `steps` (the pieces from `first - 1` on: a checkpoint step that
    /// starts at `x0` with the derivative `f0`, then the steps chained to it), keeping the start
    /// states of all but the first, those of the pieces `first..first + steps.len() - 1`.
    /// `plain` is the system without sensitivities, made once per backward pass (it copies the
    /// system's description, whose names are as many as the parameters).
    pub(super) fn run<S: HybridSystem + ?Sized>(
        &mut self,
        plain: &WithoutSens<'_, S>,
        p: &[f64],
        first: usize,
        steps: &[StepAt],
        x0: &[f64],
        f0: &[f64],
    ) {
        let n = x0.len();
        self.x.clear();
        self.x.extend_from_slice(x0);
        self.f.clear();
        self.f.extend_from_slice(f0);
        self.states.clear();
        self.first = first;
        self.count = steps.len().saturating_sub(1);
        for s in &steps[..self.count] {
            let mut rhs = rhs_for(plain, p, n, s.mode).with_ceiling(s.ceiling);
            match s.pair {
                TapePair::Dopri5 | TapePair::Dop853 => {
                    if !matches!(&self.rk, Some((pair, size, _)) if *pair == s.pair && *size == n) {
                        let tab = if s.pair == TapePair::Dopri5 { &DOPRI5 } else { &DOP853 };
                        self.rk = Some((s.pair, n, Rk::new(tab, n, n, n, 1.0, 1.0)));
                    }
                    let Some((_, _, rk)) = &mut self.rk else { unreachable!("just set") };
                    rk.restart_from(&self.f);
                    advance(rk, s, &mut self.x, &mut self.f, &mut rhs);
                }
                TapePair::Rodas5p | TapePair::Rodas4 => {
                    if !matches!(&self.ros, Some((pair, size, _)) if *pair == s.pair && *size == n) {
                        let tab = if s.pair == TapePair::Rodas5p { &RODAS5P } else { &RODAS4 };
                        let ros = Rosenbrock::new(tab, n, n, n, 1.0, 1.0).with_linear_solver(self.solver);
                        self.ros = Some((s.pair, n, ros));
                    }
                    let Some((_, _, ros)) = &mut self.ros else { unreachable!("just set") };
                    ros.restart_from(&self.f);
                    advance(ros, s, &mut self.x, &mut self.f, &mut rhs);
                }
            }
            self.states.extend_from_slice(&self.x);
        }
    }
}

/// One step of `stepper` (its first stage's derivative already set) from `x` with the
/// recorded size: `x` and `f` become its end and end derivative.
fn advance<T: Stepper, R: Rhs>(stepper: &mut T, s: &StepAt, x: &mut [f64], f: &mut [f64], rhs: &mut R) {
    let n = x.len();
    // The recorded run accepted this step from these values: the attempt is the same
    // arithmetic, so its end is the recorded one (a non-finite end cannot happen but by a bug,
    // and then shows as NaN gradients, not as a panic).
    stepper.attempt(s.t0, x, s.h, rhs);
    x.copy_from_slice(&stepper.end_state()[..n]);
    f.copy_from_slice(&stepper.end_derivative()[..n]);
}
