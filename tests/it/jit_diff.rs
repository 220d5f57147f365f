//! Differential tests: the JIT against the reference evaluator (`expr::eval`, `apply_*`).
//!
//! Every kernel evaluates the DAG in the evaluator's order and transcendental functions call the
//! evaluator's own `apply_*`, so results must agree bit for bit (all NaNs count as equal: Rust
//! leaves NaN payloads unspecified).

use crate::support::hand_functions::{output_only, same};
use hybc::codegen::{CompileOptions, CompiledModel};
use hybc::expr::{apply_binary, apply_select, apply_unary, eval, BinaryOp, ExprId, ExprStore, Node, UnaryOp};
use hybc::sim::HybridSystem;
use proptest::prelude::*;

const UNARY: [UnaryOp; 16] = UnaryOp::ALL;

const BINARY: [BinaryOp; 13] = BinaryOp::ALL;

/// Values where the semantics of the ops differ most: signed zeros, infinities, NaN, and the
/// boolean values.
const SPECIAL: [f64; 9] = [0.0, -0.0, 1.0, -1.0, 0.5, -2.5, f64::INFINITY, f64::NEG_INFINITY, f64::NAN];

#[test]
fn every_op_matches_the_evaluator_on_special_values() {
    let mut s = ExprStore::new();
    let (a, b, c) = (s.intern(Node::State(0)), s.intern(Node::State(1)), s.intern(Node::State(2)));
    let mut outputs: Vec<ExprId> = UNARY.iter().map(|&op| s.intern(Node::Unary(op, a))).collect();
    outputs.extend(BINARY.iter().map(|&op| s.intern(Node::Binary(op, a, b))));
    outputs.push(s.intern(Node::Select(a, b, c)));
    let (funcs, info) = output_only(s, outputs, 3, 0);
    let jit = CompiledModel::compile(&funcs, info, &CompileOptions::default()).expect("compiles");

    let mut y = vec![0.0; UNARY.len() + BINARY.len() + 1];
    for &va in &SPECIAL {
        for &vb in &SPECIAL {
            let vc = -vb * 3.0;
            jit.outputs(0.0, &[va, vb, vc], &[], &mut y);
            let mut want: Vec<f64> = UNARY.iter().map(|&op| apply_unary(op, va)).collect();
            want.extend(BINARY.iter().map(|&op| apply_binary(op, va, vb)));
            want.push(apply_select(va, vb, vc));
            for (i, (got, want)) in y.iter().zip(&want).enumerate() {
                let op = UNARY
                    .get(i)
                    .map(|op| format!("{op:?}"))
                    .or_else(|| BINARY.get(i - UNARY.len()).map(|op| format!("{op:?}")))
                    .unwrap_or_else(|| "Select".into());
                assert!(same(*got, *want), "{op}({va}, {vb}, {vc}): jit {got:e} vs evaluator {want:e}");
            }
        }
    }
}

#[test]
fn a_constant_square_is_the_correctly_rounded_product_in_both() {
    // The JIT lowers `x^2` with a constant 2 to one multiply; the evaluator (and so constant
    // folding and any `pow` call with a run-time exponent 2) must give the same bits.
    let mut s = ExprStore::new();
    let x = s.intern(Node::State(0));
    let two = s.intern(Node::constant(2.0));
    let square = s.intern(Node::Binary(BinaryOp::Pow, x, two));
    let (funcs, info) = output_only(s, vec![square], 1, 0);
    let jit = CompiledModel::compile(&funcs, info, &CompileOptions::default()).expect("compiles");
    let mut values = SPECIAL.to_vec();
    values.extend([1.1, -3.7e-5, 1e154, 1.5e-160, 0.1 + 0.2, std::f64::consts::PI]);
    let mut y = [0.0];
    for v in values {
        jit.outputs(0.0, &[v], &[], &mut y);
        let want = apply_binary(BinaryOp::Pow, v, 2.0);
        assert!(same(want, v * v), "evaluator {v}^2 = {want:e}");
        assert!(same(y[0], want), "jit {v}^2 = {:e} vs {want:e}", y[0]);
    }
}

