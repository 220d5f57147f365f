//! [`LocalSolver`] by L-BFGS-B for problems with bounds only and many variables: R. H. Byrd,
//! P. Lu, J. Nocedal and C. Zhu, "A limited memory algorithm for bound constrained
//! optimization", SIAM J. Sci. Comput. 16(5), 1995, with the subspace step of J. L. Morales and
//! J. Nocedal, "Remark on Algorithm 778", ACM TOMS 38(1), 2011. Written here (docs/design.md says
//! why no crate): every iteration
//!
//! 1. finds the generalized Cauchy point of the quadratic model on the projected gradient path
//!    (`cauchy.rs`), which fixes the variables held at their bounds,
//! 2. minimises the model over the others (`subspace.rs`) to a point `x_bar` in the box,
//! 3. searches the line from `x_k` to `x_bar` (steps in `(0, 1]`, so every trial point is in the
//!    box) for a point that lowers the objective enough (Armijo, `1e-4` of the predicted
//!    decrease) with a gradient that no longer falls as steeply (`0.9` of the slope: the weak
//!    Wolfe condition, so that the correction pair has positive curvature),
//! 4. keeps the step and the gradient change as the newest of `CORRECTIONS` pairs (`memory.rs`).
//!
//! Memory and work per iteration are `O(m n)` (`m = CORRECTIONS`), so the solver takes a
//! hundred thousand variables (`limits::MAX_OPTIMIZE_FREE_LBFGSB`), where SLSQP's dense
//! workspace stops at a thousand.
//!
//! A failed run is a point the line search steps back from (a quarter of the way); a line
//! search that finds no lower point forgets the memory and tries again along the projected
//! steepest descent, and only then gives up (`LineSearchFailed`). It stops on its own when the
//! projected gradient is below a tenth of the verdict's tolerance (`GtolReached`: the verdict,
//! `kkt.rs`, measures the same quantity and still decides), or when its evaluations are spent
//! (`MaxEvalReached`). An iteration that lowers the objective by less than `ftol_rel` of it
//! (`FtolReached`) or moves every variable by less than `xtol_rel` of it (`XtolReached`) ends the
//! solve only once the verdict's tolerance itself is met, in the tail down to a tenth of it:
//! short of it the objective's relative change says little. An optimal control of many knots
//! is ill-conditioned (the effort's curvature per knot is the knot spacing's size), so the
//! objective settles to 1e-12 of itself while the gradient is still above 1e-6 of the start's:
//! there the test of the objective alone stopped 400 knots at stationarity 1.3e-6, `stalled`,
//! after 32 evaluations, where 4 more converge (3.0e-7).

mod cauchy;
mod memory;
mod subspace;

use super::solver::{Evaluate, LocalSolver, Program, SolverEnd};
use memory::Memory;

/// L-BFGS-B (written for hybc, after Byrd, Lu, Nocedal and Zhu 1995).
pub struct Lbfgsb;

/// Correction pairs kept: L-BFGS-B's authors recommend 3 to 20; 10 is scipy's default.
pub const CORRECTIONS: usize = 10;

/// The fraction of the verdict's stationarity tolerance the solver stops at, so that the
/// verdict's own measurement at the end (the same projected gradient on the same scale) passes
/// with a margin.
const AIM: f64 = 0.1;

/// Armijo's constant: the least fraction of the predicted decrease a step must achieve.
const ARMIJO: f64 = 1e-4;

/// The weak Wolfe condition's constant on the directional derivative.
const WOLFE: f64 = 0.9;

/// The most trial points of one line search.
const MAX_TRIALS: usize = 20;

