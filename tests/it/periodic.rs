//! `hybc periodic`: the simplest walker's gait (Garcia, Chatterjee, Ruina and Coleman 1998) as a
//! fixed point of the heel-strike return map, and its Floquet multipliers against an independent
//! computation: central differences of the return map, run by run.

use hybc::periodic::{PeriodicResult, Search};
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
