//! Property tests of the front end: whatever the bytes, `check_source` returns a model or
//! errors, never panics, and every error renders with a location.

use proptest::prelude::*;

use crate::support::models::shipped_models;

/// The texts of the shipped models, the seeds the mutations start from.
fn shipped_sources() -> Vec<String> {
    shipped_models().into_iter().map(|m| m.source).collect()
}

/// Characters that matter to the grammar, so that mutations reach deep into the parser.
const ALPHABET: &[char] = &[
    ' ', '\n', '(', ')', '{', '}', '[', ']', ',', '=', ':', '<', '>', '-', '+', '*', '/', '^', '#', '.', 'e',
    'x', 'y', 't', '0', '1', '9',
];

fn check_never_panics(source: &str) {
    if let Err(e) = hybc::check_source(source) {
        let rendered = e.render("fuzz.hyb", source);
        assert!(rendered.contains("fuzz.hyb"), "no location in\n{rendered}");
    }
}

#[derive(Debug, Clone)]
enum Mutation {
    Delete(usize, usize),
    Insert(usize, char),
    Duplicate(usize, usize),
}

fn apply(source: &str, mutations: &[Mutation]) -> String {
    let mut chars: Vec<char> = source.chars().collect();
    for m in mutations {
        let n = chars.len().max(1);
        match *m {
            Mutation::Delete(at, len) => {
                let at = at % n;
                let end = (at + len % 8).min(chars.len());
                chars.drain(at.min(chars.len())..end);
            }
            Mutation::Insert(at, c) => chars.insert(at % (chars.len() + 1), c),
            Mutation::Duplicate(at, len) => {
                let at = at % n;
                let end = (at + len % 40).min(chars.len());
                let piece: Vec<char> = chars[at.min(end)..end].to_vec();
                let pos = at.min(chars.len());
                chars.splice(pos..pos, piece);
            }
        }
    }
    chars.into_iter().collect()
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), any::<usize>()).prop_map(|(a, l)| Mutation::Delete(a, l)),
        (any::<usize>(), prop::sample::select(ALPHABET)).prop_map(|(a, c)| Mutation::Insert(a, c)),
        (any::<usize>(), any::<usize>()).prop_map(|(a, l)| Mutation::Duplicate(a, l)),
    ]
}

proptest! {
    #![proptest_config(crate::support::proptest_config(400))]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        check_never_panics(&String::from_utf8_lossy(&bytes));
    }

    #[test]
    fn grammar_soup_never_panics(chars in prop::collection::vec(prop::sample::select(ALPHABET), 0..200)) {
        let body: String = chars.into_iter().collect();
        check_never_panics(&format!("model m\n{body}"));
    }

    #[test]
    fn mutated_models_never_panic(
        model in prop::sample::select(shipped_sources()),
        mutations in prop::collection::vec(mutation(), 1..6),
    ) {
        check_never_panics(&apply(&model, &mutations));
    }
}

#[test]
fn pathological_nesting_and_length_are_errors_not_crashes() {
    let deep = format!("model m\nstate y = 1\nder(y) = {}y{}\n", "(".repeat(5000), ")".repeat(5000));
    assert!(hybc::check_source(&deep).is_err());
    let long = format!("model m\nstate y = 1\nder(y) = y{}\n", " + y".repeat(5000));
    assert!(hybc::check_source(&long).is_err());
    let ok = format!("model m\nstate y = 1\nder(y) = {}y{}\n", "(".repeat(60), ")".repeat(60));
    assert!(hybc::check_source(&ok).is_ok());
}