impl LocalSolver for Lbfgsb {
    fn name(&self) -> &'static str {
        "L-BFGS-B"
    }

    fn max_free(&self) -> usize {
        crate::limits::MAX_OPTIMIZE_FREE_LBFGSB
    }

    fn takes_constraints(&self) -> bool {
        false
    }

    fn solve(&self, program: &Program, x0: &[f64], evaluate: &mut Evaluate<'_>) -> SolverEnd {
        let end = |x: &[f64], status: &str, out_of_evals: bool| SolverEnd {
            x: x.to_vec(),
            status: status.to_string(),
            out_of_evals,
        };
        if program.n_eq + program.n_ineq > 0 {
            return end(x0, "ConstraintsNotTaken", false);
        }
        let bounds = &program.bounds;
        let mut runs = Runs { evaluate, used: 0, max: program.max_evals };
        let Some((mut f, mut g)) = runs.at(x0) else {
            return end(x0, "StartFailed", false);
        };
        let mut x = x0.to_vec();
        let start_scale = inf_norm(&g);
        let boxed = bounds.iter().all(|(lo, hi)| lo.is_finite() && hi.is_finite());
        let mut memory = Memory::new(CORRECTIONS);
        loop {
            let scale = start_scale.max(inf_norm(&g));
            let stationary = projected_gradient(&x, &g, bounds);
            if stationary <= AIM * program.gtol * scale {
                return end(&x, "GtolReached", false);
            }
            if runs.spent() {
                return end(&x, "MaxEvalReached", true);
            }
            let cp = cauchy::cauchy_point(&x, &g, bounds, &memory);
            let target = subspace::subspace_point(&x, &g, bounds, &memory, &cp);
            let d: Vec<f64> = target.iter().zip(&x).map(|(t, x)| t - x).collect();
            let slope: f64 = d.iter().zip(&g).map(|(d, g)| d * g).sum();
            let descent = slope < 0.0;
            if !descent {
                // The model's point is no descent (round-off in the memory): start it afresh.
                if memory.len() > 0 {
                    memory.clear();
                    continue;
                }
                return end(&x, "NoDescentDirection", false);
            }
            // The first step of a fresh memory (B = I) has no curvature information: unit length,
            // unless every variable is boxed (the Cauchy point is then within the box already).
            let norm = d.iter().map(|v| v * v).sum::<f64>().sqrt();
            let first = if memory.len() == 0 && !boxed { (1.0 / norm).min(1.0) } else { 1.0 };
            match line_search(&mut runs, &x, f, slope, &d, bounds, first) {
                Search::Accepted { x: x_new, f: f_new, g: g_new } => {
                    let s: Vec<f64> = x_new.iter().zip(&x).map(|(a, b)| a - b).collect();
                    let y: Vec<f64> = g_new.iter().zip(&g).map(|(a, b)| a - b).collect();
                    let small_x = s.iter().zip(&x_new).all(|(s, x)| s.abs() <= program.xtol_rel * x.abs());
                    let small_f = f - f_new <= program.ftol_rel * f.abs().max(f_new.abs());
                    memory.push(s, y);
                    (x, f, g) = (x_new, f_new, g_new);
                    // At a point that meets the verdict's tolerance, the objective's and the
                    // step's tests may end the tail.
                    let tail =
                        projected_gradient(&x, &g, bounds) <= program.gtol * start_scale.max(inf_norm(&g));
                    if small_f && tail {
                        return end(&x, "FtolReached", false);
                    }
                    if small_x && tail {
                        return end(&x, "XtolReached", false);
                    }
                }
                Search::Failed if memory.len() > 0 => memory.clear(),
                Search::Failed if runs.spent() => return end(&x, "MaxEvalReached", true),
                Search::Failed => return end(&x, "LineSearchFailed", false),
            }
        }
    }
}

/// The evaluation function with its budget.
struct Runs<'a, 'e> {
    evaluate: &'a mut Evaluate<'e>,
    used: usize,
    max: usize,
}

impl Runs<'_, '_> {
    fn spent(&self) -> bool {
        self.used >= self.max
    }

    /// Objective and gradient at `x`; `None` where the run fails or gives a non-finite value.
    fn at(&mut self, x: &[f64]) -> Option<(f64, Vec<f64>)> {
        self.used += 1;
        let p = (self.evaluate)(x)?;
        (p.objective.is_finite() && p.gradient.iter().all(|v| v.is_finite()))
            .then_some((p.objective, p.gradient))
    }
}

/// How a line search ended.
enum Search {
    /// A point that lowers the objective enough, with its value and gradient.
    Accepted { x: Vec<f64>, f: f64, g: Vec<f64> },
    /// No such point within `MAX_TRIALS` (or the budget), or steps shrunk to round-off.
    Failed,
}

