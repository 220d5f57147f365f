//! SBML import: an SBML Level 2 or 3 document -> a readable `.hyb` model text that the rest of
//! the pipeline compiles (docs/sbml.md: what is supported, translated and refused).
//!
//! A stage beside `syntax`: it reads XML (roxmltree, only here) and writes text; it knows the
//! language's reserved names (`sema::Func`) and nothing below. The door (`Model::from_sbml`)
//! parses its text as any model.
//!
//! ```text
//! xml.rs (roxmltree, positions) -> read.rs (SBML elements -> Sbml; math.rs: MathML -> Math,
//!   function definitions inlined, constants folded) -> translate.rs (storages, flows, initial
//!   values; events.rs: triggers -> crossings;
//!   order.rs: random event order refused) -> print.rs (Math -> .hyb text; names.rs)
//! ```

mod error;
mod events;
mod math;
mod names;
mod order;
mod print;
mod read;
mod translate;
mod xml;

use std::collections::BTreeMap;

pub use error::{Refusal, SbmlError};
pub use names::is_reserved;

/// A translated SBML model: the `.hyb` text and, per SBML id, the `.hyb` expression of its value
/// (and a species' amount and concentration), which is how results are read by SBML name.
#[derive(Clone, Debug)]
pub struct Import {
    /// The `.hyb` model text.
    pub text: String,
    /// SBML ids that hybc reserves, with the names they got (`t` -> `t_`).
    pub renamed: Vec<(String, String)>,
    value: BTreeMap<String, String>,
    amount: BTreeMap<String, String>,
    concentration: BTreeMap<String, String>,
}

impl Import {
    /// The `.hyb` expression of the value of the SBML symbol `id` (as SBML math reads it: a
    /// species in concentration unless it has only substance units).
    pub fn value_of(&self, id: &str) -> Option<&str> {
        self.value.get(id).map(String::as_str)
    }

    /// The `.hyb` expression of species `id`'s amount.
    pub fn amount_of(&self, id: &str) -> Option<&str> {
        self.amount.get(id).map(String::as_str)
    }

    /// The `.hyb` expression of species `id`'s concentration.
    pub fn concentration_of(&self, id: &str) -> Option<&str> {
        self.concentration.get(id).map(String::as_str)
    }
}

/// Translates an SBML document to a `.hyb` model text, or refuses it with every reason found,
/// each at its element's line and column.
pub fn import(xml_text: &str) -> Result<Import, SbmlError> {
    let doc = match xml::Xml::parse(xml_text) {
        Ok(doc) => doc,
        Err(r) => return Err(SbmlError { refusals: vec![r] }),
    };
    let mut out = Vec::new();
    let result = read::read(&doc, &mut out).and_then(|sbml| {
        if out.is_empty() {
            translate::translate(&doc, &sbml, &mut out)
        } else {
            None
        }
    });
    match result {
        Some((text, q, renamed)) if out.is_empty() => {
            Ok(Import { text, renamed, value: q.value, amount: q.amount, concentration: q.concentration })
        }
        _ => {
            out.sort_by_key(|r| r.offset);
            out.dedup();
            if out.is_empty() {
                // Every path that gives up records why; this keeps the promise if one does not.
                out.push(Refusal {
                    offset: 0,
                    line: 1,
                    column: 1,
                    element: "<sbml>".to_string(),
                    reason: "the model could not be translated".to_string(),
                });
            }
            Err(SbmlError { refusals: out })
        }
    }
}
