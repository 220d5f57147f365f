//! Integrator tests on the bouncing ball against the closed forms of
//! /work/shared/reference/closed-forms.md (bounce times, event-time gradients, energy and its
//! gradient, state sensitivities after a bounce, Zeno accumulation point, stop events).

use crate::support::hand_systems::{close, Ball};
use crate::support::reference::BallForm;
use hybc::sim::{run, Method, SimError, SimOptions, StopReason, TrajectoryRequest};

const G: f64 = 9.81;
const E: f64 = 0.8;

fn opts(t_end: f64, method: Method, sens_error_control: bool) -> SimOptions {
    SimOptions { t_end, rtol: 1e-10, atol: 1e-12, method, sens_error_control, ..SimOptions::default() }
}

/// The closed forms at the defaults `g = 9.81, e = 0.8, h0 = 1` (the runs below use `[G, E, 1.0]`).
const BALL: BallForm = BallForm::DEFAULT;

fn check_first_point(method: Method, sens_error_control: bool) {
    let ball = Ball::new();
    let r = run(&ball, &[G, E, 1.0], &opts(2.5, method, sens_error_control)).expect("valid run");
    let tag = format!("{method:?} sens_error_control={sens_error_control}");
    assert_eq!(r.stopped_by, StopReason::TEnd, "{tag}");
    assert_eq!(r.events.len(), 4, "{tag}");
    let published = [0.4515236410, 1.1739614666, 1.7519117270, 2.2142719354];
    for (k, ev) in r.events.iter().enumerate() {
        let kk = k as i32 + 1;
        let t = BALL.touchdown(kk);
        assert!(close(ev.time, t, 1e-9), "{tag} bounce {kk}: {} vs {t}", ev.time);
        assert!(close(ev.time, published[k], 1e-9), "{tag} bounce {kk} vs published");
        let dt = ev.dtime.as_ref().expect("non-grazing bounce has a gradient");
        let want = BALL.touchdown_grad(kk);
        for j in 0..3 {
            assert!(close(dt[j], want[j], 1e-9), "{tag} bounce {kk} dt/dp{j}: {} vs {}", dt[j], want[j]);
        }
        assert!(!ev.grazing);
    }
    let dt1_dh0 = r.events[0].dtime.as_ref().unwrap()[2];
    assert!(close(dt1_dh0, 1.0 / BALL.v1(), 1e-9), "{tag}: dt1/dh0 = 1 / v1");
    assert!(close(dt1_dh0, 0.2257618205, 1e-9), "{tag}");
    // E(T) = g h0 e^8 after four bounces, and its gradient in (g, e, h0).
    let f = &r.final_state;
    assert!(close(f.outputs[0], BALL.energy(4), 1e-9), "{tag} E {}", f.outputs[0]);
    assert!(close(f.outputs[0], 1.6458448896, 1e-9), "{tag}");
    let de = f.doutputs.as_ref().expect("gradients valid");
    let want = BALL.energy_grad(4);
    for j in 0..3 {
        assert!(close(de[j], want[j], 1e-9), "{tag} dE/dp{j}: {} vs {}", de[j], want[j]);
    }
    assert!(r.warnings.is_empty());
}

#[test]
fn ball_bounces_match_closed_form_dopri5() {
    check_first_point(Method::Dopri5, true);
    check_first_point(Method::Dopri5, false);
}

#[test]
fn ball_bounces_match_closed_form_dop853() {
    check_first_point(Method::Dop853, true);
    check_first_point(Method::Dop853, false);
}

