//! Stage 5 (sim), the methods wing: how one step is taken. A [`Stepper`](stepper::Stepper)
//! attempts a step under its own error control and gives the interpolant of its last attempt;
//! it knows nothing of events, resets or recording (those are the integrator's and `event/`'s),
//! and nothing here imports `event/`.
//!
//! Code map:
//! - `stepper.rs`: the seam, the `Stepper`, `Interpolant` and `Rhs` traits.
//! - `tableau.rs`: the explicit pairs' Butcher tableaux (Dormand-Prince 5(4), DOP853) and PI
//!   control, as data.
//! - `sums.rs`: the weighted stage sums every step, error estimate and dense output is made of
//!   (the only `unsafe` in `sim`: the AVX build and checked-once block loads).
//! - `rk.rs`: `Rk`, the explicit Runge-Kutta stepper; `dense.rs`: its interpolant, `Dense`.
//! - `row_tableau.rs` (+ its tests, `row_tableau/tests.rs`): the Rosenbrock
//!   coefficients (Rodas5P, Rodas4); `rosenbrock.rs`: `Rosenbrock` and its interpolant
//!   `RowDense`, solving with `linalg/`.
//! - `auto.rs`: `Auto` (`--method auto`), the explicit pair and Rodas5P switched by stiffness.
//! - `errnorm.rs`: the step error norm every stepper uses, running costs kept aside.
//! - `poly.rs`: small polynomials on the unit interval. Here rather than in `event/`, though the
//!   detector is their main reader: an interpolant's guard polynomial is part of the seam
//!   (`Interpolant::linear_form` fills `[f64; poly::CAP]`, its default is a `Poly` through
//!   Chebyshev nodes, and every dense output implements it), so in `event/` it would make
//!   `method/` import `event/`.

pub(super) mod auto;
pub(super) mod dense;
pub(super) mod errnorm;
pub(super) mod poly;
pub(super) mod rk;
pub(super) mod rosenbrock;
pub(super) mod row_tableau;
pub(super) mod stepper;
pub(super) mod sums;
pub(super) mod tableau;
