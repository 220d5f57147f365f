//! Unit tests of `lower` on a hand-built bouncing ball (no front end needed): derivative entries
//! by value through the evaluator, the interpreter's array layouts, and the report text.

use super::*;
use crate::expr::{eval_one, ExprId};
use crate::sema::{
    Direction, Event, EventIdx, Mode, ModeId, Output, Param, ParamIdx, SimulateDefaults, State, StateIdx,
};
use crate::sim::HybridSystem;
use crate::syntax::Span;

fn b(e: Expr) -> Box<Expr> {
    Box::new(e)
}

/// The ball of the task brief: y' = v, v' = -g, event y <= 0 { v := -e * v },
/// output energy = 0.5 * v^2 + g * y. Parameters g, e, h0; states y, v.
fn ball() -> Model {
    let span = Span::default();
    let param = |name: &str, default: f64| Param { name: name.into(), default, range: None, span };
    let (g, e, h0) = (Expr::Param(ParamIdx(0)), Expr::Param(ParamIdx(1)), Expr::Param(ParamIdx(2)));
    let (y, v) = (Expr::State(StateIdx(0)), Expr::State(StateIdx(1)));
    Model {
        name: "ball".into(),
        params: vec![param("g", 9.81), param("e", 0.8), param("h0", 1.0)],
        vectors: vec![],
        states: vec![
            State { name: "y".into(), init: h0, span },
            State { name: "v".into(), init: Expr::Num(0.0), span },
        ],
        modes: vec![Mode {
            name: "main".into(),
            flows: vec![v.clone(), Expr::Neg(b(g.clone()))],
            events: vec![EventIdx(0)],
            inputs: vec![],
            span,
        }],
        initial_mode: ModeId(0),
        events: vec![Event {
            name: "touchdown".into(),
            guard: Expr::Binary(BinOp::Sub, b(y.clone()), b(Expr::Num(0.0))),
            direction: Direction::Falling,
            condition: None,
            resets: vec![(StateIdx(1), Expr::Binary(BinOp::Mul, b(Expr::Neg(b(e))), b(v.clone())))],
            target: None,
            is_stop: false,
            owner: None,
            span,
            implicit: false,
            kink: false,
        }],
        outputs: vec![Output {
            name: "energy".into(),
            expr: Expr::Binary(
                BinOp::Add,
                b(Expr::Binary(
                    BinOp::Mul,
                    b(Expr::Num(0.5)),
                    b(Expr::Binary(BinOp::Pow, b(v), b(Expr::Num(2.0)))),
                )),
                b(Expr::Binary(BinOp::Mul, b(g), b(y))),
            ),
            span,
        }],
        simulate: SimulateDefaults { t_end: None, rtol: None, atol: None },
    }
}

const P: [f64; 3] = [9.81, 0.8, 1.0];
const X: [f64; 2] = [0.3, -2.5];

fn at(f: &ModelFunctions, id: ExprId) -> f64 {
    eval_one(&f.store, id, 0.7, &X, &P)
}

#[test]
fn ball_event_derivatives_have_the_closed_form_values() {
    let f = lower(&ball());
    let ev = &f.events[0];
    assert_eq!(at(&f, ev.guard), X[0]);
    // g = y: g_x = [1, 0], no parameter or time dependence.
    let gx: Vec<(u32, f64)> = ev.guard_x.entries.iter().map(|&(k, d)| (k, at(&f, d))).collect();
    assert_eq!(gx, vec![(0, 1.0)]);
    assert!(ev.guard_p.entries.is_empty());
    assert!(f.store.is_zero(ev.guard_t));
    // R = [y, -e v]: R_x = [[1, 0], [0, -e]], R_e = [0, -v].
    let rx: Vec<(u32, u32, f64)> = ev.reset_x.entries.iter().map(|&(i, k, d)| (i, k, at(&f, d))).collect();
    assert_eq!(rx, vec![(0, 0, 1.0), (1, 1, -P[1])]);
    let rp: Vec<(u32, u32, f64)> = ev.reset_p.entries.iter().map(|&(i, k, d)| (i, k, at(&f, d))).collect();
    assert_eq!(rp, vec![(1, 1, -X[1])]);
    assert!(ev.reset_t.entries.is_empty());
}

