//! Test support for the JIT tests: hand-built model functions (no parser, no lowering) and the
//! `SystemInfo` that goes with them. Knows only the public `expr` and `sim` contracts.

use hybc::expr::{
    BinaryOp, EventFunctions, ExprId, ExprStore, ModeFunctions, ModelFunctions, Node, SparseMat, SparseVec,
    UnaryOp,
};
use hybc::sim::{Direction, EventInfo, GuardShape, ModeInfo, SystemInfo};

pub fn c(s: &mut ExprStore, v: f64) -> ExprId {
    s.intern(Node::constant(v))
}
pub fn x(s: &mut ExprStore, i: u32) -> ExprId {
    s.intern(Node::State(i))
}
pub fn p(s: &mut ExprStore, j: u32) -> ExprId {
    s.intern(Node::Param(j))
}
pub fn un(s: &mut ExprStore, op: UnaryOp, a: ExprId) -> ExprId {
    s.intern(Node::Unary(op, a))
}
pub fn bin(s: &mut ExprStore, op: BinaryOp, a: ExprId, b: ExprId) -> ExprId {
    s.intern(Node::Binary(op, a, b))
}

pub fn mat(n_rows: u32, n_cols: u32, entries: Vec<(u32, u32, ExprId)>) -> SparseMat {
    SparseMat { n_rows, n_cols, entries }
}
pub fn vec_(entries: Vec<(u32, ExprId)>) -> SparseVec {
    SparseVec { entries }
}

/// Parameters of the ball, in declaration order.
pub const G: usize = 0;
pub const E: usize = 1;
pub const H0: usize = 2;

/// The bouncing ball, by hand: states `h, v`; parameters `g, e, h0`; one mode
/// `der(h) = v, der(v) = -g`; one event `bounce` with guard `h`, condition `v < 0` and reset
/// `v := -e * v`; outputs `h` and `v * v`; initial state `(h0, 0)`.
pub fn ball() -> ModelFunctions {
    let mut s = ExprStore::new();
    let zero = c(&mut s, 0.0);
    let one = c(&mut s, 1.0);
    let m_one = c(&mut s, -1.0);
    let (h, v) = (x(&mut s, 0), x(&mut s, 1));
    let (g, e, h0) = (p(&mut s, 0), p(&mut s, 1), p(&mut s, 2));
    let neg_g = un(&mut s, UnaryOp::Neg, g);
    let neg_e = un(&mut s, UnaryOp::Neg, e);
    let neg_v = un(&mut s, UnaryOp::Neg, v);
    let new_v = bin(&mut s, BinaryOp::Mul, neg_e, v);
    let falling = bin(&mut s, BinaryOp::Lt, v, zero);
    let v2 = bin(&mut s, BinaryOp::Mul, v, v);
    let two = c(&mut s, 2.0);
    let two_v = bin(&mut s, BinaryOp::Mul, two, v);
    ModelFunctions {
        n_states: 2,
        n_params: 3,
        modes: vec![ModeFunctions {
            flow: vec![v, neg_g],
            flow_x: mat(2, 2, vec![(0, 1, one)]),
            flow_p: mat(2, 3, vec![(1, 0, m_one)]),
            flow_t: vec_(vec![]),
            lookups: Vec::new(),
        }],
        events: vec![EventFunctions {
            guard: h,
            guard_x: vec_(vec![(0, one)]),
            guard_p: vec_(vec![]),
            guard_t: zero,
            condition: Some(falling),
            reset: vec![h, new_v],
            reset_x: mat(2, 2, vec![(0, 0, one), (1, 1, neg_e)]),
            reset_p: mat(2, 3, vec![(1, 1, neg_v)]),
            reset_t: vec_(vec![]),
        }],
        knots: vec![],
        init: vec![h0, zero],
        init_p: mat(2, 3, vec![(0, 2, one)]),
        outputs: vec![h, v2],
        output_x: mat(2, 2, vec![(0, 0, one), (1, 1, two_v)]),
        output_p: mat(2, 3, vec![]),
        output_t: vec_(vec![]),
        store: s,
    }
}

pub fn ball_info(grad_params: Vec<usize>) -> SystemInfo {
    SystemInfo {
        state_names: vec!["h".into(), "v".into()],
        output_names: vec!["h".into(), "v2".into()],
        param_names: vec!["g".into(), "e".into(), "h0".into()],
        grad_params,
        modes: vec![ModeInfo { name: "main".into(), events: vec![0] }],
        events: vec![EventInfo {
            name: "bounce".into(),
            direction: Direction::Falling,
            target_mode: None,
            is_stop: false,
            has_condition: true,
            implicit: false,
            kink: false,
            guard: GuardShape::Affine,
            contact: true,
        }],
        initial_mode: 0,
        quadrature: Vec::new(),
        knots: Vec::new(),
    }
}

/// A model with no events and one output `y = expr` of `n_states` states and `n_params`
/// parameters; every other function is zero. Used to test single operations and random DAGs.
pub fn output_only(
    store: ExprStore,
    outputs: Vec<ExprId>,
    n_states: u32,
    n_params: u32,
) -> (ModelFunctions, SystemInfo) {
    let mut store = store;
    let zero = c(&mut store, 0.0);
    let k = outputs.len() as u32;
    let funcs = ModelFunctions {
        n_states,
        n_params,
        modes: vec![ModeFunctions {
            flow: vec![zero; n_states as usize],
            flow_x: mat(n_states, n_states, vec![]),
            flow_p: mat(n_states, n_params, vec![]),
            flow_t: vec_(vec![]),
            lookups: Vec::new(),
        }],
        events: vec![],
        knots: vec![],
        init: vec![zero; n_states as usize],
        init_p: mat(n_states, n_params, vec![]),
        output_x: mat(k, n_states, vec![]),
        output_p: mat(k, n_params, vec![]),
        output_t: vec_(vec![]),
        outputs,
        store,
    };
    let info = SystemInfo {
        state_names: (0..n_states).map(|i| format!("x{i}")).collect(),
        output_names: (0..k).map(|i| format!("y{i}")).collect(),
        param_names: (0..n_params).map(|j| format!("p{j}")).collect(),
        grad_params: vec![],
        modes: vec![ModeInfo { name: "main".into(), events: vec![] }],
        events: vec![],
        initial_mode: 0,
        quadrature: Vec::new(),
        knots: Vec::new(),
    };
    (funcs, info)
}

/// Equal as bit patterns, or both NaN (NaN payloads are not specified by Rust's libm calls).
pub fn same(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}
