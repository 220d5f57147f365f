//! Names in the `.hyb` text: SBML ids kept where hybc can read them, those that clash with the
//! language's reserved words or built-in names mangled predictably (a `_` appended until the name
//! is free), and fresh names for what the translation adds (`S_amount`, `x_init`, `aux_1`).

use std::collections::{BTreeMap, HashSet};

/// hybc's reserved words (docs/language.md, "Lines, comments, names").
const KEYWORDS: [&str; 22] = [
    "model", "param", "state", "der", "let", "event", "when", "if", "then", "else", "mode", "initial",
    "output", "simulate", "in", "and", "or", "not", "crosses", "stop", "const", "for",
];

/// Built-in names that a model cannot declare: the time, `pi`, the vector functions and inputs
/// (the functions of `sema::Func` are added by [`Names::new`]).
const BUILTINS: [&str; 6] = ["t", "pi", "sum", "dot", "pwl", "pwc"];

/// Whether hybc reserves `name` (a keyword or a built-in name).
pub fn is_reserved(name: &str) -> bool {
    KEYWORDS.contains(&name)
        || BUILTINS.contains(&name)
        || crate::sema::Func::ALL.iter().any(|f| f.name() == name)
}

/// Whether `name` is a hybc name (letters, digits and `_`, not starting with a digit).
fn is_identifier(name: &str) -> bool {
    let mut chars = name.chars();
    chars.next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// The names taken so far and the SBML ids renamed.
pub(super) struct Names {
    taken: HashSet<String>,
    /// SBML id -> `.hyb` name, for every id that was renamed.
    pub renamed: BTreeMap<String, String>,
}

impl Names {
    /// Reserves every SBML id of the document as it is (so that fresh names never take one).
    pub fn new<'a>(ids: impl IntoIterator<Item = &'a str>) -> Names {
        let taken = ids.into_iter().map(str::to_string).collect();
        Names { taken, renamed: BTreeMap::new() }
    }

    /// The `.hyb` name of the SBML id `id`: itself, or mangled when hybc reserves it (`t` ->
    /// `t_`, then `t__` if `t_` is another id).
    pub fn sbml(&mut self, id: &str) -> String {
        if let Some(name) = self.renamed.get(id) {
            return name.clone();
        }
        if !is_reserved(id) && is_identifier(id) {
            return id.to_string();
        }
        let base: String =
            id.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' }).collect();
        let base = if base.starts_with(|c: char| c.is_ascii_digit()) || base.is_empty() {
            format!("_{base}")
        } else {
            base
        };
        let mut name = format!("{base}_");
        while self.taken.contains(&name) || is_reserved(&name) {
            name.push('_');
        }
        self.taken.insert(name.clone());
        self.renamed.insert(id.to_string(), name.clone());
        name
    }

    /// A fresh name from `base` (`base`, `base_2`, `base_3`, ...), reserved from now on.
    pub fn fresh(&mut self, base: &str) -> String {
        let base: String =
            base.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' }).collect();
        let base = if is_identifier(&base) { base } else { format!("_{base}") };
        let mut name = base.clone();
        let mut k = 1;
        while self.taken.contains(&name) || is_reserved(&name) || !is_identifier(&name) {
            k += 1;
            name = format!("{base}_{k}");
        }
        self.taken.insert(name.clone());
        name
    }
}
