//! The SBML Test Suite's semantic cases run through `hybc::sbml::import` and hybc's integrator
//! (issue #42): pass / fail / refused / error counts overall and by the suite's component and test
//! tags. The suite is not in the repository: fetch sbmlteam/sbml-test-suite and point this at its
//! `cases/semantic`.
//!
//! Run: `cargo run --release --example sbml_suite -- PATH/cases/semantic [CASE ...]`;
//! `SBML_VERBOSE=1` prints every case's outcome; `SBML_CHECK_GRAD=1` also runs the gradient
//! checker (`--check-grad`, every parameter) on each passing case with events and counts its
//! verdicts. The figures are in docs/accuracy.md.

use std::collections::BTreeMap;
use std::path::Path;

#[path = "../support/sbml_case.rs"]
mod sbml_case;
use sbml_case::{check_gradients, run_case, GradOutcome, Outcome};

#[derive(Default)]
struct Count {
    pass: usize,
    fail: usize,
    refused: usize,
    error: usize,
}

impl Count {
    fn add(&mut self, o: &Outcome) {
        match o {
            Outcome::Pass => self.pass += 1,
            Outcome::Fail(_) => self.fail += 1,
            Outcome::Refused(_) => self.refused += 1,
            Outcome::Error(_) => self.error += 1,
        }
    }
    fn row(&self, name: &str) -> String {
        let total = self.pass + self.fail + self.refused + self.error;
        format!("| {name} | {total} | {} | {} | {} | {} |", self.pass, self.fail, self.refused, self.error)
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(root) = args.first() else {
        eprintln!("usage: sbml_suite PATH/cases/semantic [CASE ...]");
        std::process::exit(2);
    };
    let verbose = std::env::var("SBML_VERBOSE").is_ok();
    let root = Path::new(root);
    let mut cases: Vec<String> = if args.len() > 1 {
        args[1..].iter().map(|c| format!("{:0>5}", c)).collect()
    } else {
        std::fs::read_dir(root)
            .expect("the suite's cases/semantic")
            .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().to_string()))
            .filter(|n| n.len() == 5 && n.chars().all(|c| c.is_ascii_digit()))
            .collect()
    };
    cases.sort();
    let mut all = Count::default();
    let mut by_component: BTreeMap<String, Count> = BTreeMap::new();
    let mut by_test: BTreeMap<String, Count> = BTreeMap::new();
    let mut reasons: BTreeMap<String, usize> = BTreeMap::new();
    let check_grad = std::env::var("SBML_CHECK_GRAD").is_ok();
    let mut grad: BTreeMap<String, usize> = BTreeMap::new();
    let start = std::time::Instant::now();
    for case in &cases {
        let dir = root.join(case);
        let result = std::panic::catch_unwind(|| run_case(&dir, case));
        let (tags, outcome) = match result {
            Ok(r) => r,
            Err(_) => (Default::default(), Outcome::Error("panic".to_string())),
        };
        all.add(&outcome);
        for c in &tags.components {
            by_component.entry(c.clone()).or_default().add(&outcome);
        }
        for t in &tags.tests {
            by_test.entry(t.clone()).or_default().add(&outcome);
        }
        let (kind, why) = match &outcome {
            Outcome::Pass => ("pass", String::new()),
            Outcome::Fail(m) => ("FAIL", m.clone()),
            Outcome::Refused(m) => ("refused", m.clone()),
            Outcome::Error(m) => ("ERROR", m.clone()),
        };
        if let Outcome::Refused(m) | Outcome::Error(m) = &outcome {
            // Group reasons by their wording, without the element's id.
            let key: String = m.split_once(": ").map_or(m.as_str(), |(_, r)| r).chars().take(90).collect();
            *reasons.entry(format!("{kind}: {key}")).or_default() += 1;
        }
        if verbose || matches!(outcome, Outcome::Fail(_) | Outcome::Error(_)) {
            println!("{case} {kind} {}", why.lines().next().unwrap_or(""));
        }
        let with_events = tags.components.iter().any(|c| c.starts_with("Event"));
        if check_grad && with_events && outcome == Outcome::Pass {
            let checked = std::panic::catch_unwind(|| check_gradients(&dir, case))
                .unwrap_or_else(|_| GradOutcome::Error("panic".to_string()));
            let key = match &checked {
                GradOutcome::Checked(v) => v.word().to_string(),
                GradOutcome::NoParameter => "no parameter".to_string(),
                GradOutcome::Error(_) => "error".to_string(),
            };
            if !matches!(
                checked,
                GradOutcome::Checked(hybc::gradcheck::Verdict::Passed) | GradOutcome::NoParameter
            ) {
                println!(
                    "{case} --check-grad {key} {}",
                    match &checked {
                        GradOutcome::Error(m) => m.lines().next().unwrap_or(""),
                        _ => "",
                    }
                );
            }
            *grad.entry(key).or_default() += 1;
        }
    }
    if check_grad {
        println!("\n--check-grad on the passing cases with events (every parameter):");
        for (k, n) in &grad {
            println!("{n:5}  {k}");
        }
    }
    println!("\n{} cases in {:.1} s\n", cases.len(), start.elapsed().as_secs_f64());
    println!("| tag | cases | pass | fail | refused | error |\n| --- | --- | --- | --- | --- | --- |");
    println!("{}", all.row("all"));
    println!(
        "\n| component tag | cases | pass | fail | refused | error |\n| --- | --- | --- | --- | --- | --- |"
    );
    for (k, c) in &by_component {
        println!("{}", c.row(k));
    }
    println!("\n| test tag | cases | pass | fail | refused | error |\n| --- | --- | --- | --- | --- | --- |");
    for (k, c) in &by_test {
        println!("{}", c.row(k));
    }
    println!("\nreasons (refused and errors):");
    let mut reasons: Vec<_> = reasons.into_iter().collect();
    reasons.sort_by_key(|r| std::cmp::Reverse(r.1));
    for (r, n) in reasons {
        println!("{n:5}  {r}");
    }
}
