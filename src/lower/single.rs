//! One checked expression to infix text, for summaries (`hybc check`) that show a model's
//! expressions without lowering the whole model.

use super::Lowerer;
use crate::expr::{to_infix, Differentiator, ExprStore};
use crate::sema::{Expr, Model};

/// `e` simplified and printed with the model's names (e.g. the guard `y - 0` prints as `y`).
pub fn show_expr(model: &Model, e: &Expr) -> String {
    let mut cx = Lowerer {
        store: ExprStore::new(),
        diff: Differentiator::new(),
        n_states: model.n_states() as u32,
        n_params: model.n_params() as u32,
    };
    let id = cx.expr(e);
    let states: Vec<String> = model.states.iter().map(|s| s.name.clone()).collect();
    let params: Vec<String> = model.params.iter().map(|p| p.name.clone()).collect();
    to_infix(&cx.store, id, &states, &params)
}
