//! `hybc periodic`: the simplest walker's gait (Garcia, Chatterjee, Ruina and Coleman 1998) as a
//! fixed point of the heel-strike return map, and its Floquet multipliers against an independent
//! computation: central differences of the return map, run by run.

use hybc::periodic::{PeriodicError, PeriodicResult, Search, Stability};
use hybc::{Model, PeriodicRequest};

use crate::event_edges::WALKER;
use crate::support::cli::hybc;
use crate::support::runs::run;

/// The published fixed point at gamma = 0.009 (theta0, dtheta0, dphi0; phi0 = 2 theta0).
const PUBLISHED: [f64; 3] = [0.200310900544287, -0.199832473004977, -0.015822999948318];

fn problem_from(model: &Model, start: [f64; 3]) -> (Model, PeriodicRequest) {
    let free: Vec<_> = ["theta0", "dtheta0", "dphi0"].iter().map(|n| model.param_index(n).unwrap()).collect();
    let mut params: Vec<f64> = model.params().values().to_vec();
    for (p, v) in free.iter().zip(start) {
        params[p.0 as usize] = v;
    }
    let sim = hybc::sim::SimOptions { t_end: 10.0, rtol: 1e-12, atol: 1e-14, ..Default::default() };
    let search = Search { free, params, sim, max_iter: 30, tol: 1e-11 };
    let request = PeriodicRequest { section: "heelstrike".into(), firing: 1, search };
    (model.clone(), request)
}

/// The orbit `request` asks for on `model`, through the door (which compiles the section's
/// models).
fn find((model, request): &(Model, PeriodicRequest)) -> Result<PeriodicResult, hybc::Error> {
    request.run(model).map(|report| report.result)
}

/// The walker's state right after the heel strike from the full initial state `x0` (its swing
/// angle free, unlike the model's `phi = 2 theta0`), by an ordinary run.
fn strike(x0: [f64; 4]) -> Vec<f64> {
    let text = WALKER
        .replace("state phi = 2 * theta0", &format!("state phi = {:e}", x0[2]))
        .replace("param theta0 = 0.200310900544287", &format!("param theta0 = {:e}", x0[0]))
        .replace("param dtheta0 = -0.199832473004977", &format!("param dtheta0 = {:e}", x0[1]))
        .replace("param dphi0 = -0.015822999948318", &format!("param dphi0 = {:e}", x0[3]));
    let r = run(&text, &[], |o| {
        o.t_end = 10.0;
        o.rtol = 1e-12;
        o.atol = 1e-14;
    });
    r.result().final_state.state.clone()
}

/// The return map's Jacobian at `x` by central differences (h = 1e-6), run by run: at rtol
/// 1e-12 the differences resolve each entry to about 1e-7.
fn differenced_monodromy(x: &[f64]) -> nalgebra::DMatrix<f64> {
    let x = [x[0], x[1], x[2], x[3]];
    let h = 1e-6;
    let mut fd = nalgebra::DMatrix::zeros(4, 4);
    for j in 0..4 {
        let (mut up, mut down) = (x, x);
        up[j] += h;
        down[j] -= h;
        let (a, b) = (strike(up), strike(down));
        for i in 0..4 {
            fd[(i, j)] = (a[i] - b[i]) / (2.0 * h);
        }
    }
    fd
}

