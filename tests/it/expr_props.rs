//! Property tests of the expression engine over random trees using every operation:
//! - the symbolic derivative agrees with a central finite difference of the evaluator
//!   (relative error <= 1e-6) at random points that are away from kinks, domain edges and
//!   singularities; the filter looks only at the input point (intermediate values of the
//!   expression there), never at the derivatives being compared;
//! - simplified and unsimplified construction evaluate equal wherever every intermediate value of
//!   the unsimplified tree is finite (the documented NaN policy of the simplifier);
//! - building the same expression twice gives identical ids and nodes.

use hybc::expr::{
    apply_binary, apply_unary, diff, eval, BinaryOp, ExprId, ExprStore, Node, Tape, UnaryOp, Var,
};
use proptest::prelude::*;

#[derive(Clone, Debug)]
enum Tree {
    State(u32),
    Param(u32),
    Time,
    Const(f64),
    Unary(UnaryOp, Box<Tree>),
    Binary(BinaryOp, Box<Tree>, Box<Tree>),
    Select(Box<Tree>, Box<Tree>, Box<Tree>),
}

const UNARY: [UnaryOp; 16] = UnaryOp::ALL;

const BINARY: [BinaryOp; 13] = BinaryOp::ALL;

fn tree() -> impl Strategy<Value = Tree> {
    let leaf = prop_oneof![
        (0u32..2).prop_map(Tree::State),
        (0u32..2).prop_map(Tree::Param),
        Just(Tree::Time),
        prop::sample::select(vec![0.0, 1.0, -1.0, 2.0, 0.5, 3.0, -0.25]).prop_map(Tree::Const),
        (-2.0f64..2.0).prop_map(Tree::Const),
    ];
    leaf.prop_recursive(5, 24, 3, |inner| {
        prop_oneof![
            (prop::sample::select(UNARY.to_vec()), inner.clone())
                .prop_map(|(op, a)| Tree::Unary(op, Box::new(a))),
            (prop::sample::select(BINARY.to_vec()), inner.clone(), inner.clone())
                .prop_map(|(op, a, b)| Tree::Binary(op, Box::new(a), Box::new(b))),
            (inner.clone(), inner.clone(), inner).prop_map(|(c, a, b)| Tree::Select(
                Box::new(c),
                Box::new(a),
                Box::new(b)
            )),
        ]
    })
}

/// Builds with the simplifying constructors.
fn build(s: &mut ExprStore, t: &Tree) -> ExprId {
    match t {
        Tree::State(i) => s.state(*i),
        Tree::Param(i) => s.param(*i),
        Tree::Time => s.time(),
        Tree::Const(v) => s.constant(*v),
        Tree::Unary(op, a) => {
            let a = build(s, a);
            s.unary(*op, a)
        }
        Tree::Binary(op, a, b) => {
            let (a, b) = (build(s, a), build(s, b));
            s.binary(*op, a, b)
        }
        Tree::Select(c, a, b) => {
            let (c, a, b) = (build(s, c), build(s, a), build(s, b));
            s.select(c, a, b)
        }
    }
}

/// Builds the same tree node for node through `intern`, without any simplification.
fn build_raw(s: &mut ExprStore, t: &Tree) -> ExprId {
    let node = match t {
        Tree::State(i) => Node::State(*i),
        Tree::Param(i) => Node::Param(*i),
        Tree::Time => Node::Time,
        Tree::Const(v) => Node::constant(*v),
        Tree::Unary(op, a) => Node::Unary(*op, build_raw(s, a)),
        Tree::Binary(op, a, b) => {
            let a = build_raw(s, a);
            Node::Binary(*op, a, build_raw(s, b))
        }
        Tree::Select(c, a, b) => {
            let c = build_raw(s, c);
            let a = build_raw(s, a);
            Node::Select(c, a, build_raw(s, b))
        }
    };
    s.intern(node)
}

#[derive(Clone, Copy, Debug)]
struct Point {
    t: f64,
    x: [f64; 2],
    p: [f64; 2],
}

fn point() -> impl Strategy<Value = Point> {
    (-2.0f64..2.0, [-2.0f64..2.0, -2.0f64..2.0], [-2.0f64..2.0, -2.0f64..2.0]).prop_map(|(t, x, p)| Point {
        t,
        x,
        p,
    })
}

fn shifted(at: Point, wrt: Var, d: f64) -> Point {
    let mut q = at;
    match wrt {
        Var::State(i) => q.x[i as usize] += d,
        Var::Param(i) => q.p[i as usize] += d,
        Var::Time => q.t += d,
        Var::Node(_) => unreachable!("the strategy draws leaves only"),
    }
    q
}

