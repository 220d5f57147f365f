//! Stage 5 (sim), the linear algebra wing: the linear solves of a Rosenbrock step. Knows
//! matrices and patterns only; imports nothing else of `sim`.
//!
//! Code map:
//! - `linsolve.rs`: `LinearSolver` and the factorisations of `W = I / (h gamma) - f_x`: dense,
//!   banded after reverse Cuthill-McKee, sparse; the choice by operation counts (`FactorCosts`).
//! - `sparse_lu.rs`: the sparse LU with static pivots after minimum degree.

pub(super) mod linsolve;
pub(super) mod sparse_lu;
