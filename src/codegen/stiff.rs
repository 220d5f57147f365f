//! Stage 4 (codegen): the plans of the kernels a Rosenbrock stepper needs beyond the flow, per
//! mode. They take second derivatives, which an explicit run never needs, so they are planned
//! and compiled on demand (`CompiledModel::prepare_jacobians`), not with the model.
//!
//! - `mode{k}_flow_jac` (inputs `x` (n), `s = S` (n m)): `f_x` as the values of its structurally
//!   nonzero entries only, in the order of the mode's pattern (`StiffPlan::patterns`: the
//!   entries of the symbolic `f_x`, known here at compile time), `f_t` (n), and the
//!   sensitivities' time derivative `f_xt s_j + f_pt_j` (n m, column per parameter). A chain of
//!   1000 states writes about 3000 numbers, not a million; the dense `n x n` matrix, for small
//!   models, is scattered from them by the caller (`CompiledModel::flow_jac`).
//! - `mode{k}_sens_dir` (inputs `x = [x, v]` (2n), `s = S` (n m)): for the direction `v`, the
//!   derivative of the sensitivity right-hand side along `v`,
//!   `(d/dx (f_x s_j + f_p_j)) v = f_xx[s_j, v] + f_xp_j v` (n m). The direction enters as the
//!   extra states `x[n..2n]`, so the directional derivative of an entry `e` of `f_x` is the
//!   plain expression `sum_d (de/dx_d) v_d` and the whole term is one `SensDot` per entry: the
//!   kernel planner and lowering need nothing new.

use super::plan::{index_u32, rows, KernelPlan, Lens, Term};
use super::CodegenError;
use crate::expr::{Differentiator, ExprId, ExprStore, ModelFunctions, Node, Var};
use crate::sim::SystemInfo;

/// The stiff kernels of every mode, indexed by mode, with the pattern of each mode's `f_x`.
pub(crate) struct StiffPlan {
    pub jac: Vec<KernelPlan>,
    pub dir: Vec<KernelPlan>,
    /// `(row, column)` of each value `flow_jac` writes to its first output, in that order.
    pub patterns: Vec<Vec<(u32, u32)>>,
}

/// Plans the stiff kernels of `funcs` (already checked against `info` by `plan_model`); the new
/// derivative expressions are added to `funcs.store`.
pub(crate) fn plan_stiff(funcs: &mut ModelFunctions, info: &SystemInfo) -> Result<StiffPlan, CodegenError> {
    let n = info.n_states();
    let m = info.n_grad();
    let n_params = info.n_params();
    let mut grad_col = vec![None; n_params];
    for (c, &param) in info.grad_params.iter().enumerate() {
        if let Some(slot) = grad_col.get_mut(param) {
            *slot = Some(c);
        }
    }
    let mut d = Differentiator::new();
    let mut plan = StiffPlan { jac: Vec::new(), dir: Vec::new(), patterns: Vec::new() };
    let modes = funcs.modes.clone();
    let store = &mut funcs.store;
    for (k, mode) in modes.iter().enumerate() {
        let fx_rows = rows(&mode.flow_x, n);
        let fp_rows = rows(&mode.flow_p, n);
        // The entry of `f_p` for sensitivity column `j` in row `i`, if any.
        let fp = |i: usize, j: usize| {
            fp_rows[i].iter().find(|&&(param, _)| grad_col[param] == Some(j)).map(|&(_, e)| e)
        };

        // Every entry of the pattern is written (the sparse matrix holds no zeros), so the
        // values need no zero fill.
        let pattern: Vec<(u32, u32)> = mode.flow_x.entries.iter().map(|&(i, c, _)| (i, c)).collect();
        let lens = Lens { x: n, s: n * m, p: n_params, out: [pattern.len(), n, n * m] };
        let mut jac = KernelPlan::new(format!("mode{k}_flow_jac"), lens);
        jac.prefill = [false, true, false];
        for (slot, &(_, _, e)) in mode.flow_x.entries.iter().enumerate() {
            jac.write(0, slot, Term::Expr(e))?;
        }
        plan.patterns.push(pattern);
        for &(i, e) in &mode.flow_t.entries {
            jac.write(1, i as usize, Term::Expr(e))?;
        }
        // d/dt of f_x S + f_p, entry by entry in the order `flow_sens` sums them.
        let fxt_rows: Vec<Vec<(usize, ExprId)>> = fx_rows
            .iter()
            .map(|row| row.iter().map(|&(c, e)| (c, d.diff(store, e, Var::Time))).collect())
            .collect();
        for j in 0..m {
            for (i, row) in fxt_rows.iter().enumerate() {
                let products = row
                    .iter()
                    .filter(|&&(_, e)| !store.is_zero(e))
                    .map(|&(c, e)| Ok((e, index_u32(&jac.name, j * n + c)?)))
                    .collect::<Result<Vec<_>, CodegenError>>()?;
                let bias = fp(i, j).map(|e| d.diff(store, e, Var::Time)).filter(|&e| !store.is_zero(e));
                jac.write(2, j * n + i, sens_term(products, bias))?;
            }
        }

        let lens = Lens { x: 2 * n, s: n * m, p: n_params, out: [n * m, 0, 0] };
        let mut dir = KernelPlan::new(format!("mode{k}_sens_dir"), lens);
        let fxv_rows: Vec<Vec<(usize, ExprId)>> = fx_rows
            .iter()
            .map(|row| row.iter().map(|&(c, e)| (c, directional(store, &mut d, e, n))).collect())
            .collect();
        for j in 0..m {
            for (i, row) in fxv_rows.iter().enumerate() {
                let products = row
                    .iter()
                    .filter(|&&(_, e)| !store.is_zero(e))
                    .map(|&(c, e)| Ok((e, index_u32(&dir.name, j * n + c)?)))
                    .collect::<Result<Vec<_>, CodegenError>>()?;
                let bias = fp(i, j).map(|e| directional(store, &mut d, e, n)).filter(|&e| !store.is_zero(e));
                dir.write(0, j * n + i, sens_term(products, bias))?;
            }
        }
        plan.jac.push(jac);
        plan.dir.push(dir);
    }
    for kernel in plan.jac.iter_mut().chain(&mut plan.dir) {
        kernel.write_small_zeros();
        kernel.check(store)?;
    }
    Ok(plan)
}

