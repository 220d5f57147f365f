//! SBML at the door: an SBML document imported (`crate::sbml`) into a `.hyb` text, then parsed
//! and checked as any model. `Model::from_file` sends `.xml` and `.sbml` paths here.

use std::io::Read as _;
use std::path::Path;

use super::{Error, Model, MAX_MODEL_BYTES};
use crate::sbml::{Import, SbmlError};

/// An SBML document the importer refused, with its refusals rendered against the file.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{rendered}")]
pub struct ImportError {
    /// The refusals, each at its element's line and column.
    pub errors: SbmlError,
    /// The refusals rendered as text (`error: ...`, `--> file:line:column`, the element).
    pub rendered: String,
}

/// Whether `path` names an SBML document by its extension (`.xml`, `.sbml`).
pub fn is_sbml_path(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("xml") || e.eq_ignore_ascii_case("sbml"))
}

/// Reads a file of at most [`MAX_MODEL_BYTES`] as text (bytes that are not UTF-8 replaced).
pub(super) fn read_text(path: &Path) -> Result<String, Error> {
    let read_error = |source| Error::Read { path: path.to_path_buf(), source };
    let file = std::fs::File::open(path).map_err(read_error)?;
    let mut bytes = Vec::new();
    file.take(MAX_MODEL_BYTES + 1).read_to_end(&mut bytes).map_err(read_error)?;
    if bytes.len() as u64 > MAX_MODEL_BYTES {
        return Err(Error::TooLarge { path: path.to_path_buf(), limit: MAX_MODEL_BYTES });
    }
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

/// Imports the SBML document `xml` (refusals naming `file_name`), without checking the text.
pub fn import_sbml(xml: &str, file_name: &str) -> Result<Import, Error> {
    crate::sbml::import(xml).map_err(|errors| {
        let rendered = errors.render(file_name);
        Error::Import(ImportError { errors, rendered })
    })
}

/// Reads and imports the SBML file at `path` ([`import_sbml`]).
pub fn import_sbml_file(path: impl AsRef<Path>) -> Result<Import, Error> {
    let path = path.as_ref();
    import_sbml(&read_text(path)?, &path.display().to_string())
}

impl Model {
    /// Imports the SBML document `xml` and checks the `.hyb` text it becomes. Refusals name
    /// `file_name` with the line and column of the element refused; the checked model's
    /// diagnostics (if the text does not check) name `file_name (imported)`.
    pub fn from_sbml(xml: &str, file_name: &str) -> Result<Model, Error> {
        let import = import_sbml(xml, file_name)?;
        Model::parse_named(&import.text, &format!("{file_name} (imported)"))
    }

    /// Reads an SBML file (at most [`MAX_MODEL_BYTES`]) and imports it ([`Self::from_sbml`]).
    pub fn from_sbml_file(path: impl AsRef<Path>) -> Result<Model, Error> {
        let path = path.as_ref();
        Model::from_sbml(&read_text(path)?, &path.display().to_string())
    }
}
