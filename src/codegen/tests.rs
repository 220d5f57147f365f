//! The plans of the adjoint's kernel, `mode{k}_flow_vjp`: its products are the columns of the
//! symbolic Jacobians, and its size grows with a sparse model's entries and an input's knots,
//! never with `n^2`. (Its values are tested against the interpreter and the transpose
//! relations in tests/it/adjoint_kernels.rs.)

use super::plan::{plan_vjp, KernelPlan, Term};
use super::translate::needed_nodes;
use crate::expr::{ExprId, ModelFunctions};
use crate::lower::{lower, system_info};
use crate::sema::ParamIdx;

/// The functions and the `flow_vjp` plan of mode 0 of `source`, every parameter differentiated.
fn vjp_plan(source: &str) -> (ModelFunctions, KernelPlan) {
    let file = crate::syntax::parse(source).expect("parses");
    let model = crate::sema::check(&file).expect("checks");
    let funcs = lower(&model);
    let grad: Vec<ParamIdx> = (0..model.n_params() as u32).map(ParamIdx).collect();
    let info = system_info(&model, &grad);
    let vjp = plan_vjp(&funcs, &info).expect("plans").swap_remove(0);
    (funcs, vjp)
}

/// `(output, index)` -> products of the plan's `SensDot` writes; `Zero` writes as no products.
fn products(plan: &KernelPlan, out: usize, index: usize) -> Vec<(ExprId, u32)> {
    let mut found = plan.writes.iter().filter(|w| w.out == out && w.index as usize == index);
    let w = found.next().unwrap_or_else(|| panic!("no write of output {out} entry {index}"));
    assert!(found.next().is_none(), "output {out} entry {index} written twice");
    match &w.term {
        Term::SensDot { products, bias: None } => products.clone(),
        Term::Zero => Vec::new(),
        other => panic!("output {out} entry {index}: {other:?}"),
    }
}

#[test]
fn the_vjp_kernel_sums_each_column_of_the_jacobians_rows_ascending() {
    let (funcs, plan) = vjp_plan(
        "model m
param a = 1
param b = 2
param c = 3
state x = 1
state y = 2
state z = 3
der(x) = a * x * y
der(y) = -b * y + x
der(z) = x + y
",
    );
    let mode = &funcs.modes[0];
    assert_eq!((plan.lens.x, plan.lens.s, plan.lens.out), (3, 3, [3, 3, 0]));
    // Small outputs: the kernel writes its zeros itself (`write_small_zeros`), no prefill.
    assert_eq!(plan.prefill, [false; 3]);
    for c in 0..3u32 {
        let want: Vec<(ExprId, u32)> =
            mode.flow_x.entries.iter().filter(|e| e.1 == c).map(|&(i, _, e)| (e, i)).collect();
        assert_eq!(products(&plan, 0, c as usize), want, "gx[{c}]");
    }
    // Column x: rows 0, 1, 2; column y: rows 0, 1, 2; column z: no entry.
    assert_eq!(products(&plan, 0, 0).iter().map(|p| p.1).collect::<Vec<_>>(), [0, 1, 2]);
    assert!(products(&plan, 0, 2).is_empty());
    for (j, rows) in [(0, vec![0]), (1, vec![1]), (2, vec![])] {
        let got = products(&plan, 1, j);
        assert_eq!(got.iter().map(|p| p.1).collect::<Vec<_>>(), rows, "gp[{j}]");
        let want: Vec<(ExprId, u32)> =
            mode.flow_p.entries.iter().filter(|e| e.1 == j as u32).map(|&(i, _, e)| (e, i)).collect();
        assert_eq!(got, want, "gp[{j}]");
    }
    assert_eq!(plan.size(), 3 + 6 + 3 + 2, "one per entry and one per product");
}

/// `der(x) = pwl(t, 0, 1, u) - k x` with `u` of `knots` elements: the plan's size and the
/// expression nodes its roots need.
fn pwl_kernel(knots: usize) -> (usize, usize) {
    let (funcs, plan) = vjp_plan(&format!(
        "model knots
param k = 1
param u[{knots}] = 0
state x = 0
der(x) = pwl(t, 0, 1, u) - k * x
"
    ));
    // gx: the one entry -k; gp: -x for k, then each element's weight at the knot position.
    assert_eq!(plan.lens.out, [1, knots + 1, 0]);
    assert_eq!(products(&plan, 0, 0).len(), 1);
    for j in 0..=knots {
        assert_eq!(products(&plan, 1, j).len(), 1, "gp[{j}]");
    }
    (plan.size(), needed_nodes(&funcs.store, plan.roots()).len())
}

#[test]
fn a_pwl_input_gives_the_vjp_kernel_one_product_per_knot() {
    // Each element of `u` has its own `f_p` entry (its hat weight at the knot position): the
    // kernel writes all of them, with a constant number of nodes per knot. A run-time scatter
    // onto the two elements the position reads is a later step (issue 40).
    let sizes: Vec<(usize, usize)> = [50, 100, 200, 400].into_iter().map(pwl_kernel).collect();
    for (&(size, _), knots) in sizes.iter().zip([50, 100, 200, 400]) {
        assert_eq!(size, 2 * (knots + 1) + 2, "{knots} knots");
    }
    let per_knot = (sizes[1].1 - sizes[0].1) / 50;
    for w in sizes.windows(2) {
        let (dk, dn) = (w[1].0 - w[0].0, w[1].1 - w[0].1);
        assert_eq!(dn, per_knot * dk / 2, "the nodes grow linearly with the knots: {sizes:?}");
    }
}
