//! Two of issue #27's shipped problems posed for `hybc optimize` and checked independently of the
//! optimiser (the ball's two-parameter exercise and the hopper are in `optimize.rs`, the simplest
//! walker's gaits in `periodic.rs`):
//!
//! - The juggler (`models/juggler.hyb`): the paddle's velocity, piecewise linear through 7 values
//!   over [0, 3] s, brings the ball back to its drop height h0 = 1 m at its first two apexes
//!   (`apex1 = 1`, `apex2 = 1`: each hit must give back what the restitution e = 0.8 takes) with
//!   the least paddle effort (the integral of the paddle's squared velocity over the window). The
//!   whole run has a closed form given the knots: the paddle's height is the integral of a
//!   piecewise-linear velocity (piecewise quadratic), each flight is a parabola from its apex, a
//!   hit is the first time the parabola meets the paddle (found here by bisection), the ball
//!   leaves at `(1 + e) vpad - e v-` and rises `v+^2 / (2 g)` above the paddle. That closed form
//!   recomputes the hit times, the apexes and the effort at the reported optimum, and its finite
//!   differences recheck the KKT conditions and the multipliers without any sensitivity.
//! - The compass gait (`models/compass_gait.hyb`): the fastest periodic gait on the 3 degree
//!   slope at a bounded cost of transport. Free: the state after the strike (`st0`, `dst0`,
//!   `dsw0`) and the hip torque `tau` (5 values over the first 0.7 s, within [-3, 3] N m).
//!   Minimise the pace (step time / step length, the inverse of the average speed) subject to
//!   periodicity (`gap_st = gap_dst = gap_dsw = 0`: the state after the strike is the one the step
//!   started from), the effort per metre `cot <= 0.1` N^2 m s, and the swing foot landing
//!   (`strike#1 <= 1.5`: a trial whose foot never lands has no strike time and counts as a failed
//!   run, instead of reading a pace off a walker that fell). Started from the passive gait
//!   (`tau = 0`, feasible). Checked: KKT residual and event sequence; `hybc periodic` with the
//!   optimal torque finds the same fixed point and calls it stable; the cost bound's multiplier is
//!   the derivative of the optimal pace with respect to the bound (the envelope theorem), measured
//!   by re-solving at `0.1 -/+ 0.001`.

use crate::support::cli::hybc;

use hybc::fit::Bounds;
use hybc::optimize::{
    optimize, parse_constraint, OptimizeOptions, OptimizeProblem, Quantity, Slsqp, Verdict,
};
use hybc::Model;
use serde_json::Value;

const G: f64 = 9.81;
const E: f64 = 0.8;
const H0: f64 = 1.0;
/// The juggler's input window and run: `pwl(t, 0, T, vp)` through 7 values, `t_end = T`.
const T: f64 = 3.0;
const KNOTS: usize = 7;
/// The compass gait's slope (3 degrees, as `models/compass_gait.hyb` declares it).
const GAMMA: f64 = 0.0523598775598;

/// The paddle of the juggler in closed form: velocity, height, and the effort over [0, T].
struct Paddle {
    vp: Vec<f64>,
}

impl Paddle {
    fn width() -> f64 {
        T / (KNOTS - 1) as f64
    }

    /// The segment of `t` and the time into it.
    fn segment(t: f64) -> (usize, f64) {
        let k = ((t / Self::width()).floor() as usize).min(KNOTS - 2);
        (k, t - k as f64 * Self::width())
    }

    fn velocity(&self, t: f64) -> f64 {
        let (k, tau) = Self::segment(t);
        self.vp[k] + (self.vp[k + 1] - self.vp[k]) * tau / Self::width()
    }

    /// The paddle's height: whole segments by the trapezoid rule, the last one in part.
    fn height(&self, t: f64) -> f64 {
        let (k, tau) = Self::segment(t);
        let w = Self::width();
        let whole: f64 = (0..k).map(|j| 0.5 * w * (self.vp[j] + self.vp[j + 1])).sum();
        let slope = (self.vp[k + 1] - self.vp[k]) / w;
        whole + self.vp[k] * tau + 0.5 * slope * tau * tau
    }

    /// The integral of the squared velocity over [0, T]: `w (a^2 + a b + b^2) / 3` per segment.
    fn effort(&self) -> f64 {
        let w = Self::width();
        self.vp.windows(2).map(|s| w * (s[0] * s[0] + s[0] * s[1] + s[1] * s[1]) / 3.0).sum()
    }
}