/// The adjoint's second-order kernels, one per mode: `mode{k}_flow_vjp_dir` (inputs
/// `x = [x, v, a]` (2n + 1), `s = w` (n)) writes `d phi/dx` (n) and `d phi/dp` (m, by
/// sensitivity column) for `phi = w^T (f_x v + a f_t)` (`expr::flow_vjp_dir_terms`: one `SensDot`
/// over the rows per entry), which `HybridSystem::flow_vjp_dir` adds into the cotangents. Planned
/// and compiled on its first call, into a module of its own: only an adjoint through Rosenbrock
/// steps pays for these second derivatives.
pub(crate) fn plan_vjp_dir(
    funcs: &mut ModelFunctions,
    info: &SystemInfo,
) -> Result<Vec<KernelPlan>, CodegenError> {
    let n = info.n_states();
    let m = info.n_grad();
    let n_params = info.n_params();
    let mut grad_col = vec![None; n_params];
    for (c, &param) in info.grad_params.iter().enumerate() {
        if let Some(slot) = grad_col.get_mut(param) {
            *slot = Some(c);
        }
    }
    let mut d = Differentiator::new();
    let modes = funcs.modes.clone();
    let store = &mut funcs.store;
    let mut plans = Vec::new();
    for (k, mode) in modes.iter().enumerate() {
        let terms = crate::expr::flow_vjp_dir_terms(store, &mut d, mode, n, &grad_col, m);
        let lens = Lens { x: 2 * n + 1, s: n, p: n_params, out: [n, m, 0] };
        let mut plan = KernelPlan::new(format!("mode{k}_flow_vjp_dir"), lens);
        plan.prefill = [true, true, false];
        for (out, columns) in [(0, terms.x), (1, terms.p)] {
            for (c, products) in columns.into_iter().enumerate() {
                if !products.is_empty() {
                    plan.write(out, c, Term::SensDot { products, bias: None })?;
                }
            }
        }
        plan.write_small_zeros();
        plan.check(store)?;
        plans.push(plan);
    }
    Ok(plans)
}

fn sens_term(products: Vec<(ExprId, u32)>, bias: Option<ExprId>) -> Term {
    if products.is_empty() && bias.is_none() {
        Term::Zero
    } else {
        Term::SensDot { products, bias }
    }
}

/// `sum_d (de/dx_d) v_d` over the states `e` reads, with `v_d` the state `n + d`: the derivative
/// of `e` along the direction `v`. Only the states that occur in `e` are differentiated, so a
/// constant entry (a linear flow's) costs nothing.
fn directional(store: &mut ExprStore, d: &mut Differentiator, e: ExprId, n: usize) -> ExprId {
    let states: Vec<u32> = crate::expr::eval::reachable(store, &[e])
        .into_iter()
        .filter_map(|id| match *store.node(id) {
            Node::State(i) => Some(i),
            _ => None,
        })
        .collect();
    let mut acc = store.zero();
    for st in states {
        let de = d.diff(store, e, Var::State(st));
        if store.is_zero(de) {
            continue;
        }
        let v = store.state(n as u32 + st);
        let term = store.mul(de, v);
        acc = store.add(acc, term);
    }
    acc
}
