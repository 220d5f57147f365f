//! Data-driven cases of the `hybc` command line: each directory `tests/data/cli/<case>/` is one
//! case, and a new case is a new directory (tests/README.md):
//! - `args`: the arguments after `hybc` on the first line that is not a comment, split at
//!   whitespace (no quoting); `$CASE` stands for the case's directory (`$CASE/model.hyb`). Lines
//!   starting with `#` say what the case is for.
//! - any model or data file the arguments name, in the case's directory or elsewhere
//!   (`models/ball.hyb`: hybc runs from the repository root).
//! - `expected`: `exit N`, then what hybc printed to stderr under a `--- stderr` line and to stdout
//!   under a `--- stdout` line (a section is left out when nothing was printed there).
//!
//! Printed text must match exactly, numbers within a relative 1e-9 (one unit of the tenth
//! significant digit hybc prints); timings (a number followed by `ms` or `us`, the value of a JSON
//! key ending in `_seconds`) only need to be numbers. `HYBC_BLESS=1 cargo test --test it
//! cli_cases` writes `expected` of every case whose output does not match (review the diff).

use std::path::Path;
use std::process::Command;

use crate::support::printed::{close, tokens, Token};

/// Where the cases live, from the repository root.
const CASES: &str = "tests/data/cli";
/// Numbers agree when within this relative difference.
const REL: f64 = 1e-9;

/// The `expected` file's form of what a command printed and how it exited.
fn render(exit: Option<i32>, stderr: &str, stdout: &str) -> String {
    let mut out = match exit {
        Some(code) => format!("exit {code}\n"),
        None => "exit by signal\n".to_string(),
    };
    for (name, text) in [("stderr", stderr), ("stdout", stdout)] {
        if !text.is_empty() {
            out.push_str(&format!("--- {name}\n{text}"));
            if !text.ends_with('\n') {
                out.push('\n');
            }
        }
    }
    out
}

/// The arguments of a case's `args` file, with `$CASE` replaced by `case_dir`.
fn case_args(args_file: &str, case_dir: &str) -> Vec<String> {
    let line = args_file
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with('#'))
        .unwrap_or_else(|| panic!("{case_dir}/args: no command line"));
    line.split_whitespace().map(|w| w.replace("$CASE", case_dir)).collect()
}

/// Whether the number at `index` of `toks` is a timing: followed by ` ms` or ` us`, or the value
/// of a JSON key `..._seconds`.
fn is_timing(toks: &[Token], index: usize) -> bool {
    let unit_after = matches!(toks.get(index + 1), Some(Token::Text(t))
        if [" ms", " us"].iter().any(|u| t.strip_prefix(u).is_some_and(|rest| !rest.starts_with(char::is_alphanumeric))));
    let key_before =
        index > 0 && matches!(&toks[index - 1], Token::Text(t) if t.trim_end().ends_with("_seconds\":"));
    unit_after || key_before
}

/// The line (1-based) of `text` at the start of token `index`.
fn line_of(toks: &[Token], index: usize) -> usize {
    let before: String = toks[..index]
        .iter()
        .map(|t| match t {
            Token::Text(s) | Token::Number(s, _) => s.as_str(),
        })
        .collect();
    before.matches('\n').count() + 1
}

/// The first place where `got` differs from `want` beyond the tolerances, described.
fn difference(want: &str, got: &str) -> Option<String> {
    let (w, g) = (tokens(want), tokens(got));
    for (i, pair) in w.iter().zip(&g).enumerate() {
        let same = match pair {
            (Token::Text(a), Token::Text(b)) => a == b,
            (Token::Number(_, a), Token::Number(_, b)) => close(*a, *b, REL) || is_timing(&w, i),
            _ => false,
        };
        if !same {
            return Some(format!("line {}: expected {:?}, printed {:?}", line_of(&w, i), pair.0, pair.1));
        }
    }
    match w.len().cmp(&g.len()) {
        std::cmp::Ordering::Equal => None,
        std::cmp::Ordering::Greater => Some(format!("missing from the output: {:?}", &w[g.len()..])),
        std::cmp::Ordering::Less => Some(format!("printed beyond the expected: {:?}", &g[w.len()..])),
    }
}

#[test]
fn difference_masks_timings_and_compares_numbers_relatively() {
    let want = "compile 0.68 ms, run 34.9 us, 12 steps\n\"run_seconds\": 0.001, \"y\": 1.000000000\n";
    let got = "compile 1.25 ms, run 3.1 us, 12 steps\n\"run_seconds\": 2e-4, \"y\": 1.0000000001\n";
    assert_eq!(difference(want, got), None);
    assert!(difference("12 steps", "13 steps").is_some());
    assert!(difference("y = 1.000000000", "y = 1.00000001").is_some(), "1e-8 relative is too much");
    assert!(difference("run 3 ms", "run 3 msec").is_some(), "text must match");
    assert!(difference("0.5 mss", "0.6 mss").is_some(), "only the units ms and us are timings");
    assert!(difference("exit 1\n", "exit 2\n").is_some());
    assert!(difference("a 1", "a 1 b").is_some());
}

#[test]
fn every_cli_case_prints_its_expected_output() {
    let root = env!("CARGO_MANIFEST_DIR");
    let bless = std::env::var_os("HYBC_BLESS").is_some();
    let mut dirs: Vec<_> = std::fs::read_dir(Path::new(root).join(CASES))
        .expect("tests/data/cli")
        .map(|e| e.expect("directory entry").path())
        .filter(|p| p.is_dir())
        .collect();
    dirs.sort();
    assert!(dirs.len() >= 20, "only {} cases in {CASES}", dirs.len());
    let mut failures = Vec::new();
    for dir in &dirs {
        let name = dir.file_name().expect("a name").to_string_lossy().into_owned();
        let case_dir = format!("{CASES}/{name}");
        let args_file =
            std::fs::read_to_string(dir.join("args")).unwrap_or_else(|e| panic!("{case_dir}/args: {e}"));
        let args = case_args(&args_file, &case_dir);
        let out = Command::new(env!("CARGO_BIN_EXE_hybc"))
            .args(&args)
            .current_dir(root)
            .output()
            .expect("hybc runs");
        let actual = render(
            out.status.code(),
            &String::from_utf8_lossy(&out.stderr),
            &String::from_utf8_lossy(&out.stdout),
        );
        let expected_path = dir.join("expected");
        let problem = match std::fs::read_to_string(&expected_path) {
            Ok(expected) => difference(&expected, &actual),
            Err(e) => Some(format!("no expected output ({e})")),
        };
        if let Some(problem) = problem {
            if bless {
                std::fs::write(&expected_path, &actual).expect("expected file is writable");
            } else {
                failures
                    .push(format!("{case_dir}: hybc {}\n  {problem}\nprinted:\n{actual}", args.join(" ")));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} cases differ (HYBC_BLESS=1 rewrites their expected files):\n\n{}",
        failures.len(),
        dirs.len(),
        failures.join("\n")
    );
}
