//! Stage 3b: [`Interpreter`], a `HybridSystem` that runs [`ModelFunctions`] with the reference
//! evaluator. It is the oracle the JIT is checked against and a JIT-free way to run a model.
//! Knows `expr` and the `sim` trait; no Cranelift, no IO.
//!
//! Each function group becomes one [`Tape`] (shared subexpressions evaluated once) plus a list of
//! where each root's value goes in the caller's arrays, following the layouts in
//! `src/sim/system.rs`. Array lengths are the caller's responsibility, as the trait states; a mode
//! or event index out of range leaves the outputs untouched instead of panicking.

use crate::expr::{scatter_lookup, Enclosure, ExprId, Lookup, ModelFunctions, SparseMat, SparseVec, Tape};
use crate::interval::{Dual, Interval};
use crate::sim::{HybridSystem, SystemInfo};

/// Roots evaluated together and scattered into up to three output arrays.
#[derive(Clone, Debug)]
struct Kernel {
    tape: Tape,
    /// `(array, offset)` of each root.
    dests: Vec<(usize, usize)>,
}

impl Kernel {
    fn new(store: &crate::expr::ExprStore, parts: Vec<(usize, usize, ExprId)>) -> Kernel {
        let roots: Vec<ExprId> = parts.iter().map(|&(_, _, r)| r).collect();
        let dests = parts.into_iter().map(|(a, o, _)| (a, o)).collect();
        Kernel { tape: Tape::new(store, &roots), dests }
    }

    /// Zeroes every output array, then writes the structurally non-zero entries.
    fn run(&self, t: f64, x: &[f64], p: &[f64], outs: &mut [&mut [f64]]) {
        for out in outs.iter_mut() {
            out.fill(0.0);
        }
        let mut values = vec![0.0; self.tape.n_roots()];
        self.tape.eval_into(t, x, p, &mut Vec::new(), &mut values);
        for (&(array, offset), v) in self.dests.iter().zip(values) {
            if let Some(slot) = outs.get_mut(array).and_then(|o| o.get_mut(offset)) {
                *slot = v;
            }
        }
    }
}

#[derive(Clone, Debug)]
struct ModeKernels {
    flow: Tape,
    /// Roots: the flow, then `f_x` entries, then `f_p` entries of the differentiated params.
    flow_sens: Tape,
    /// `(row, column)` of each `f_x` entry in `flow_sens`.
    fx: Vec<(usize, usize)>,
    /// Whether each `f_x` entry is finite at every finite input (`expr::finite_at_finite_inputs`).
    fx_finite: Vec<bool>,
    /// `(row, sensitivity column)` of each `f_p` entry in `flow_sens`.
    fp: Vec<(usize, usize)>,
    guards: Tape,
    /// `flow_vjp`'s roots, as the compiled kernel's (`codegen::plan::plan_flow_vjp`): the `f_x`
    /// entries (as in `fx`), the `f_p` entries of the differentiated parameters that no lookup
    /// of `ModeFunctions::lookups` reads, the `df_i/dL` of each of `vjp_lookups`, then their
    /// positions.
    vjp: Tape,
    /// `(row, sensitivity column)` of each of those `f_p` entries, and whether it is finite at
    /// every finite input (`flow_vjp` multiplies them).
    vjp_fp: Vec<(usize, usize)>,
    vjp_fp_finite: Vec<bool>,
    /// The lookups of vectors read through lookups only with a differentiated element
    /// (`ModeFunctions::lookups`), each with the rows of its `df_i/dL` and their finiteness:
    /// their cotangents are scattered onto the elements they read.
    vjp_lookups: Vec<(Lookup, Vec<(usize, bool)>)>,
}

#[derive(Clone, Debug)]
struct EventKernels {
    /// Arrays: gx, gp, [g_t].
    guard_grad: Kernel,
    condition: Option<Tape>,
    reset: Tape,
    /// Arrays: rx, rp, rt.
    reset_jac: Kernel,
    enclosure: Enclosure,
}

/// The knot position of one knot set, and (arrays: sp, [s_t]) its gradient.
#[derive(Clone, Debug)]
struct KnotKernels {
    position: Tape,
    grad: Kernel,
}

