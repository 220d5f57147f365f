//! The JIT on the hand-built bouncing ball: every `HybridSystem` method against closed forms,
//! the array layouts of `sim::system`, zero-filling of sparse outputs, the length checks, and
//! sharing one compiled model between threads.

use crate::support::hand_functions::{ball, ball_info, same, E, G, H0};
use hybc::codegen::{CompileOptions, CompiledModel, OptLevel, RegAlloc};
use hybc::sim::HybridSystem;

const P: [f64; 3] = [9.81, 0.8, 10.0];

fn compiled(grad: Vec<usize>) -> CompiledModel {
    CompiledModel::compile(&ball(), ball_info(grad), &CompileOptions::default()).expect("the ball compiles")
}

#[test]
fn initial_state_and_sensitivities_follow_the_column_per_parameter_layout() {
    // Columns in grad_params order: h0 first, then g.
    let m = compiled(vec![H0, G]);
    let mut x0 = [f64::NAN; 2];
    m.initial_state(&P, &mut x0);
    assert_eq!(x0, [10.0, 0.0]);
    let mut s0 = [7.0; 4];
    m.initial_sens(&P, &mut s0);
    // dx0/dh0 = (1, 0); dx0/dg = (0, 0), written as zeros over the 7.0s.
    assert_eq!(s0, [1.0, 0.0, 0.0, 0.0]);
}

#[test]
fn flow_and_fused_sensitivity_rhs_match_the_closed_form() {
    let m = compiled(vec![H0, G]);
    let x = [3.0, -2.0];
    let mut dx = [f64::NAN; 2];
    m.flow(0, 0.5, &x, &P, &mut dx);
    assert_eq!(dx, [-2.0, -9.81]);

    // f_x = [[0, 1], [0, 0]], f_p column g = (0, -1), column h0 = 0.
    let s = [0.25, -1.5, 3.0, 0.125];
    let mut dx2 = [f64::NAN; 2];
    let mut ds = [f64::NAN; 4];
    m.flow_sens(0, 0.5, &x, &s, &P, &mut dx2, &mut ds);
    assert_eq!(dx2, dx);
    assert_eq!(ds, [s[1], 0.0, s[3], -1.0]);
}

#[test]
fn guards_gradients_and_condition() {
    let m = compiled(vec![E]);
    let mut g = [f64::NAN];
    m.guards(0, 0.0, &[0.75, -1.0], &P, &mut g);
    assert_eq!(g, [0.75]);

    let (mut gx, mut gp) = ([5.0; 2], [5.0; 1]);
    let gt = m.guard_grad(0, 0.0, &[0.75, -1.0], &P, &mut gx, &mut gp);
    assert_eq!((gx, gp, gt), ([1.0, 0.0], [0.0], 0.0));

    assert!(m.condition(0, 0.0, &[0.0, -1.0], &P));
    assert!(!m.condition(0, 0.0, &[0.0, 1.0], &P));
    // `v < 0` is false for NaN, like Rust's `<`.
    assert!(!m.condition(0, 0.0, &[0.0, f64::NAN], &P));
}

#[test]
fn reset_and_its_jacobians_match_closed_form_and_central_differences() {
    let m = compiled(vec![G, E]);
    let x = [0.0, -4.0];
    let mut r = [f64::NAN; 2];
    m.reset(0, 1.0, &x, &P, &mut r);
    assert_eq!(r, [0.0, -P[E] * x[1]]);

    let (mut rx, mut rp, mut rt) = ([9.0; 4], [9.0; 4], [9.0; 2]);
    m.reset_jac(0, 1.0, &x, &P, &mut rx, &mut rp, &mut rt);
    assert_eq!(rx, [1.0, 0.0, 0.0, -P[E]]);
    // Column g is zero; column e is dR/de = (0, -v).
    assert_eq!(rp, [0.0, 0.0, 0.0, -x[1]]);
    assert_eq!(rt, [0.0, 0.0]);

    // Central differences of the compiled reset in e and in v; the reset is linear in both, so
    // the only error is rounding (tolerance 1e-9 at step 1e-4).
    let h = 1e-4;
    let reset_at = |x: [f64; 2], p: [f64; 3]| {
        let mut r = [0.0; 2];
        m.reset(0, 1.0, &x, &p, &mut r);
        r
    };
    let (mut pp, mut pm) = (P, P);
    pp[E] += h;
    pm[E] -= h;
    let fd_e = (reset_at(x, pp)[1] - reset_at(x, pm)[1]) / (2.0 * h);
    approx::assert_abs_diff_eq!(fd_e, rp[3], epsilon = 1e-9);
    let fd_v = (reset_at([0.0, x[1] + h], P)[1] - reset_at([0.0, x[1] - h], P)[1]) / (2.0 * h);
    approx::assert_abs_diff_eq!(fd_v, rx[3], epsilon = 1e-9);
}

