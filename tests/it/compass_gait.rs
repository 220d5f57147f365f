//! `models/compass_gait.hyb` (Goswami, Thuilot and Espiau 1996) against what does not depend on
//! its own derivation:
//! - without torque, the swing conserves the Lagrangian's energy (the flow is that Lagrangian's);
//! - the heel-strike reset equals the rigid-body impact law computed another way: the walker as a
//!   floating base `(x, y, stance, swing)`, its mass matrix `sum m J^T J` from the point masses'
//!   position Jacobians, and the impulse that stops the swing foot,
//!   `v+ = v- - M^-1 J^T (J M^-1 J^T)^-1 J v-` (nalgebra, here);
//! - the passive gait is a fixed point of `hybc periodic`, stable, with the running cost `work`
//!   left out of the orbit, and a torque profile's gradients check against differences.

use nalgebra::{DMatrix, DVector, Matrix2x4};

use hybc::{Model, PeriodicRequest};

use crate::support::cli::hybc;

const COMPASS: &str = include_str!("../../models/compass_gait.hyb");
const M: f64 = 5.0;
const MH: f64 = 10.0;
const A: f64 = 0.5;
const B: f64 = 0.5;
const GAMMA: f64 = 0.0523598775598;

fn n(t: f64) -> [f64; 2] {
    [t.cos(), -t.sin()]
}

/// The Jacobian of a point `(x, y) + c1 e(stance) + c2 e(swing)` with respect to
/// `(x, y, stance, swing)`.
fn jacobian(st: f64, sw: f64, c1: f64, c2: f64) -> Matrix2x4<f64> {
    let (n1, n2) = (n(st), n(sw));
    Matrix2x4::new(1.0, 0.0, c1 * n1[0], c2 * n2[0], 0.0, 1.0, c1 * n1[1], c2 * n2[1])
}

/// The rates right after the strike (new stance, new swing) from the rates before it, by the
/// floating-base impact law.
fn projected(st: f64, sw: f64, dst: f64, dsw: f64) -> (f64, f64) {
    let l = A + B;
    let legs = [(M, jacobian(st, sw, A, 0.0)), (MH, jacobian(st, sw, l, 0.0)), (M, jacobian(st, sw, l, -B))];
    let mut mass = DMatrix::<f64>::zeros(4, 4);
    for (m, j) in &legs {
        mass += (j.transpose() * j).scale(*m);
    }
    let foot = DMatrix::from_iterator(2, 4, jacobian(st, sw, l, -l).iter().copied());
    let v = DVector::from_vec(vec![0.0, 0.0, dst, dsw]);
    let inv = mass.try_inverse().expect("a mass matrix");
    let impulse = (&foot * &inv * foot.transpose()).try_inverse().expect("invertible");
    let after = &v - &inv * foot.transpose() * impulse * &foot * &v;
    // The old swing leg is the new stance leg.
    (after[3], after[2])
}