/// One mode's `flow_vjp_dir` (`expr::flow_vjp_dir_terms`): the products' expressions and, per
/// root, `(output, entry, row)`: `output[entry] += w[row] * value`, the entries' products in the
/// compiled kernel's order.
#[derive(Clone, Debug)]
struct VjpDirKernel {
    tape: Tape,
    dests: Vec<(usize, usize, usize)>,
}

/// Runs a model's functions with the reference evaluator.
#[derive(Clone, Debug)]
pub struct Interpreter {
    /// The functions, kept for the adjoint's second-order kernels (built on their first call).
    source: std::sync::Arc<ModelFunctions>,
    vjp_dir: std::sync::OnceLock<Vec<VjpDirKernel>>,
    info: SystemInfo,
    /// The sensitivity column of every parameter, `None` where it is not differentiated.
    columns: Vec<Option<usize>>,
    init: Tape,
    init_sens: Kernel,
    modes: Vec<ModeKernels>,
    events: Vec<EventKernels>,
    knots: Vec<KnotKernels>,
    outputs: Tape,
    /// Arrays: yx, yp, yt.
    output_jac: Kernel,
}

impl Interpreter {
    /// Prepares the tapes of every function. `info` must describe the same model as `funcs`;
    /// its `grad_params` select and order the `_p` columns (entries of other parameters are
    /// dropped).
    pub fn new(funcs: ModelFunctions, mut info: SystemInfo) -> Interpreter {
        super::classify_events(&funcs, &mut info);
        let store = &funcs.store;
        let n = funcs.n_states as usize;
        let n_out = funcs.outputs.len();
        // Sensitivity column of each parameter, if it is differentiated.
        let mut column = vec![None; funcs.n_params as usize];
        for (j, &p) in info.grad_params.iter().enumerate() {
            if let Some(c) = column.get_mut(p) {
                *c = Some(j);
            }
        }
        let col = |k: u32| column.get(k as usize).copied().flatten();
        // Entries of a `_p` matrix with `rows` rows, as (array, offset, root) in column layout.
        let p_parts = |array: usize, m: &SparseMat, rows: usize| -> Vec<(usize, usize, ExprId)> {
            m.entries
                .iter()
                .filter_map(|&(i, k, e)| col(k).map(|j| (array, j * rows + i as usize, e)))
                .collect()
        };
        let x_parts = |array: usize, m: &SparseMat| -> Vec<(usize, usize, ExprId)> {
            let cols = m.n_cols as usize;
            m.entries.iter().map(|&(i, k, e)| (array, i as usize * cols + k as usize, e)).collect()
        };
        let v_parts = |array: usize, v: &SparseVec| -> Vec<(usize, usize, ExprId)> {
            v.entries.iter().map(|&(i, e)| (array, i as usize, e)).collect()
        };

        let modes = funcs
            .modes
            .iter()
            .enumerate()
            .map(|(mode_idx, mode)| {
                let mut roots = mode.flow.clone();
                let mut fx = Vec::new();
                let mut fx_finite = Vec::new();
                for &(i, k, e) in &mode.flow_x.entries {
                    fx.push((i as usize, k as usize));
                    fx_finite.push(crate::expr::finite_at_finite_inputs(store, e));
                    roots.push(e);
                }
                let mut fp = Vec::new();
                for &(i, k, e) in &mode.flow_p.entries {
                    if let Some(j) = col(k) {
                        fp.push((i as usize, j));
                        roots.push(e);
                    }
                }
                let finite = |e: ExprId| crate::expr::finite_at_finite_inputs(store, e);
                let mut vjp_roots: Vec<ExprId> = mode.flow_x.entries.iter().map(|e| e.2).collect();
                let by_lookup = |k: u32| mode.lookups.iter().any(|fl| fl.lookup.reads(k));
                let (mut vjp_fp, mut vjp_fp_finite) = (Vec::new(), Vec::new());
                for &(i, k, e) in &mode.flow_p.entries {
                    match col(k) {
                        Some(j) if !by_lookup(k) => {
                            vjp_fp.push((i as usize, j));
                            vjp_fp_finite.push(finite(e));
                            vjp_roots.push(e);
                        }
                        _ => {}
                    }
                }
                let scattered: Vec<_> = mode
                    .lookups
                    .iter()
                    .filter(|fl| (fl.lookup.base..fl.lookup.base + fl.lookup.len).any(|k| col(k).is_some()))
                    .collect();
                let mut vjp_lookups = Vec::new();
                for fl in &scattered {
                    let rows = fl.flow_l.entries.iter().map(|&(i, e)| (i as usize, finite(e))).collect();
                    vjp_roots.extend(fl.flow_l.entries.iter().map(|e| e.1));
                    vjp_lookups.push((fl.lookup, rows));
                }
                vjp_roots.extend(scattered.iter().map(|fl| fl.position));
                let guard_roots: Vec<ExprId> = info
                    .modes
                    .get(mode_idx)
                    .map(|m| m.events.iter().filter_map(|&e| funcs.events.get(e)).map(|e| e.guard))
                    .into_iter()
                    .flatten()
                    .collect();
                ModeKernels {
                    flow: Tape::new(store, &mode.flow),
                    flow_sens: Tape::new(store, &roots),
                    fx,
                    fx_finite,
                    fp,
                    guards: Tape::new(store, &guard_roots),
                    vjp: Tape::new(store, &vjp_roots),
                    vjp_fp,
                    vjp_fp_finite,
                    vjp_lookups,
                }
            })
            .collect();

        let events = funcs
            .events
            .iter()
            .map(|ev| {
                let mut gparts: Vec<_> =
                    ev.guard_x.entries.iter().map(|&(k, e)| (0, k as usize, e)).collect();
                gparts.extend(ev.guard_p.entries.iter().filter_map(|&(k, e)| col(k).map(|j| (1, j, e))));
                gparts.push((2, 0, ev.guard_t));
                let mut rparts = x_parts(0, &ev.reset_x);
                rparts.extend(p_parts(1, &ev.reset_p, n));
                rparts.extend(v_parts(2, &ev.reset_t));
                EventKernels {
                    guard_grad: Kernel::new(store, gparts),
                    condition: ev.condition.map(|c| Tape::new(store, &[c])),
                    reset: Tape::new(store, &ev.reset),
                    reset_jac: Kernel::new(store, rparts),
                    enclosure: Enclosure::new(store, ev.guard),
                }
            })
            .collect();

        let knots = funcs
            .knots
            .iter()
            .map(|knot| {
                let mut parts: Vec<_> =
                    knot.position_p.entries.iter().filter_map(|&(k, e)| col(k).map(|j| (0, j, e))).collect();
                parts.push((1, 0, knot.position_t));
                KnotKernels { position: Tape::new(store, &[knot.position]), grad: Kernel::new(store, parts) }
            })
            .collect();

        let mut yparts = x_parts(0, &funcs.output_x);
        yparts.extend(p_parts(1, &funcs.output_p, n_out));
        yparts.extend(v_parts(2, &funcs.output_t));

        Interpreter {
            vjp_dir: std::sync::OnceLock::new(),
            columns: column.clone(),
            init: Tape::new(store, &funcs.init),
            init_sens: Kernel::new(store, p_parts(0, &funcs.init_p, n)),
            modes,
            events,
            knots,
            outputs: Tape::new(store, &funcs.outputs),
            output_jac: Kernel::new(store, yparts),
            info,
            source: std::sync::Arc::new(funcs),
        }
    }
}

