//! A fuzz test over the whole front end and run path, with a fixed seed and a fixed count: the
//! shipped models mutated by byte flips, token edits, control and invisible characters, line-end
//! changes, long lines, deep nesting, extreme numbers and long `let` chains. Every input must give
//! either a located diagnostic (file:line:column and a caret) or a model that compiles and runs
//! to an outcome (a result or a runtime error), never a panic. An abort (stack overflow, out of
//! memory) kills the test binary, which fails the test as well.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::Instant;

use rand_chacha::ChaCha8Rng;
use rand_core::{Rng, SeedableRng};

/// The generator's seed: CI fuzzes the same inputs on every run (a failure names its case).
const SEED: u64 = 20261124;
/// Inputs generated and run: the same ones on every run whatever the machine's load (a time
/// budget made the count, and so the inputs, depend on it): 4,247 inputs took 20 s in a debug build
/// run alone, so these take about 3 s.
const CASES: usize = 600;

/// Control, invisible and otherwise awkward characters.
const NASTY: &[char] = &[
    '\0', '\x07', '\x08', '\x0b', '\x0c', '\x1b', '\x7f', '\u{85}', '\u{9b}', '\u{a0}', '\u{ad}', '\u{200b}',
    '\u{200e}', '\u{202e}', '\u{2066}', '\u{feff}', '\u{fffd}', 'é', '∂', '𝑥',
];

const EXTREME_NUMBERS: &[&str] =
    &["1e308", "-1e308", "1e309", "1e-320", "0", "-0", "0.0e0", "123456789012345678901234567890", "1e-400"];

fn pick<'a, T>(rng: &mut ChaCha8Rng, items: &'a [T]) -> &'a T {
    &items[(rng.next_u64() % items.len() as u64) as usize]
}

fn below(rng: &mut ChaCha8Rng, n: usize) -> usize {
    (rng.next_u64() % n.max(1) as u64) as usize
}