#[test]
fn ball_state_sensitivities_after_one_bounce() {
    for method in [Method::Dopri5, Method::Dop853] {
        let r = run(&Ball::new(), &[G, E, 10.0], &opts(2.0, method, true)).expect("valid run");
        assert_eq!(r.events.len(), 1);
        let ev = &r.events[0];
        assert!(close(ev.time, 1.42784312293, 1e-10));
        // Saltation denominator is the pre-impact speed g_x f = v-.
        assert!(close(ev.denominator, -14.0071410359, 1e-10));
        let dt = ev.dtime.as_ref().unwrap();
        let want = [-0.0727748788444, 0.0, 0.0713921561464];
        for j in 0..3 {
            assert!(close(dt[j], want[j], 1e-9), "dt1/dp{j} {} vs {}", dt[j], want[j]);
        }
        let f = &r.final_state;
        assert!(close(f.state[0], 4.80570772929, 1e-10), "{:?}", f.state);
        assert!(close(f.state[1], 5.59285386465, 1e-10), "{:?}", f.state);
        let s = f.dstate.as_ref().unwrap();
        // Columns g, e, h0; rows y, v.
        let want = [
            [0.570117621269, -0.714941189366],
            [8.01428207183, 14.0071410359],
            [-0.0787146135354, 1.26064269323],
        ];
        for j in 0..3 {
            for i in 0..2 {
                assert!(
                    close(s[j * 2 + i], want[j][i], 1e-9),
                    "{method:?} dx{i}/dp{j}: {} vs {}",
                    s[j * 2 + i],
                    want[j][i]
                );
            }
        }
    }
}

#[test]
fn ball_stops_as_zeno_near_the_accumulation_point() {
    let r = run(&Ball::new(), &[G, E, 1.0], &opts(10.0, Method::Auto, true)).expect("valid run");
    let t_star = BALL.accumulation_time();
    assert!((t_star - 4.0637127689).abs() < 1e-9);
    match r.stopped_by {
        StopReason::Zeno { time, count, accumulation, .. } => {
            let acc = accumulation.expect("shrinking intervals give an estimate").estimate;
            assert!((acc - t_star).abs() < 1e-8, "accumulation {acc} vs {t_star}");
            assert!(time < t_star && t_star - time < 1e-4, "stopped at {time}");
            assert_eq!(count, r.events.len());
        }
        other => panic!("expected a Zeno stop, got {other:?}"),
    }
    // Stopped early and cheaply, keeping what was computed.
    assert!(r.events.len() < 200, "{} events", r.events.len());
    assert!(r.stats.steps < 2000, "{} steps", r.stats.steps);
    assert!(r.final_state.time < 4.07);
    // Each bounce time still matches the closed form (checked on the first 20).
    for (k, ev) in r.events.iter().take(20).enumerate() {
        assert!(close(ev.time, BALL.touchdown(k as i32 + 1), 1e-9));
    }
}

#[test]
fn stop_event_total_derivative() {
    let h0 = 1.0;
    let r = run(&Ball::stopping(), &[G, E, h0], &opts(5.0, Method::Auto, true)).expect("valid");
    assert_eq!(r.stopped_by, StopReason::Event { event: 0, name: "floor".into() });
    let v1 = BALL.v1();
    let f = &r.final_state;
    assert!(close(f.time, BALL.t1(), 1e-12));
    assert!(f.state[0].abs() < 1e-12);
    assert!(close(f.state[1], E * v1, 1e-12));
    // Final state R(t1, x(t1), p) = [0, e v1] as a function of (g, e, h0).
    let total = f.dstate_total.as_ref().expect("stop event has a total derivative");
    let want_v = [E * h0 / v1, v1, E * G / v1];
    for j in 0..3 {
        assert!(total[2 * j].abs() < 1e-10, "dy/dp{j} = {}", total[2 * j]);
        assert!(close(total[2 * j + 1], want_v[j], 1e-10), "dv/dp{j}");
    }
    // Final energy e^2 g h0 (the ball sits on the floor).
    let dy = f.doutputs_total.as_ref().unwrap();
    let want_e = [E * E * h0, 2.0 * E * G * h0, E * E * G];
    for j in 0..3 {
        assert!(close(dy[j], want_e[j], 1e-10), "dE/dp{j}: {} vs {}", dy[j], want_e[j]);
    }
}

