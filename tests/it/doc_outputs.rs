//! The documents run as written: in README.md and every markdown file under docs/, every
//! `$ hybc ...` line inside a ```console block is run (from the repository root, with this build's
//! binary; `$ cargo run --release -- ARGS` is run as `hybc ARGS`), and the numbers in what it
//! prints (stderr first, then stdout: the order a terminal shows for these commands, whose
//! warnings come before the report) must equal the numbers pasted below the command, in order.
//! Equal means within a relative 1e-9, one unit of the tenth significant digit hybc prints.
//! Timings are left out on both sides (see `numbers`). Arguments are split as a shell splits them,
//! quotes included; a `#` that starts a word begins a comment (`# exit code 4`). Output that no
//! command produced is an error, so every shown output of hybc is checked: anything else is
//! shown in a ```sh block or as prose. The commands run in a debug build: a shown command must
//! take at most a few seconds there.
//!
//! After a change that moves printed numbers, `HYBC_BLESS=1 cargo test --release --test it
//! doc_outputs` rewrites every pasted output with what this build prints (release, so that the
//! pasted statistics lines show representative timings; review the diff before committing).

use std::process::Command;

use crate::support::printed::numbers as numbers_in;

/// The prefixes of a command line in a console block; what follows is hybc's arguments.
const PROMPTS: [&str; 2] = ["$ hybc ", "$ cargo run --release -- "];

/// The arguments of a console line that is a hybc command.
fn command(line: &str) -> Option<Vec<String>> {
    PROMPTS.iter().find_map(|p| line.strip_prefix(p)).map(words)
}

/// One command of a document and the output pasted under it.
struct Example {
    args: Vec<String>,
    expected: String,
}

fn examples(name: &str, doc: &str) -> Vec<Example> {
    let mut out: Vec<Example> = Vec::new();
    let mut in_console = false;
    let mut current: Option<Example> = None;
    for line in doc.lines() {
        if line.starts_with("```") {
            in_console = !in_console && line.starts_with("```console");
            out.extend(current.take());
            continue;
        }
        if !in_console {
            continue;
        }
        if let Some(args) = command(line) {
            out.extend(current.take());
            current = Some(Example { args, expected: String::new() });
        } else if let Some(ex) = current.as_mut() {
            ex.expected.push_str(line);
            ex.expected.push('\n');
        } else {
            panic!("output without a `$ hybc` command in {name}: {line}");
        }
    }
    out
}

/// A command's arguments as a POSIX shell splits them, for the quoting the documents use: words
/// split at whitespace, except inside '...' or "..." (which are removed), so that
/// `--subject-to "y >= 0.9"` is one argument, as it is when a reader pastes it; a `#` that starts
/// a word outside quotes ends the command (a comment, `touchdown#4` is a word).
fn words(command: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut word: Option<String> = None;
    let mut quote: Option<char> = None;
    for c in command.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), c) => word.get_or_insert_with(String::new).push(c),
            (None, '\'' | '"') => {
                quote = Some(c);
                word.get_or_insert_with(String::new);
            }
            (None, '#') if word.is_none() => break,
            (None, c) if c.is_whitespace() => out.extend(word.take()),
            (None, c) => word.get_or_insert_with(String::new).push(c),
        }
    }
    assert!(quote.is_none(), "unclosed quote in `{command}`");
    out.extend(word);
    out
}

