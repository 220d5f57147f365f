//! Which local solver runs a problem (`hybc optimize --solver`, Python `solver=`): SLSQP for general
//! constraints and for few variables, L-BFGS-B for bounds alone above [`LBFGSB_ABOVE`] free
//! variables, or the one asked for. The front ends call [`SolverChoice::cap`] before compiling (a
//! count above the cap is refused at once) and the request calls [`SolverChoice::pick`].

use super::lbfgsb::Lbfgsb;
use super::slsqp::Slsqp;
use super::solver::LocalSolver;

/// With bounds only and more free variables than this, `auto` picks L-BFGS-B. SLSQP's dense
/// quasi-Newton matrix and its least-squares subproblem cost `O(n^2)` memory and `O(n^3)` work per
/// iteration, L-BFGS-B `O(m n)` of both; on knot controls L-BFGS-B also took fewer runs from 10
/// knots on, and SLSQP stopped short of the verdict's stationarity from 25 knots on with bounds
/// active, 50 without (docs/performance.md, "Optimisation over many knots"). Below the count
/// SLSQP stays, the solver the shipped problems of a few parameters are tested with.
pub const LBFGSB_ABOVE: usize = 20;

/// A solver as the user names it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SolverChoice {
    /// SLSQP with general constraints or at most [`LBFGSB_ABOVE`] free variables, else L-BFGS-B.
    #[default]
    Auto,
    /// SLSQP whatever the problem.
    Slsqp,
    /// L-BFGS-B (bounds only).
    Lbfgsb,
}

impl SolverChoice {
    /// Every choice, in the order the usage text lists them.
    pub const ALL: [SolverChoice; 3] = [SolverChoice::Auto, SolverChoice::Slsqp, SolverChoice::Lbfgsb];

    /// The word the front ends take: `auto`, `slsqp`, `lbfgsb`.
    pub fn word(self) -> &'static str {
        match self {
            SolverChoice::Auto => "auto",
            SolverChoice::Slsqp => "slsqp",
            SolverChoice::Lbfgsb => "lbfgsb",
        }
    }

    /// The choice a word names.
    pub fn parse(word: &str) -> Result<SolverChoice, String> {
        SolverChoice::ALL
            .into_iter()
            .find(|c| c.word() == word)
            .ok_or_else(|| format!("expected auto, slsqp or lbfgsb, found `{word}`"))
    }

    /// The solver that runs `free` variables under `constraints` general constraints; `lbfgsb`
    /// with constraints is refused (a usage error the front end prefixes with its spelling).
    pub fn pick(self, free: usize, constraints: usize) -> Result<&'static dyn LocalSolver, String> {
        match self {
            SolverChoice::Slsqp => Ok(&Slsqp),
            // Not their count: the front ends check before a path constraint is expanded.
            SolverChoice::Lbfgsb if constraints > 0 => Err(
                "lbfgsb takes bounds only, not general constraints: use slsqp (or auto, which picks it for constraints)"
                    .to_string(),
            ),
            SolverChoice::Lbfgsb => Ok(&Lbfgsb),
            SolverChoice::Auto if constraints == 0 && free > LBFGSB_ABOVE => Ok(&Lbfgsb),
            SolverChoice::Auto => Ok(&Slsqp),
        }
    }

    /// The most free variables this choice can take, and the solver whose cap it is, for a
    /// problem with or without general constraints: what the front ends check before compiling.
    pub fn cap(self, constrained: bool) -> (usize, &'static str) {
        let solver: &dyn LocalSolver = match self {
            SolverChoice::Slsqp => &Slsqp,
            SolverChoice::Auto if constrained => &Slsqp,
            // Above LBFGSB_ABOVE `auto` runs L-BFGS-B on bounds alone, so its cap is the cap.
            SolverChoice::Auto | SolverChoice::Lbfgsb => &Lbfgsb,
        };
        (solver.max_free(), solver.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_picks_lbfgsb_for_bounds_alone_above_the_count_and_slsqp_otherwise() {
        let auto = SolverChoice::Auto;
        assert_eq!(auto.pick(LBFGSB_ABOVE + 1, 0).map(|s| s.name()), Ok("L-BFGS-B"));
        assert_eq!(auto.pick(LBFGSB_ABOVE, 0).map(|s| s.name()), Ok("SLSQP"));
        assert_eq!(auto.pick(10 * LBFGSB_ABOVE, 1).map(|s| s.name()), Ok("SLSQP"));
        assert_eq!(SolverChoice::Slsqp.pick(5000, 0).map(|s| s.name()), Ok("SLSQP"));
        assert_eq!(SolverChoice::Lbfgsb.pick(2, 0).map(|s| s.name()), Ok("L-BFGS-B"));
        let refused = SolverChoice::Lbfgsb.pick(2, 3).map(|s| s.name()).unwrap_err();
        assert!(refused.starts_with("lbfgsb takes bounds only, not general constraints"), "{refused}");
    }

    #[test]
    fn the_cap_is_the_solver_that_would_run() {
        use crate::limits::{MAX_OPTIMIZE_FREE, MAX_OPTIMIZE_FREE_LBFGSB};
        assert_eq!(SolverChoice::Auto.cap(false), (MAX_OPTIMIZE_FREE_LBFGSB, "L-BFGS-B"));
        assert_eq!(SolverChoice::Auto.cap(true), (MAX_OPTIMIZE_FREE, "SLSQP"));
        assert_eq!(SolverChoice::Slsqp.cap(false), (MAX_OPTIMIZE_FREE, "SLSQP"));
        assert_eq!(SolverChoice::Lbfgsb.cap(false), (MAX_OPTIMIZE_FREE_LBFGSB, "L-BFGS-B"));
        for c in SolverChoice::ALL {
            assert_eq!(SolverChoice::parse(c.word()), Ok(c));
        }
        assert_eq!(SolverChoice::parse("bfgs").unwrap_err(), "expected auto, slsqp or lbfgsb, found `bfgs`");
    }
}