/// Searches `x + alpha d`, `alpha` in `(0, 1]` from `first`, for the Armijo and weak Wolfe
/// conditions (`slope = g . d < 0`). Steps that fail them by too little decrease are cut by
/// quadratic interpolation (safeguarded to `[0.1, 0.5]` of the bracket), failed runs by a
/// quarter; steps that decrease enough but still descend steeply grow by 4 up to 1, or bisect
/// the bracket. The last point that met Armijo is taken if the trials run out.
fn line_search(
    runs: &mut Runs<'_, '_>,
    x: &[f64],
    f: f64,
    slope: f64,
    d: &[f64],
    bounds: &[(f64, f64)],
    first: f64,
) -> Search {
    let (mut lo, mut f_lo, mut slope_lo) = (0.0, f, slope);
    let mut hi: Option<f64> = None;
    let mut alpha = first;
    let mut best: Option<(Vec<f64>, f64, Vec<f64>)> = None;
    for _ in 0..MAX_TRIALS {
        if runs.spent() {
            break;
        }
        let trial: Vec<f64> =
            x.iter().zip(d).zip(bounds).map(|((x, d), &(l, h))| (x + alpha * d).clamp(l, h)).collect();
        // Steps shrunk until the point no longer moves: nothing lower along d at this precision.
        if trial == x {
            break;
        }
        let Some((f_new, g_new)) = runs.at(&trial) else {
            hi = Some(alpha);
            alpha = lo + 0.25 * (alpha - lo);
            continue;
        };
        let slope_new: f64 = g_new.iter().zip(d).map(|(g, d)| g * d).sum();
        let armijo = f_new <= f + ARMIJO * alpha * slope;
        if armijo && (slope_new >= WOLFE * slope || alpha >= 1.0) {
            return Search::Accepted { x: trial, f: f_new, g: g_new };
        }
        if armijo {
            // Lower, and still falling steeply: a longer step.
            (lo, f_lo, slope_lo) = (alpha, f_new, slope_new);
            best = Some((trial, f_new, g_new));
            alpha = match hi {
                Some(h) => 0.5 * (lo + h),
                None => (4.0 * alpha).min(1.0),
            };
        } else {
            // Not low enough: the minimiser of the quadratic through (lo, f_lo, slope_lo) and
            // (alpha, f_new), kept within [0.1, 0.5] of the bracket.
            let width = alpha - lo;
            let curvature = f_new - f_lo - slope_lo * width;
            let step =
                if curvature > 0.0 { -slope_lo * width * width / (2.0 * curvature) } else { 0.5 * width };
            hi = Some(alpha);
            alpha = lo + step.clamp(0.1 * width, 0.5 * width);
        }
    }
    match best {
        Some((x, f, g)) => Search::Accepted { x, f, g },
        None => Search::Failed,
    }
}

/// `|P g|_inf`: at a lower bound only the gradient's negative part counts, at an upper bound its
/// positive part (as the verdict projects it, `kkt.rs`).
fn projected_gradient(x: &[f64], g: &[f64], bounds: &[(f64, f64)]) -> f64 {
    x.iter()
        .zip(g)
        .zip(bounds)
        .map(|((&x, &g), &(lo, hi))| {
            if x <= lo {
                g.min(0.0)
            } else if x >= hi {
                g.max(0.0)
            } else {
                g
            }
        })
        .fold(0.0_f64, |a, v| a.max(v.abs()))
}

fn inf_norm(v: &[f64]) -> f64 {
    v.iter().fold(0.0_f64, |a, x| a.max(x.abs()))
}

#[cfg(test)]
mod tests {
    use super::super::solver::SmoothPoint;
    use super::*;

    fn program(bounds: Vec<(f64, f64)>) -> Program {
        Program {
            bounds,
            n_eq: 0,
            n_ineq: 0,
            tolerances: Vec::new(),
            max_evals: 500,
            xtol_rel: 1e-14,
            ftol_rel: 1e-16,
            gtol: 1e-10,
        }
    }

    /// Rosenbrock's function in `n` variables (chained), with its gradient.
    fn rosenbrock(x: &[f64]) -> SmoothPoint {
        let n = x.len();
        let mut objective = 0.0;
        let mut gradient = vec![0.0; n];
        for i in 0..n - 1 {
            let a = x[i + 1] - x[i] * x[i];
            let b = 1.0 - x[i];
            objective += 100.0 * a * a + b * b;
            gradient[i] += -400.0 * a * x[i] - 2.0 * b;
            gradient[i + 1] += 200.0 * a;
        }
        SmoothPoint { objective, gradient, constraints: Vec::new(), jacobian: Vec::new() }
    }

    #[test]
    fn it_finds_rosenbrocks_minimum_and_stops_on_the_projected_gradient() {
        let n = 10;
        let x0: Vec<f64> = (0..n).map(|i| if i % 2 == 0 { -1.2 } else { 1.0 }).collect();
        let mut runs = 0;
        let mut f = |x: &[f64]| {
            runs += 1;
            Some(rosenbrock(x))
        };
        let end = Lbfgsb.solve(&program(vec![(f64::NEG_INFINITY, f64::INFINITY); n]), &x0, &mut f);
        assert_eq!(end.status, "GtolReached");
        for v in &end.x {
            approx::assert_relative_eq!(*v, 1.0, max_relative = 1e-8);
        }
        assert!(runs < 200, "{runs} runs");
    }

