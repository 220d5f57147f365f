//! Test helper for the closed-form and convergence tests: compile a model with every parameter
//! differentiated, run it by parameter name, differentiate a reference computation by
//! Richardson-extrapolated central differences, and compare with stated tolerances while
//! recording the largest error seen (printed with `--nocapture` for the README's Accuracy section).
#![allow(dead_code)]

use hybc::codegen::{compile, CompileOptions, CompiledModel};
use hybc::lower::{lower, system_info};
use hybc::sema::ParamIdx;
use hybc::sim::{run, SimOptions, SimResult, StopReason};

/// A model compiled once with gradients for all of its parameters (in declaration order).
pub struct Compiled {
    pub names: Vec<String>,
    pub defaults: Vec<f64>,
    pub model: CompiledModel,
}

impl Compiled {
    pub fn from_file(path: &str) -> Compiled {
        let full = format!("{}/{path}", env!("CARGO_MANIFEST_DIR"));
        Compiled::from_source(&std::fs::read_to_string(&full).unwrap_or_else(|e| panic!("{full}: {e}")))
    }

    pub fn from_source(source: &str) -> Compiled {
        let model = hybc::check_source(source).unwrap_or_else(|e| panic!("{e}"));
        let grad: Vec<ParamIdx> = (0..model.params.len()).map(|i| ParamIdx(i as u32)).collect();
        let info = system_info(&model, &grad);
        Compiled {
            names: model.params.iter().map(|p| p.name.clone()).collect(),
            defaults: model.params.iter().map(|p| p.default).collect(),
            model: compile(&lower(&model), info, &CompileOptions::default()).expect("compiles"),
        }
    }

    /// The defaults with `sets` applied.
    pub fn params(&self, sets: &[(&str, f64)]) -> Vec<f64> {
        let mut p = self.defaults.clone();
        for (name, v) in sets {
            let i =
                self.names.iter().position(|n| n == name).unwrap_or_else(|| panic!("no parameter {name}"));
            p[i] = *v;
        }
        p
    }

    /// A run to `t_end` that must end there.
    pub fn run(&self, p: &[f64], t_end: f64, rtol: f64) -> SimResult {
        let opts = SimOptions { t_end, rtol, atol: rtol * 1e-2, ..SimOptions::default() };
        let r = run(&self.model, p, &opts).expect("valid run");
        assert_eq!(r.stopped_by, StopReason::TEnd, "p = {p:?}");
        r
    }
}

/// `d f / d p_j` of a smooth reference computation: central differences at steps h and h/2
/// combined by Richardson extrapolation (error O(h^4)); `h = 1e-3 max(|p_j|, 1)` keeps the
/// truncation near 1e-12 relative and the round-off near 1e-13 / 1e-3 = 1e-13 relative.
pub fn derivative(f: impl Fn(&[f64]) -> Vec<f64>, p: &[f64], j: usize) -> Vec<f64> {
    let h = 1e-4 * p[j].abs().max(1.0);
    let central = |h: f64| -> Vec<f64> {
        let (mut a, mut b) = (p.to_vec(), p.to_vec());
        a[j] += h;
        b[j] -= h;
        let (fa, fb) = (f(&a), f(&b));
        assert_eq!(fa.len(), fb.len(), "the reference changes shape within +/- h of {p:?}");
        fa.iter().zip(&fb).map(|(x, y)| (x - y) / (2.0 * h)).collect()
    };
    let (d1, d2) = (central(h), central(h / 2.0));
    d1.iter().zip(&d2).map(|(a, b)| (4.0 * b - a) / 3.0).collect()
}

/// Compares numbers with a relative tolerance and an absolute floor, remembering the worst
/// relative error per kind (event times, their gradients, ...).
#[derive(Default)]
pub struct Errors {
    worst: Vec<(String, f64)>,
}

impl Errors {
    /// Asserts `|got - want| <= rel * |want| + abs` and records `|got - want| / max(|want|, abs / rel)`.
    pub fn check(&mut self, kind: &str, what: &str, got: f64, want: f64, rel: f64, abs: f64) {
        let err = (got - want).abs();
        assert!(err <= rel * want.abs() + abs, "{kind}: {what}: got {got}, want {want} (error {err:e})");
        let relative = err / want.abs().max(abs / rel);
        match self.worst.iter_mut().find(|(k, _)| k == kind) {
            Some((_, w)) => *w = w.max(relative),
            None => self.worst.push((kind.to_string(), relative)),
        }
    }

    /// One line per kind, for `--nocapture`.
    pub fn print(&self, title: &str) {
        for (kind, w) in &self.worst {
            println!("{title}: max relative error of {kind}: {w:.1e}");
        }
    }
}

/// An end time in the middle of the flight that contains `around`, given event times of a long
/// reference run, so that small parameter changes do not move an event across it.
pub fn mid_flight(times: &[f64], around: f64) -> f64 {
    let next = times.iter().position(|&t| t > around).expect("an event after `around`");
    let prev = if next == 0 { 0.0 } else { times[next - 1] };
    0.5 * (prev + times[next])
}