/// A random DAG: leaves (three states, two parameters, time, constants) followed by operations
/// whose operands are earlier nodes. Built with the raw `intern`, so nothing is simplified away
/// and every op reaches the code generator as drawn.
#[derive(Clone, Debug)]
struct RandomDag {
    consts: Vec<f64>,
    ops: Vec<(usize, usize, usize, usize)>,
    n_outputs: usize,
}

fn value() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -3.0..3.0f64,
        1 => proptest::sample::select(SPECIAL.to_vec()),
    ]
}

fn random_dag() -> impl Strategy<Value = RandomDag> {
    (
        proptest::collection::vec(value(), 1..4),
        proptest::collection::vec(
            (0..UNARY.len() + BINARY.len() + 1, any::<usize>(), any::<usize>(), any::<usize>()),
            1..40,
        ),
        1..6usize,
    )
        .prop_map(|(consts, ops, n_outputs)| RandomDag { consts, ops, n_outputs })
}

impl RandomDag {
    fn build(&self) -> (ExprStore, Vec<ExprId>) {
        let mut s = ExprStore::new();
        let mut nodes: Vec<ExprId> = vec![
            s.intern(Node::State(0)),
            s.intern(Node::State(1)),
            s.intern(Node::State(2)),
            s.intern(Node::Param(0)),
            s.intern(Node::Param(1)),
            s.intern(Node::Time),
        ];
        nodes.extend(self.consts.iter().map(|&v| s.intern(Node::constant(v))));
        for &(kind, i, j, k) in &self.ops {
            // Prefer recent nodes so the DAG grows deep rather than wide.
            let pick = |r: usize| nodes[nodes.len() - 1 - r % nodes.len().min(8)];
            let node = if kind < UNARY.len() {
                Node::Unary(UNARY[kind], pick(i))
            } else if kind < UNARY.len() + BINARY.len() {
                Node::Binary(BINARY[kind - UNARY.len()], pick(i), pick(j))
            } else {
                Node::Select(pick(i), pick(j), pick(k))
            };
            let id = s.intern(node);
            nodes.push(id);
        }
        let outputs = nodes.iter().rev().take(self.n_outputs).copied().collect();
        (s, outputs)
    }
}

proptest! {
    #![proptest_config(crate::support::proptest_config(96))]

    #[test]
    fn random_dags_match_the_evaluator_bit_for_bit(
        dag in random_dag(),
        inputs in proptest::collection::vec(value(), 6),
    ) {
        let (store, outputs) = dag.build();
        let roots = outputs.clone();
        let (funcs, info) = output_only(store, outputs, 3, 2);
        let jit = CompiledModel::compile(&funcs, info, &CompileOptions::default())
            .expect("a random DAG compiles");
        let (x, p, t) = (&inputs[0..3], &inputs[3..5], inputs[5]);
        let want = eval(&funcs.store, &roots, t, x, p);
        let mut got = vec![f64::NAN; roots.len()];
        jit.outputs(t, x, p, &mut got);
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            prop_assert!(same(*g, *w), "output {i}: jit {g:e} vs evaluator {w:e}");
        }
    }
}

#[test]
fn one_random_model_evaluated_from_several_threads_agrees_with_the_evaluator() {
    let dag = RandomDag {
        consts: vec![0.5, -1.25],
        ops: (0..60).map(|i| ((i * 7) % 29, i * 3 + 1, i * 5 + 2, i + 3)).collect(),
        n_outputs: 5,
    };
    let (store, outputs) = dag.build();
    let roots = outputs.clone();
    let (funcs, info) = output_only(store, outputs, 3, 2);
    let jit = CompiledModel::compile(&funcs, info, &CompileOptions::default()).expect("compiles");
    std::thread::scope(|scope| {
        for thread in 0..4u32 {
            let (jit, funcs, roots) = (&jit, &funcs, &roots);
            scope.spawn(move || {
                for step in 0..500u32 {
                    let v = f64::from(thread * 1000 + step) * 1e-3 - 1.0;
                    let (x, p, t) = ([v, -v * 0.5, v * v], [1.5, v + 0.25], v * 2.0);
                    let want = eval(&funcs.store, roots, t, &x, &p);
                    let mut got = vec![f64::NAN; roots.len()];
                    jit.outputs(t, &x, &p, &mut got);
                    assert!(got.iter().zip(&want).all(|(g, w)| same(*g, *w)), "{got:?} vs {want:?}");
                }
            });
        }
    });
}
