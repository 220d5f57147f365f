//! Every analysis as a user asks for it: a request per analysis, filled by a front end (the
//! command line from its flags, Python from its keywords) and run on the door's [`Compiled`]
//! (or [`Model`], for an analysis that compiles models of its own). A request parses what the
//! user wrote as text against the model, runs the analysis's core (generic over the system, in
//! its own folder) and returns the library's report of it, so that every front end says the same
//! things about the same analysis. Their refusals are the door's [`Error`](super::Error).
//!
//! They live at the door, not in the analyses' folders, because they take the door's types while
//! the door's error type names the cores' errors: a request inside `fit/` would make `fit/` and
//! `api/` import each other.
//!
//! [`Compiled`]: super::Compiled
//! [`Model`]: super::Model

pub mod fit;
pub mod gradcheck;
pub mod optimize;
pub mod periodic;
pub mod sobol;
pub mod sweep;
