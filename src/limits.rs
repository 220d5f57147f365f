//! The caps on counts every interface takes (the CLI's flags, the Python keywords, `hybc.jax`):
//! one definition, so a count that is refused in one place is refused everywhere with the same
//! cap. A count costs memory or time in proportion; a cap turns a typo (`events=10**9`) into a
//! clear error instead of gigabytes allocated or a run of years. docs/cli.md, "Limits", gives the table.
//! No IO: callers name the flag or keyword in the message.

/// Events a run may record (`max_events`, `--max-events`): each record takes about 100 bytes plus
/// 8 per gradient parameter, so 10^6 events stay well under a gigabyte.
pub const MAX_EVENTS: usize = 1_000_000;
/// Event-time columns of a sweep row (`--events`, Python `events=`) and event slots of a
/// `hybc.jax` function (`events=`): each row or call holds that many names and times (and, in
/// JAX, that many rows of every Jacobian).
pub const MAX_EVENT_COLUMNS: usize = 1_000;
/// Worker threads of a sweep (`--threads`, Python `threads=`): one stack and one simulator each.
pub const MAX_THREADS: usize = 1024;
/// Points of a streamed sweep (`hybc sweep`, `hybc.dask.sweep`): rows are written as they
/// complete, so points cost time, not memory.
pub const MAX_SWEEP_POINTS: usize = 1_000_000_000;
/// Points of a sweep whose rows are all kept (Python `Model.sweep` returns its columns; about
/// 100 bytes per point and column).
pub const MAX_SWEEP_POINTS_IN_MEMORY: usize = 10_000_000;
/// Base points of a Sobol' analysis (`hybc sobol -n`): it keeps every row's outputs
/// (`N (D + 2)` or `N (2 D + 2)` numbers per output), 2^22 base points of 3 parameters are
/// 21 million rows. The rows are also capped by [`MAX_SWEEP_POINTS`], the kept numbers by
/// [`MAX_SOBOL_VALUES`].
pub const MAX_SOBOL_BASE_POINTS: usize = 1 << 22;
/// Output values a Sobol' analysis keeps (rows x outputs): 8 bytes each, so at most 800 MB.
pub const MAX_SOBOL_VALUES: usize = 100_000_000;
/// Bootstrap resamples of a Sobol' analysis (`--bootstrap`): each recomputes every index over
/// all base points.
pub const MAX_BOOTSTRAP: usize = 100_000;
/// Attempted steps of one run (`--max-steps`, Python `max_steps=`): steps cost time, not memory
/// (unless a trajectory keeps every one), and a billion small steps take minutes.
pub const MAX_STEPS: usize = 1_000_000_000;
/// Trials of a fit (`--max-iter`): every trial is kept for the report.
pub const MAX_FIT_ITER: usize = 1_000_000;
/// Runs of one local optimisation (`hybc optimize --max-iter`): every run is kept for the report.
pub const MAX_OPTIMIZE_RUNS: usize = 1_000_000;
/// Starting points of a multi-start optimisation (`--starts`): each is a whole local solve.
pub const MAX_STARTS: usize = 10_000;
/// Constraints of one optimisation, each time of a path constraint (`--subject-to
/// "y@0:2:41 >= 0"`) counted: SLSQP's dense workspace holds about
/// `(3 n + 2 m) n + (n + 2 m)(n + 1)` doubles for `n` free parameters and `m` constraints (an
/// equality is two inequalities for the crate), so with [`MAX_OPTIMIZE_FREE`] about 130 MB.
pub const MAX_CONSTRAINTS: usize = 2_000;
/// Free parameters of one optimisation by SLSQP (`hybc optimize --free`, the solver for general
/// constraints): see [`MAX_CONSTRAINTS`]; a vector parameter counts each element.
pub const MAX_OPTIMIZE_FREE: usize = 1_000;
/// Free parameters of one optimisation by L-BFGS-B (bounds only): its memory is `2 m n` doubles
/// for `m = 10` correction pairs (16 MB at this cap) and a few vectors of `n`; the report keeps
/// each run's point, `8 n` bytes a run (0.8 MB at this cap).
pub const MAX_OPTIMIZE_FREE_LBFGSB: usize = 100_000;

/// A count outside its allowed range: `{what}: at least {min}, found {value}` or
/// `{what}: at most {max}, found {value}`, `what` naming the flag or keyword.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CountError {
    /// Below the least allowed.
    #[error("{what}: at least {min}, found {value}")]
    TooFew {
        /// The flag or keyword.
        what: String,
        /// The least.
        min: usize,
        /// The value given.
        value: usize,
    },
    /// Above the most allowed.
    #[error("{what}: at most {max}, found {value}")]
    TooMany {
        /// The flag or keyword.
        what: String,
        /// The most.
        max: usize,
        /// The value given.
        value: usize,
    },
}

/// `value` if `min <= value <= max`, else the error naming `what`.
pub fn count(what: &str, value: usize, min: usize, max: usize) -> Result<usize, CountError> {
    if value < min {
        Err(CountError::TooFew { what: what.to_string(), min, value })
    } else if value > max {
        Err(CountError::TooMany { what: what.to_string(), max, value })
    } else {
        Ok(value)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_count_names_what_and_the_bound_it_broke() {
        assert_eq!(count("--events", 1000, 0, MAX_EVENT_COLUMNS), Ok(1000));
        let e = count("events", 1001, 0, MAX_EVENT_COLUMNS).unwrap_err();
        assert_eq!(e.to_string(), "events: at most 1000, found 1001");
        let e = count("--max-events", 0, 1, MAX_EVENTS).unwrap_err();
        assert_eq!(e.to_string(), "--max-events: at least 1, found 0");
    }
}
