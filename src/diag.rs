//! Rendering of front-end errors as source-annotated diagnostics: file:line:column, the source
//! line and a caret under the span. Knows nothing of the stages that produce the errors beyond
//! their `Span`s.

use codespan_reporting::diagnostic::{Diagnostic as CsDiagnostic, Label};
use codespan_reporting::files::SimpleFile;
use codespan_reporting::term::{self, Chars, Config};

use crate::syntax::Span;

/// One error to show the user.
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnostic {
    /// The headline, lowercase, no trailing period.
    pub message: String,
    pub span: Span,
    /// Text under the caret: what was expected there.
    pub label: String,
    /// Extra lines (`= note: ...`), e.g. a suggestion.
    pub notes: Vec<String>,
}

/// Renders `diagnostics` against the source text, as plain text (no colour): stable for snapshots
/// and readable in logs.
pub fn render(file_name: &str, source: &str, diagnostics: &[Diagnostic]) -> String {
    let file = SimpleFile::new(file_name, source);
    let config = Config { chars: Chars::ascii(), ..Config::default() };
    let mut out = String::new();
    for d in diagnostics {
        // Clamp so that a span at the very end of the file still renders.
        let start = d.span.start.min(source.len());
        let end = d.span.end.clamp(start, source.len());
        let cs = CsDiagnostic::error()
            .with_message(&d.message)
            .with_labels(vec![Label::primary((), start..end).with_message(&d.label)])
            .with_notes(d.notes.clone());
        match term::emit_into_string(&config, &file, &cs) {
            Ok(text) => out.push_str(&text),
            // Rendering fails only for a span outside the file; fall back to a plain line.
            Err(_) => out.push_str(&format!("error: {}\n --> {file_name}\n", d.message)),
        }
    }
    out
}
