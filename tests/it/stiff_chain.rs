//! Workload W5 of issue #25 and the banded factorisation (`sim::linsolve`): the diffusion chain
//! (`support::chain::diffusion_source`) with Rodas5P, the banded LU against the dense LU and
//! both against the closed form of the linear chain, a matrix exponential; the chain with its
//! top-up event through `hybc::gradcheck`; the Jacobian kernel writes only the pattern. The
//! sparse LU on a hub (an arrowhead `f_x`) and a 2-D grid against the dense LU.

use hybc::sim::{HybridSystem, LinearSolver, Method, SimOptions};
use hybc::Model;
use nalgebra::{DMatrix, DVector};

use crate::support::chain::{diffusion_source, diffusion_start, grid_source, hub_source};

const N: usize = 40;

/// The conductance segment of the link between cells `i` and `i + 1` (as the generator).
fn seg(i: usize, n: usize) -> usize {
    10 * i / n
}

/// `A(d)` of the linear chain `x' = A x` and `dA/dd_j`.
fn chain_matrix(n: usize, d: &[f64], c: f64, wrt: Option<usize>) -> DMatrix<f64> {
    let mut a = DMatrix::zeros(n, n);
    for i in 0..n {
        if wrt.is_none() {
            a[(i, i)] -= c;
        }
        if i + 1 < n {
            let j = seg(i, n);
            let g = match wrt {
                None => d[j],
                Some(w) if w == j => 1.0,
                Some(_) => 0.0,
            };
            a[(i, i)] -= g;
            a[(i, i + 1)] += g;
            a[(i + 1, i + 1)] -= g;
            a[(i + 1, i)] += g;
        }
    }
    a
}

/// `x(T)` and `dx(T)/dd_j` of the linear chain from its ramp `x(0)`: the exponential of the
/// system with one sensitivity, `[[A, 0], [A_j, A]]`, applied to `[x(0), 0]`.
fn closed_form(n: usize, d: &[f64], c: f64, t: f64) -> (Vec<f64>, Vec<Vec<f64>>) {
    let a = chain_matrix(n, d, c, None);
    let mut x0 = DVector::zeros(2 * n);
    for i in 0..n {
        x0[i] = diffusion_start(i, n);
    }
    let mut x = Vec::new();
    let mut sens = Vec::new();
    for j in 0..d.len() {
        let mut big = DMatrix::zeros(2 * n, 2 * n);
        big.view_mut((0, 0), (n, n)).copy_from(&a);
        big.view_mut((n, n), (n, n)).copy_from(&a);
        big.view_mut((n, 0), (n, n)).copy_from(&chain_matrix(n, d, c, Some(j)));
        let z = (big * t).exp() * &x0;
        x = z.rows(0, n).iter().copied().collect();
        sens.push(z.rows(n, n).iter().copied().collect());
    }
    (x, sens)
}

fn run(model: &Model, solver: LinearSolver, rtol: f64, t_end: f64) -> hybc::Run {
    let compiled = model.compile_all().expect("compiles");
    let opts = SimOptions {
        t_end,
        rtol,
        atol: rtol * 1e-2,
        method: Method::Rodas5p,
        linear_solver: solver,
        ..SimOptions::default()
    };
    compiled.simulate(&compiled.params(), &opts).expect("runs")
}

