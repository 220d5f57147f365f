//! Which expressions are finite wherever their inputs are: the sensitivity kernels use this to
//! guard only the Jacobian entries that can be infinite or NaN at a finite state (a derivative of
//! `sqrt`, `hypot`, a quotient...), so that a zero sensitivity annihilates them.

use super::eval::reachable;
use super::node::{BinaryOp, ExprId, Node, UnaryOp};
use super::store::ExprStore;

/// Whether `root` is finite at every finite time, state and parameter: built only from
/// operations that cannot overflow or leave their domain there. Conservative: `false` means
/// "may not be".
pub fn finite_at_finite_inputs(store: &ExprStore, root: ExprId) -> bool {
    reachable(store, &[root]).into_iter().all(|id| match *store.node(id) {
        Node::Const(bits) => f64::from_bits(bits).is_finite(),
        // A lookup of finite parameters is finite at any position but NaN (its slope a difference).
        Node::State(_) | Node::Param(_) | Node::Time | Node::Select(..) | Node::Lookup(..) => true,
        Node::Unary(op, _) => matches!(
            op,
            UnaryOp::Neg
                | UnaryOp::Sin
                | UnaryOp::Cos
                | UnaryOp::Tan
                | UnaryOp::Atan
                | UnaryOp::Tanh
                | UnaryOp::Abs
                | UnaryOp::Sign
                | UnaryOp::Not
        ),
        Node::Binary(op, _, b) => match op {
            BinaryOp::Pow => {
                store.node(b).as_const().is_some_and(|e| e >= 0.0 && e.fract() == 0.0 && e <= 64.0)
            }
            BinaryOp::Div | BinaryOp::PowLog => false,
            _ => true,
        },
    })
}
