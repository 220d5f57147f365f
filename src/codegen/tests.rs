//! The plans of the adjoint's kernel, `mode{k}_flow_vjp`: its products are the columns of the
//! symbolic Jacobians, and its size grows with a sparse model's entries, never with `n^2` nor
//! with the knots of a control read through lookups only (the host scatters its cotangent).
//! (Its values are tested against the interpreter and the transpose relations in
//! tests/it/adjoint_kernels.rs.)

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
    let vjp = plan_vjp(&funcs, &info).expect("plans").kernels.swap_remove(0);
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
    // `gp` compact: the columns with products (a's and b's; c enters no flow).
    assert_eq!((plan.lens.x, plan.lens.s, plan.lens.out), (3, 3, [3, 2, 0]));
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
        // Compact index = column here (columns 0 and 1 are the summed ones, in order).
        let got = if j < 2 { products(&plan, 1, j) } else { Vec::new() };
        assert_eq!(got.iter().map(|p| p.1).collect::<Vec<_>>(), rows, "gp[{j}]");
        let want: Vec<(ExprId, u32)> =
            mode.flow_p.entries.iter().filter(|e| e.1 == j as u32).map(|&(i, _, e)| (e, i)).collect();
        assert_eq!(got, want, "gp[{j}]");
    }
    // gx: 3 entries, 6 products; the compact gp: 2 entries, 2 products (c's column is not one).
    assert_eq!(plan.size(), 3 + 6 + 2 + 2, "one per entry and one per product");
}

/// `der(x) = pwl(t, 0, 1, u) - k x` (and `extra` added to it) with `u` of `knots` elements: the
/// plan (every parameter differentiated), its size and the expression nodes its roots need.
fn pwl_kernel(knots: usize, extra: &str) -> (KernelPlan, usize, usize) {
    let (funcs, plan) = vjp_plan(&format!(
        "model knots
param k = 1
param u[{knots}] = 0
state x = 0
der(x) = pwl(t, 0, 1, u) - k * x{extra}
"
    ));
    let nodes = needed_nodes(&funcs.store, plan.roots()).len();
    let size = plan.size();
    (plan, size, nodes)
}

#[test]
fn a_control_read_through_lookups_only_gives_the_vjp_kernel_a_size_independent_of_its_knots() {
    // gx: the one entry -k; gp: -x for k only; the third output: `[c_L, pos]` of the one lookup,
    // `c_L` the product `1 * w_0`. The elements' entries are the host's scatter: none written,
    // the whole of gp zero-filled by the caller.
    let mut seen = Vec::new();
    for knots in [10, 100, 1000] {
        let (plan, size, nodes) = pwl_kernel(knots, "");
        // `gp` compact: k's column alone; the knots' entries are the host's scatter.
        assert_eq!(plan.lens.out, [1, 1, 2], "{knots} knots");
        assert_eq!(plan.prefill, [false, false, false], "{knots} knots");
        assert_eq!(products(&plan, 0, 0).len(), 1);
        assert_eq!(products(&plan, 1, 0).len(), 1, "k's own entry stays a normal one");
        assert_eq!(plan.writes.iter().filter(|w| w.out == 1).count(), 1, "no knot's entry written");
        assert_eq!(products(&plan, 2, 0).iter().map(|p| p.1).collect::<Vec<_>>(), [0], "c_L over row 0");
        assert!(plan.writes.iter().any(|w| w.out == 2 && w.index == 1 && matches!(w.term, Term::Expr(_))));
        assert_eq!(size, 2 + 2 + 2 + 1, "{knots} knots");
        seen.push((size, nodes));
    }
    assert!(seen.windows(2).all(|w| w[0] == w[1]), "size and nodes equal at 10, 100, 1000 knots: {seen:?}");
}

#[test]
fn a_control_also_summed_keeps_one_product_per_knot() {
    // `sum(u)` reads every element as a parameter: the vector takes today's path, one `f_p`
    // product per element (its weight at the position plus the sum's 1), and no lookup pair.
    for knots in [10, 50] {
        let (plan, size, _) = pwl_kernel(knots, " + sum(u)");
        assert_eq!(plan.lens.out, [1, knots + 1, 0], "{knots} knots");
        for j in 0..=knots {
            assert_eq!(products(&plan, 1, j).len(), 1, "gp[{j}]");
        }
        assert_eq!(size, 2 + 2 * (knots + 1), "{knots} knots");
    }
}

#[test]
fn a_control_not_differentiated_has_no_lookup_pair() {
    // Only `k` differentiated: `u`'s lookup has no column to scatter onto.
    let file = crate::syntax::parse(
        "model m\nparam k = 1\nparam u[20] = 0\nstate x = 0\nder(x) = pwl(t, 0, 1, u) - k * x\n",
    )
    .expect("parses");
    let model = crate::sema::check(&file).expect("checks");
    let funcs = lower(&model);
    assert_eq!(funcs.modes[0].lookups.len(), 1, "the lookup is listed with the mode");
    let plan = plan_vjp(&funcs, &system_info(&model, &[ParamIdx(0)])).expect("plans");
    assert_eq!(plan.kernels[0].lens.out, [1, 1, 0]);
    assert_eq!(plan.summed[0], [0]);
    assert!(plan.lookups[0].is_empty());
    let plan = plan_vjp(&funcs, &system_info(&model, &[ParamIdx(5)])).expect("plans");
    // u[4] alone: no column summed by the kernel, one lookup pair.
    assert_eq!(plan.kernels[0].lens.out, [1, 0, 2], "u[4] alone is enough");
    assert!(plan.summed[0].is_empty());
    assert_eq!(plan.lookups[0].len(), 1);
}