/// The linear chain (no event) of 40 cells to T = 2 at rtol 1e-10: the banded and the dense LU
/// both agree with the matrix exponential, values to 1e-9 and the ten gradients to 1e-8
/// (relative to the largest of each), and with each other to 1e-11 (the same steps).
#[test]
fn the_linear_chain_matches_its_matrix_exponential_banded_and_dense() {
    let model = Model::parse(&diffusion_source(N, false)).expect("parses");
    let (d, c, t_end) = ([50.0; 10], 0.1, 2.0);
    let (x_exact, s_exact) = closed_form(N, &d, c, t_end);
    let banded = run(&model, LinearSolver::Banded, 1e-10, t_end);
    let dense = run(&model, LinearSolver::Dense, 1e-10, t_end);
    let x_scale = x_exact.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    let s_scale = s_exact.iter().flatten().fold(0.0f64, |a, b| a.max(b.abs()));
    for (tag, r) in [("banded", &banded), ("dense", &dense)] {
        for i in 0..N {
            let name = format!("x{i}");
            let x = r.state(&name).unwrap();
            assert!((x - x_exact[i]).abs() <= 1e-9 * x_scale, "{tag} {name}: {x} vs {}", x_exact[i]);
            for (j, s) in s_exact.iter().enumerate() {
                let got = r.dstate(&name, &format!("d[{j}]")).unwrap();
                assert!((got - s[i]).abs() <= 1e-8 * s_scale, "{tag} d{name}/dd[{j}]: {got} vs {}", s[i]);
            }
        }
    }
    let (a, b) = (&banded.result().final_state, &dense.result().final_state);
    assert_eq!(banded.result().stats.steps, dense.result().stats.steps);
    for (x, y) in a.state.iter().zip(&b.state) {
        assert!((x - y).abs() <= 1e-11 * x_scale, "{x} vs {y}");
    }
    // Every column, the leak `c`'s too (not in the closed form: relative to itself).
    for (x, y) in a.dstate.as_ref().unwrap().iter().zip(b.dstate.as_ref().unwrap()) {
        assert!((x - y).abs() <= 1e-11 * s_scale.max(y.abs()), "{x} vs {y}");
    }
}

/// The chain with its top-up event (N = 40, T = 10): the banded LU fires the same
/// events as the dense one at the same times (1e-9), and its gradients with respect to all ten
/// conductances pass `hybc::gradcheck` at rtol 1e-8.
#[test]
fn the_chain_with_its_event_is_the_same_banded_and_its_gradients_check() {
    let model = Model::parse(&diffusion_source(N, true)).expect("parses");
    let banded = run(&model, LinearSolver::Banded, 1e-8, 10.0);
    let dense = run(&model, LinearSolver::Dense, 1e-8, 10.0);
    assert!(banded.is_complete());
    assert_eq!(banded.events().len(), 1);
    assert_eq!(banded.events().len(), dense.events().len());
    for (a, b) in banded.events().iter().zip(dense.events()) {
        assert!((a.time - b.time).abs() <= 1e-9, "{} vs {}", a.time, b.time);
    }
    gradients_check(&banded, LinearSolver::Banded);
}

/// The Jacobian kernel of a chain of 1000 cells writes its 2998 structural nonzeros, not a
/// million entries, and `flow_jac` (the dense view) scatters exactly them.
#[test]
fn the_jacobian_kernel_writes_only_the_pattern() {
    let n = 1000;
    let model = Model::parse(&diffusion_source(n, false)).expect("parses");
    let compiled = model.compile_all().expect("compiles");
    let sys = compiled.native();
    sys.prepare_jacobians().expect("stiff kernels");
    let pattern = sys.jac_pattern(0).expect("a pattern").to_vec();
    assert_eq!(pattern.len(), 3 * n - 2);
    for &(r, c) in &pattern {
        assert!(r.abs_diff(c) <= 1, "({r}, {c}) off the tridiagonal");
    }
    let m = sys.info().n_grad();
    let p = compiled.params().values().to_vec();
    let x: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
    let s = vec![0.0; n * m];
    let (mut vals, mut ft, mut st) = (vec![0.0; pattern.len()], vec![0.0; n], vec![0.0; n * m]);
    sys.flow_jac_values(0, 0.0, &x, &s, &p, &mut vals, &mut ft, &mut st);
    // Row 500's entries: -(d_prev + d_next + c) on the diagonal, the conductances beside it.
    let d = 50.0;
    for (&(r, c), &v) in pattern.iter().zip(&vals) {
        if r == 500 {
            let want = if c == 500 { -(2.0 * d + 0.1) } else { d };
            assert_eq!(v, want, "f_x[{r}][{c}]");
        }
    }
    let mut fx = vec![f64::NAN; n * n];
    sys.flow_jac(0, 0.0, &x, &s, &p, &mut fx, &mut ft, &mut st);
    let nonzero = fx.iter().filter(|v| **v != 0.0).count();
    assert_eq!(nonzero, 3 * n - 2);
    for (&(r, c), &v) in pattern.iter().zip(&vals) {
        assert_eq!(fx[r as usize * n + c as usize], v);
    }
}

