//! Data-driven front-end tests: every file in `tests/data/parse_ok` and `models/` checks clean;
//! every file in `tests/data/parse_err` and `tests/data/sema_err` fails in the right stage, and
//! its rendered diagnostics are pinned by an insta snapshot. A new file is a new test.

use std::fs;
use std::path::Path;

use hybc::FrontendError;

use crate::support::models::{hyb_files, shipped_models};

fn stem(path: &Path) -> String {
    path.file_stem().expect("file name").to_string_lossy().into_owned()
}

fn relative(path: &Path) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    path.strip_prefix(root).unwrap_or(path).display().to_string()
}

#[test]
fn shipped_models_check_clean() {
    for model in shipped_models() {
        if let Err(e) = hybc::check_source(&model.source) {
            panic!("{} does not check:\n{}", model.path, e.render(&model.path, &model.source));
        }
    }
}

#[test]
fn parse_ok_files_check_clean() {
    for path in hyb_files("tests/data/parse_ok") {
        let source = fs::read_to_string(&path).expect("readable model");
        if let Err(e) = hybc::check_source(&source) {
            panic!("{} does not check:\n{}", path.display(), e.render(&relative(&path), &source));
        }
    }
}

fn snapshot_errors(dir: &str, want_parse_error: bool) {
    for path in hyb_files(dir) {
        let source = fs::read_to_string(&path).expect("readable model");
        let err = match hybc::check_source(&source) {
            Ok(_) => panic!("{} was accepted but should fail", path.display()),
            Err(e) => e,
        };
        let is_parse_error = matches!(err, FrontendError::Parse(_));
        assert_eq!(is_parse_error, want_parse_error, "{}: wrong stage: {err:?}", path.display());
        let rendered = err.render(&relative(&path), &source);
        assert!(rendered.contains('^'), "{}: no caret in\n{rendered}", path.display());
        insta::assert_snapshot!(
            format!("{}__{}", dir.rsplit('/').next().unwrap_or(dir), stem(&path)),
            rendered
        );
    }
}

#[test]
fn parse_errors_are_reported_with_a_caret() {
    snapshot_errors("tests/data/parse_err", true);
}

#[test]
fn semantic_errors_are_reported_with_a_caret() {
    snapshot_errors("tests/data/sema_err", false);
}

#[test]
fn every_error_in_a_file_is_reported() {
    let source =
        fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sema_err/many_errors.hyb"))
            .expect("readable");
    match hybc::check_source(&source) {
        Err(FrontendError::Check(errors)) => {
            assert!(errors.len() >= 5, "only {} errors: {errors:?}", errors.len())
        }
        other => panic!("expected semantic errors, got {other:?}"),
    }
}