    #[test]
    fn the_objectives_test_ends_a_solve_only_where_the_gradient_meets_the_tolerance() {
        // f = 1e6 + sum_i c_i (x_i - 1)^2 / 2, curvatures 1 down to 1e-4, from 0: the objective
        // improves by less than 1e-12 of itself while the gradient is still far above 1e-6 of
        // the start's (1), as a control of many knots does.
        let n = 20;
        let c: Vec<f64> = (0..n).map(|i| 10f64.powf(-4.0 * i as f64 / (n - 1) as f64)).collect();
        let mut seen: Vec<(f64, f64)> = Vec::new();
        let mut f = |x: &[f64]| {
            let gradient: Vec<f64> = x.iter().zip(&c).map(|(x, c)| c * (x - 1.0)).collect();
            let objective = 1e6 + x.iter().zip(&c).map(|(x, c)| 0.5 * c * (x - 1.0).powi(2)).sum::<f64>();
            seen.push((objective, inf_norm(&gradient)));
            Some(SmoothPoint { objective, gradient, constraints: Vec::new(), jacobian: Vec::new() })
        };
        let mut p = program(vec![(f64::NEG_INFINITY, f64::INFINITY); n]);
        (p.ftol_rel, p.xtol_rel, p.gtol) = (1e-12, 1e-10, 1e-6);
        let end = Lbfgsb.solve(&p, &vec![0.0; n], &mut f);
        let g_end = end.x.iter().zip(&c).map(|(x, c)| (c * (x - 1.0)).abs()).fold(0.0, f64::max);
        assert!(g_end <= 1e-6, "{} with gradient {g_end:e}", end.status);
        // The objective had settled earlier: a new best by less than 1e-12 of it, with the
        // gradient above the tolerance, where a test of the objective alone would have stopped.
        let mut best = f64::INFINITY;
        let settled = seen.iter().any(|&(v, g)| {
            let witness = v < best && best - v <= 1e-12 * v && g > 1e-6;
            best = best.min(v);
            witness
        });
        assert!(settled, "{seen:?}");
    }

    #[test]
    fn an_active_bound_holds_its_variable_with_a_gradient_pointing_out() {
        // Rosenbrock with x_0 <= 0.5: the minimum has x_0 = 0.5 on its bound, x_1 = 0.25, and
        // the gradient in x_0 there is -2 (1 - 0.5) = -1 < 0: pointing out of the box.
        let mut f = |x: &[f64]| Some(rosenbrock(x));
        let end = Lbfgsb.solve(&program(vec![(-2.0, 0.5), (-2.0, 2.0)]), &[-1.2, 1.0], &mut f);
        assert_eq!(end.status, "GtolReached");
        assert_eq!(end.x[0], 0.5);
        approx::assert_relative_eq!(end.x[1], 0.25, max_relative = 1e-9);
    }

    #[test]
    fn a_failed_run_is_stepped_back_from() {
        // (x - 3)^2, but every run at x > 2 fails: the solver ends at the edge of what runs,
        // never having been told more than `None` there.
        let mut failed = 0;
        let mut f = |x: &[f64]| {
            if x[0] > 2.0 {
                failed += 1;
                return None;
            }
            Some(SmoothPoint {
                objective: (x[0] - 3.0).powi(2),
                gradient: vec![2.0 * (x[0] - 3.0)],
                constraints: Vec::new(),
                jacobian: Vec::new(),
            })
        };
        let end = Lbfgsb.solve(&program(vec![(0.0, 10.0)]), &[0.0], &mut f);
        assert!(end.x[0] <= 2.0 && end.x[0] > 1.9, "{:?} {}", end.x, end.status);
        assert!(failed > 0);
    }

    #[test]
    fn the_evaluations_are_counted_and_a_spent_budget_says_so() {
        let mut runs = 0;
        let mut f = |x: &[f64]| {
            runs += 1;
            Some(rosenbrock(x))
        };
        let mut p = program(vec![(f64::NEG_INFINITY, f64::INFINITY); 2]);
        p.max_evals = 7;
        let end = Lbfgsb.solve(&p, &[-1.2, 1.0], &mut f);
        assert_eq!((runs, end.status.as_str(), end.out_of_evals), (7, "MaxEvalReached", true));
    }

    #[test]
    fn general_constraints_are_not_taken() {
        let mut p = program(vec![(0.0, 1.0)]);
        p.n_ineq = 1;
        let mut f = |_: &[f64]| -> Option<SmoothPoint> { panic!("no run") };
        assert_eq!(Lbfgsb.solve(&p, &[0.5], &mut f).status, "ConstraintsNotTaken");
    }
}
