//! The one walk over checked expressions and conditions that every pass of the checker takes
//! (initial values that must be constant, the states a condition or a model reads, the flow
//! switches and whether they move): every node in pre-order, a condition before the branches of
//! its `if`, a comparison's sides before the comparison itself, and each shared `let`
//! definition entered once per [`Walk`] (through `stack::deep`, so a chain of `let`s as deep as
//! `MAX_EXPR_DEPTH` does not overflow the stack). A checked model is a DAG as large as its
//! text; a pass that walked every use of a `let` would cost the size of the expanded tree.

use std::collections::{HashMap, HashSet};
use std::ops::ControlFlow;

use super::model::{Cond, Expr, SharedDef};

/// Whether a walk goes on into a node's children.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Descend {
    /// Walk the children.
    Into,
    /// Leave them out.
    Over,
}

/// What a pass does at the nodes of a walk. Each method continues by default.
pub(crate) trait Visit {
    /// What ends a walk early (a search's answer); `std::convert::Infallible` for a pass that
    /// reads every node.
    type Break: Clone;

    /// At `e`, before its children (and, for a shared `let`, before its definition).
    fn expr(&mut self, _e: &Expr) -> ControlFlow<Self::Break, Descend> {
        ControlFlow::Continue(Descend::Into)
    }

    /// At the comparison `lhs OP rhs` of a condition, after both sides.
    fn comparison(&mut self, _lhs: &Expr, _rhs: &Expr) -> ControlFlow<Self::Break> {
        ControlFlow::Continue(())
    }
}

/// A walk, and what it learnt of the shared `let` definitions it entered: one walked to the
/// end is not entered again, and one whose walk broke breaks again with the same answer. So a
/// walk kept across calls, for one pass's question, answers it once per definition.
pub(crate) struct Walk<B> {
    done: HashSet<*const SharedDef>,
    broke: HashMap<*const SharedDef, B>,
}

impl<B: Clone> Walk<B> {
    pub(crate) fn new() -> Walk<B> {
        Walk { done: HashSet::new(), broke: HashMap::new() }
    }

    /// Walks `e` with `visit`.
    pub(crate) fn expr<V: Visit<Break = B>>(&mut self, e: &Expr, visit: &mut V) -> ControlFlow<B> {
        if visit.expr(e)? == Descend::Over {
            return ControlFlow::Continue(());
        }
        match e {
            Expr::Num(_) | Expr::Param(_) | Expr::Time | Expr::State(_) => ControlFlow::Continue(()),
            Expr::Shared(s) => {
                let key = s.key();
                if self.done.contains(&key) {
                    return ControlFlow::Continue(());
                }
                if let Some(answer) = self.broke.get(&key) {
                    return ControlFlow::Break(answer.clone());
                }
                match crate::stack::deep(|| self.expr(s.expr(), visit)) {
                    ControlFlow::Continue(()) => {
                        self.done.insert(key);
                        ControlFlow::Continue(())
                    }
                    ControlFlow::Break(answer) => {
                        self.broke.insert(key, answer.clone());
                        ControlFlow::Break(answer)
                    }
                }
            }
            Expr::Neg(a) => self.expr(a, visit),
            Expr::Binary(_, a, b) => {
                self.expr(a, visit)?;
                self.expr(b, visit)
            }
            Expr::Call(_, args) => args.iter().try_for_each(|a| self.expr(a, visit)),
            Expr::If(c, a, b) => {
                self.cond(c, visit)?;
                self.expr(a, visit)?;
                self.expr(b, visit)
            }
            Expr::Input(input) => {
                self.expr(&input.t0, visit)?;
                self.expr(&input.t1, visit)
            }
        }
    }

    /// Walks `c` with `visit`.
    pub(crate) fn cond<V: Visit<Break = B>>(&mut self, c: &Cond, visit: &mut V) -> ControlFlow<B> {
        match c {
            Cond::Cmp(_, lhs, rhs) => {
                self.expr(lhs, visit)?;
                self.expr(rhs, visit)?;
                visit.comparison(lhs, rhs)
            }
            Cond::And(a, b) | Cond::Or(a, b) => {
                self.cond(a, visit)?;
                self.cond(b, visit)
            }
            Cond::Not(a) => self.cond(a, visit),
        }
    }
}

/// The states the walked expressions read: `by[i]` for state `i`.
pub(crate) struct StatesRead {
    pub(crate) by: Vec<bool>,
}

impl StatesRead {
    /// None read yet, of a model with `n` states.
    pub(crate) fn new(n: usize) -> StatesRead {
        StatesRead { by: vec![false; n] }
    }
}

impl Visit for StatesRead {
    type Break = std::convert::Infallible;

    fn expr(&mut self, e: &Expr) -> ControlFlow<Self::Break, Descend> {
        if let Expr::State(i) = e {
            self.by[i.0 as usize] = true;
        }
        ControlFlow::Continue(Descend::Into)
    }
}

/// What makes an expression vary along a run, found first by [`first_non_constant`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum NonConstant {
    /// The time `t`.
    Time,
    /// State `i`.
    State(usize),
    /// An input (`pwl`, `pwc`), which varies with `t`.
    Input,
}

/// The first use of `t`, a state or an input in `e`, in walk order, if any.
pub(crate) fn first_non_constant(e: &Expr) -> Option<NonConstant> {
    struct Search;
    impl Visit for Search {
        type Break = NonConstant;
        fn expr(&mut self, e: &Expr) -> ControlFlow<NonConstant, Descend> {
            match e {
                Expr::Time => ControlFlow::Break(NonConstant::Time),
                Expr::State(i) => ControlFlow::Break(NonConstant::State(i.0 as usize)),
                Expr::Input(_) => ControlFlow::Break(NonConstant::Input),
                _ => ControlFlow::Continue(Descend::Into),
            }
        }
    }
    match Walk::new().expr(e, &mut Search) {
        ControlFlow::Break(found) => Some(found),
        ControlFlow::Continue(()) => None,
    }
}