#[test]
fn ball_flow_init_and_output_derivatives_have_the_closed_form_values() {
    let f = lower(&ball());
    let m = &f.modes[0];
    assert!(m.flow_x.entries.len() == 1 && at(&f, m.flow_x.entries[0].2) == 1.0);
    assert_eq!((m.flow_p.entries[0].0, m.flow_p.entries[0].1), (1, 0));
    assert_eq!(at(&f, m.flow_p.entries[0].2), -1.0);
    assert_eq!(f.init_p.entries.len(), 1);
    assert_eq!((f.init_p.entries[0].0, f.init_p.entries[0].1), (0, 2));
    // energy = v^2/2 + g y: h_x = [g, v], h_g = y.
    let hx: Vec<f64> = f.output_x.entries.iter().map(|&(_, _, d)| at(&f, d)).collect();
    assert_eq!(hx, vec![P[0], X[1]]);
    let hp: Vec<(u32, f64)> = f.output_p.entries.iter().map(|&(_, k, d)| (k, at(&f, d))).collect();
    assert_eq!(hp, vec![(0, X[0])]);
}

#[test]
fn interpreter_follows_the_array_layouts() {
    let model = ball();
    // Differentiate h0 then e, so column order differs from declaration order.
    let info = system_info(&model, &[ParamIdx(2), ParamIdx(1)]);
    let sys = Interpreter::new(lower(&model), info);
    let mut x0 = [0.0; 2];
    sys.initial_state(&P, &mut x0);
    assert_eq!(x0, [1.0, 0.0]);
    let mut s0 = [9.0; 4];
    sys.initial_sens(&P, &mut s0);
    assert_eq!(s0, [1.0, 0.0, 0.0, 0.0]);

    // ds = f_x s + f_p with f_x = [[0, 1], [0, 0]] and f_p zero for h0, e.
    let s = [1.0, 2.0, 3.0, 4.0];
    let (mut dx, mut ds) = ([0.0; 2], [0.0; 4]);
    sys.flow_sens(0, 0.0, &X, &s, &P, &mut dx, &mut ds);
    assert_eq!(dx, [X[1], -P[0]]);
    assert_eq!(ds, [2.0, 0.0, 4.0, 0.0]);

    let (mut rx, mut rp, mut rt) = ([9.0; 4], [9.0; 4], [9.0; 2]);
    sys.reset_jac(0, 0.0, &X, &P, &mut rx, &mut rp, &mut rt);
    assert_eq!(rx, [1.0, 0.0, 0.0, -P[1]]);
    // Column 0 is h0 (zero), column 1 is e: dR_v/de = -v.
    assert_eq!(rp, [0.0, 0.0, 0.0, -X[1]]);
    assert_eq!(rt, [0.0, 0.0]);

    let (mut gx, mut gp) = ([9.0; 2], [9.0; 2]);
    assert_eq!(sys.guard_grad(0, 0.0, &X, &P, &mut gx, &mut gp), 0.0);
    assert_eq!((gx, gp), ([1.0, 0.0], [0.0, 0.0]));
    let mut g = [0.0];
    sys.guards(0, 0.0, &X, &P, &mut g);
    assert_eq!(g, [X[0]]);
    assert!(sys.condition(0, 0.0, &X, &P));

    let (mut y, mut yx, mut yp, mut yt) = ([0.0], [0.0; 2], [9.0; 2], [9.0]);
    sys.outputs(0.0, &X, &P, &mut y);
    assert_eq!(y, [0.5 * X[1] * X[1] + P[0] * X[0]]);
    sys.output_jac(0.0, &X, &P, &mut yx, &mut yp, &mut yt);
    assert_eq!((yx, yp, yt), ([P[0], X[1]], [0.0, 0.0], [0.0]));
}

#[test]
fn ball_report_shows_the_event_derivatives() {
    let model = ball();
    let f = lower(&model);
    let text = derive_report(&model, &f, &[ParamIdx(1), ParamIdx(2)], None);
    println!("{text}");
    for line in ["g_x = [1, 0]", "R_x = [[1, 0], [0, -e]]", "R_e = [0, -v]", "x0_h0 = [1, 0]"] {
        assert!(text.lines().any(|l| l.trim() == line), "missing `{line}` in:\n{text}");
    }
    assert!(text.lines().any(|l| l.trim() == "h = 0.5 * v^2 + g * y"), "{text}");
    assert!(text.lines().any(|l| l.trim() == "h_x = [g, v]"), "{text}");
}

#[test]
fn system_info_maps_the_model_shape() {
    let info = system_info(&ball(), &[ParamIdx(1)]);
    assert_eq!(info.state_names, ["y", "v"]);
    assert_eq!(info.grad_params, [1]);
    assert_eq!(info.modes[0].events, [0]);
    assert_eq!(info.events[0].direction, crate::sim::Direction::Falling);
    assert!(!info.events[0].has_condition);
}