/// Byte offsets of the starts of whitespace-separated tokens.
fn token_starts(text: &str) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, c) in text.char_indices() {
        match (c.is_whitespace(), start) {
            (false, None) => start = Some(i),
            (true, Some(s)) => {
                out.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push((s, text.len()));
    }
    out
}

fn char_boundary(text: &str, at: usize) -> usize {
    let mut at = at.min(text.len());
    while !text.is_char_boundary(at) {
        at -= 1;
    }
    at
}

/// One mutation of `text`; returns its name (for failure messages) and the new text.
fn mutate(rng: &mut ChaCha8Rng, text: &str) -> (&'static str, String) {
    let tokens = token_starts(text);
    match below(rng, 9) {
        0 => {
            let mut bytes = text.as_bytes().to_vec();
            for _ in 0..1 + below(rng, 4) {
                let i = below(rng, bytes.len());
                bytes[i] ^= 1 << below(rng, 8);
            }
            ("byte flips", String::from_utf8_lossy(&bytes).into_owned())
        }
        1 => {
            let (s, e) = *pick(rng, &tokens);
            ("token deleted", format!("{}{}", &text[..s], &text[e..]))
        }
        2 => {
            let (s, e) = *pick(rng, &tokens);
            let (s2, _) = *pick(rng, &tokens);
            ("token copied", format!("{} {} {}", &text[..s2], &text[s..e], &text[s2..]))
        }
        3 => {
            let at = char_boundary(text, below(rng, text.len() + 1));
            let c = *pick(rng, NASTY);
            ("nasty character", format!("{}{c}{}", &text[..at], &text[at..]))
        }
        4 => {
            let ends = *pick(rng, &["\r\n", "\r", "\n\r", "\u{2028}"]);
            ("line ends", text.replace('\n', ends))
        }
        5 => {
            let at = char_boundary(text, below(rng, text.len() + 1));
            let piece = *pick(rng, &["x", " + 1", "(", "a_b", "9"]);
            let long = piece.repeat(1 + below(rng, 6000 / piece.len()));
            ("long line", format!("{}{long}{}", &text[..at], &text[at..]))
        }
        6 => {
            let (s, e) = *pick(rng, &tokens);
            let depth = 1 + below(rng, 100);
            let nested = format!("{}{}{}", "(".repeat(depth), &text[s..e], ")".repeat(depth));
            ("deep nesting", format!("{}{nested}{}", &text[..s], &text[e..]))
        }
        7 => {
            let numbers: Vec<&(usize, usize)> = tokens
                .iter()
                .filter(|(s, e)| text[*s..*e].trim_end_matches(',').parse::<f64>().is_ok())
                .collect();
            let Some(&&(s, e)) = numbers.get(below(rng, numbers.len())) else {
                return ("no number", text.to_string());
            };
            ("extreme number", format!("{}{}{}", &text[..s], pick(rng, EXTREME_NUMBERS), &text[e..]))
        }
        _ => {
            let n = 1 + below(rng, 300);
            let mut lets = String::from("\nlet fz0 = 1\n");
            for k in 1..n {
                let twice = if below(rng, 2) == 0 { "+" } else { "*" };
                lets.push_str(&format!("let fz{k} = fz{} {twice} fz{}\n", k - 1, k - 1));
            }
            lets.push_str(&format!("output fz = fz{}\n", n - 1));
            ("let chain", format!("{text}{lets}"))
        }
    }
}

/// What became of one input.
enum Outcome {
    Refused,
    Ran,
}

/// The whole path a user's text takes: check, compile, a short run.
fn exercise(text: &str) -> Result<Outcome, String> {
    let model = match hybc::Model::parse_named(text, "fuzz.hyb") {
        Ok(model) => model,
        Err(e) => {
            let rendered = e.to_string();
            let located = rendered.contains("fuzz.hyb:") && rendered.contains('^');
            let clean = !rendered.chars().any(|c| hybc::diag::is_invisible(c) || c == '\r');
            return match (located, clean) {
                (true, true) => Ok(Outcome::Refused),
                (false, _) => Err(format!("diagnostic without a location:\n{rendered}")),
                (_, false) => Err(format!("diagnostic echoes an invisible character:\n{rendered:?}")),
            };
        }
    };
    let compiled = model.compile_all().map_err(|e| format!("compile failed: {e}"))?;
    let mut opts = model.sim_options();
    opts.t_end = opts.t_start + (opts.t_end - opts.t_start).clamp(0.0, 1.0);
    opts.max_steps = 20_000;
    opts.max_events = 200;
    // A runtime error is an outcome; the run must only return.
    let _ = compiled.simulate(&model.params(), &opts);
    Ok(Outcome::Ran)
}

#[test]
fn mutated_models_are_refused_with_a_location_or_run() {
    let models: Vec<String> =
        crate::support::models::shipped_models().into_iter().map(|m| m.source).collect();
    let mut rng = ChaCha8Rng::seed_from_u64(SEED);
    let start = Instant::now();
    let (mut cases, mut refused, mut ran) = (0usize, 0usize, 0usize);
    let mut failures = Vec::new();
    while cases < CASES {
        let base = pick(&mut rng, &models).clone();
        let mut text = base;
        let mut applied = Vec::new();
        for _ in 0..1 + below(&mut rng, 3) {
            let (name, next) = mutate(&mut rng, &text);
            applied.push(name);
            text = next;
        }
        cases += 1;
        match catch_unwind(AssertUnwindSafe(|| exercise(&text))) {
            Ok(Ok(Outcome::Refused)) => refused += 1,
            Ok(Ok(Outcome::Ran)) => ran += 1,
            Ok(Err(why)) => failures.push(format!("case {cases} ({applied:?}): {why}")),
            Err(_) => failures.push(format!("case {cases} ({applied:?}) panicked on:\n{text}")),
        }
        if failures.len() >= 5 {
            break;
        }
    }
    eprintln!("fuzzed {cases} inputs in {:.1?}: {refused} refused, {ran} ran", start.elapsed());
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
    assert!(refused > 0 && ran > 0, "{refused} refused, {ran} ran: the mutations miss one side");
}

#[test]
fn control_characters_are_named_and_escaped_in_diagnostics() {
    let text = "model m\nstate x = 1\x1b[2J\nder(x) = -x\n";
    let err = hybc::Model::parse_named(text, "m.hyb").unwrap_err().to_string();
    assert!(err.contains("control character <U+001B>"), "{err}");
    assert!(err.contains("m.hyb:2:12"), "{err}");
    assert!(err.contains("x = 1<U+001B>[2J"), "{err}");
    assert!(!err.contains('\x1b'), "{err:?}");

    // A right-to-left override (as in "Trojan source" attacks) is shown, not obeyed.
    let text = "model m\nstate x = 1 \u{202e}+ 2\nder(x) = -x\n";
    let err = hybc::Model::parse_named(text, "m.hyb").unwrap_err().to_string();
    assert!(err.contains("invisible character <U+202E>"), "{err}");
    assert!(!err.contains('\u{202e}'), "{err:?}");
}

#[test]
fn a_bom_is_skipped_and_every_line_end_counts_alike() {
    let ball = include_str!("../../models/ball.hyb");
    let plain = hybc::Model::parse(ball).expect("the ball checks");
    for variant in [format!("\u{feff}{ball}"), ball.replace('\n', "\r\n"), ball.replace('\n', "\r")] {
        let model = hybc::Model::parse(&variant).expect("the ball checks with a BOM or other line ends");
        assert_eq!(model.checked().states.len(), plain.checked().states.len());
        assert_eq!(model.sim_options().t_end, plain.sim_options().t_end);
    }
    // An error on line 3 is reported on line 3 whatever the line ends.
    for nl in ["\n", "\r\n", "\r"] {
        let text = format!("\u{feff}model m{nl}state x = 1{nl}der(x) = -x +{nl}");
        let err = hybc::Model::parse_named(&text, "m.hyb").unwrap_err().to_string();
        assert!(err.contains("m.hyb:3:"), "{nl:?}:\n{err}");
        assert!(!err.contains('\r'), "{nl:?}:\n{err:?}");
    }
}
