//! The reference models with closed forms, written once for every test (the bouncing ball, the
//! thermostat, the tilted floor, dosing; derivations in shared/reference/closed-forms.md), and the
//! helpers that compare hybc with them: compile a model with every parameter differentiated, run it
//! by parameter name, differentiate a reference computation by Richardson-extrapolated central
//! differences, and compare with stated tolerances while recording the largest error seen (printed
//! with `--nocapture` for docs/accuracy.md).

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

// ---- the vertical bouncing ball: p = [g, e, h0] -----------------------------------------------

/// The ball of `models/ball.hyb` (and `hand_systems::Ball`): dropped at rest from `h0`, `y'' = -g`,
/// `v := -e v` at `y = 0`. It first touches down at `t1 = sqrt(2 h0 / g)` with speed
/// `v1 = sqrt(2 g h0)`; the k-th touchdown is at `t_k = t1 (1 + 2 e + ... + 2 e^(k-1))`, after which
/// it leaves at `e^k v1` with the energy `g h0 e^(2k)`. The touchdowns accumulate at
/// `t* = t1 + 2 e v1 / (g (1 - e))` (a Zeno point for `e < 1`).
#[derive(Clone, Copy, Debug)]
pub struct BallForm {
    pub g: f64,
    pub e: f64,
    pub h0: f64,
}

impl BallForm {
    /// `models/ball.hyb`'s defaults.
    pub const DEFAULT: BallForm = BallForm { g: 9.81, e: 0.8, h0: 1.0 };

    /// The ball at the model's parameter vector `[g, e, h0]`.
    pub fn at(p: &[f64]) -> BallForm {
        BallForm { g: p[0], e: p[1], h0: p[2] }
    }

    /// The speed at the first touchdown, `sqrt(2 g h0)`.
    pub fn v1(&self) -> f64 {
        (2.0 * self.g * self.h0).sqrt()
    }

    /// The first touchdown, `v1 / g = sqrt(2 h0 / g)`.
    pub fn t1(&self) -> f64 {
        self.v1() / self.g
    }

    /// Every touchdown `(t_k, v1 e^(k-1))`, k = 1, 2, ...: its time and the speed the ball arrives
    /// with. Each flight lasts twice the rise time of the speed it starts with,
    /// `t_(k+1) = t_k + 2 v1 e^k / g`, which sums to `t1 (1 + 2 e + ... + 2 e^(k-1))`.
    fn touchdowns(&self) -> impl Iterator<Item = (f64, f64)> {
        let (g, e, v1) = (self.g, self.e, self.v1());
        std::iter::successors(Some((v1 / g, v1)), move |&(t, speed)| {
            let leaving = speed * e;
            Some((t + 2.0 * leaving / g, leaving))
        })
    }

    /// The k-th touchdown (k >= 1).
    pub fn touchdown(&self, k: i32) -> f64 {
        self.touchdowns().nth(k as usize - 1).expect("an endless sequence").0
    }

    /// `[dt_k/dg, dt_k/de, dt_k/dh0]` of the k-th touchdown, differentiated by hand: `t_k` is
    /// proportional to `g^(-1/2)` and `h0^(1/2)`, and `dt_k/de = 2 t1 sum_{0<i<k} i e^(i-1)`.
    pub fn touchdown_grad(&self, k: i32) -> [f64; 3] {
        let t = self.touchdown(k);
        let de = 2.0 * self.t1() * (1..k).map(|i| i as f64 * self.e.powi(i - 1)).sum::<f64>();
        [-t / (2.0 * self.g), de, t / (2.0 * self.h0)]
    }

    /// The touchdowns at or before `t_end`, at most [`MAX_EVENTS`] of them (they accumulate at
    /// `t*`).
    pub fn touchdowns_before(&self, t_end: f64) -> Vec<f64> {
        self.touchdowns().map(|(t, _)| t).take_while(|&t| t <= t_end).take(MAX_EVENTS).collect()
    }

    /// Height and velocity at `t`: free fall before the first touchdown, then a parabola from the
    /// latest one, left at the speed the next one is reached with.
    pub fn state_at(&self, t: f64) -> (f64, f64) {
        let (g, e) = (self.g, self.e);
        let n = self.touchdowns_before(t).len();
        if n == 0 {
            return (self.h0 - 0.5 * g * t * t, -g * t);
        }
        let mut touchdowns = self.touchdowns().skip(n - 1);
        let (latest, _) = touchdowns.next().expect("endless");
        let (_, speed) = touchdowns.next().expect("endless");
        let tau = t - latest;
        // `speed / e * e` rather than `speed`: the arithmetic of this reference's first version,
        // kept so that the errors printed against it (docs/accuracy.md) stay the same bit for bit.
        (speed / e * e * tau - 0.5 * g * tau * tau, speed - g * tau)
    }

    /// The energy after k bounces, `g h0 e^(2k)` (kinetic plus potential, constant in flight).
    pub fn energy(&self, k: i32) -> f64 {
        self.g * self.h0 * self.e.powi(2 * k)
    }

    /// `[dE/dg, dE/de, dE/dh0]` of [`BallForm::energy`].
    pub fn energy_grad(&self, k: i32) -> [f64; 3] {
        let (g, e, h0) = (self.g, self.e, self.h0);
        [h0 * e.powi(2 * k), 2.0 * k as f64 * g * h0 * e.powi(2 * k - 1), g * e.powi(2 * k)]
    }

