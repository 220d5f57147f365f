//! The second-order products the adjoint of a Rosenbrock step needs (`HybridSystem::flow_vjp_dir`),
//! as expressions both back ends evaluate: the compiled kernel (`codegen::stiff`) and the
//! interpreter (`lower::interp`), from the same entries.
//!
//! A Rosenbrock step evaluates `J = f_x` and `F_t = f_t` once at its start; the forward
//! sensitivities differentiate them along the state's direction (`sens_dir`: `f_xx[s, v] +
//! f_xp v`, and `f_xt s + f_pt`). Their transposes are the gradients of the scalar
//! `phi = w^T (f_x v + a f_t)` with respect to the state and the parameters, for the weights `w`,
//! a direction `v` and a time weight `a`. With `v` and `a` as extra states (`x[n..2n]` and
//! `x[2n]`) and `w` as the sensitivity input `s`, each row `D_i = sum_d f_x[i, d] v_d +
//! a f_t[i]` is a plain expression, and
//! `d phi / dx_c = sum_i w_i dD_i/dx_c` is one `SensDot` per state over the rows that read it
//! (likewise per parameter): no `n x n x n` tensor is ever formed, and a sparse model's work is
//! its second derivatives' entries.

use super::{Differentiator, ExprId, ExprStore, ModeFunctions, Node, Var};

/// The products of `flow_vjp_dir` for one mode: `x[c]` (n) and `p[j]` (m, by sensitivity
/// column) list `(dD_i/d., i)` over the rows `i` whose `D_i` depends on it, rows ascending.
#[derive(Clone, Debug, Default)]
pub struct VjpDirTerms {
    /// Per state `c`: `(dD_i/dx_c, i)`.
    pub x: Vec<Vec<(ExprId, u32)>>,
    /// Per sensitivity column `j`: `(dD_i/dp_j, i)`.
    pub p: Vec<Vec<(ExprId, u32)>>,
}

/// The terms of `mode` (n states; `grad_col[param]` the sensitivity column of a parameter, `m`
/// of them), the new expressions added to `store`.
pub fn flow_vjp_dir_terms(
    store: &mut ExprStore,
    d: &mut Differentiator,
    mode: &ModeFunctions,
    n: usize,
    grad_col: &[Option<usize>],
    m: usize,
) -> VjpDirTerms {
    let mut rows: Vec<ExprId> = vec![store.zero(); n];
    for &(i, c, e) in &mode.flow_x.entries {
        let v = store.state(n as u32 + c);
        let term = store.mul(e, v);
        rows[i as usize] = store.add(rows[i as usize], term);
    }
    let a = store.state(2 * n as u32);
    for &(i, e) in &mode.flow_t.entries {
        let term = store.mul(e, a);
        rows[i as usize] = store.add(rows[i as usize], term);
    }
    let mut terms = VjpDirTerms { x: vec![Vec::new(); n], p: vec![Vec::new(); m] };
    for (i, &row) in rows.iter().enumerate() {
        if store.is_zero(row) {
            continue;
        }
        let (mut states, mut params) = (Vec::new(), Vec::new());
        for id in super::eval::reachable(store, &[row]) {
            match *store.node(id) {
                Node::State(c) if (c as usize) < n => states.push(c),
                Node::Param(q) => params.push(q),
                // A vector read by a lookup: its parameters are not children of the node.
                Node::Lookup(l, _) => params.extend(l.base..l.base + l.len),
                _ => {}
            }
        }
        states.sort_unstable();
        states.dedup();
        params.sort_unstable();
        params.dedup();
        for c in states {
            let e = d.diff(store, row, Var::State(c));
            if !store.is_zero(e) {
                terms.x[c as usize].push((e, i as u32));
            }
        }
        for q in params {
            let Some(j) = grad_col.get(q as usize).copied().flatten() else { continue };
            let e = d.diff(store, row, Var::Param(q));
            if !store.is_zero(e) {
                terms.p[j].push((e, i as u32));
            }
        }
    }
    terms
}
