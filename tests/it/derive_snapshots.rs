//! `hybc derive` output for every shipped model, as reviewable insta snapshots, and a property
//! test that every derivative entry `lower` produces (and every entry it leaves out as a
//! structural zero) agrees with a central finite difference of the evaluator.

use std::collections::HashMap;
use std::sync::OnceLock;

use hybc::expr::{eval_one, ExprId, ModelFunctions, SparseMat, SparseVec, Var};
use hybc::lower::{derive_report, lower};
use hybc::sema::{Model, ParamIdx};
use proptest::prelude::*;

use crate::support::models::{shipped_models, ShippedModel};

/// Every shipped model, checked and lowered once.
fn models() -> &'static [(String, Model, ModelFunctions)] {
    static MODELS: OnceLock<Vec<(String, Model, ModelFunctions)>> = OnceLock::new();
    MODELS.get_or_init(|| {
        shipped_models()
            .into_iter()
            .map(|ShippedModel { name, path, source, .. }| {
                let model =
                    hybc::check_source(&source).unwrap_or_else(|e| panic!("{}", e.render(&path, &source)));
                let funcs = lower(&model);
                (name, model, funcs)
            })
            .collect()
    })
}

#[test]
fn every_model_has_a_derive_snapshot() {
    assert!(models().len() >= 7, "expected the shipped models");
    for (name, model, funcs) in models() {
        let all: Vec<ParamIdx> = (0..model.n_params() as u32).map(ParamIdx).collect();
        let report = derive_report(model, funcs, &all, None);
        insta::assert_snapshot!(format!("derive_{name}"), report);
    }
}

#[test]
fn ball_report_has_the_event_derivatives() {
    let (_, model, funcs) = models().iter().find(|(n, ..)| n == "ball").expect("ball.hyb");
    let wrt = ["e", "h0"].map(|n| model.param_index(n).expect("parameter"));
    let report = derive_report(model, funcs, &wrt, None);
    for line in ["g_x = [1, 0]", "R_x = [[1, 0], [0, -e]]", "R_e = [0, -v]", "x0_h0 = [1, 0]"] {
        assert!(report.lines().any(|l| l.trim() == line), "missing `{line}` in:\n{report}");
    }
}

/// One function row and its derivatives: `(row, variable) -> entry`; missing means zero.
struct Rows {
    rows: Vec<ExprId>,
    entries: HashMap<(usize, Var), ExprId>,
}

impl Rows {
    fn new(rows: Vec<ExprId>) -> Rows {
        Rows { rows, entries: HashMap::new() }
    }
    fn mat(mut self, m: &SparseMat, var: fn(u32) -> Var) -> Rows {
        for &(i, k, e) in &m.entries {
            self.entries.insert((i as usize, var(k)), e);
        }
        self
    }
    fn time(mut self, v: &SparseVec) -> Rows {
        for &(i, e) in &v.entries {
            self.entries.insert((i as usize, Var::Time), e);
        }
        self
    }
}

fn all_rows(f: &ModelFunctions) -> Vec<Rows> {
    let mut out = vec![Rows::new(f.init.clone()).mat(&f.init_p, Var::Param)];
    for m in &f.modes {
        out.push(
            Rows::new(m.flow.clone()).mat(&m.flow_x, Var::State).mat(&m.flow_p, Var::Param).time(&m.flow_t),
        );
    }
    for e in &f.events {
        let as_mat = |v: &SparseVec, n: u32| SparseMat {
            n_rows: 1,
            n_cols: n,
            entries: v.entries.iter().map(|&(k, d)| (0, k, d)).collect(),
        };
        let mut guard = Rows::new(vec![e.guard])
            .mat(&as_mat(&e.guard_x, f.n_states), Var::State)
            .mat(&as_mat(&e.guard_p, f.n_params), Var::Param);
        guard.entries.insert((0, Var::Time), e.guard_t);
        out.push(guard);
        out.push(
            Rows::new(e.reset.clone())
                .mat(&e.reset_x, Var::State)
                .mat(&e.reset_p, Var::Param)
                .time(&e.reset_t),
        );
    }
    out.push(
        Rows::new(f.outputs.clone())
            .mat(&f.output_x, Var::State)
            .mat(&f.output_p, Var::Param)
            .time(&f.output_t),
    );
    out
}