#[test]
fn sampled_trajectory_follows_the_parabolas() {
    let o = SimOptions { trajectory: TrajectoryRequest::Every(0.1), ..opts(2.5, Method::Dopri5, true) };
    let r = run(&Ball::new(), &[G, E, 1.0], &o).expect("valid");
    let rows = r.trajectory.expect("trajectory requested");
    assert_eq!(rows.len(), 26);
    for row in &rows {
        // Closed-form height: the flight after bounce k starts at t_k with speed e^k v1.
        let (y, _) = BALL.state_at(row.t);
        assert!((row.x[0] - y).abs() < 1e-9, "t = {}: {} vs {y}", row.t, row.x[0]);
    }
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let ball = Ball::new();
    assert_eq!(
        run(&ball, &[G, E], &SimOptions::default()).unwrap_err(),
        SimError::ParamLength { expected: 3, got: 2 }
    );
    let bad = SimOptions { rtol: -1.0, ..SimOptions::default() };
    assert!(matches!(run(&ball, &[G, E, 1.0], &bad), Err(SimError::InvalidOption { name: "rtol", .. })));
    let bad = SimOptions { t_end: f64::NAN, ..SimOptions::default() };
    assert!(run(&ball, &[G, E, 1.0], &bad).is_err());
}

#[test]
fn a_nan_parameter_ends_in_a_fault_not_a_hang() {
    let r = run(&Ball::new(), &[f64::NAN, E, 1.0], &opts(1.0, Method::Auto, true)).expect("ran");
    match r.stopped_by {
        StopReason::Fault { error } => {
            let msg = error.to_string();
            assert!(msg.contains("mode 0"), "{msg}");
        }
        other => panic!("expected a fault, got {other:?}"),
    }
}

#[test]
fn too_many_steps_is_a_fault_with_partial_result() {
    let o = SimOptions { max_steps: 5, ..opts(2.5, Method::Dopri5, true) };
    let r = run(&Ball::new(), &[G, E, 1.0], &o).expect("valid");
    assert!(matches!(r.stopped_by, StopReason::Fault { error: SimError::TooManySteps { max_steps: 5, .. } }));
    assert!(r.final_state.time > 0.0 && r.final_state.time < 2.5);
}

#[test]
fn works_through_dyn_and_serialises() {
    let ball = Ball::new();
    let sys: &dyn hybc::sim::HybridSystem = &ball;
    let r = run(sys, &[G, E, 1.0], &opts(1.0, Method::Auto, true)).expect("valid");
    assert_eq!(r.events.len(), 1);
    let json = serde_json::to_string(&r).expect("serialisable");
    assert!(json.contains("\"final\""), "{json}");
    assert!(json.contains("\"floor\""));
}

#[test]
fn a_reused_simulator_gives_the_results_of_fresh_runs() {
    // The scratch buffers outlive each run; nothing of one run may leak into the next, also
    // after a run that stopped early (Zeno, a NaN fault) or used other parameters.
    use hybc::sim::Runner;
    let ball = Ball::new();
    for method in [Method::Dopri5, Method::Dop853] {
        let o = opts(5.0, method, true);
        let mut sim = Runner::new(&ball, &o).expect("valid options");
        let points = [[G, E, 1.0], [G, 0.95, 3.0], [f64::NAN, E, 1.0], [3.7, 0.5, 0.2], [G, E, 1.0]];
        for p in points {
            let fresh = run(&ball, &p, &o).expect("valid");
            let reused = sim.run(&p).expect("valid");
            // Debug formatting compares NaN fields as equal text and every float exactly.
            assert_eq!(format!("{reused:?}"), format!("{fresh:?}"), "{method:?} at {p:?}");
        }
        assert!(matches!(sim.run(&[G, E]), Err(SimError::ParamLength { expected: 3, got: 2 })));
    }
}