#[test]
fn the_walker_returns_to_its_published_gait_and_its_multipliers_match_differences() {
    let model = Model::parse(WALKER).unwrap();
    // From a start 1% off the published gait.
    let start = PUBLISHED.map(|v| v * 1.01);
    let r = find(&problem_from(&model, start)).expect("a fixed point");
    for (got, want) in
        r.fixed_point.iter().zip([PUBLISHED[0], PUBLISHED[1], 2.0 * PUBLISHED[0], PUBLISHED[2]])
    {
        assert!((got - want).abs() < 1e-9, "{:?}", r.fixed_point);
    }
    assert!(r.residuals.len() <= 8, "{:?}", r.residuals);
    // The period: one step of the published gait (3.8 s at gamma = 0.009).
    assert!(r.period > 3.0 && r.period < 4.5, "{}", r.period);
    // The monodromy matrix against central differences of the return map (h = 1e-6): each
    // entry to 1e-6, which the differences resolve at rtol 1e-12.
    let fd = differenced_monodromy(&r.fixed_point);
    for (i, j) in (0..4).flat_map(|i| (0..4).map(move |j| (i, j))) {
        let (exact, fd) = (r.monodromy[(i, j)], fd[(i, j)]);
        assert!((exact - fd).abs() < 1e-6, "M[{i}][{j}] = {exact} vs {fd}");
    }
    // Two multipliers are trivial (the section's), and the gait is stable: the others inside
    // the unit circle.
    let sizes: Vec<f64> = r.multipliers.iter().map(|(re, im)| re.hypot(*im)).collect();
    assert_eq!(
        sizes.iter().filter(|s| **s <= hybc::periodic::TRIVIAL_MULTIPLIER).count(),
        2,
        "{:?}",
        r.multipliers
    );
    assert!(r.stable, "{:?}", r.multipliers);
}

#[test]
fn a_section_without_stop_is_its_first_firing_and_an_unknown_one_is_refused() {
    // The walker that walks on (no `stop`): its first heel strike is the same section.
    let walking = Model::parse(&WALKER.replace("    stop\n", "")).unwrap();
    let stopping = Model::parse(WALKER).unwrap();
    let a = find(&problem_from(&walking, PUBLISHED.map(|v| v * 1.01))).expect("a fixed point");
    let b = find(&problem_from(&stopping, PUBLISHED.map(|v| v * 1.01))).expect("a fixed point");
    assert_eq!(a.fixed_point, b.fixed_point);
    assert_eq!(a.multipliers, b.multipliers);
    let mut p = problem_from(&stopping, PUBLISHED);
    p.1.section = "toe".into();
    assert!(find(&p).unwrap_err().to_string().contains("no event `toe`"));
}

#[test]
fn the_second_heel_strike_closes_the_same_gait_with_twice_the_period_and_squared_multipliers() {
    // A one-step gait is a fixed point of the two-step map too: the same state, twice the
    // period, and the two-step monodromy is M^2, so its multipliers are the squares. With the
    // section declared `stop` (moved to the second firing) and without (the walker walks on).
    let stopping = Model::parse(WALKER).unwrap();
    let one = find(&problem_from(&stopping, PUBLISHED)).expect("one step");
    for text in [WALKER.to_string(), WALKER.replace("    stop\n", "")] {
        let model = Model::parse(&text).unwrap();
        let mut p = problem_from(&model, PUBLISHED.map(|v| v * 1.01));
        p.1.firing = 2;
        let two = find(&p).expect("two steps");
        assert_eq!(two.fixed_point.len(), 4, "the counter is not part of the orbit");
        for (a, b) in two.fixed_point.iter().zip(&one.fixed_point) {
            assert!((a - b).abs() < 1e-9, "{:?} vs {:?}", two.fixed_point, one.fixed_point);
        }
        assert!(
            (two.period - 2.0 * one.period).abs() < 1e-9 * one.period,
            "{} vs {}",
            two.period,
            one.period
        );
        assert_eq!(two.events, 2 * one.events);
        let squared = &one.monodromy * &one.monodromy;
        for (i, j) in (0..4).flat_map(|i| (0..4).map(move |j| (i, j))) {
            assert!((two.monodromy[(i, j)] - squared[(i, j)]).abs() < 1e-8, "M2[{i}][{j}]");
        }
        let square = |(re, im): (f64, f64)| (re * re - im * im, 2.0 * re * im);
        for (&got, &single) in two.multipliers.iter().zip(&one.multipliers).take(2) {
            let want = square(single);
            assert!(
                (got.0 - want.0).abs() < 1e-8 && (got.1.abs() - want.1.abs()).abs() < 1e-8,
                "{got:?} vs {want:?}"
            );
        }
        assert!(two.stable);
    }
    let mut p = problem_from(&stopping, PUBLISHED);
    p.1.firing = 0;
    assert!(find(&p).unwrap_err().to_string().contains("firing must be 1 to"));
}

