//! Rendering of front-end errors as source-annotated diagnostics: file:line:column, the source
//! line and a caret under the span. Knows nothing of the stages that produce the errors beyond
//! their `Span`s.

use codespan_reporting::diagnostic::{Diagnostic as CsDiagnostic, Label};
use codespan_reporting::files::SimpleFile;
use codespan_reporting::term::{self, Chars, Config};

pub use crate::syntax::chars::{escaped, is_combining, is_invisible};
use crate::syntax::Span;

/// One error to show the user.
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnostic {
    /// The headline, lowercase, no trailing period.
    pub message: String,
    /// The source range the caret underlines.
    pub span: Span,
    /// Text under the caret: what was expected there.
    pub label: String,
    /// Extra lines (`= note: ...`), e.g. a suggestion.
    pub notes: Vec<String>,
}

/// Renders `diagnostics` against the source text, as plain text (no colour): stable for snapshots
/// and readable in logs. The source lines are shown as [`Shown`] describes: every line end counts,
/// and no byte of the file reaches the terminal unescaped.
pub fn render(file_name: &str, source: &str, diagnostics: &[Diagnostic]) -> String {
    render_as(CsDiagnostic::error, "error", file_name, source, diagnostics)
}

/// As [`render`], for warnings: the model is valid, and runs.
pub fn render_warnings(file_name: &str, source: &str, diagnostics: &[Diagnostic]) -> String {
    render_as(CsDiagnostic::warning, "warning", file_name, source, diagnostics)
}

fn render_as(
    severity: fn() -> CsDiagnostic<()>,
    word: &str,
    file_name: &str,
    source: &str,
    diagnostics: &[Diagnostic],
) -> String {
    let shown = Shown::new(source);
    let file = SimpleFile::new(file_name, shown.text.as_str());
    let config = Config { chars: Chars::ascii(), ..Config::default() };
    let mut out = String::new();
    for d in diagnostics {
        // Clamp so that a span at the very end of the file still renders.
        let start = shown.offset(d.span.start.min(source.len()));
        let end = shown.offset(d.span.end.clamp(d.span.start, source.len())).max(start);
        let cs = severity()
            .with_message(&d.message)
            .with_labels(vec![Label::primary((), start..end).with_message(&d.label)])
            .with_notes(d.notes.clone());
        match term::emit_into_string(&config, &file, &cs) {
            Ok(text) => out.push_str(&text),
            // Rendering fails only for a span outside the file; fall back to a plain line.
            Err(_) => out.push_str(&format!("{word}: {}\n --> {file_name}\n", d.message)),
        }
    }
    out
}

/// The source as diagnostics show it.
/// - Line ends: LF, CRLF and a lone CR each end a line, as in the parser (a CRLF's CR shows as a
///   space, a lone CR as LF: same byte lengths, so spans need no mapping for them).
/// - A byte-order mark at the start is not shown.
/// - Every other control or invisible character (see [`is_invisible`]) is shown as `<U+XXXX>`, so
///   a caret can point at it and no escape sequence in a file reaches the terminal.
///
/// Columns are counted in the shown line.
struct Shown {
    text: String,
    /// `(end of a replaced character in the source, shown minus source length up to there)`, in
    /// source order: a sparse map from source offsets to shown offsets.
    shifts: Vec<(usize, isize)>,
}

impl Shown {
    fn new(source: &str) -> Shown {
        let mut text = String::with_capacity(source.len());
        let mut shifts = Vec::new();
        let mut shift = 0isize;
        let mut chars = source.char_indices().peekable();
        while let Some((i, c)) = chars.next() {
            let end = i + c.len_utf8();
            match c {
                '\r' if chars.peek().map(|&(_, n)| n) == Some('\n') => text.push(' '),
                '\r' => text.push('\n'),
                '\u{FEFF}' if i == 0 => {
                    shift -= c.len_utf8() as isize;
                    shifts.push((end, shift));
                }
                c if is_invisible(c) => {
                    let escaped = escaped(c);
                    shift += escaped.len() as isize - c.len_utf8() as isize;
                    text.push_str(&escaped);
                    shifts.push((end, shift));
                }
                c => text.push(c),
            }
        }
        Shown { text, shifts }
    }

