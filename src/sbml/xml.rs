//! The XML side of the importer: roxmltree's tree, elements found by local name (SBML's and
//! MathML's namespaces are matched by their local names; a package's elements are told apart by
//! their namespace), attributes read with SBML's defaults, and the places refusals point to.

use roxmltree::{Document, Node};

use super::error::Refusal;

/// A parsed document and its text, for the line and column of a refusal.
pub(super) struct Xml<'a> {
    pub doc: Document<'a>,
}

impl<'a> Xml<'a> {
    /// Parses `text`; a malformed document is one refusal at the place the parser stopped. DTDs
    /// are refused by roxmltree's defaults (no entity expansion: no "billion laughs").
    pub fn parse(text: &'a str) -> Result<Xml<'a>, Refusal> {
        match Document::parse(text) {
            Ok(doc) => Ok(Xml { doc }),
            Err(e) => {
                let pos = e.pos();
                Err(Refusal {
                    offset: 0,
                    line: pos.row,
                    column: pos.col,
                    element: "the XML document".to_string(),
                    reason: format!("not well-formed XML: {e}"),
                })
            }
        }
    }

    /// A refusal at `node`'s start tag.
    pub fn refuse(&self, node: Node<'_, '_>, reason: impl Into<String>) -> Refusal {
        let offset = node.range().start;
        let pos = self.doc.text_pos_at(offset);
        Refusal { offset, line: pos.row, column: pos.col, element: describe(node), reason: reason.into() }
    }
}

/// How a refusal names an element: its tag with the attribute that identifies it.
pub(super) fn describe(node: Node<'_, '_>) -> String {
    let tag = node.tag_name().name();
    for key in ["id", "variable", "symbol", "species"] {
        if let Some(v) = node.attribute(key) {
            return format!("<{tag} {key}=\"{v}\">");
        }
    }
    format!("<{tag}>")
}

/// The element children of `node`.
pub(super) fn elements<'a, 'i>(node: Node<'a, 'i>) -> impl Iterator<Item = Node<'a, 'i>> {
    node.children().filter(|c| c.is_element())
}

/// The first element child named `name` (local name).
pub(super) fn child<'a, 'i>(node: Node<'a, 'i>, name: &str) -> Option<Node<'a, 'i>> {
    elements(node).find(|c| c.tag_name().name() == name)
}

/// The element children of `node`'s child list `list` named `item` (`listOfSpecies`/`species`).
pub(super) fn list<'a, 'i>(node: Node<'a, 'i>, list: &str, item: &'static str) -> Vec<Node<'a, 'i>> {
    child(node, list).map_or_else(Vec::new, |l| elements(l).filter(|c| c.tag_name().name() == item).collect())
}

/// A boolean attribute (`true`/`false`, `1`/`0` as XML Schema allows), `None` when absent or
/// malformed (the caller applies SBML's default for its level).
pub(super) fn flag(node: Node<'_, '_>, key: &str) -> Option<bool> {
    match node.attribute(key)?.trim() {
        "true" | "1" => Some(true),
        "false" | "0" => Some(false),
        _ => None,
    }
}

/// A number attribute: `Ok(None)` when absent, an error naming the attribute when malformed.
pub(super) fn number(xml: &Xml<'_>, node: Node<'_, '_>, key: &str) -> Result<Option<f64>, Refusal> {
    match node.attribute(key) {
        None => Ok(None),
        Some(text) => parse_f64(text)
            .map(Some)
            .ok_or_else(|| xml.refuse(node, format!("attribute `{key}=\"{text}\"` is not a number"))),
    }
}

/// A number as SBML and MathML write it: XML Schema's double (`1.5e-4`, `INF`, `-INF`, `NaN`).
pub(super) fn parse_f64(text: &str) -> Option<f64> {
    match text.trim() {
        "INF" | "inf" | "Infinity" => Some(f64::INFINITY),
        "-INF" | "-inf" | "-Infinity" => Some(f64::NEG_INFINITY),
        "NaN" | "nan" => Some(f64::NAN),
        t => t.parse::<f64>().ok(),
    }
}
