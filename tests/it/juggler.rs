//! `models/juggler.hyb`, a paddle juggling a ball, against closed forms:
//! - a still paddle (`vp = 0`): the apexes after the k-th hit are `e^(2k) h0`, so
//!   `d apex_k / de = 2k e^(2k-1) h0` and `d apex_k / dh0 = e^(2k)`;
//! - a paddle rising at a constant speed `c` (every `vp` equal to `c`): the first hit is at
//!   `t1 = (sqrt(c^2 + 2 g h0) - c) / g`, where the ball falls at `-g t1` and leaves at
//!   `v+ = (1 + e) c + e g t1`, so `apex1 = c t1 + v+^2 / (2 g)`. The derivative with respect to
//!   `c` is the sum of those with respect to the seven knot values (each moves the paddle over
//!   its own part of the window; together they move it as `c` does), and that with respect to
//!   `e` is `(v+ / g) (c + g t1)`.
//!
//! `effort` is the integral of the paddle's squared velocity: `c^2 t_end` for a constant `c`.

use hybc::Model;

const JUGGLER: &str = include_str!("../../models/juggler.hyb");
const G: f64 = 9.81;

fn close(a: f64, b: f64, tol: f64, what: &str) {
    assert!((a - b).abs() <= tol * b.abs().max(1.0), "{what}: {a} vs {b} (relative tolerance {tol})");
}

fn run(vp: f64, e: f64) -> hybc::Run {
    let model = Model::parse(JUGGLER).expect("parses");
    let mut grad: Vec<String> = (0..7).map(|k| format!("vp[{k}]")).collect();
    grad.extend(["e".to_string(), "h0".to_string()]);
    let compiled = model.compile(&grad).expect("compiles");
    let mut p = compiled.params();
    for k in 0..7 {
        p.set(&format!("vp[{k}]"), vp).expect("vp");
    }
    p.set("e", e).expect("e");
    let run = compiled.simulate(&p, &model.sim_options()).expect("runs");
    assert!(run.is_complete(), "{:?}", run.stopped_by());
    run
}

/// `d output / d param` of a complete run.
fn d(run: &hybc::Run, output: &str, param: &str) -> f64 {
    run.doutput(output, param).expect("a derivative")
}

#[test]
fn a_still_paddle_gives_apexes_of_e_to_the_2k_with_their_derivatives() {
    let (e, h0) = (0.8, 1.0);
    let r = run(0.0, e);
    for (k, name) in [(1, "apex1"), (2, "apex2"), (3, "apex3")] {
        let k2 = 2 * k;
        close(r.output(name).unwrap(), e.powi(k2) * h0, 1e-9, name);
        close(d(&r, name, "e"), k2 as f64 * e.powi(k2 - 1) * h0, 1e-8, &format!("d{name}/de"));
        close(d(&r, name, "h0"), e.powi(k2), 1e-8, &format!("d{name}/dh0"));
    }
    assert_eq!(r.output("cost").unwrap(), 0.0);
}

#[test]
fn a_paddle_rising_at_a_constant_speed_gives_the_first_apex_in_closed_form() {
    let (e, h0, t_end) = (0.8, 1.0, 3.0);
    for c in [0.25, 0.5, -0.3] {
        let r = run(c, e);
        let t1 = ((c * c + 2.0 * G * h0).sqrt() - c) / G;
        let v_plus = (1.0 + e) * c + e * G * t1;
        let apex1 = c * t1 + v_plus * v_plus / (2.0 * G);
        close(r.output("apex1").unwrap(), apex1, 1e-9, "apex1");
        // d/dc: t1' = (c / sqrt(c^2 + 2 g h0) - 1) / g, v+' = (1 + e) + e g t1'.
        let dt1 = (c / (c * c + 2.0 * G * h0).sqrt() - 1.0) / G;
        let dv = (1.0 + e) + e * G * dt1;
        let dapex_dc = t1 + c * dt1 + v_plus * dv / G;
        let summed: f64 = (0..7).map(|j| d(&r, "apex1", &format!("vp[{j}]"))).sum();
        close(summed, dapex_dc, 1e-7, "sum of d apex1 / d vp[k]");
        close(d(&r, "apex1", "e"), v_plus / G * (c + G * t1), 1e-7, "d apex1 / de");
        close(r.output("cost").unwrap(), c * c * t_end, 1e-9, "effort");
    }
}

#[test]
fn the_juggler_checks_its_gradients_with_the_paddle_moving() {
    let out = crate::support::cli::hybc(&[
        "run",
        "models/juggler.hyb",
        "--grad",
        "vp,e",
        "--set",
        "vp=0,1,-0.5,0.5,0,0.3,0",
        "--check-grad",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("gradient check passed"));
}