    /// The shown offset of a source offset (on a character boundary).
    fn offset(&self, source_offset: usize) -> usize {
        let before = self.shifts.partition_point(|&(end, _)| end <= source_offset);
        let shift = if before == 0 { 0 } else { self.shifts[before - 1].1 };
        source_offset.saturating_add_signed(shift).min(self.text.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one(source: &str, start: usize, end: usize) -> String {
        let d = Diagnostic {
            message: "bad".into(),
            span: Span::new(start, end),
            label: "here".into(),
            notes: vec![],
        };
        render("m.hyb", source, &[d])
    }

    #[test]
    fn a_control_character_is_escaped_with_the_caret_under_it() {
        let out = one("model m\nstate x = 1\x1b[2J\n", 19, 20);
        assert!(!out.contains('\x1b'), "{out}");
        assert!(out.contains("state x = 1<U+001B>[2J"), "{out}");
        assert!(out.contains("m.hyb:2:12"), "{out}");
        let caret_line = out.lines().find(|l| l.contains('^')).unwrap();
        let line = out.lines().find(|l| l.contains("<U+001B>")).unwrap();
        let col = |l: &str, pat: &str| l.find(pat).unwrap();
        assert_eq!(col(caret_line, "^"), col(line, "<U+001B>"), "{out}");
        assert_eq!(caret_line.matches('^').count(), "<U+001B>".len(), "{out}");
    }

    #[test]
    fn zero_width_and_combining_characters_are_escaped_with_the_caret_under_them() {
        // `e` + U+0301 would show as one letter `é`; U+200B and U+FEFF inside a line show as
        // nothing at all; U+20DD (enclosing, Me) would draw a circle around the `)`.
        for (c, tag) in [
            ('\u{0301}', "<U+0301>"),
            ('\u{200B}', "<U+200B>"),
            ('\u{200D}', "<U+200D>"),
            ('\u{2060}', "<U+2060>"),
            ('\u{FEFF}', "<U+FEFF>"),
            ('\u{20DD}', "<U+20DD>"),
            ('\u{FE0F}', "<U+FE0F>"),
        ] {
            let source = format!("model m\nstate x = e{c})\n");
            let at = source.find(c).unwrap();
            let out = one(&source, at, at + c.len_utf8());
            assert!(!out.contains(c), "{tag}: {out}");
            assert!(out.contains(&format!("state x = e{tag})")), "{tag}: {out}");
            assert!(out.contains("m.hyb:2:12"), "{tag}: {out}");
            let caret_line = out.lines().find(|l| l.contains('^')).unwrap();
            let line = out.lines().find(|l| l.contains(tag)).unwrap();
            assert_eq!(caret_line.find('^'), line.find(tag), "{tag}: {out}");
            assert_eq!(caret_line.matches('^').count(), tag.len(), "{tag}: {out}");
        }
        // Letters with their own code point and a script's own marks stay as they are.
        assert!(!is_invisible('é') && !is_invisible('\u{093F}'));
    }

    #[test]
    fn lone_cr_and_crlf_end_lines_like_lf() {
        for nl in ["\n", "\r\n", "\r"] {
            let source = format!("model m{nl}state x = 1{nl}der(x) = )");
            let at = source.rfind(')').unwrap();
            let out = one(&source, at, at + 1);
            assert!(out.contains("m.hyb:3:10"), "{nl:?}: {out}");
            assert!(!out.contains('\r'), "{nl:?}: {out}");
        }
    }

    #[test]
    fn a_bom_is_not_shown_and_columns_ignore_it() {
        let out = one("\u{FEFF}model m )", 11, 12);
        assert!(out.contains("m.hyb:1:9"), "{out}");
        assert!(!out.contains("U+FEFF"), "{out}");
    }
}
