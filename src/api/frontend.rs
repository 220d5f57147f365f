//! The front end joined: text -> checked model, every rejection as diagnostics (`syntax` then
//! `sema`). What [`Model::parse`](super::Model::parse) runs; the crate root re-exports it for
//! tests and measurements that want the checked model itself.

use crate::diag::{self, Diagnostic};
use crate::{sema, syntax};

/// Everything the front end can reject in a model text.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FrontendError {
    /// The text does not parse.
    #[error(transparent)]
    Parse(#[from] syntax::ParseError),
    /// The parsed model does not check: every error, in source order.
    #[error("{} error(s) in the model", .0.len())]
    Check(Vec<sema::CheckError>),
}

impl FrontendError {
    /// The errors as diagnostics, in source order.
    pub fn diagnostics(&self, source: &str) -> Vec<Diagnostic> {
        match self {
            FrontendError::Parse(e) => vec![Diagnostic {
                message: e.message.clone(),
                span: e.span,
                label: format!("expected {}", e.expected),
                notes: Vec::new(),
            }],
            FrontendError::Check(errors) => errors.iter().map(|e| e.to_diagnostic(source)).collect(),
        }
    }

    /// The errors rendered against the source, with `file_name` in every location.
    pub fn render(&self, file_name: &str, source: &str) -> String {
        diag::render(file_name, source, &self.diagnostics(source))
    }
}

/// Parses and checks a model text.
pub fn check_source(source: &str) -> Result<sema::Model, FrontendError> {
    let file = syntax::parse(source)?;
    sema::check(&file).map_err(FrontendError::Check)
}