/// The juggler's hit times and apex heights (after each hit) up to `hits` hits, in closed form.
fn juggle(paddle: &Paddle, hits: usize) -> (Vec<f64>, Vec<f64>) {
    let (mut t_apex, mut y_apex) = (0.0, H0);
    let (mut times, mut apexes) = (Vec::new(), Vec::new());
    for _ in 0..hits {
        let gap = |t: f64| y_apex - 0.5 * G * (t - t_apex).powi(2) - paddle.height(t);
        // The first time the parabola meets the paddle: scan for the sign change, then bisect.
        let dt = 1e-4;
        let mut lo = t_apex;
        while gap(lo + dt) > 0.0 {
            lo += dt;
            assert!(lo < T, "no hit before T");
        }
        let mut hi = lo + dt;
        while hi - lo > 1e-15 * hi.max(1.0) {
            let mid = 0.5 * (lo + hi);
            if gap(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let t_hit = 0.5 * (lo + hi);
        let v_minus = -G * (t_hit - t_apex);
        let v_plus = (1.0 + E) * paddle.velocity(t_hit) - E * v_minus;
        assert!(v_plus > 0.0, "the ball leaves the paddle upwards");
        times.push(t_hit);
        t_apex = t_hit + v_plus / G;
        y_apex = paddle.height(t_hit) + v_plus * v_plus / (2.0 * G);
        apexes.push(y_apex);
    }
    (times, apexes)
}

fn model(path: &str) -> Model {
    Model::from_file(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(path)).expect("model")
}

#[test]
fn the_juggler_returns_the_ball_to_its_drop_height_with_least_paddle_effort() {
    let model = model("models/juggler.hyb");
    let free: Vec<String> = (0..KNOTS).map(|k| format!("vp[{k}]")).collect();
    let compiled = model.compile(&free).expect("compiles");
    let info = compiled.info();
    let problem = OptimizeProblem {
        system: compiled.native(),
        start: model.params().values().to_vec(),
        bounds: vec![Bounds { lower: -3.0, upper: 3.0 }; KNOTS],
        objective: Quantity::parse("cost", info).expect("objective"),
        constraints: ["apex1 = 1", "apex2 = 1"]
            .iter()
            .flat_map(|c| parse_constraint(c, info).expect("constraint"))
            .collect(),
        sim: model.sim_options(),
    };
    let r = optimize(&problem, &OptimizeOptions::default(), &Slsqp, None).expect("optimises");
    let end = r.best().expect("converged");
    assert_eq!(end.verdict, Verdict::Converged);
    let kkt = end.kkt.as_ref().expect("kkt");
    assert!(kkt.stationarity <= 1e-6, "stationarity {}", kkt.stationarity);
    assert!(kkt.at_bound.iter().all(|&b| b == 0), "no knot at its bound: {:?}", end.x);
    assert!(end.cusp_notes.is_empty(), "{:?}", end.cusp_notes);
    // The event sequence: the start (an apex at t = 0), then hits and apexes alternating; six
    // hits before T with this profile.
    let run = end.run.as_ref().expect("the end's run");
    let names: Vec<&str> = run.events.iter().map(|e| &*e.name).collect();
    let alternating: Vec<&str> = (0..12).map(|k| if k % 2 == 0 { "apex" } else { "hit" }).collect();
    assert_eq!(names, alternating);

    // The closed form at the reported knots: hit times, apexes, effort.
    let paddle = Paddle { vp: end.x.clone() };
    let (hit_times, apexes) = juggle(&paddle, 2);
    let run_hits: Vec<f64> = run.events.iter().filter(|e| &*e.name == "hit").map(|e| e.time).collect();
    for (k, (closed, simulated)) in hit_times.iter().zip(&run_hits).enumerate() {
        assert!((closed - simulated).abs() <= 1e-9, "hit {k}: closed form {closed}, run {simulated}");
    }
    for (k, a) in apexes.iter().enumerate() {
        // The targets, to the constraint's tolerance plus the run's own error (1e-9 at rtol 1e-10).
        assert!((a - 1.0).abs() <= r.tolerances[k] + 1e-9, "apex {}: {a}", k + 1);
        approx::assert_relative_eq!(*a, end.values[k + 1], max_relative = 1e-9);
    }
    approx::assert_relative_eq!(paddle.effort(), end.values[0], max_relative = 1e-9);

    // KKT by central differences of the closed form (no sensitivities): d effort + sum_k
    // lambda_k d apex_k = 0 along every knot, lambda by least squares.
    let h = 1e-5;
    let at = |vp: &[f64]| {
        let p = Paddle { vp: vp.to_vec() };
        let (_, a) = juggle(&p, 2);
        [p.effort(), a[0], a[1]]
    };
    let grads: Vec<[f64; 3]> = (0..KNOTS)
        .map(|k| {
            let (mut up, mut down) = (end.x.clone(), end.x.clone());
            up[k] += h;
            down[k] -= h;
            let (u, d) = (at(&up), at(&down));
            [0, 1, 2].map(|i| (u[i] - d[i]) / (2.0 * h))
        })
        .collect();
    // Normal equations of min |grad f + A lambda|, A = [grad apex1, grad apex2].
    let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for g in &grads {
        a11 += g[1] * g[1];
        a12 += g[1] * g[2];
        a22 += g[2] * g[2];
        b1 -= g[0] * g[1];
        b2 -= g[0] * g[2];
    }
    let det = a11 * a22 - a12 * a12;
    let lambda = [(b1 * a22 - b2 * a12) / det, (a11 * b2 - a12 * b1) / det];
    let scale = grads.iter().map(|g| g[0].abs()).fold(0.0, f64::max);
    for (k, g) in grads.iter().enumerate() {
        let residual = g[0] + lambda[0] * g[1] + lambda[1] * g[2];
        assert!(residual.abs() <= 1e-6 * scale, "vp[{k}]: Lagrangian slope {residual} (scale {scale})");
    }
    for (k, l) in lambda.iter().enumerate() {
        approx::assert_relative_eq!(*l, kkt.multipliers[k], max_relative = 1e-4);
    }
}

/// `hybc optimize` on the compass gait with the cost of transport bounded by `c`, as JSON.
fn fastest_gait(c: f64) -> Value {
    let bound = format!("cot <= {c}");
    let out = hybc(&[
        "optimize",
        "models/compass_gait.hyb",
        "--free",
        "st0,dst0,dsw0,tau",
        "--set",
        "tau=0,0,0,0,0",
        "--bounds",
        "tau=-3:3",
        "--t-end",
        "1.5",
        "--minimize",
        "pace",
        "--subject-to",
        "gap_st = 0",
        "--subject-to",
        "gap_dst = 0",
        "--subject-to",
        "gap_dsw = 0",
        "--subject-to",
        &bound,
        "--subject-to",
        "strike#1 <= 1.5",
        "--quiet",
        "--format",
        "json",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("JSON")
}

fn number(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("a number: {v}"))
}

#[test]
fn the_compass_gaits_fastest_periodic_gait_at_a_cost_of_transport_is_a_stable_gait() {
    let v = fastest_gait(0.1);
    assert_eq!(v["reason"], "converged");
    assert!(number(&v["kkt"]["stationarity"]) <= 1e-6, "{}", v["kkt"]);
    assert_eq!(v["events"], serde_json::json!(["strike"]));
    assert_eq!(v["cusp_notes"], serde_json::json!([]));
    let constraints = v["constraints"].as_array().expect("constraints");
    // Periodicity and the cost bound hold the optimum; the landing time does not.
    let active: Vec<bool> = constraints.iter().map(|c| c["active"].as_bool().expect("bool")).collect();
    assert_eq!(active, [true, true, true, true, false]);
    let cot = &constraints[3];
    assert_eq!(cot["constraint"], "cot <= 0.1");
    assert!(number(&cot["multiplier"]) > 0.0, "more effort would buy speed");
    // Faster than the passive gait (step 0.5354454154 m in 0.7343463912 s, docs/periodic.md).
    let pace = number(&v["objective_value"]);
    assert!(pace < 0.7343463912 / 0.5354454154, "pace {pace}");

    // `hybc periodic` with the optimal torque, from the optimal initial state: the same fixed
    // point (Newton has nothing left to do), period the strike time, and stable.
    let sets: Vec<String> =
        v["set"].as_array().expect("set").iter().map(|s| s.as_str().expect("text").to_string()).collect();
    let mut args =
        vec!["periodic", "models/compass_gait.hyb", "--section", "strike", "--free", "st0,dst0,dsw0"];
    for s in &sets {
        args.extend(["--set", s.as_str()]);
    }
    args.extend(["--format", "json"]);
    let out = hybc(&args);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let p: Value = serde_json::from_slice(&out.stdout).expect("JSON");
    for name in ["st0", "dst0", "dsw0"] {
        let (found, optimal) = (number(&p["params"][name]), number(&v["optimum"][name]));
        assert!((found - optimal).abs() <= 1e-8, "{name}: periodic {found}, optimize {optimal}");
    }
    // The period is the step time: the pace times the step length, which at the fixed point is
    // 2 l sin((sw - st) / 2) with sw = 2 gamma - st0 and l = 1 m.
    let st0 = number(&v["optimum"]["st0"]);
    let step = 2.0 * (GAMMA - st0).sin();
    approx::assert_relative_eq!(number(&p["period"]), pace * step, max_relative = 1e-9);
    assert_eq!(p["stable"], true, "{}", p["multipliers"]);
    assert_eq!(p["trivial"], 1);

    // The envelope theorem: d pace* / d c = -lambda. Central difference of two more solves: each
    // optimal pace is exact to about lambda times the bound's tolerance (1e-9 x 0.3, 2e-7 of the
    // slope after dividing by 2 dc) and the truncation is dc^2 pace''' / 6 (the multiplier moves
    // from 0.31 to 0.49 between c = 0.1 and 0.2); measured: 1.2e-5 relative.
    let dc = 1e-3;
    let (up, down) = (fastest_gait(0.1 + dc), fastest_gait(0.1 - dc));
    let slope = (number(&up["objective_value"]) - number(&down["objective_value"])) / (2.0 * dc);
    approx::assert_relative_eq!(-slope, number(&cot["multiplier"]), max_relative = 1e-4);
}
