//! Stage 1: source text -> AST with spans. The only module that knows pest.

pub mod ast;
pub mod chars;
mod parser;

pub use parser::parse;

/// A byte range in the source file. Every AST node has one.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub struct Span {
    /// The first byte.
    pub start: usize,
    /// One past the last byte.
    pub end: usize,
}

impl Span {
    /// The bytes `start .. end`.
    pub fn new(start: usize, end: usize) -> Self {
        Span { start, end }
    }
}

/// A syntax error: where, what was found, what was expected.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{message}, expected {expected}")]
pub struct ParseError {
    /// Where it was found.
    pub span: Span,
    /// What was found, e.g. "unexpected `)`".
    pub message: String,
    /// What the grammar would have accepted there, in words.
    pub expected: String,
}