#[test]
fn bounces_too_small_to_resolve_stop_as_zeno_instead_of_falling_through() {
    // With a tiny restitution the bounces shrink by e each time and soon fall below round-off:
    // the state must never end up under the floor; the run stops as Zeno at the last bounce,
    // with the accumulation point t1 + 2 e v1 / (g (1 - e)) estimated.
    let ball = Ball::new();
    let o = opts(2.5, Method::Auto, true);
    let mut zeno = 0;
    for i in 0..200 {
        let e = 1e-3 * 1.03f64.powi(i); // 0.001 .. 0.37
        let r = run(&ball, &[G, e, 1.0], &o).expect("valid");
        let y = r.final_state.state[0];
        assert!(y > -1e-9, "e = {e}: the ball fell through the floor to y = {y}");
        match r.stopped_by {
            StopReason::TEnd => {}
            StopReason::Zeno { time, accumulation, .. } => {
                zeno += 1;
                let t_star = BallForm { e, ..BALL }.accumulation_time();
                assert!((time - t_star).abs() < 1e-6, "e = {e}: stopped at {time}, accumulation at {t_star}");
                if let Some(a) = accumulation.map(|a| a.estimate) {
                    assert!((a - t_star).abs() < 1e-6, "e = {e}: estimated {a}, exact {t_star}");
                }
            }
            ref other => panic!("e = {e}: stopped by {other:?}"),
        }
    }
    assert!(zeno > 0, "no run reached its accumulation point before t = 2.5");
}

#[test]
fn ball_bounces_match_closed_form_rosenbrock_on_central_difference_jacobians() {
    // The hand-written ball has no Jacobian kernels: the Rosenbrock methods take the documented
    // central-difference defaults of `HybridSystem::flow_jac` and `sens_dir` (exact here, the
    // flow being linear), and meet the same closed forms to the same 1e-9.
    check_first_point(Method::Rodas5p, true);
    check_first_point(Method::Rodas4, true);
}

/// The ball, with kernels that cannot be had: Jacobians (as a model whose second derivatives
/// are out of reach would say) or the sensitivities' right-hand side (as a compiled model's
/// kernel that failed to compile on first use would say).
struct Refusing {
    ball: Ball,
    jacobians: Option<&'static str>,
    sensitivities: Option<&'static str>,
}

impl hybc::sim::HybridSystem for Refusing {
    fn info(&self) -> &hybc::sim::SystemInfo {
        self.ball.info()
    }
    fn initial_state(&self, p: &[f64], x0: &mut [f64]) {
        self.ball.initial_state(p, x0)
    }
    fn initial_sens(&self, p: &[f64], s0: &mut [f64]) {
        self.ball.initial_sens(p, s0)
    }
    fn flow(&self, mode: usize, t: f64, x: &[f64], p: &[f64], dx: &mut [f64]) {
        self.ball.flow(mode, t, x, p, dx)
    }
    fn flow_sens(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        s: &[f64],
        p: &[f64],
        dx: &mut [f64],
        ds: &mut [f64],
    ) {
        self.ball.flow_sens(mode, t, x, s, p, dx, ds)
    }
    fn prepare_jacobians(&self) -> Result<(), String> {
        self.jacobians.map_or(Ok(()), |why| Err(why.into()))
    }
    fn prepare_sensitivities(&self) -> Result<(), String> {
        self.sensitivities.map_or(Ok(()), |why| Err(why.into()))
    }
    fn guards(&self, mode: usize, t: f64, x: &[f64], p: &[f64], g: &mut [f64]) {
        self.ball.guards(mode, t, x, p, g)
    }
    fn guard_grad(&self, event: usize, t: f64, x: &[f64], p: &[f64], gx: &mut [f64], gp: &mut [f64]) -> f64 {
        self.ball.guard_grad(event, t, x, p, gx, gp)
    }
    fn condition(&self, event: usize, t: f64, x: &[f64], p: &[f64]) -> bool {
        self.ball.condition(event, t, x, p)
    }
    fn reset(&self, event: usize, t: f64, x: &[f64], p: &[f64], r: &mut [f64]) {
        self.ball.reset(event, t, x, p, r)
    }
    fn reset_jac(
        &self,
        event: usize,
        t: f64,
        x: &[f64],
        p: &[f64],
        rx: &mut [f64],
        rp: &mut [f64],
        rt: &mut [f64],
    ) {
        self.ball.reset_jac(event, t, x, p, rx, rp, rt)
    }
    fn outputs(&self, t: f64, x: &[f64], p: &[f64], y: &mut [f64]) {
        self.ball.outputs(t, x, p, y)
    }
    fn output_jac(&self, t: f64, x: &[f64], p: &[f64], yx: &mut [f64], yp: &mut [f64], yt: &mut [f64]) {
        self.ball.output_jac(t, x, p, yx, yp, yt)
    }
}

