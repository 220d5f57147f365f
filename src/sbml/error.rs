//! The importer's refusals: what was refused, where in the XML, and why.

use std::fmt;

/// One SBML construct the importer refuses, at the XML element that holds it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Refusal {
    /// Byte offset of the element's start tag in the document.
    pub offset: usize,
    /// 1-based line of the element's start tag.
    pub line: u32,
    /// 1-based column of the element's start tag (in characters).
    pub column: u32,
    /// The element as a reader finds it: `<event id="e1">`, `<apply>` in `<rateRule variable="x">`.
    pub element: String,
    /// Why: what is not supported or not valid, in a sentence without a trailing period.
    pub reason: String,
}

/// An SBML document the importer cannot turn into a `.hyb` model: every refusal found, in
/// document order.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub struct SbmlError {
    /// The refusals, sorted by position.
    pub refusals: Vec<Refusal>,
}

impl SbmlError {
    /// The refusals rendered for a terminal, each naming `file:line:column` and the element.
    pub fn render(&self, file: &str) -> String {
        let mut out = String::new();
        for r in &self.refusals {
            out.push_str(&format!(
                "error: {}\n  --> {}:{}:{}\n  | {}\n",
                r.reason, file, r.line, r.column, r.element
            ));
        }
        out
    }
}

impl fmt::Display for SbmlError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (k, r) in self.refusals.iter().enumerate() {
            if k > 0 {
                writeln!(f)?;
            }
            write!(f, "{}:{}: {}: {}", r.line, r.column, r.element, r.reason)?;
        }
        Ok(())
    }
}