#[test]
fn words_keep_quoted_arguments_whole() {
    assert_eq!(
        words(r#"optimize m.hyb --subject-to "y >= 0.9" --set 'u[0]=1'  --quiet"#),
        ["optimize", "m.hyb", "--subject-to", "y >= 0.9", "--set", "u[0]=1", "--quiet"]
    );
    assert_eq!(
        words("fit m.hyb --target touchdown#4=2.5   # exit code 4"),
        ["fit", "m.hyb", "--target", "touchdown#4=2.5"]
    );
    assert_eq!(
        command("$ cargo run --release -- run m.hyb"),
        Some(vec!["run".to_string(), "m.hyb".to_string()])
    );
}

/// The numbers in `text`, in order, leaving out digits that are part of a name (`h0`, `dt1`) and
/// the timings: a run's statistics line (`... kernel calls, compile ... ms, run ... us`) whole,
/// an optimisation's or a fit's (`21 runs (20 evaluations, ...), compile ... ms, optimize ... ms`)
/// from its timings on (its counts of runs and evaluations are compared), and in JSON the value
/// of every key ending in `_seconds`.
fn numbers(text: &str) -> Vec<f64> {
    text.lines()
        .filter(|l| !l.contains("kernel calls, compile"))
        .map(|l| l.find(", compile ").map_or(l, |i| &l[..i]))
        .map(without_seconds)
        .flat_map(|l| numbers_in(&l))
        .collect()
}

/// `line` without the values of JSON keys ending in `_seconds` (`"run_seconds": 3.4e-5`).
fn without_seconds(line: &str) -> String {
    const KEY_END: &str = "_seconds\":";
    let mut out = String::new();
    let mut rest = line;
    while let Some(i) = rest.find(KEY_END) {
        out.push_str(&rest[..i]);
        rest = rest[i + KEY_END.len()..].trim_start();
        rest =
            rest.trim_start_matches(|c: char| c.is_ascii_digit() || matches!(c, '.' | 'e' | 'E' | '-' | '+'));
    }
    out.push_str(rest);
    out
}

#[test]
fn number_extraction_skips_names_and_reads_exponents() {
    let got = numbers("h0 = 1.000000000e-6, dt1/dh0 -4.4e-3 (d = -0.5). #3 main -> cooling 7\n9 steps, 1 kernel calls, compile 2 ms");
    assert_eq!(got, [1e-6, -4.4e-3, -0.5, 3.0, 7.0]);
    assert_eq!(
        numbers(r#"{"steps": 9, "compile_seconds": 0.0007, "run_seconds": 3.4e-5, "events": 4}"#),
        [9.0, 4.0]
    );
}

/// What `hybc ARGS` prints, run from the repository root: stderr, then stdout.
fn printed(root: &str, args: &[String]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_hybc")).args(args).current_dir(root).output().expect("runs");
    format!("{}{}", String::from_utf8_lossy(&out.stderr), String::from_utf8_lossy(&out.stdout))
}

/// Whether the numbers of two outputs agree: as many, each within a relative 1e-9.
fn same_numbers(want: &[f64], got: &[f64]) -> bool {
    want.len() == got.len() && want.iter().zip(got).all(|(w, g)| (w - g).abs() <= 1e-9 * w.abs().max(g.abs()))
}

/// `doc` with the output under every `$ hybc` line of a console block replaced by what this
/// build prints, where its numbers differ (an output whose numbers agree keeps its pasted text,
/// timings included, so that blessing from a debug build rewrites only what moved).
fn blessed(root: &str, doc: &str) -> String {
    let mut out = String::new();
    let mut in_console = false;
    // The output of the command being read: what this build prints, and what is pasted.
    let mut pending: Option<(String, String)> = None;
    let flush = |out: &mut String, pending: &mut Option<(String, String)>| {
        if let Some((printed, pasted)) = pending.take() {
            let keep = !pasted.is_empty() && same_numbers(&numbers(&pasted), &numbers(&printed));
            out.push_str(if keep { &pasted } else { &printed });
        }
    };
    for line in doc.lines() {
        if line.starts_with("```") {
            flush(&mut out, &mut pending);
            in_console = !in_console && line.starts_with("```console");
        } else if in_console {
            if let Some(args) = command(line) {
                flush(&mut out, &mut pending);
                out.push_str(line);
                out.push('\n');
                pending = Some((printed(root, &args), String::new()));
                continue;
            }
            if let Some((_, pasted)) = pending.as_mut() {
                pasted.push_str(line);
                pasted.push('\n');
                continue;
            }
        }
        out.push_str(line);
        out.push('\n');
    }
    flush(&mut out, &mut pending);
    out
}

/// README.md and every markdown file under docs/, relative to the repository root.
fn documents(root: &str) -> Vec<String> {
    let mut out = vec!["README.md".to_string()];
    let mut dirs = vec!["docs".to_string()];
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(format!("{root}/{dir}")).expect("docs/ is readable") {
            let entry = entry.expect("a directory entry");
            let name = format!("{dir}/{}", entry.file_name().to_string_lossy());
            if entry.file_type().expect("a file type").is_dir() {
                dirs.push(name);
            } else if name.ends_with(".md") {
                out.push(name);
            }
        }
    }
    out.sort();
    out
}

#[test]
fn every_shown_command_prints_what_its_document_shows() {
    let root = env!("CARGO_MANIFEST_DIR");
    let mut checked = 0;
    for name in documents(root) {
        let path = format!("{root}/{name}");
        let mut doc = std::fs::read_to_string(&path).expect("a readable document");
        if std::env::var_os("HYBC_BLESS").is_some() {
            let blessed = blessed(root, &doc);
            if blessed != doc {
                std::fs::write(&path, &blessed).expect("the document is writable");
                doc = blessed;
            }
        }
        for ex in examples(&name, &doc) {
            let shown = format!("{name}: hybc {}", ex.args.join(" "));
            let actual = printed(root, &ex.args);
            let (want, got) = (numbers(&ex.expected), numbers(&actual));
            assert!(!want.is_empty(), "{shown}: no output pasted");
            assert!(same_numbers(&want, &got), "{shown}: pasted\n{}\nprinted\n{actual}", ex.expected);
            checked += 1;
        }
    }
    assert!(checked >= 30, "only {checked} commands found");
}