impl Interpreter {
    /// Every mode's `flow_vjp_dir` from the same expressions as the compiled kernel's.
    fn vjp_dir_kernels(&self) -> &[VjpDirKernel] {
        self.vjp_dir.get_or_init(|| {
            let mut funcs = (*self.source).clone();
            let n = funcs.n_states as usize;
            let m = self.info.n_grad();
            let mut d = crate::expr::Differentiator::new();
            let modes = funcs.modes.clone();
            modes
                .iter()
                .map(|mode| {
                    let terms =
                        crate::expr::flow_vjp_dir_terms(&mut funcs.store, &mut d, mode, n, &self.columns, m);
                    let (mut roots, mut dests) = (Vec::new(), Vec::new());
                    for (out, columns) in [(0, &terms.x), (1, &terms.p)] {
                        for (c, products) in columns.iter().enumerate() {
                            for &(e, i) in products {
                                roots.push(e);
                                dests.push((out, c, i as usize));
                            }
                        }
                    }
                    VjpDirKernel { tape: Tape::new(&funcs.store, &roots), dests }
                })
                .collect()
        })
    }
}

impl HybridSystem for Interpreter {
    fn info(&self) -> &SystemInfo {
        &self.info
    }

    fn initial_state(&self, p: &[f64], x0: &mut [f64]) {
        // x0 depends on parameters only; the state slots are never read.
        self.init.eval_into(0.0, &[], p, &mut Vec::new(), x0);
    }

