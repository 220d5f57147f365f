//! Stage 5 (sim), the events wing: what happens between a step's ends and at an instant.
//! Detection finds and selects crossings along a step's interpolant (through `method/`'s
//! `Interpolant` and `Stepper` traits, nothing else of the methods); jumps apply an event's
//! reset and the saltation of the sensitivities. The integrator decides when each is called.
//!
//! Code map:
//! - `detect.rs`: `Detector`, sampling the mode's guards over a step, brackets, resolution,
//!   selection of the earliest crossings, pending guards and bounces.
//! - `enclose.rs`: bounds of a state's or an affine guard's polynomial over pieces of a step
//!   (Bernstein coefficients) and the walk over the pieces, the proof behind detection.
//! - `guards.rs`: `Guards`, the context of a detection call (system, parameters, mode), built
//!   by the integrator once per step instead of passed as five arguments to each call.
//! - `roots.rs`: one-dimensional root finding (Illinois regula falsi, Hermite first estimates,
//!   extrema).
//! - `jump.rs`: `Jump`, the event-time gradient, its conditioning (grazing), the reset and the
//!   saltation.
//! - `zeno.rs`: accumulating events, read off the run's event record.

pub(super) mod detect;
pub(super) mod enclose;
pub(super) mod guards;
pub(super) mod jump;
pub(super) mod roots;
pub(super) mod zeno;