/// `a` and `b` ran the same steps and agree: the events' times to 1e-9, the final states to
/// `tol` of the largest and every gradient column to `tol` of the largest gradient.
fn assert_same(tag: &str, a: &hybc::Run, b: &hybc::Run, tol: f64) {
    let (ra, rb) = (a.result(), b.result());
    assert!(a.is_complete() && b.is_complete(), "{tag}");
    assert_eq!(ra.stats.steps, rb.stats.steps, "{tag}: steps");
    assert_eq!(a.events().len(), b.events().len(), "{tag}: events");
    for (x, y) in a.events().iter().zip(b.events()) {
        assert!((x.time - y.time).abs() <= 1e-9, "{tag}: event at {} vs {}", x.time, y.time);
    }
    let (sa, sb) = (&ra.final_state, &rb.final_state);
    let x_scale = sb.state.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (x, y) in sa.state.iter().zip(&sb.state) {
        assert!((x - y).abs() <= tol * x_scale, "{tag}: {x} vs {y}");
    }
    let (da, db) = (sa.dstate.as_ref().unwrap(), sb.dstate.as_ref().unwrap());
    let s_scale = db.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(s_scale > 0.0, "{tag}: no gradient");
    for (x, y) in da.iter().zip(db) {
        assert!((x - y).abs() <= tol * s_scale, "{tag}: d {x} vs {y}");
    }
}

/// The pattern of mode 0 of a model's compiled Jacobian.
fn pattern_of(model: &Model) -> Vec<(u32, u32)> {
    let compiled = model.compile_all().expect("compiles");
    let sys = compiled.native();
    sys.prepare_jacobians().expect("stiff kernels");
    sys.jac_pattern(0).expect("a pattern").to_vec()
}

/// A hub of 200 states (one node coupled to all others, an arrowhead `f_x` that no band fits)
/// with its top-up event, to T = 5 at rtol 1e-8: the sparse LU takes the same steps as the dense
/// one, fires the event at the same time and agrees on the states and the eleven gradient
/// columns to 1e-10; `Auto` picks the sparse LU for it (the same run, bit for bit), the band
/// does not pay.
#[test]
fn a_hub_is_solved_sparse_and_matches_the_dense_lu() {
    let n = 200;
    let model = Model::parse(&hub_source(n, true)).expect("parses");
    let pattern = pattern_of(&model);
    assert_eq!(pattern.len(), 3 * (n - 1) + 1);
    assert_eq!(LinearSolver::Auto.resolve(n, &pattern), LinearSolver::Sparse);
    assert_eq!(LinearSolver::Banded.resolve(n, &pattern), LinearSolver::Dense);
    let sparse = run(&model, LinearSolver::Sparse, 1e-8, 5.0);
    let dense = run(&model, LinearSolver::Dense, 1e-8, 5.0);
    let auto = run(&model, LinearSolver::Auto, 1e-8, 5.0);
    assert_eq!(sparse.events().len(), 1);
    assert_same("sparse vs dense", &sparse, &dense, 1e-10);
    assert_eq!(auto.result().final_state.state, sparse.result().final_state.state);
    assert_eq!(auto.result().final_state.dstate, sparse.result().final_state.dstate);
}

/// A 12 x 12 grid with its event (T = 10, rtol 1e-8): sparse, banded and dense agree (1e-10),
/// and the sparse LU's gradients pass `hybc::gradcheck` at rtol 1e-8.
#[test]
fn a_grid_is_the_same_sparse_banded_and_dense_and_its_gradients_check() {
    let side = 12;
    let model = Model::parse(&grid_source(side, true)).expect("parses");
    let sparse = run(&model, LinearSolver::Sparse, 1e-8, 10.0);
    let banded = run(&model, LinearSolver::Banded, 1e-8, 10.0);
    let dense = run(&model, LinearSolver::Dense, 1e-8, 10.0);
    assert_eq!(sparse.events().len(), 1);
    assert_same("sparse vs dense", &sparse, &dense, 1e-10);
    assert_same("banded vs dense", &banded, &dense, 1e-10);
    gradients_check(&sparse, LinearSolver::Sparse);
}

/// `run` (Rodas5P with `solver`, T = 10, rtol 1e-8, atol 1e-10) passes `hybc::gradcheck`: its
/// gradients against central differences of re-runs with the same options.
fn gradients_check(run: &hybc::Run, solver: LinearSolver) {
    let opts = SimOptions {
        t_end: 10.0,
        rtol: 1e-8,
        atol: 1e-10,
        method: Method::Rodas5p,
        linear_solver: solver,
        ..SimOptions::default()
    };
    crate::support::assert_gradients_check(run, &opts);
}
