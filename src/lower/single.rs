//! One checked expression to infix text, for summaries (`hybc check`) that show a model's
//! expressions without lowering the whole model.

use super::Lowerer;
use crate::expr::to_infix_capped;
use crate::sema::{Expr, Model};

/// Longest text a summary shows for one expression (a chain of `let`s can make it as long as
/// the chain, or exponentially long when each `let` uses its predecessor twice).
pub const SHOWN_CHARS: usize = 400;

/// Prints a model's expressions with its names. The names are gathered once, so a summary of a
/// model with many states costs its size, not its size times the number of states.
pub struct ExprPrinter<'m> {
    model: &'m Model,
    states: Vec<String>,
    params: Vec<String>,
}

impl<'m> ExprPrinter<'m> {
    /// A printer for the expressions of `model` (its states' and parameters' names).
    pub fn new(model: &'m Model) -> ExprPrinter<'m> {
        ExprPrinter {
            model,
            states: model.states.iter().map(|s| s.name.clone()).collect(),
            params: model.params.iter().map(|p| p.name.clone()).collect(),
        }
    }

    /// `e` simplified and printed (e.g. the guard `y - 0` prints as `y`), cut after
    /// [`SHOWN_CHARS`] characters with `...`.
    pub fn show(&self, e: &Expr) -> String {
        let mut cx = Lowerer::new(self.model.n_states() as u32, self.model.n_params() as u32);
        let id = cx.expr(e);
        to_infix_capped(&cx.store, id, &self.states, &self.params, SHOWN_CHARS)
    }
}