    fn initial_sens(&self, p: &[f64], s0: &mut [f64]) {
        self.init_sens.run(0.0, &[], p, &mut [s0]);
    }

    fn flow(&self, mode: usize, t: f64, x: &[f64], p: &[f64], dx: &mut [f64]) {
        if let Some(m) = self.modes.get(mode) {
            m.flow.eval_into(t, x, p, &mut Vec::new(), dx);
        }
    }

    fn flow_sens(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        s: &[f64],
        p: &[f64],
        dx: &mut [f64],
        ds: &mut [f64],
    ) {
        let Some(m) = self.modes.get(mode) else {
            return;
        };
        let n = self.info.n_states();
        let mut values = vec![0.0; m.flow_sens.n_roots()];
        m.flow_sens.eval_into(t, x, p, &mut Vec::new(), &mut values);
        let (flow, rest) = values.split_at(n.min(values.len()));
        let (fx, fp) = rest.split_at(m.fx.len().min(rest.len()));
        dx[..flow.len()].copy_from_slice(flow);
        // ds_j = f_x s_j + f_p[:, j] for every sensitivity column j.
        ds.fill(0.0);
        // As the compiled kernels: a zero sensitivity annihilates a Jacobian entry that can be
        // infinite or NaN at a finite state.
        for j in 0..self.info.n_grad() {
            for ((&(i, k), v), &finite) in m.fx.iter().zip(fx).zip(&m.fx_finite) {
                let sk = s[j * n + k];
                if finite || sk != 0.0 {
                    ds[j * n + i] += v * sk;
                }
            }
        }
        for (&(i, j), v) in m.fp.iter().zip(fp) {
            ds[j * n + i] += v;
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn flow_vjp_dir(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        v: &[f64],
        a: f64,
        w: &[f64],
        p: &[f64],
        xbar: &mut [f64],
        pbar: &mut [f64],
    ) {
        let Some(k) = self.vjp_dir_kernels().get(mode) else {
            return;
        };
        let mut xva = x.to_vec();
        xva.extend_from_slice(v);
        xva.push(a);
        let mut values = vec![0.0; k.tape.n_roots()];
        k.tape.eval_into(t, &xva, p, &mut Vec::new(), &mut values);
        // Each entry's products summed in order from zero, then added, as the kernel's output is.
        let (mut gx, mut gp) = (vec![0.0; xbar.len()], vec![0.0; pbar.len()]);
        for (&(out, c, i), value) in k.dests.iter().zip(values) {
            let slot = if out == 0 { gx.get_mut(c) } else { gp.get_mut(c) };
            if let (Some(slot), Some(wi)) = (slot, w.get(i)) {
                *slot += value * wi;
            }
        }
        for (o, g) in xbar.iter_mut().zip(&gx) {
            *o += g;
        }
        for (o, g) in pbar.iter_mut().zip(&gp) {
            *o += g;
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn flow_vjp(&self, mode: usize, t: f64, x: &[f64], w: &[f64], p: &[f64], gx: &mut [f64], gp: &mut [f64]) {
        let Some(m) = self.modes.get(mode) else {
            return;
        };
        let mut values = vec![0.0; m.vjp.n_roots()];
        m.vjp.eval_into(t, x, p, &mut Vec::new(), &mut values);
        let (fx, rest) = values.split_at(m.fx.len().min(values.len()));
        let (fp, mut rest) = rest.split_at(m.vjp_fp.len().min(rest.len()));
        gx.fill(0.0);
        gp.fill(0.0);
        // The entries run by row, so each output entry sums its rows ascending, as the
        // compiled kernel does; a zero `w_i` annihilates a possibly infinite entry, as there.
        for ((&(i, k), v), &finite) in m.fx.iter().zip(fx).zip(&m.fx_finite) {
            if finite || w[i] != 0.0 {
                gx[k] += v * w[i];
            }
        }
        for ((&(i, j), v), &finite) in m.vjp_fp.iter().zip(fp).zip(&m.vjp_fp_finite) {
            if finite || w[i] != 0.0 {
                gp[j] += v * w[i];
            }
        }
        // Each scattered lookup's cotangent `c_L = sum_i w_i df_i/dL` (rows ascending), then
        // `c_L` times its weights at its position, lookup by lookup, as the compiled model.
        let mut cotangents = Vec::with_capacity(m.vjp_lookups.len());
        for (_, rows) in &m.vjp_lookups {
            let (entries, after) = rest.split_at(rows.len().min(rest.len()));
            rest = after;
            let mut c = 0.0;
            for (&(i, finite), v) in rows.iter().zip(entries) {
                if finite || w[i] != 0.0 {
                    c += v * w[i];
                }
            }
            cotangents.push(c);
        }
        for ((l, _), (c, &pos)) in m.vjp_lookups.iter().zip(cotangents.into_iter().zip(rest)) {
            scatter_lookup(*l, pos, c, &self.columns, gp);
        }
    }

    fn guards(&self, mode: usize, t: f64, x: &[f64], p: &[f64], g: &mut [f64]) {
        if let Some(m) = self.modes.get(mode) {
            m.guards.eval_into(t, x, p, &mut Vec::new(), g);
        }
    }

    fn guard_grad(&self, event: usize, t: f64, x: &[f64], p: &[f64], gx: &mut [f64], gp: &mut [f64]) -> f64 {
        let mut gt = [0.0];
        if let Some(e) = self.events.get(event) {
            e.guard_grad.run(t, x, p, &mut [gx, gp, &mut gt]);
        }
        gt[0]
    }

    fn guard_enclosure(
        &self,
        event: usize,
        t: Interval,
        x: &[Interval],
        dx: &[Interval],
        p: &[f64],
        scratch: &mut Vec<Dual>,
    ) -> Dual {
        match self.events.get(event) {
            Some(e) => e.enclosure.eval(t, x, dx, p, scratch),
            None => Dual { v: Interval::ENTIRE, d: Interval::ENTIRE },
        }
    }

    fn guard_states(&self, event: usize) -> Option<&[u32]> {
        self.events.get(event).map(|e| e.enclosure.states())
    }

    fn knot_position(&self, set: usize, t: f64, p: &[f64]) -> f64 {
        let mut s = [f64::NAN];
        if let Some(k) = self.knots.get(set) {
            k.position.eval_into(t, &[], p, &mut Vec::new(), &mut s);
        }
        s[0]
    }

    fn knot_position_grad(&self, set: usize, t: f64, p: &[f64], sp: &mut [f64]) -> f64 {
        let mut st = [f64::NAN];
        if let Some(k) = self.knots.get(set) {
            k.grad.run(t, &[], p, &mut [sp, &mut st]);
        }
        st[0]
    }

    fn condition(&self, event: usize, t: f64, x: &[f64], p: &[f64]) -> bool {
        match self.events.get(event).and_then(|e| e.condition.as_ref()) {
            Some(tape) => {
                let mut v = [0.0];
                tape.eval_into(t, x, p, &mut Vec::new(), &mut v);
                v[0] != 0.0
            }
            None => true,
        }
    }

    fn reset(&self, event: usize, t: f64, x: &[f64], p: &[f64], r: &mut [f64]) {
        if let Some(e) = self.events.get(event) {
            e.reset.eval_into(t, x, p, &mut Vec::new(), r);
        }
    }

    fn reset_jac(
        &self,
        event: usize,
        t: f64,
        x: &[f64],
        p: &[f64],
        rx: &mut [f64],
        rp: &mut [f64],
        rt: &mut [f64],
    ) {
        if let Some(e) = self.events.get(event) {
            e.reset_jac.run(t, x, p, &mut [rx, rp, rt]);
        }
    }

    fn outputs(&self, t: f64, x: &[f64], p: &[f64], y: &mut [f64]) {
        self.outputs.eval_into(t, x, p, &mut Vec::new(), y);
    }

    fn output_jac(&self, t: f64, x: &[f64], p: &[f64], yx: &mut [f64], yp: &mut [f64], yt: &mut [f64]) {
        self.output_jac.run(t, x, p, &mut [yx, yp, yt]);
    }
}
