//! Stage 4 (codegen): the host functions that generated kernels call for operations Cranelift
//! has no instruction for. Knows nothing of the DAG's structure or of kernels; it only names each
//! callee and points at an `extern "C"` wrapper.
//!
//! Every wrapper calls the reference evaluator's `apply_unary`/`apply_binary`, the one place each
//! operation's meaning is written, so JIT and evaluator results agree bit for bit.

use crate::expr::{apply_binary, apply_unary, BinaryOp, UnaryOp};

/// A host function reachable from generated code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(crate) enum Callee {
    Unary(UnaryOp),
    Binary(BinaryOp),
}

impl Callee {
    /// Every callee, so the JIT can register all symbols before any kernel refers to one.
    pub(crate) fn all() -> impl Iterator<Item = Callee> {
        // Exactly the operations that have a host wrapper (the rest Cranelift lowers natively).
        let unary = UnaryOp::ALL.into_iter().filter_map(Callee::for_unary);
        unary.chain(BinaryOp::ALL.into_iter().filter_map(Callee::for_binary))
    }

    /// The callee for a unary operation, or `None` when Cranelift lowers it natively.
    pub(crate) fn for_unary(op: UnaryOp) -> Option<Callee> {
        unary_wrapper(op).map(|_| Callee::Unary(op))
    }

    /// The callee for a binary operation, or `None` when Cranelift lowers it natively.
    pub(crate) fn for_binary(op: BinaryOp) -> Option<Callee> {
        binary_wrapper(op).map(|_| Callee::Binary(op))
    }

    /// The symbol name the JIT resolves; prefixed so it never collides with a libc symbol that
    /// the JIT's fallback `dlsym` lookup might find instead.
    pub(crate) fn symbol(self) -> String {
        match self {
            Callee::Unary(op) => format!("hybc_{op:?}"),
            Callee::Binary(op) => format!("hybc_{op:?}"),
        }
    }

    pub(crate) fn arity(self) -> usize {
        match self {
            Callee::Unary(_) => 1,
            Callee::Binary(_) => 2,
        }
    }

    /// The wrapper's address. Every callee from [`Callee::all`] has one.
    pub(crate) fn address(self) -> Option<*const u8> {
        match self {
            Callee::Unary(op) => unary_wrapper(op).map(|f| f as *const u8),
            Callee::Binary(op) => binary_wrapper(op).map(|f| f as *const u8),
        }
    }
}

type UnaryFn = extern "C" fn(f64) -> f64;
type BinaryFn = extern "C" fn(f64, f64) -> f64;

fn unary_wrapper(op: UnaryOp) -> Option<UnaryFn> {
    let f: UnaryFn = match op {
        UnaryOp::Sin => hybc_sin,
        UnaryOp::Cos => hybc_cos,
        UnaryOp::Tan => hybc_tan,
        UnaryOp::Asin => hybc_asin,
        UnaryOp::Acos => hybc_acos,
        UnaryOp::Atan => hybc_atan,
        UnaryOp::Sinh => hybc_sinh,
        UnaryOp::Cosh => hybc_cosh,
        UnaryOp::Tanh => hybc_tanh,
        UnaryOp::Exp => hybc_exp,
        UnaryOp::Log => hybc_log,
        UnaryOp::Neg | UnaryOp::Sqrt | UnaryOp::Abs | UnaryOp::Sign | UnaryOp::Not => return None,
    };
    Some(f)
}

fn binary_wrapper(op: BinaryOp) -> Option<BinaryFn> {
    let f: BinaryFn = match op {
        BinaryOp::Pow => hybc_pow,
        BinaryOp::PowLog => hybc_pow_log,
        BinaryOp::Atan2 => hybc_atan2,
        BinaryOp::Hypot => hybc_hypot,
        // Cranelift's fmin/fmax propagate NaN and order -0 below +0 (IEEE minimum/maximum);
        // f64::min/max return the non-NaN operand instead, so they go through the host.
        BinaryOp::Min => hybc_min,
        BinaryOp::Max => hybc_max,
        BinaryOp::Add
        | BinaryOp::Mul
        | BinaryOp::Div
        | BinaryOp::Lt
        | BinaryOp::Le
        | BinaryOp::And
        | BinaryOp::Or => return None,
    };
    Some(f)
}

macro_rules! unary_wrappers {
    ($($name:ident => $op:ident),* $(,)?) => {$(
        extern "C" fn $name(a: f64) -> f64 {
            apply_unary(UnaryOp::$op, a)
        }
    )*};
}

macro_rules! binary_wrappers {
    ($($name:ident => $op:ident),* $(,)?) => {$(
        extern "C" fn $name(a: f64, b: f64) -> f64 {
            apply_binary(BinaryOp::$op, a, b)
        }
    )*};
}

unary_wrappers! {
    hybc_sin => Sin, hybc_cos => Cos, hybc_tan => Tan, hybc_asin => Asin, hybc_acos => Acos,
    hybc_atan => Atan, hybc_sinh => Sinh, hybc_cosh => Cosh, hybc_tanh => Tanh, hybc_exp => Exp,
    hybc_log => Log,
}

binary_wrappers! {
    hybc_pow => Pow, hybc_pow_log => PowLog, hybc_atan2 => Atan2, hybc_hypot => Hypot, hybc_min => Min,
    hybc_max => Max,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_callee_has_a_wrapper_and_a_unique_symbol() {
        let callees: Vec<Callee> = Callee::all().collect();
        let mut names: Vec<String> = callees.iter().map(|c| c.symbol()).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), callees.len());
        assert!(callees.iter().all(|c| c.address().is_some()));
    }

    #[test]
    fn min_max_return_the_non_nan_operand() {
        assert_eq!(hybc_min(f64::NAN, 2.0), 2.0);
        assert_eq!(hybc_max(3.0, f64::NAN), 3.0);
    }
}
