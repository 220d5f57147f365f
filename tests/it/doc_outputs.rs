//! docs/tutorial.md runs as written: every `$ hybc ...` line inside a ```console block is run
//! (from the repository root, with this build's binary), and the numbers in what it prints (stderr
//! first, then stdout: the order a terminal shows for these commands, whose warnings come before
//! the report) must equal the numbers pasted below the command, in order. Equal means within a
//! relative 1e-9, one unit of the tenth significant digit hybc prints. Timings are left out on
//! both sides (see `numbers`). Arguments are split as a shell splits them, quotes included.
//!
//! After a change that moves printed numbers, `HYBC_BLESS=1 cargo test --release --test it tutorial`
//! rewrites every pasted output with what this build prints (release, so that the pasted
//! statistics lines show representative timings; review the diff before committing).

use std::process::Command;

use crate::support::printed::numbers as numbers_in;

/// One command of the tutorial and the output pasted under it.
struct Example {
    args: Vec<String>,
    expected: String,
}

fn examples(doc: &str) -> Vec<Example> {
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
        if let Some(command) = line.strip_prefix("$ hybc ") {
            out.extend(current.take());
            current = Some(Example { args: words(command), expected: String::new() });
        } else if let Some(ex) = current.as_mut() {
            ex.expected.push_str(line);
            ex.expected.push('\n');
        } else {
            panic!("output without a `$ hybc` command in docs/tutorial.md: {line}");
        }
    }
    out
}

/// A command's arguments as a POSIX shell splits them, for the quoting the tutorial uses: words
/// split at whitespace, except inside '...' or "..." (which are removed), so that
/// `--subject-to "y >= 0.9"` is one argument, as it is when a reader pastes it.
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
}

/// The numbers in `text`, in order, leaving out digits that are part of a name (`h0`, `dt1`) and
/// the timings: a run's statistics line (`... kernel calls, compile ... ms, run ... us`) whole,
/// an optimisation's or a fit's (`21 runs (20 evaluations, ...), compile ... ms, optimize ... ms`)
/// from its timings on (its counts of runs and evaluations are compared).
fn numbers(text: &str) -> Vec<f64> {
    text.lines()
        .filter(|l| !l.contains("kernel calls, compile"))
        .map(|l| l.find(", compile ").map_or(l, |i| &l[..i]))
        .flat_map(numbers_in)
        .collect()
}

#[test]
fn number_extraction_skips_names_and_reads_exponents() {
    let got = numbers("h0 = 1.000000000e-6, dt1/dh0 -4.4e-3 (d = -0.5). #3 main -> cooling 7\n9 steps, 1 kernel calls, compile 2 ms");
    assert_eq!(got, [1e-6, -4.4e-3, -0.5, 3.0, 7.0]);
}

/// What `hybc ARGS` prints, run from the repository root: stderr, then stdout.
fn printed(root: &str, args: &[String]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_hybc")).args(args).current_dir(root).output().expect("runs");
    format!("{}{}", String::from_utf8_lossy(&out.stderr), String::from_utf8_lossy(&out.stdout))
}

/// `doc` with the output under every `$ hybc` line of a console block replaced by what this
/// build prints.
fn blessed(root: &str, doc: &str) -> String {
    let mut out = String::new();
    let mut in_console = false;
    let mut skipping = false;
    for line in doc.lines() {
        if line.starts_with("```") {
            in_console = !in_console && line.starts_with("```console");
            skipping = false;
        } else if in_console {
            if let Some(command) = line.strip_prefix("$ hybc ") {
                out.push_str(line);
                out.push('\n');
                let args = words(command);
                out.push_str(&printed(root, &args));
                skipping = true;
                continue;
            }
        }
        if !skipping {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

#[test]
fn every_tutorial_command_prints_what_the_tutorial_shows() {
    let root = env!("CARGO_MANIFEST_DIR");
    let path = format!("{root}/docs/tutorial.md");
    let mut doc = std::fs::read_to_string(&path).expect("docs/tutorial.md");
    if std::env::var_os("HYBC_BLESS").is_some() {
        doc = blessed(root, &doc);
        std::fs::write(&path, &doc).expect("docs/tutorial.md is writable");
    }
    let examples = examples(&doc);
    assert!(examples.len() >= 7, "only {} commands found", examples.len());
    for ex in examples {
        let shown = format!("hybc {}", ex.args.join(" "));
        let actual = printed(root, &ex.args);
        let (want, got) = (numbers(&ex.expected), numbers(&actual));
        assert!(!want.is_empty(), "{shown}: no output pasted");
        assert_eq!(want.len(), got.len(), "{shown}: pasted\n{}\nprinted\n{actual}", ex.expected);
        for (w, g) in want.iter().zip(&got) {
            assert!(
                (w - g).abs() <= 1e-9 * w.abs().max(g.abs()),
                "{shown}: pasted {w}, printed {g}\n{actual}"
            );
        }
    }
}