proptest! {
    #![proptest_config(crate::support::proptest_config(200))]

    /// At a random point around each model's defaults (states near their initial values,
    /// parameters within 20% of their defaults, t in [0, 10]), every entry of every Jacobian
    /// equals a central difference with step 1e-6 * max(1, |v|), relative error <= 1e-6.
    /// Rows whose expression is near a kink at the point are skipped (an input filter).
    #[test]
    fn every_derivative_entry_matches_a_central_difference(
        u in prop::collection::vec(-1.0f64..1.0, 32),
        t in 0.0f64..10.0,
    ) {
        for (name, model, f) in models() {
            let n = model.n_states();
            let p: Vec<f64> = model.params.iter().enumerate()
                .map(|(j, q)| q.default * (1.0 + 0.2 * u[(n + j) % u.len()]) + 0.01 * u[(n + j) % u.len()])
                .collect();
            let x0: Vec<f64> = f.init.iter().map(|&e| eval_one(&f.store, e, 0.0, &[], &p)).collect();
            let x: Vec<f64> = x0.iter().enumerate().map(|(i, v)| v + u[i % u.len()] * (1.0 + 0.5 * v.abs())).collect();
            let vars: Vec<Var> = (0..n as u32).map(Var::State)
                .chain((0..p.len() as u32).map(Var::Param))
                .chain([Var::Time])
                .collect();
            for group in all_rows(f) {
                for (i, &row) in group.rows.iter().enumerate() {
                    if !crate::support::expr::is_smooth_at(&f.store, row, t, &x, &p, 1e8) {
                        continue;
                    }
                    for &var in &vars {
                        let symbolic = group.entries.get(&(i, var)).map_or(0.0, |&d| eval_one(&f.store, d, t, &x, &p));
                        let (mut xs, mut ps, mut ts) = (x.clone(), p.clone(), t);
                        let v = match var { Var::State(k) => &mut xs[k as usize], Var::Param(k) => &mut ps[k as usize], Var::Time => &mut ts, Var::Node(_) => unreachable!("a report's columns are leaves") };
                        let h = 1e-6 * v.abs().max(1.0);
                        *v += h;
                        let up = eval_one(&f.store, row, ts, &xs, &ps);
                        let (mut xs, mut ps, mut ts) = (x.clone(), p.clone(), t);
                        let v = match var { Var::State(k) => &mut xs[k as usize], Var::Param(k) => &mut ps[k as usize], Var::Time => &mut ts, Var::Node(_) => unreachable!("a report's columns are leaves") };
                        *v -= h;
                        let down = eval_one(&f.store, row, ts, &xs, &ps);
                        let numeric = (up - down) / (2.0 * h);
                        let value = eval_one(&f.store, row, t, &x, &p);
                        // Rounding in the difference is about eps * |value| / h; allow for it.
                        let scale = symbolic.abs().max(numeric.abs()).max(1.0) + 1e-16 * value.abs() / h * 1e6;
                        prop_assert!((symbolic - numeric).abs() <= 1e-6 * scale,
                            "{} row {} d/d{:?}: symbolic {} vs numeric {}", name, i, var, symbolic, numeric);
                    }
                }
            }
        }
    }
}

/// Above six states vectors and matrices list only their non-zero entries, one a line.
#[test]
fn large_models_list_sparse_entries() {
    let mut src = String::from("model big\nparam k = 2\n");
    for i in 0..7 {
        src.push_str(&format!("state x{i} = {i}\n"));
    }
    for i in 0..7 {
        let prev = if i == 0 { 6 } else { i - 1 };
        src.push_str(&format!("der(x{i}) = -k * x{i} + x{prev}\n"));
    }
    let model = hybc::check_source(&src).expect("valid model");
    let report = derive_report(&model, &lower(&model), &[ParamIdx(0)], None);
    let lines: Vec<&str> = report.lines().map(str::trim).collect();
    for expected in ["f_x:", "(0, 0) x0/x0: -k", "(0, 6) x0/x6: 1", "(6, 5) x6/x5: 1", "f_k:", "(3) x3: -x3"]
    {
        assert!(lines.contains(&expected), "missing `{expected}` in:\n{report}");
    }
    // 7 diagonal and 7 coupling entries, nothing for the zeros.
    assert_eq!(lines.iter().filter(|l| l.contains("/x")).count(), 14, "{report}");
}