#[test]
fn a_rosenbrock_method_without_jacobians_is_an_error_naming_the_method_and_why() {
    let sys =
        Refusing { ball: Ball::new(), jacobians: Some("no second derivatives here"), sensitivities: None };
    let err = run(&sys, &[G, E, 1.0], &opts(2.5, Method::Rodas5p, true)).expect_err("refused");
    let text = err.to_string();
    assert!(text.contains("rodas5p") && text.contains("no second derivatives here"), "{text}");
    // The explicit methods need nothing of the kind.
    assert!(run(&sys, &[G, E, 1.0], &opts(2.5, Method::Dopri5, true)).is_ok());
}

#[test]
fn forward_sensitivities_that_cannot_be_prepared_are_an_error_saying_why() {
    let sys =
        Refusing { ball: Ball::new(), jacobians: None, sensitivities: Some("the kernel did not compile") };
    let o = opts(2.5, Method::Dopri5, false);
    let err = run(&sys, &[G, E, 1.0], &o).expect_err("refused");
    assert!(matches!(err, SimError::NoSensitivities { .. }), "{err:?}");
    let text = err.to_string();
    assert!(text.contains("forward sensitivities") && text.contains("the kernel did not compile"), "{text}");
    // The adjoint's recording run carries no sensitivities and asks for none: its gradient of
    // the final height is the forward one of the ball itself (same steps, round-off apart).
    let recorded = hybc::sim::adjoint::record(&sys, &[G, E, 1.0], &o).expect("records");
    let seed = hybc::sim::adjoint::Seed { state: vec![1.0, 0.0], ..Default::default() };
    let grad = recorded.gradient(&sys, &[G, E, 1.0], &seed).expect("a gradient");
    let forward = run(&Ball::new(), &[G, E, 1.0], &o).expect("runs");
    let dy = forward.final_state.dstate.expect("sensitivities");
    let m = 3;
    for j in 0..m {
        let want = dy[j * 2];
        assert!((grad[j] - want).abs() <= 1e-12 * want.abs().max(1.0), "d y / d p{j}: {} vs {want}", grad[j]);
    }
    // A run asked of the adjoint does not ask either (its simulator is built before it knows
    // which mode will run); where the adjoint declines (`auto` with more quantities than a
    // fifth of the parameters) and the run falls back to forward, the refusal is the same error.
    let by_adjoint = SimOptions { sens: hybc::sim::Sens::Adjoint, ..o.clone() };
    let r = run(&sys, &[G, E, 1.0], &by_adjoint).expect("the adjoint runs");
    assert_eq!(r.stats.sens, Some(hybc::sim::Sens::Adjoint));
    let declined = SimOptions { sens: hybc::sim::Sens::Auto, ..by_adjoint };
    let err = run(&sys, &[G, E, 1.0], &declined).expect_err("falls back to forward, refused");
    assert!(matches!(err, SimError::NoSensitivities { .. }), "{err:?}");
}
