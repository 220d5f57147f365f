//! Test helper for the closed-form and convergence tests: compile a model with every parameter
//! differentiated, run it by parameter name, differentiate a reference computation by
//! Richardson-extrapolated central differences, and compare with stated tolerances while
//! recording the largest error seen (printed with `--nocapture` for the README's Accuracy section).

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

/// Events a reference computes at most (the balls' bounces accumulate at a finite time).
pub const MAX_EVENTS: usize = 100;

/// A reference solution: event times, then the final state and outputs (in the model's order).
pub struct Reference {
    pub times: Vec<f64>,
    pub finals: Vec<f64>,
}

impl Reference {
    pub fn flat(&self) -> Vec<f64> {
        self.times.iter().chain(&self.finals).copied().collect()
    }
}

/// Bounces until `t_end`, then free flight: `[y, v]` and the energy at `t_end`.
pub fn ball_reference(p: &[f64], t_end: f64) -> Reference {
    let (g, e, h0) = (p[0], p[1], p[2]);
    let v1 = (2.0 * g * h0).sqrt();
    let mut times = vec![v1 / g];
    let mut speed = v1; // upward speed after the latest bounce
    let mut bounces = 0;
    // (Bounces accumulate at a finite time: the count cap keeps a long horizon finite.)
    while times[bounces] <= t_end && bounces < MAX_EVENTS {
        speed *= e;
        times.push(times[bounces] + 2.0 * speed / g);
        bounces += 1;
    }
    times.pop(); // the first bounce after t_end
    let (y, v) = match times.last() {
        None => (h0 - 0.5 * g * t_end * t_end, -g * t_end),
        Some(&t) => {
            let tau = t_end - t;
            (speed / e * e * tau - 0.5 * g * tau * tau, speed - g * tau)
        }
    };
    Reference { times, finals: vec![y, v, 0.5 * v * v + g * y] }
}

/// In each mode `T' = -k (T - T_eq)` with `T_eq = T_out + P / k` (heating) or `T_out` (cooling), so
/// `T(t) = T_eq + (T_a - T_eq) e^(-k t)` and the time from `T_a` to `T_b` is
/// `ln((T_a - T_eq) / (T_b - T_eq)) / k`. Final values: `[T, heat_loss]`.
pub fn thermostat_reference(p: &[f64], t_end: f64) -> Reference {
    let (k, power, t_out, t_lo, t_hi, t0) = (p[0], p[1], p[2], p[3], p[4], p[5]);
    let (mut t, mut temp, mut heating) = (0.0, t0, true);
    let mut times = Vec::new();
    loop {
        let (eq, target) = if heating { (t_out + power / k, t_hi) } else { (t_out, t_lo) };
        let tau = ((temp - eq) / (target - eq)).ln() / k;
        if t + tau > t_end {
            temp = eq + (temp - eq) * (-k * (t_end - t)).exp();
            break;
        }
        t += tau;
        times.push(t);
        temp = target;
        heating = !heating;
    }
    Reference { times, finals: vec![temp, k * (temp - t_out)] }
}