#[test]
fn outputs_and_output_jacobians_are_fully_written() {
    let m = compiled(vec![G]);
    let x = [2.0, -3.0];
    let mut y = [f64::NAN; 2];
    m.outputs(0.0, &x, &P, &mut y);
    assert_eq!(y, [2.0, 9.0]);
    let (mut yx, mut yp, mut yt) = ([f64::NAN; 4], [f64::NAN; 2], [f64::NAN; 2]);
    m.output_jac(0.0, &x, &P, &mut yx, &mut yp, &mut yt);
    assert_eq!(yx, [1.0, 0.0, 0.0, -6.0]);
    assert_eq!(yp, [0.0, 0.0]);
    assert_eq!(yt, [0.0, 0.0]);
}

#[test]
fn wrong_lengths_and_indices_poison_outputs_instead_of_running_native_code() {
    let m = compiled(vec![G]);
    let mut dx = [1.0; 3];
    m.flow(0, 0.0, &[1.0, 2.0], &P, &mut dx);
    assert!(dx.iter().all(|v| v.is_nan()), "too long an output: {dx:?}");

    let mut dx = [1.0; 2];
    m.flow(0, 0.0, &[1.0], &P, &mut dx);
    assert!(dx.iter().all(|v| v.is_nan()), "too short a state: {dx:?}");

    let mut dx = [1.0; 2];
    m.flow(0, 0.0, &[1.0, 2.0], &P[..2], &mut dx);
    assert!(dx.iter().all(|v| v.is_nan()), "too few parameters: {dx:?}");

    let mut dx = [1.0; 2];
    m.flow(3, 0.0, &[1.0, 2.0], &P, &mut dx);
    assert!(dx.iter().all(|v| v.is_nan()), "unknown mode: {dx:?}");

    let (mut gx, mut gp) = ([1.0; 2], [1.0; 1]);
    assert!(m.guard_grad(7, 0.0, &[1.0, 2.0], &P, &mut gx, &mut gp).is_nan());
    assert!(gx.iter().chain(&gp).all(|v| v.is_nan()));
    assert!(!m.condition(7, 0.0, &[0.0, -1.0], &P));
    assert!(!m.condition(0, 0.0, &[0.0, -1.0, 5.0], &P));

    // Sensitivities sized for two gradient parameters while one was compiled.
    let (mut dx, mut ds) = ([1.0; 2], [1.0; 4]);
    m.flow_sens(0, 0.0, &[1.0, 2.0], &[0.0; 4], &P, &mut dx, &mut ds);
    assert!(dx.iter().chain(&ds).all(|v| v.is_nan()));
}

#[test]
fn every_option_combination_computes_the_same_bits() {
    let x = [1.25, -0.5];
    let s = [0.3, -0.7, 1.1, 0.9];
    let mut reference: Option<Vec<f64>> = None;
    for opt_level in [OptLevel::None, OptLevel::Speed, OptLevel::SpeedAndSize] {
        for regalloc in [RegAlloc::Backtracking, RegAlloc::SinglePass, RegAlloc::Auto] {
            // Part size 1 compiles every output entry as its own native function.
            for (verifier, max_part_size) in [(false, usize::MAX), (true, usize::MAX), (true, 1), (false, 3)]
            {
                let opts = CompileOptions { opt_level, verifier, regalloc, max_part_size };
                let m =
                    CompiledModel::compile(&ball(), ball_info(vec![G, E]), &opts).expect("the ball compiles");
                let (mut dx, mut ds, mut r) = ([0.0; 2], [0.0; 4], [0.0; 2]);
                m.flow_sens(0, 0.0, &x, &s, &P, &mut dx, &mut ds);
                m.reset(0, 0.0, &x, &P, &mut r);
                let got: Vec<f64> = dx.iter().chain(&ds).chain(&r).copied().collect();
                match &reference {
                    None => reference = Some(got),
                    Some(want) => assert!(
                        want.iter().zip(&got).all(|(a, b)| same(*a, *b)),
                        "{opts:?}: {got:?} != {want:?}"
                    ),
                }
            }
        }
    }
}

#[test]
fn one_model_serves_several_threads_at_once() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<CompiledModel>();

    let m = compiled(vec![G, E]);
    std::thread::scope(|scope| {
        for thread in 0..4 {
            let m = &m;
            scope.spawn(move || {
                for step in 0..2000 {
                    let v = f64::from(thread * 10_000 + step) * 1e-3;
                    let x = [1.0, v];
                    let s = [0.5, v, -v, 2.0];
                    let (mut dx, mut ds) = ([0.0; 2], [0.0; 4]);
                    m.flow_sens(0, 0.0, &x, &s, &P, &mut dx, &mut ds);
                    assert_eq!(dx, [v, -P[G]]);
                    assert_eq!(ds, [v, -1.0, 2.0, 0.0]);
                }
            });
        }
    });
}