#[test]
fn the_swing_conserves_the_lagrangians_energy_without_torque() {
    let path = std::env::temp_dir().join(format!("hybc_compass_energy_{}.csv", std::process::id()));
    let out = hybc(&[
        "run",
        "models/compass_gait.hyb",
        "--set",
        "tau=0,0,0,0,0",
        "--trajectory",
        path.to_str().unwrap(),
        "--sample",
        "0.01",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&path).unwrap();
    let _ = std::fs::remove_file(&path);
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().expect("a header").split(',').collect();
    let col = head.iter().position(|h| *h == "energy").expect("an energy column");
    let energies: Vec<f64> = lines.map(|l| l.split(',').nth(col).unwrap().parse().unwrap()).collect();
    assert!(energies.len() > 50, "{} rows", energies.len());
    let (lo, hi) = energies.iter().fold((f64::MAX, f64::MIN), |(lo, hi), &e| (lo.min(e), hi.max(e)));
    assert!((hi - lo) / hi < 1e-10, "energy {lo} .. {hi}");
}

#[test]
fn the_strike_is_the_rigid_body_impact_law() {
    // The model starts with both feet on the slope (st + sw = 2 gamma): with the swing leg behind
    // (sw < st) and the feet closing (dst + dsw > 0) the strike fires at t = 0, and the final
    // state is the one right after it.
    let model = Model::parse(COMPASS).unwrap();
    let compiled = model.compile::<&str>(&[]).unwrap();
    for (st, dst, dsw) in [(0.3, 1.3, 0.2), (0.25, 0.9, -0.5), (0.4, 2.0, 0.5)] {
        let mut p = compiled.params();
        p.set("st0", st).unwrap();
        p.set("dst0", dst).unwrap();
        p.set("dsw0", dsw).unwrap();
        let run = compiled.simulate(&p, &model.sim_options()).unwrap();
        assert_eq!(run.events().len(), 1);
        assert_eq!(run.events()[0].time, 0.0);
        let sw = 2.0 * GAMMA - st;
        let (new_dst, new_dsw) = projected(st, sw, dst, dsw);
        let got = (run.state("st").unwrap(), run.state("sw").unwrap());
        assert!((got.0 - sw).abs() < 1e-15 && (got.1 - st).abs() < 1e-15, "{got:?}");
        let rates = (run.state("dst").unwrap(), run.state("dsw").unwrap());
        assert!(
            (rates.0 - new_dst).abs() < 1e-12 && (rates.1 - new_dsw).abs() < 1e-12,
            "{rates:?} vs {new_dst}, {new_dsw}"
        );
    }
}

#[test]
fn the_passive_gait_is_a_stable_fixed_point_with_the_running_cost_left_out() {
    let model = Model::parse(COMPASS).unwrap();
    let free: Vec<_> = ["st0", "dst0", "dsw0"].iter().map(|s| model.param_index(s).unwrap()).collect();
    let mut params: Vec<f64> = model.params().values().to_vec();
    // The passive gait: no torque.
    for (p, v) in model.checked().params.iter().zip(params.iter_mut()) {
        if p.name.starts_with("tau[") {
            *v = 0.0;
        }
    }
    let published: Vec<f64> = free.iter().map(|p| params[p.0 as usize]).collect();
    // From 5% off the shipped gait.
    for p in &free {
        params[p.0 as usize] *= 1.05;
    }
    let sim = hybc::sim::SimOptions { t_end: 3.0, rtol: 1e-12, atol: 1e-14, ..Default::default() };
    let search = hybc::periodic::Search { free: free.clone(), params, sim, max_iter: 30, tol: 1e-11 };
    let request = PeriodicRequest { section: "strike".into(), firing: 1, search };
    let r = request.run(&model).expect("a fixed point").result;
    for (p, want) in free.iter().zip(&published) {
        assert!((r.params[p.0 as usize] - want).abs() < 1e-8, "{:?}", r.params);
    }
    assert_eq!(r.orbit, vec![0, 1, 2, 3], "work is not part of the orbit");
    // One multiplier is the section's (the flow direction); the reset's image (st + sw =
    // 2 gamma) is three-dimensional, so no second one.
    let trivial =
        r.multipliers.iter().filter(|(re, im)| re.hypot(*im) <= hybc::periodic::TRIVIAL_MULTIPLIER).count();
    assert_eq!(trivial, 1, "{:?}", r.multipliers);
    assert!(r.stable, "{:?}", r.multipliers);
    assert!((r.period - 0.7343).abs() < 1e-3, "{}", r.period);
}

#[test]
fn a_hip_torque_profile_checks_its_gradients() {
    let out = hybc(&[
        "run",
        "models/compass_gait.hyb",
        "--grad",
        "tau,st0,dst0",
        "--set",
        "tau=1,2,0,-1,0",
        "--check-grad",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("gradient check passed"));
}
