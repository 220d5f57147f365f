//! One case of the SBML Test Suite (`cases/semantic/NNNNN/`) run through hybc: its settings
//! file read, its model imported (the highest SBML level the case has), each requested variable
//! sampled at the case's times and compared with its results CSV as the suite says: a value
//! passes where `|expected - actual| <= absolute + relative * |expected|`. Shared by the runner
//! (`benches/measure/sbml_suite.rs`) and the committed subset's test (`tests/it/sbml.rs`).

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use hybc::{Model, SimOptions};

/// The case's `NNNNN-settings.txt`.
#[derive(Clone, Debug, Default)]
pub struct Settings {
    pub start: f64,
    pub duration: f64,
    pub steps: usize,
    pub variables: Vec<String>,
    pub absolute: f64,
    pub relative: f64,
    pub amount: Vec<String>,
    pub concentration: Vec<String>,
}

/// The case's `NNNNN-model.m` header: what the suite's tables count by.
#[derive(Clone, Debug, Default)]
pub struct Tags {
    pub components: Vec<String>,
    pub tests: Vec<String>,
    pub test_type: String,
}

/// How a case ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    Pass,
    /// Imported, ran, and some value is off: the message says which.
    Fail(String),
    /// Refused with a reason (the importer's, or a test type hybc does not simulate).
    Refused(String),
    /// The imported text did not compile, or the run stopped early: a bug of the importer or a
    /// run hybc could not finish.
    Error(String),
}

fn list(v: &str) -> Vec<String> {
    v.split(',').map(|s| s.trim().to_string()).filter(|s| !s.is_empty()).collect()
}

pub fn read_settings(text: &str) -> Settings {
    let mut s = Settings::default();
    for line in text.lines() {
        let Some((k, v)) = line.split_once(':') else { continue };
        let v = v.trim();
        match k.trim() {
            "start" => s.start = v.parse().unwrap_or(0.0),
            "duration" => s.duration = v.parse().unwrap_or(0.0),
            "steps" => s.steps = v.parse().unwrap_or(0),
            "variables" => s.variables = list(v),
            "absolute" => s.absolute = v.parse().unwrap_or(0.0),
            "relative" => s.relative = v.parse().unwrap_or(0.0),
            "amount" => s.amount = list(v),
            "concentration" => s.concentration = list(v),
            _ => {}
        }
    }
    s
}

pub fn read_tags(text: &str) -> Tags {
    let mut t = Tags::default();
    for line in text.lines() {
        let Some((k, v)) = line.split_once(':') else { continue };
        match k.trim() {
            "componentTags" => t.components = list(v),
            "testTags" => t.tests = list(v),
            "testType" => t.test_type = v.trim().to_string(),
            _ => {}
        }
    }
    t
}

/// The case's model file: the highest level and version it has.
pub fn model_file(dir: &Path, case: &str) -> Option<PathBuf> {
    ["l3v2", "l3v1", "l2v5", "l2v4", "l2v3", "l2v2", "l2v1"]
        .iter()
        .map(|lv| dir.join(format!("{case}-sbml-{lv}.xml")))
        .find(|p| p.exists())
}

/// A number of the results CSV (`INF`, `-INF`, `NaN` as the suite writes them).
fn value(s: &str) -> f64 {
    match s.trim() {
        "INF" | "inf" => f64::INFINITY,
        "-INF" | "-inf" => f64::NEG_INFINITY,
        "NaN" | "nan" | "NAN" => f64::NAN,
        t => t.parse().unwrap_or(f64::NAN),
    }
}

fn agrees(expected: f64, actual: f64, s: &Settings) -> bool {
    if expected.is_nan() {
        return actual.is_nan();
    }
    if expected.is_infinite() {
        return actual == expected;
    }
    (expected - actual).abs() <= s.absolute + s.relative * expected.abs()
}

/// Runs case `case` in `dir` (`.../cases/semantic/00001`).
pub fn run_case(dir: &Path, case: &str) -> (Tags, Outcome) {
    let read =
        |suffix: &str| std::fs::read_to_string(dir.join(format!("{case}-{suffix}"))).unwrap_or_default();
    let tags = read_tags(&read("model.m"));
    if tags.test_type != "TimeCourse" {
        return (
            tags.clone(),
            Outcome::Refused(format!("test type {} (hybc simulates time courses)", tags.test_type)),
        );
    }
    let settings = read_settings(&read("settings.txt"));
    let Some(file) = model_file(dir, case) else {
        return (tags, Outcome::Refused("no SBML Level 2 or 3 file".to_string()));
    };
    let xml = std::fs::read_to_string(&file).unwrap_or_default();
    let import = match hybc::sbml::import(&xml) {
        Ok(i) => i,
        Err(e) => {
            let first = e.refusals.first().map_or(String::new(), |r| format!("{}: {}", r.element, r.reason));
            return (tags, Outcome::Refused(first));
        }
    };
    let outcome = simulate(&import, &settings, &read("results.csv"));
    (tags, outcome)
}

/// The imported text with each of the suite's variables (the results' header after `time`) as
/// an output `sbml_out_K`, or why a variable has no value in it.
fn with_variables(
    import: &hybc::sbml::Import,
    settings: &Settings,
    header: &[String],
) -> Result<String, Outcome> {
    let mut text = import.text.clone();
    text.push_str("\n# The suite's variables\n");
    for (k, v) in header.iter().enumerate().skip(1) {
        let expr = if settings.amount.contains(v) {
            import.amount_of(v).or(import.value_of(v))
        } else if settings.concentration.contains(v) {
            import.concentration_of(v).or(import.value_of(v))
        } else {
            import.value_of(v)
        };
        let Some(expr) = expr else {
            return Err(Outcome::Error(format!("no variable `{v}` in the imported model")));
        };
        text.push_str(&format!("output sbml_out_{k} = {expr}\n"));
    }
    Ok(text)
}