    /// Where the touchdowns accumulate (`e < 1`): `t1 + 2 e v1 / (g (1 - e))`.
    pub fn accumulation_time(&self) -> f64 {
        self.t1() + 2.0 * self.e * self.v1() / (self.g * (1.0 - self.e))
    }
}

/// The ball's touchdowns until `t_end`, then free flight: `[y, v]` and the energy at `t_end`.
pub fn ball_reference(p: &[f64], t_end: f64) -> Reference {
    let ball = BallForm::at(p);
    let (y, v) = ball.state_at(t_end);
    Reference { times: ball.touchdowns_before(t_end), finals: vec![y, v, 0.5 * v * v + ball.g * y] }
}

// ---- the thermostat: p = [k, P, T_out, T_lo, T_hi, T0] ------------------------------------------

/// The thermostat of `models/thermostat.hyb` (and `hand_systems::Thermostat`), starting in heating.
/// In each mode `T' = -k (T - T_eq)` with `T_eq = T_out + P / k` (heating) or `T_out` (cooling), so
/// `T(t) = T_eq + (T_a - T_eq) e^(-k t)` and the time from `T_a` to `T_b` is
/// `ln((T_a - T_eq) / (T_b - T_eq)) / k`.
#[derive(Clone, Copy, Debug)]
pub struct ThermostatForm {
    pub k: f64,
    pub power: f64,
    pub t_out: f64,
    pub t_lo: f64,
    pub t_hi: f64,
    pub t0: f64,
}

impl ThermostatForm {
    /// The switching times up to `t_end` and the temperature at `t_end`.
    pub fn switches(&self, t_end: f64) -> (Vec<f64>, f64) {
        let ThermostatForm { k, power, t_out, t_lo, t_hi, t0 } = *self;
        let (mut t, mut temp, mut heating) = (0.0, t0, true);
        let mut times = Vec::new();
        loop {
            let (eq, target) = if heating { (t_out + power / k, t_hi) } else { (t_out, t_lo) };
            let tau = ((temp - eq) / (target - eq)).ln() / k;
            if t + tau > t_end {
                return (times, eq + (temp - eq) * (-k * (t_end - t)).exp());
            }
            t += tau;
            times.push(t);
            temp = target;
            heating = !heating;
        }
    }
}

/// The thermostat model's switching times and final values `[T, heat_loss]`.
pub fn thermostat_reference(p: &[f64], t_end: f64) -> Reference {
    let form = ThermostatForm { k: p[0], power: p[1], t_out: p[2], t_lo: p[3], t_hi: p[4], t0: p[5] };
    let (times, temp) = form.switches(t_end);
    Reference { times, finals: vec![temp, form.k * (temp - form.t_out)] }
}

// ---- the ball on a tilted floor: p = [g, e, s, vx0, h0] ----------------------------------------

/// Each flight is a parabola meeting the line y = -s x: the clearance `c = y + s x` follows
/// `c0 + b tau - g tau^2 / 2` with `b = vy + s vx`, so the impact is the larger root of a quadratic
/// (`2 b / g` when starting on the floor). Then the normal velocity is reflected with restitution.
/// Final values: `[x, y, vx, vy, energy, clearance]`.
pub fn tilted_reference(p: &[f64], t_end: f64) -> Reference {
    let (g, e, s, vx0, h0) = (p[0], p[1], p[2], p[3], p[4]);
    let (mut t, mut x, mut y, mut vx, mut vy) = (0.0, 0.0, h0, vx0, 0.0);
    let mut c0 = h0;
    let mut times = Vec::new();
    loop {
        let b = vy + s * vx;
        let tau = if c0 == 0.0 { 2.0 * b / g } else { (b + (b * b + 2.0 * g * c0).sqrt()) / g };
        if t + tau > t_end || times.len() == MAX_EVENTS {
            break;
        }
        t += tau;
        times.push(t);
        x += vx * tau;
        y += vy * tau - 0.5 * g * tau * tau;
        vy -= g * tau;
        let vn = (s * vx + vy) / (1.0 + s * s);
        vx -= (1.0 + e) * vn * s;
        vy -= (1.0 + e) * vn;
        c0 = 0.0; // on the floor: the clearance is exactly zero in exact arithmetic
    }
    let tau = t_end - t;
    x += vx * tau;
    y += vy * tau - 0.5 * g * tau * tau;
    vy -= g * tau;
    let energy = 0.5 * (vx * vx + vy * vy) + g * y;
    Reference { times, finals: vec![x, y, vx, vy, energy, y + s * x] }
}

// ---- dosing: p = [ka, ke, dose, t_dose, tau, V] ------------------------------------------------

/// Linear kinetics, superposed per dose given at `t_d`: `gut = D e^(-ka (t - t_d))`,
/// `central = D ka / (ka - ke) (e^(-ke (t - t_d)) - e^(-ka (t - t_d)))`. Final values:
/// `[gut, central, conc]`.
pub fn dosing_reference(p: &[f64], t_end: f64) -> Reference {
    let (ka, ke, dose, t_dose, tau, v) = (p[0], p[1], p[2], p[3], p[4], p[5]);
    let times: Vec<f64> = [t_dose, t_dose + tau].into_iter().filter(|&t| t <= t_end).collect();
    let (mut gut, mut central) = (0.0, 0.0);
    for td in &times {
        let dt = t_end - td;
        gut += dose * (-ka * dt).exp();
        central += dose * ka / (ka - ke) * ((-ke * dt).exp() - (-ka * dt).exp());
    }
    Reference { times, finals: vec![gut, central, central / v] }
}