#[test]
fn the_short_period_gait_is_found_from_its_own_start_and_is_unstable() {
    // Garcia et al.'s second gait at gamma = 0.009: shorter steps, one multiplier near 4.
    let model = Model::parse(WALKER).unwrap();
    let r = find(&problem_from(&model, [0.194, -0.204, -0.06])).expect("a fixed point");
    assert!((r.fixed_point[0] - 0.19393736).abs() < 1e-7, "{:?}", r.fixed_point);
    assert!(r.period < 3.2, "{}", r.period);
    assert!(!r.stable);
    // Its largest multiplier against the eigenvalues of the return map's central differences.
    let fd_top = hybc::periodic::multipliers(&differenced_monodromy(&r.fixed_point))[0];
    assert!(
        (r.multipliers[0].0 - fd_top.0).abs() < 1e-5 && r.multipliers[0].1 == 0.0,
        "{:?} vs {fd_top:?}",
        r.multipliers
    );
    assert!(r.multipliers[0].0 > 3.9 && r.multipliers[0].0 < 4.1, "{:?}", r.multipliers);
}

#[test]
fn the_cli_finds_the_gait_on_a_second_slope_and_prints_the_json_contract() {
    let out = hybc(&[
        "periodic",
        "models/walker.hyb",
        "--section",
        "heelstrike",
        "--free",
        "theta0,dtheta0,dphi0",
        "--set",
        "gamma=0.004",
        "--format",
        "json",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let theta = json["fixed_point"]["theta"].as_f64().unwrap();
    let phi = json["fixed_point"]["phi"].as_f64().unwrap();
    assert!((phi - 2.0 * theta).abs() < 1e-12 && theta > 0.1 && theta < 0.2, "{json}");
    assert_eq!(json["multipliers"].as_array().unwrap().len(), 4);
    assert_eq!(json["trivial"], 2);
    assert_eq!(json["stable"], true);
    assert!(json["period"].as_f64().unwrap() > 3.0);
    // The shipped model's own defaults are the fixed point already: no iteration.
    let out = hybc(&[
        "periodic",
        "models/walker.hyb",
        "--section",
        "heelstrike",
        "--free",
        "theta0,dtheta0,dphi0",
        "--format",
        "json",
    ]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["iterations"], 0, "{json}");
    // No fixed point from a start that falls over (the stance leg never reaches heel strike):
    // exit 3, the run does not reach the section.
    let out = hybc(&[
        "periodic",
        "models/walker.hyb",
        "--section",
        "heelstrike",
        "--free",
        "theta0",
        "--set",
        "dtheta0=0.5",
    ]);
    assert_eq!(out.status.code(), Some(3), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stderr).contains("does not reach the section"));
}

// The orbits of tests/data/periodic/: closed forms through every firing, the start on the
// section's guard, the verification of a fixed point, and the stability verdict on both sides.

/// A search of the model at `path` through `section` over `free`, from its defaults with `set`
/// over them, at the model's own options.
fn search(path: &str, section: &str, free: &[&str], set: &[(&str, f64)]) -> (Model, PeriodicRequest) {
    let model = Model::from_file(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(path)).unwrap();
    let mut params = model.params();
    for (name, value) in set {
        params.set(name, *value).unwrap();
    }
    let free = free.iter().map(|n| model.param_index(n).unwrap()).collect();
    let (section, firing) = hybc::periodic::parse_section(section).unwrap();
    let search =
        Search { free, params: params.values().to_vec(), sim: model.sim_options(), max_iter: 30, tol: 1e-10 };
    (model.clone(), PeriodicRequest { section, firing, search })
}

const KICKED: &str = "tests/data/periodic/kicked.hyb";

/// The kicked oscillator's period between two kicks and its velocity's factor over it, at
/// damping `c`.
fn kicked_form(c: f64) -> (f64, f64) {
    let period = 2.0 * std::f64::consts::PI / (1.0 - c * c / 4.0).sqrt();
    (period, (-c * period / 2.0).exp())
}

#[test]
fn the_kicked_oscillator_closes_through_every_kick_at_its_closed_form() {
    // Started right after a kick, (0, v0): the run sits on the kick's guard moving across, and
    // the kick at t = 0 is not a return (it is the one the state is right after). Through the
    // K-th kick the orbit is the one-kick orbit K times: v0 = -k / (1 - rho), the period K T,
    // multipliers rho^K and 0. Before the section's copies were ordered, `kick#2` closed at the
    // first kick with the kick applied twice (v0 = -2 / (1 - rho) = -4.27, period T): exit 0 on
    // a point a run of the model does not come back to.
    let (period, rho) = kicked_form(0.2);
    let v_star = -1.0 / (1.0 - rho);
    for firing in 1..=3 {
        let section = format!("kick#{firing}");
        let r = find(&search(KICKED, &section, &["v0"], &[("v0", -2.0)])).expect("the orbit");
        let k = firing as f64;
        assert!((r.fixed_point[1] - v_star).abs() < 1e-10, "{section}: {:?}", r.fixed_point);
        assert_eq!(r.fixed_point[0], 0.0);
        assert!((r.period - k * period).abs() < 1e-10 * k, "{section}: {}", r.period);
        assert_eq!(r.events, firing, "{section}: one kick a period");
        assert_eq!(r.multipliers.len(), 2);
        assert!(
            (r.multipliers[0].0 - rho.powi(firing as i32)).abs() < 1e-10,
            "{section}: {:?}",
            r.multipliers
        );
        assert_eq!(r.multipliers[0].1, 0.0);
        assert!(r.multipliers[1].0.hypot(r.multipliers[1].1) <= hybc::periodic::TRIVIAL_MULTIPLIER);
        assert_eq!(r.stability, Stability::Stable);
        // The run of the model as written from the fixed point came back to it.
        assert!(r.verification.residual <= 1e-10 * (1.0 + v_star.abs()), "{:?}", r.verification);
        assert!((r.verification.period - r.period).abs() < 1e-12 * r.period, "{:?}", r.verification);
    }
    // Both states free, from off the section (x0 = 0.5): the same orbit, x0 = 0 to round-off.
    let r = find(&search(KICKED, "kick#2", &["x0", "v0"], &[("x0", 0.5), ("v0", -2.0)])).expect("the orbit");
    assert!(
        r.fixed_point[0].abs() < 1e-12 && (r.fixed_point[1] - v_star).abs() < 1e-10,
        "{:?}",
        r.fixed_point
    );
    assert!((r.period - 2.0 * period).abs() < 1e-9, "{}", r.period);
}

#[test]
fn the_stability_verdict_is_stable_unstable_or_borderline_at_exact_multipliers() {
    // Negative damping with a kick that brakes (k < 0): v0 = -k / (1 - rho) < 0, rho > 1.
    let (_, rho) = kicked_form(-0.2);
    let r =
        find(&search(KICKED, "kick", &["v0"], &[("c", -0.2), ("k", -1.0), ("v0", -1.0)])).expect("the orbit");
    assert!((r.fixed_point[1] - 1.0 / (1.0 - rho)).abs() < 1e-10, "{:?}", r.fixed_point);
    assert!((r.multipliers[0].0 - rho).abs() < 1e-10 && rho > 1.8, "{:?} vs {rho}", r.multipliers);
    assert_eq!((r.stability, r.stable), (Stability::Unstable, false));
    // Undamped and unkicked: every (0, v0) is a periodic orbit, the velocity's multiplier is 1
    // exactly (a neutral direction), computed to round-off: borderline, not stable or unstable
    // by the round-off's sign.
    let r = find(&search(KICKED, "kick", &["v0"], &[("c", 0.0), ("k", 0.0)])).expect("the orbit");
    assert_eq!(r.residuals.len(), 1, "the start is a fixed point");
    assert!((r.multipliers[0].0 - 1.0).abs() < 1e-12, "{:?}", r.multipliers);
    assert_eq!((r.stability, r.stable), (Stability::Borderline, false));
    assert_eq!(r.neutral_band, 1000.0 * 1e-12);
    // Damping of 1e-6: rho = 1 - 3.2e-6. At rtol 1e-12 (band 1e-9) that is stable; at rtol 1e-8
    // (band 1e-5) the multipliers cannot tell it from 1.
    let (_, rho) = kicked_form(1e-6);
    let mut tight = search(KICKED, "kick", &["v0"], &[("c", 1e-6), ("k", 1e-6), ("v0", -0.3)]);
    let r = find(&tight).expect("the orbit");
    assert!((r.multipliers[0].0 - rho).abs() < 1e-10, "{:?} vs {rho}", r.multipliers);
    assert_eq!(r.stability, Stability::Stable);
    tight.1.search.sim.rtol = 1e-8;
    tight.1.search.sim.atol = 1e-10;
    tight.1.search.tol = 1e-8;
    let r = find(&tight).expect("the orbit");
    assert!((r.multipliers[0].0 - rho).abs() < 1e-7, "{:?} vs {rho}", r.multipliers);
    assert_eq!(r.stability, Stability::Borderline);
}

#[test]
fn a_fixed_point_a_run_of_the_model_does_not_come_back_to_is_refused() {
    // A brake that the kick's reset sets off: `v <= -2` crossed by the kick (rho v0 = -1.14 to
    // -2.14), a cascade at the kick's instant. The return map stops right after `kick` and closes
    // at v0 = -1 / (1 - rho) = -2.136; a run of the model from there starts across the brake's
    // guard (no firing: rule 5), kicks at T and brakes at the same instant, and is back at
    // 0.5 v0, not at v0. Newton converges on the map; the point is refused (exit 4 at the
    // command line), with where the search ended.
    let (_, rho) = kicked_form(0.2);
    let v_star = -1.0 / (1.0 - rho);
    let with = |event: &str| -> Model {
        let text =
            std::fs::read_to_string(KICKED).unwrap().replace("simulate", &format!("{event}\n\nsimulate"));
        Model::parse(&text).unwrap()
    };
    let (_, request) = search(KICKED, "kick", &["v0"], &[]);
    let error = request.run(&with("event brake when v <= -2 {\n    v := 0.5 * v\n}")).unwrap_err();
    let message = error.to_string();
    assert!(
        message.contains(
            "no fixed point found: the return map closed within tolerance, but a run of the model from it returns"
        ),
        "{message}"
    );
    let hybc::Error::Periodic(e @ PeriodicError::NotVerified { residual: Some(residual), attempt, .. }) =
        &error
    else {
        panic!("{error:?}")
    };
    assert!((residual - 0.5 * v_star.abs()).abs() < 1e-9, "{residual} vs {}", 0.5 * v_star.abs());
    assert!((attempt.params[3] - v_star).abs() < 1e-10, "{:?}", attempt.params);
    assert_eq!(e.reason(), Some("not_verified"));
    // A drag on the kick's guard, declared after it, fires at the same instants: right after
    // every kick, and at the start, where the state right after a kick sits on its guard (rule
    // 5). The map from (0, v0) drags, flows, kicks: v0 = 0.5 rho v0 - 1. The run of the model
    // is back after the kick's instant at the state it had after its start (both dragged): a
    // true orbit, verified.
    let r = request.run(&with("event drag when x <= 0 {\n    v := 0.5 * v\n}")).expect("the orbit").result;
    let v_drag = -1.0 / (1.0 - 0.5 * rho);
    assert!((r.fixed_point[1] - v_drag).abs() < 1e-10, "{:?} vs {v_drag}", r.fixed_point);
    assert!(r.verification.residual < 1e-10, "{:?}", r.verification);
    assert!((r.multipliers[0].0 - 0.5 * rho).abs() < 1e-10, "{:?}", r.multipliers);
    assert_eq!(r.events, 2, "the drag at the start and the kick");
    // Neither: the plain kicked oscillator is verified.
    assert!(find(&search(KICKED, "kick", &["v0"], &[])).is_ok());
}

#[test]
fn a_bounce_on_a_vibrating_table_closes_at_every_hit_and_every_second_hit() {
    // `--section hit#2` said the run "does not reach the section" (the section's stopping copy,
    // judged after the counted hit at the first hit, reversed the ball again and it fell through
    // the table). The orbit: v* = g pi / w, cos(ph*) = v* (1 - e) / ((1 + e) A w), hits every
    // 0.64 s; the complex pair of multipliers has modulus e (e^2 through two hits).
    let (g, e, a, w) = (9.81, 0.8, 0.05, 2.0 * std::f64::consts::PI / 0.64);
    let v_star = g * std::f64::consts::PI / w;
    let ph_star = (v_star * (1.0 - e) / ((1.0 + e) * a * w)).acos();
    let table = "tests/data/periodic/table.hyb";
    let one = find(&search(table, "hit", &["v0", "ph0"], &[])).expect("one hit");
    let two = find(&search(table, "hit#2", &["v0", "ph0"], &[])).expect("two hits");
    for (r, k) in [(&one, 1), (&two, 2)] {
        let want = [a * ph_star.sin(), v_star, ph_star];
        for (got, want) in r.fixed_point.iter().zip(want) {
            assert!((got - want).abs() < 1e-9, "hit#{k}: {:?} vs {want}", r.fixed_point);
        }
        assert!((r.period - 0.64 * k as f64).abs() < 1e-10, "hit#{k}: {}", r.period);
        assert_eq!(r.events, 2 * k, "a hit and a wrap of the phase a period");
        let modulus = e.powi(k as i32);
        for &(re, im) in &r.multipliers[..2] {
            assert!((re.hypot(im) - modulus).abs() < 1e-9 && im != 0.0, "hit#{k}: {:?}", r.multipliers);
        }
        assert_eq!(r.stability, Stability::Stable);
    }
    let squared = &one.monodromy * &one.monodromy;
    for (i, j) in (0..3).flat_map(|i| (0..3).map(move |j| (i, j))) {
        assert!((two.monodromy[(i, j)] - squared[(i, j)]).abs() < 1e-8, "M2[{i}][{j}]");
    }
}

#[test]
fn a_bounce_on_a_floor_closes_at_every_hit_with_a_neutral_multiplier() {
    // e = 1: the start (0, 3.2) is an orbit; through K hits its period is 2 K v0 / g. `hit#2`
    // missed the section before (stopped as Zeno: the copy reversed the ball back down).
    let bounce = "tests/data/periodic/bounce.hyb";
    for firing in 1..=3 {
        let section = format!("hit#{firing}");
        let r = find(&search(bounce, &section, &["v0"], &[])).expect("the orbit");
        assert_eq!(r.residuals.len(), 1, "{section}: the start is a fixed point");
        assert_eq!(r.fixed_point, vec![0.0, 3.2]);
        assert!((r.period - firing as f64 * 2.0 * 3.2 / 9.81).abs() < 1e-12, "{section}: {}", r.period);
        assert!((r.multipliers[0].0 - 1.0).abs() < 1e-12, "{section}: {:?}", r.multipliers);
        assert_eq!(r.stability, Stability::Borderline);
    }
}

#[test]
fn an_apex_section_started_at_the_apex_is_a_whole_bounce_never_a_zero_length_orbit() {
    // Dropped from its apex (y0 = 1, v0 = 0), the run starts on the apex guard moving across: the
    // apex there is not a return, so the orbit is the bounce back to it, period 2 sqrt(2 / g),
    // not 0. Started rising (v0 = 0.1), Newton drives v0 to 0 from above, where the apex comes
    // 1e-20 after the start: that firing is inside the start window too (the orbit reported
    // before was that one, period 7.4e-20).
    let bounce = "tests/data/periodic/bounce.hyb";
    let whole = 2.0 * (2.0f64 / 9.81).sqrt();
    for v0 in [0.0, 0.1, -0.1] {
        let r = find(&search(bounce, "apex", &["y0", "v0"], &[("y0", 1.0), ("v0", v0)])).expect("the orbit");
        assert!((r.period - whole).abs() < 1e-9, "v0 = {v0}: period {}", r.period);
        assert!(
            (r.fixed_point[0] - 1.0).abs() < 1e-9 && r.fixed_point[1].abs() < 1e-12,
            "{:?}",
            r.fixed_point
        );
        assert_eq!(r.events, 2, "the hit and the apex");
    }
    // The window: 1e-9 past the start, or 1e-9 of it at |t_start| > 1.
    assert_eq!(hybc::periodic::returns_after(0.0), 1e-9);
    assert!((hybc::periodic::returns_after(-1e6) - (-1e6 + 1e-3)).abs() < 1e-9);
}
