//! [`LocalSolver`] by Kraft's SLSQP (the `slsqp` crate, a pure-Rust translation of NLopt 2.7.1's).
//!
//! Two things the crate's API fixes, and how they are met here:
//! - It takes inequality constraints only (`c(x) <= 0`; NLopt's equality slot is passed empty)
//!   and counts a point feasible only when every `c <= 0` exactly. An equality `h = 0` with
//!   tolerance `tol` is handed over as the band `h - s <= 0`, `-h - s <= 0` with `s = SLACK tol`,
//!   an inequality as `c - s <= 0`: the crate's own stopping tests (which look at feasible points
//!   only) then work, and a point it returns meets every constraint to within 1% of the tolerance
//!   that the verdict (`kkt`) allows. (Half the tolerance worked too, but left the ball's
//!   closed-form solution off by 5e-9; 1% leaves 1e-10.)
//! - It asks for the objective and then each constraint at the same point through separate
//!   callbacks (`Fn`, not `FnMut`): the last point's evaluation (one run) is cached and shared.
//!
//! A failed run is reported to it as an infinite objective, on which it backtracks its line
//! search.

use std::cell::RefCell;

use super::solver::{Evaluate, LocalSolver, Program, SmoothPoint, SolverEnd};

/// SLSQP from the `slsqp` crate.
pub struct Slsqp;

/// The last point asked for and its evaluation.
struct Cache<'a, 'e> {
    evaluate: &'a mut Evaluate<'e>,
    x: Vec<f64>,
    point: Option<SmoothPoint>,
    evaluated: bool,
}

impl Cache<'_, '_> {
    fn at(&mut self, x: &[f64]) -> Option<&SmoothPoint> {
        if !self.evaluated || self.x != x {
            self.x = x.to_vec();
            self.point = (self.evaluate)(x);
            self.evaluated = true;
        }
        self.point.as_ref()
    }
}

/// One inequality handed to the crate: constraint `index`, its sign, and its slack.
struct Side {
    index: usize,
    sign: f64,
    slack: f64,
}

impl LocalSolver for Slsqp {
    fn name(&self) -> &'static str {
        "SLSQP"
    }

    fn max_free(&self) -> usize {
        crate::limits::MAX_OPTIMIZE_FREE
    }

    fn takes_constraints(&self) -> bool {
        true
    }

    fn solve(&self, program: &Program, x0: &[f64], evaluate: &mut Evaluate<'_>) -> SolverEnd {
        let cache = RefCell::new(Cache { evaluate, x: Vec::new(), point: None, evaluated: false });
        let objective = |x: &[f64], gradient: Option<&mut [f64]>, _: &mut ()| -> f64 {
            let mut cache = cache.borrow_mut();
            match cache.at(x) {
                Some(p) => {
                    if let Some(g) = gradient {
                        g.copy_from_slice(&p.gradient);
                    }
                    p.objective
                }
                None => {
                    if let Some(g) = gradient {
                        g.fill(0.0);
                    }
                    f64::INFINITY
                }
            }
        };
        let mut sides = Vec::new();
        for index in 0..program.n_eq + program.n_ineq {
            let slack = SLACK * program.tolerances[index];
            sides.push(Side { index, sign: 1.0, slack });
            if index < program.n_eq {
                sides.push(Side { index, sign: -1.0, slack });
            }
        }
        let constraints: Vec<_> = sides
            .iter()
            .map(|side| {
                let cache = &cache;
                move |x: &[f64], gradient: Option<&mut [f64]>, _: &mut ()| -> f64 {
                    let mut cache = cache.borrow_mut();
                    // Asked only after a finite objective at the same point, so the run worked.
                    match cache.at(x) {
                        Some(p) => {
                            if let Some(g) = gradient {
                                for (g, d) in g.iter_mut().zip(&p.jacobian[side.index]) {
                                    *g = side.sign * d;
                                }
                            }
                            side.sign * p.constraints[side.index] - side.slack
                        }
                        None => f64::INFINITY,
                    }
                }
            })
            .collect();
        let refs: Vec<&dyn slsqp::Func<()>> = constraints.iter().map(|c| c as &dyn slsqp::Func<()>).collect();
        let tols =
            slsqp::StopTols { ftol_rel: program.ftol_rel, xtol_rel: program.xtol_rel, ..Default::default() };
        let (status, x) =
            match slsqp::minimize(objective, x0, &program.bounds, &refs, (), program.max_evals, Some(tols)) {
                Ok((status, x, _)) => (format!("{status:?}"), x),
                Err((status, x, _)) => (format!("{status:?}"), x),
            };
        SolverEnd { out_of_evals: status == "MaxEvalReached", x, status }
    }
}

/// The fraction of a constraint's tolerance the band handed to the crate leaves.
const SLACK: f64 = 0.01;