fn var() -> impl Strategy<Value = Var> {
    prop_oneof![(0u32..2).prop_map(Var::State), (0u32..2).prop_map(Var::Param), Just(Var::Time)]
}

proptest! {
    #![proptest_config(ProptestConfig { max_global_rejects: 200_000, ..crate::support::proptest_config(2000) })]

    #[test]
    fn derivative_matches_central_difference(t in tree(), at in point(), wrt in var()) {
        let mut raw = ExprStore::new();
        let r = build_raw(&mut raw, &t);
        prop_assume!(crate::support::expr::is_smooth_at(&raw, r, at.t, &at.x, &at.p, 1e4));

        let mut s = ExprStore::new();
        let e = build(&mut s, &t);
        let d = diff(&mut s, e, wrt);
        let symbolic = eval(&s, &[d], at.t, &at.x, &at.p)[0];
        // Step scaled to the variable. Central differences at h and h/2, Richardson-combined
        // (truncation ~h^4); where the two differences disagree the function is too steep for a
        // difference to be an oracle at this step (near a pole of tan, say), and the point is
        // rejected: a judgement on the oracle alone, never on the symbolic result.
        let x0 = match wrt { Var::State(i) => at.x[i as usize], Var::Param(i) => at.p[i as usize], Var::Time => at.t, Var::Node(_) => unreachable!("leaves only") };
        let h = 1e-4 * x0.abs().max(1.0);
        let f = |q: Point| eval(&s, &[e], q.t, &q.x, &q.p)[0];
        let central = |h: f64| (f(shifted(at, wrt, h)) - f(shifted(at, wrt, -h))) / (2.0 * h);
        let (coarse, fine) = (central(h), central(h / 2.0));
        prop_assume!((coarse - fine).abs() <= 1e-4 * coarse.abs().max(fine.abs()).max(1.0));
        let numeric = (4.0 * fine - coarse) / 3.0;
        let scale = symbolic.abs().max(numeric.abs()).max(1.0);
        prop_assert!((symbolic - numeric).abs() <= 1e-6 * scale,
            "d/d{:?}: symbolic {} vs numeric {}", wrt, symbolic, numeric);
    }

    #[test]
    fn simplification_keeps_values(t in tree(), at in point()) {
        let mut raw = ExprStore::new();
        let r = build_raw(&mut raw, &t);
        // Every node's value, to apply the NaN policy: compare where all are finite.
        let all: Vec<ExprId> = (0..raw.len() as u32).map(ExprId).collect();
        let v = Tape::new(&raw, &all).eval(at.t, &at.x, &at.p);
        prop_assume!(v.iter().all(|x| x.is_finite()));
        let mut s = ExprStore::new();
        let e = build(&mut s, &t);
        let simplified = eval(&s, &[e], at.t, &at.x, &at.p)[0];
        // `==` treats 0.0 and -0.0 as equal, the one difference the NaN policy allows.
        prop_assert_eq!(simplified, v[r.index()]);
    }

    #[test]
    fn building_twice_gives_identical_ids(t in tree(), wrt in var()) {
        let mut a = ExprStore::new();
        let mut b = ExprStore::new();
        let (ea, eb) = (build(&mut a, &t), build(&mut b, &t));
        let (da, db) = (diff(&mut a, ea, wrt), diff(&mut b, eb, wrt));
        prop_assert_eq!((ea, da), (eb, db));
        prop_assert_eq!(a.len(), b.len());
        for i in 0..a.len() as u32 {
            prop_assert_eq!(a.node(ExprId(i)), b.node(ExprId(i)));
        }
        // And hash-consing: the same tree again in the same store adds nothing.
        let before = a.len();
        prop_assert_eq!(build(&mut a, &t), ea);
        prop_assert_eq!(a.len(), before);
    }

    #[test]
    fn folding_uses_the_evaluator_semantics(op in prop::sample::select(UNARY.to_vec()), x in -3.0f64..3.0) {
        let mut s = ExprStore::new();
        let c = s.constant(x);
        let e = s.unary(op, c);
        let expected = apply_unary(op, x);
        match s.const_value(e) {
            Some(v) => prop_assert_eq!(v.to_bits(), expected.to_bits()),
            None => prop_assert!(!expected.is_finite()),
        }
    }

    #[test]
    fn binary_folding_uses_the_evaluator_semantics(op in prop::sample::select(BINARY.to_vec()), x in -3.0f64..3.0, y in -3.0f64..3.0) {
        let mut s = ExprStore::new();
        let (cx, cy) = (s.constant(x), s.constant(y));
        let e = s.binary(op, cx, cy);
        let expected = apply_binary(op, x, y);
        match s.const_value(e) {
            Some(v) => prop_assert_eq!(v.to_bits(), expected.to_bits()),
            None => prop_assert!(!expected.is_finite()),
        }
    }
}
