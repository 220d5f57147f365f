//! The models hybc ships (`models/*.hyb`) and other directories of `.hyb` files, listed from disk
//! so that a model added to `models/` is covered by every test and bench that walks them, without
//! a list to keep in step. Only `std` is used: the benches include this file with `#[path]`.

use std::path::{Path, PathBuf};

/// One shipped model, read once.
#[allow(dead_code)] // each user (tests, every bench) reads the fields it needs
pub struct ShippedModel {
    /// The file stem: `ball` for `models/ball.hyb`.
    pub name: String,
    /// The path from the repository root (`models/ball.hyb`), as a user types it to `hybc`; the
    /// CLI tests run `hybc` from the root.
    pub path: String,
    /// The absolute path.
    pub full_path: PathBuf,
    /// The model's text.
    pub source: String,
}

/// The `.hyb` files in `dir` (relative to the repository root), sorted by name; panics on an
/// empty or unreadable directory, so that a moved directory cannot make a test vacuous.
pub fn hyb_files(dir: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(dir);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()))
        .map(|e| e.expect("directory entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "hyb"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no .hyb files in {}", dir.display());
    files
}

/// Every `models/*.hyb`, sorted by file name.
pub fn shipped_models() -> Vec<ShippedModel> {
    hyb_files("models")
        .into_iter()
        .map(|full_path| {
            let name = full_path.file_stem().expect("file name").to_string_lossy().into_owned();
            let source = std::fs::read_to_string(&full_path)
                .unwrap_or_else(|e| panic!("{}: {e}", full_path.display()));
            ShippedModel { path: format!("models/{name}.hyb"), name, full_path, source }
        })
        .collect()
}
