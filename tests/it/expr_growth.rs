//! Growth of the derivative DAG: for a chain of 200 coupled states,
//! `der(x_i) = -k_i * x_i + sin(x_{i-1}) * x_{i+1}` (ends open), the nodes of all flow
//! Jacobians (`f_x`, `f_p`, `f_t`) stay within a small constant factor of the flow's own node
//! count, because derivatives reuse primal nodes and the differentiator shares its cache.

use hybc::expr::eval::reachable;
use hybc::expr::ExprId;
use hybc::lower::lower;
use hybc::sema::{
    BinOp, Expr, Func, Mode, ModeId, Model, Param, ParamIdx, SimulateDefaults, State, StateIdx,
};
use hybc::syntax::Span;

const N: u32 = 200;

fn chain() -> Model {
    let span = Span::default();
    let x = |i: u32| Expr::State(StateIdx(i));
    let flow = |i: u32| {
        let decay =
            Expr::Neg(Box::new(Expr::Binary(BinOp::Mul, Box::new(Expr::Param(ParamIdx(i))), Box::new(x(i)))));
        if i == 0 || i + 1 == N {
            return decay;
        }
        let coupling =
            Expr::Binary(BinOp::Mul, Box::new(Expr::Call(Func::Sin, vec![x(i - 1)])), Box::new(x(i + 1)));
        Expr::Binary(BinOp::Add, Box::new(decay), Box::new(coupling))
    };
    Model {
        name: "chain".into(),
        params: (0..N).map(|i| Param { name: format!("k{i}"), default: 1.0, range: None, span }).collect(),
        vectors: vec![],
        states: (0..N).map(|i| State { name: format!("x{i}"), init: Expr::Num(1.0), span }).collect(),
        modes: vec![Mode {
            name: "main".into(),
            flows: (0..N).map(flow).collect(),
            events: vec![],
            inputs: vec![],
            span,
        }],
        initial_mode: ModeId(0),
        events: vec![],
        outputs: vec![],
        simulate: SimulateDefaults { t_end: None, rtol: None, atol: None },
    }
}

#[test]
fn jacobian_nodes_grow_linearly_with_the_flow() {
    let f = lower(&chain());
    let mode = &f.modes[0];
    let flow_nodes = reachable(&f.store, &mode.flow).len();
    let jac_roots: Vec<ExprId> = mode
        .flow_x
        .entries
        .iter()
        .chain(&mode.flow_p.entries)
        .map(|&(_, _, e)| e)
        .chain(mode.flow_t.entries.iter().map(|&(_, e)| e))
        .collect();
    let jac_nodes = reachable(&f.store, &jac_roots).len();
    let factor = jac_nodes as f64 / flow_nodes as f64;
    // Everything in the store (flow, init, all Jacobians) relative to the flow alone.
    let total = f.store.len() as f64 / flow_nodes as f64;
    println!(
        "flow nodes {flow_nodes}, jacobian nodes {jac_nodes}, factor {factor:.2}, \
         whole store {} ({total:.2}x)",
        f.store.len()
    );
    // Interior row: d/dx_{i-1} = cos(x_{i-1}) x_{i+1}, d/dx_i = -k_i, d/dx_{i+1} = sin(x_{i-1}),
    // d/dk_i = -x_i: 3 non-zeros per interior row in f_x, 1 per row in f_p, none in f_t.
    assert_eq!(mode.flow_x.entries.len() as u32, 3 * (N - 2) + 2);
    assert_eq!(mode.flow_p.entries.len() as u32, N);
    assert!(mode.flow_t.entries.is_empty());
    assert!(factor <= 4.0, "jacobian/flow node factor {factor}");
    assert!(total <= 4.0, "store/flow node factor {total}");
}