/// Simulates an imported case and compares it with its results.
pub fn simulate(import: &hybc::sbml::Import, settings: &Settings, results: &str) -> Outcome {
    let mut lines = results.lines();
    let header: Vec<String> = lines.next().unwrap_or("").split(',').map(|s| s.trim().to_string()).collect();
    let rows: Vec<Vec<f64>> =
        lines.filter(|l| !l.trim().is_empty()).map(|l| l.split(',').map(value).collect()).collect();
    let text = match with_variables(import, settings, &header) {
        Ok(text) => text,
        Err(outcome) => return outcome,
    };
    let model = match Model::parse_named(&text, "imported.hyb") {
        Ok(m) => m,
        Err(e) => return Outcome::Error(format!("the imported text does not check: {e}")),
    };
    let compiled = match model.compile::<&str>(&[]) {
        Ok(c) => c,
        Err(e) => return Outcome::Error(format!("compile: {e}")),
    };
    let times: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    let t_end = settings.start + settings.duration;
    let opts = SimOptions {
        t_start: settings.start,
        t_end,
        rtol: 1e-10,
        atol: (settings.absolute * 1e-4).clamp(1e-16, 1e-10),
        at: times.iter().map(|t| t.clamp(settings.start, t_end)).collect(),
        // Some cases fire an event every hundredth of a time unit for 100 time units.
        max_events: 1_000_000,
        ..SimOptions::default()
    };
    let run = match compiled.simulate(&model.params(), &opts) {
        Ok(r) => r,
        Err(e) => return Outcome::Error(format!("run: {e}")),
    };
    // The importer's only `stop`: a delayed event triggered again while its execution is
    // pending, which SBML queues and hybc's translation does not hold.
    if let hybc::StopReason::Event { name, .. } = run.stopped_by() {
        return Outcome::Refused(format!(
            "`{name}`: a second execution of a delayed event pending (hybc holds one)"
        ));
    }
    if !run.is_complete() {
        return Outcome::Error(format!("the run stopped early: {:?}", run.stopped_by()));
    }
    let first_out = model.output_names().position(|n| n == "sbml_out_1").unwrap_or(0);
    for (r, sample) in rows.iter().zip(run.samples().iter()) {
        for (k, v) in header.iter().enumerate().skip(1) {
            let expected = r.get(k).copied().unwrap_or(f64::NAN);
            let actual = sample.outputs[first_out + k - 1];
            if !agrees(expected, actual, settings) {
                return Outcome::Fail(format!(
                    "{v} at t = {}: expected {expected}, got {actual}",
                    sample.time
                ));
            }
        }
    }
    Outcome::Pass
}

/// What `--check-grad` says of a case: `hybc run --check-grad` on the case's model with every
/// parameter differentiated, at the case's settings (rtol 1e-10, the final values of the suite's
/// variables and the event times compared with central differences).
#[derive(Clone, Debug, PartialEq)]
pub enum GradOutcome {
    /// The checker's verdict.
    Checked(hybc::gradcheck::Verdict),
    /// The model has no parameter to differentiate.
    NoParameter,
    /// The check could not be made: why.
    Error(String),
}

/// The gradient check of case `case` in `dir`, which must import (see [`run_case`]).
pub fn check_gradients(dir: &Path, case: &str) -> GradOutcome {
    let read =
        |suffix: &str| std::fs::read_to_string(dir.join(format!("{case}-{suffix}"))).unwrap_or_default();
    let settings = read_settings(&read("settings.txt"));
    let Some(file) = model_file(dir, case) else {
        return GradOutcome::Error("no SBML Level 2 or 3 file".to_string());
    };
    let xml = std::fs::read_to_string(&file).unwrap_or_default();
    let Ok(import) = hybc::sbml::import(&xml) else {
        return GradOutcome::Error("refused".to_string());
    };
    let results = read("results.csv");
    let header: Vec<String> =
        results.lines().next().unwrap_or("").split(',').map(|s| s.trim().to_string()).collect();
    let text = match with_variables(&import, &settings, &header) {
        Ok(text) => text,
        Err(outcome) => return GradOutcome::Error(format!("{outcome:?}")),
    };
    let model = match Model::parse_named(&text, "imported.hyb") {
        Ok(m) => m,
        Err(e) => return GradOutcome::Error(format!("the imported text does not check: {e}")),
    };
    let names: Vec<String> = model.param_names().map(str::to_string).collect();
    if names.is_empty() {
        return GradOutcome::NoParameter;
    }
    let compiled = match model.compile(&names) {
        Ok(c) => c,
        Err(e) => return GradOutcome::Error(format!("compile: {e}")),
    };
    let opts = SimOptions {
        t_start: settings.start,
        t_end: settings.start + settings.duration,
        rtol: 1e-10,
        atol: (settings.absolute * 1e-4).clamp(1e-16, 1e-10),
        max_events: 1_000_000,
        ..SimOptions::default()
    };
    let params = model.params();
    let run = match compiled.simulate(&params, &opts) {
        Ok(r) => r,
        Err(e) => return GradOutcome::Error(format!("run: {e}")),
    };
    let request = hybc::GradCheckRequest {
        sim: opts.clone(),
        check: hybc::gradcheck::CheckOptions::for_rtol(opts.rtol),
    };
    match request.run(&compiled, params.values(), run.result()) {
        Ok(check) => GradOutcome::Checked(check.verdict()),
        Err(e) => GradOutcome::Error(format!("check: {e}")),
    }
}
