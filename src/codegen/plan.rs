//! Stage 4 (codegen): what each kernel computes, as plain data. Maps the lowered model functions
//! onto the array layouts of `sim::system` and checks every shape and index on the way. Knows no
//! Cranelift and no `unsafe`: a plan that passes [`KernelPlan::check`] only ever touches memory
//! inside the lengths it declares.

use super::CodegenError;
use crate::expr::{ExprId, ExprStore, Lookup, ModeFunctions, ModelFunctions, SparseMat, SparseVec};
use crate::sim::SystemInfo;

/// Number of output pointers every kernel takes (unused ones receive empty slices).
pub(crate) const N_OUTS: usize = 3;

/// Largest sparse output that the kernel zero-fills itself (see
/// [`KernelPlan::write_small_zeros`]); larger ones are zero-filled by the caller.
const MAX_ZERO_WRITES: usize = 64;

/// The slice lengths a kernel reads and writes; the caller must pass exactly these.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Lens {
    pub x: usize,
    pub s: usize,
    pub p: usize,
    pub out: [usize; N_OUTS],
}

/// The value stored into one output entry.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Term {
    Expr(ExprId),
    Zero,
    /// `sum_k a_k * s[s_k]` over `products` in order, then `+ bias`: one entry of `f_x S + f_p`.
    /// The order is fixed so that a hand-written loop in the same order agrees bit for bit.
    SensDot {
        products: Vec<(ExprId, u32)>,
        bias: Option<ExprId>,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Write {
    pub out: usize,
    pub index: u32,
    pub term: Term,
}

impl Write {
    /// This write's share of [`KernelPlan::size`].
    fn size(&self) -> usize {
        match &self.term {
            Term::SensDot { products, .. } => 1 + products.len(),
            _ => 1,
        }
    }
}

/// One native function to generate.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct KernelPlan {
    /// Exported symbol name, unique per module.
    pub name: String,
    pub lens: Lens,
    /// Outputs the caller zero-fills before the call, because the kernel writes only their
    /// structurally non-zero entries (sparse Jacobians).
    pub prefill: [bool; N_OUTS],
    pub writes: Vec<Write>,
    /// The kernel's f64 return value; 0.0 when `None`.
    pub ret: Option<ExprId>,
}

impl KernelPlan {
    pub(crate) fn new(name: String, lens: Lens) -> Self {
        KernelPlan { name, lens, prefill: [false; N_OUTS], writes: Vec::new(), ret: None }
    }

    pub(crate) fn write(&mut self, out: usize, index: usize, term: Term) -> Result<(), CodegenError> {
        let index = u32::try_from(index)
            .map_err(|_| CodegenError::TooLarge { what: self.name.clone(), len: index })?;
        self.writes.push(Write { out, index, term });
        Ok(())
    }

    /// A size measure for choosing the register allocator: output entries plus sensitivity
    /// products.
    pub(crate) fn size(&self) -> usize {
        self.writes.iter().map(Write::size).sum()
    }

    /// The kernel cut into consecutive runs of writes of at most `limit` [`size`](Self::size)
    /// each (a single larger write stays whole), to be compiled as separate native functions
    /// and called one after the other. Each part shares the kernel's lengths and writes a
    /// subset of its entries; the return value is computed by the last part. The plan is
    /// [checked](Self::check) whole, before it is cut.
    pub(crate) fn parts(&self, limit: usize) -> Vec<KernelPlan> {
        if self.size() <= limit {
            return vec![self.clone()];
        }
        let mut parts: Vec<KernelPlan> = Vec::new();
        let mut size = 0;
        for w in &self.writes {
            let w_size = w.size();
            if parts.is_empty() || size + w_size > limit {
                let name = format!("{}_part{}", self.name, parts.len());
                parts.push(KernelPlan { prefill: self.prefill, ..KernelPlan::new(name, self.lens) });
                size = 0;
            }
            size += w_size;
            parts.last_mut().expect("a part was just pushed").writes.push(w.clone());
        }
        if let Some(last) = parts.last_mut() {
            last.ret = self.ret;
        }
        parts
    }

    /// Outputs of at most [`MAX_ZERO_WRITES`] entries get explicit zero writes for their
    /// structural zeros instead of being zero-filled by the caller: a handful of constant stores
    /// in the kernel cost less than a `memset` call per output per call (the guard and reset
    /// Jacobians, called at every step and event).
    pub(crate) fn write_small_zeros(&mut self) {
        self.write_small_zeros_in(0..N_OUTS);
    }

    /// [`Self::write_small_zeros`] for the outputs `outs` only; the others keep their prefill.
    pub(crate) fn write_small_zeros_in(&mut self, outs: std::ops::Range<usize>) {
        for out in outs {
            let len = self.lens.out[out];
            if !self.prefill[out] || len > MAX_ZERO_WRITES {
                continue;
            }
            let mut written = vec![false; len];
            for w in self.writes.iter().filter(|w| w.out == out) {
                if let Some(slot) = written.get_mut(w.index as usize) {
                    *slot = true;
                }
            }
            for (index, _) in written.iter().enumerate().filter(|(_, &w)| !w) {
                self.writes.push(Write { out, index: index as u32, term: Term::Zero });
            }
            self.prefill[out] = false;
        }
    }

    /// Every expression the kernel needs, in no particular order.
    pub(crate) fn roots(&self) -> impl Iterator<Item = ExprId> + '_ {
        let writes = self.writes.iter().flat_map(|w| match &w.term {
            Term::Expr(e) => vec![*e],
            Term::Zero => Vec::new(),
            Term::SensDot { products, bias } => products.iter().map(|&(e, _)| e).chain(*bias).collect(),
        });
        writes.chain(self.ret)
    }

    /// Checks that every write and every sensitivity read lies inside the declared lengths, that
    /// every output entry is written or prefilled, and that every root is in `store`. State and
    /// parameter reads are checked against `lens` when the nodes are lowered.
    pub(crate) fn check(&self, store: &ExprStore) -> Result<(), CodegenError> {
        let mut covered: [Vec<bool>; N_OUTS] = self.lens.out.map(|len| vec![false; len]);
        for w in &self.writes {
            let slot = covered.get_mut(w.out).and_then(|c| c.get_mut(w.index as usize)).ok_or_else(|| {
                CodegenError::IndexOutOfRange {
                    what: format!("{} output {}", self.name, w.out),
                    index: w.index as usize,
                    len: self.lens.out.get(w.out).copied().unwrap_or(0),
                }
            })?;
            *slot = true;
            if let Term::SensDot { products, .. } = &w.term {
                for &(_, s) in products {
                    if s as usize >= self.lens.s {
                        return Err(CodegenError::IndexOutOfRange {
                            what: format!("{} sensitivity read", self.name),
                            index: s as usize,
                            len: self.lens.s,
                        });
                    }
                }
            }
        }
        for (out, cov) in covered.iter().enumerate() {
            if let Some(index) = cov.iter().position(|&c| !c) {
                if !self.prefill[out] {
                    return Err(CodegenError::Unwritten {
                        what: format!("{} output {out}", self.name),
                        index,
                    });
                }
            }
        }
        for root in self.roots() {
            if root.index() >= store.len() {
                return Err(CodegenError::UnknownExpr { id: root.0, len: store.len() });
            }
        }
        Ok(())
    }
}

/// One `K` per kernel of a model, indexed like the `HybridSystem` methods that call them:
/// first the plans, then the compiled functions.
#[derive(Clone, Debug)]
pub(crate) struct ModelKernels<K> {
    /// Per mode.
    pub flow: Vec<K>,
    /// Per mode, or empty: a large model's are planned and compiled on first use
    /// ([`EAGER_FLOW_SENS_LIMIT`]).
    pub flow_sens: Vec<K>,
    pub guards: Vec<K>,
    /// `g_x f + g_t` of every guard of the mode, with the flow `f` passed as the `s` input.
    pub guard_speeds: Vec<K>,
    /// Per event.
    pub guard_grad: Vec<K>,
    pub condition: Vec<Option<K>>,
    pub reset: Vec<K>,
    pub reset_jac: Vec<K>,
    /// Per knot set (`SystemInfo::knots`): the knot position, returned, and its gradient with
    /// its rate returned.
    pub knot_position: Vec<K>,
    pub knot_grad: Vec<K>,
    pub init: K,
    pub init_sens: K,
    pub outputs: K,
    pub output_jac: K,
}

pub(crate) type ModelPlan = ModelKernels<KernelPlan>;

impl<K> ModelKernels<K> {
    /// Every kernel, in a fixed order.
    pub(crate) fn iter(&self) -> impl Iterator<Item = &K> {
        self.flow
            .iter()
            .chain(&self.flow_sens)
            .chain(&self.guards)
            .chain(&self.guard_speeds)
            .chain(&self.guard_grad)
            .chain(self.condition.iter().flatten())
            .chain(&self.reset)
            .chain(&self.reset_jac)
            .chain(&self.knot_position)
            .chain(&self.knot_grad)
            .chain([&self.init, &self.init_sens, &self.outputs, &self.output_jac])
    }

    /// Every kernel, mutably, in the order of [`Self::iter`].
    pub(crate) fn iter_mut(&mut self) -> impl Iterator<Item = &mut K> {
        self.flow
            .iter_mut()
            .chain(&mut self.flow_sens)
            .chain(&mut self.guards)
            .chain(&mut self.guard_speeds)
            .chain(&mut self.guard_grad)
            .chain(self.condition.iter_mut().flatten())
            .chain(&mut self.reset)
            .chain(&mut self.reset_jac)
            .chain(&mut self.knot_position)
            .chain(&mut self.knot_grad)
            .chain([&mut self.init, &mut self.init_sens, &mut self.outputs, &mut self.output_jac])
    }

    /// Applies `f` to every kernel, keeping the structure; stops at the first error.
    pub(crate) fn try_map<L, E>(&self, mut f: impl FnMut(&K) -> Result<L, E>) -> Result<ModelKernels<L>, E> {
        let mut all = |ks: &[K]| ks.iter().map(&mut f).collect::<Result<Vec<L>, E>>();
        let flow = all(&self.flow)?;
        let flow_sens = all(&self.flow_sens)?;
        let guards = all(&self.guards)?;
        let guard_speeds = all(&self.guard_speeds)?;
        let guard_grad = all(&self.guard_grad)?;
        let reset = all(&self.reset)?;
        let reset_jac = all(&self.reset_jac)?;
        let knot_position = all(&self.knot_position)?;
        let knot_grad = all(&self.knot_grad)?;
        let condition = self
            .condition
            .iter()
            .map(|k| k.as_ref().map(&mut f).transpose())
            .collect::<Result<Vec<Option<L>>, E>>()?;
        Ok(ModelKernels {
            flow,
            flow_sens,
            guards,
            guard_speeds,
            guard_grad,
            condition,
            reset,
            reset_jac,
            knot_position,
            knot_grad,
            init: f(&self.init)?,
            init_sens: f(&self.init_sens)?,
            outputs: f(&self.outputs)?,
            output_jac: f(&self.output_jac)?,
        })
    }
}

/// Sizes shared by all plan builders.
struct Dims {
    n: usize,
    n_params: usize,
    n_grad: usize,
    n_outputs: usize,
    /// Sensitivity column of each parameter, `None` for parameters not differentiated.
    grad_col: Vec<Option<usize>>,
}

impl Dims {
    fn lens(&self, x: usize, s: usize, out: [usize; N_OUTS]) -> Lens {
        Lens { x, s, p: self.n_params, out }
    }
}

/// Largest [`flow_sens_size`] whose kernels are compiled with the model; larger ones are planned
/// and compiled on their first use ([`plan_flow_sens`], `CompiledModel::prepare_sensitivities`),
/// so that a run without forward sensitivities (a plain run of a model compiled with gradients,
/// the adjoint's recording run) never pays their compile time nor their memory: `n m` entries
/// and `m nnz(f_x)` products, 3 million of them for a 1000-state chain with 999 differentiated
/// parameters, which took about 61 s of CPU and 560 MiB to compile. Below the limit a module of
/// their own would add its fixed cost to the first forward run for no memory worth saving, and a
/// plain run (`m = 0`, size 0) calls `flow_sens` too; the shipped models' kernels are all below it
/// (docs/design.md).
pub(crate) const EAGER_FLOW_SENS_LIMIT: usize = 5_000;

/// The [`KernelPlan::size`] of every mode's `flow_sens` together, computed without planning them:
/// per mode, `m` times (`n` entries plus the flow Jacobian's structural nonzeros).
pub(crate) fn flow_sens_size(funcs: &ModelFunctions, info: &SystemInfo) -> usize {
    let (n, m) = (info.n_states(), info.n_grad());
    funcs
        .modes
        .iter()
        .map(|mode| m.saturating_mul(n + mode.flow_x.entries.len()))
        .fold(0, usize::saturating_add)
}

/// Builds and checks the plan of every kernel of `funcs` under the shape `info`; the forward
/// sensitivity kernels only when small ([`EAGER_FLOW_SENS_LIMIT`]; `flow_sens` is left empty
/// otherwise).
pub(crate) fn plan_model(funcs: &ModelFunctions, info: &SystemInfo) -> Result<ModelPlan, CodegenError> {
    let dims = check_shape(funcs, info)?;
    let (n, m) = (dims.n, dims.n_grad);
    let with_flow_sens = flow_sens_size(funcs, info) <= EAGER_FLOW_SENS_LIMIT;
    let mut plan = ModelPlan {
        flow: Vec::new(),
        flow_sens: Vec::new(),
        guards: Vec::new(),
        guard_speeds: Vec::new(),
        guard_grad: Vec::new(),
        condition: Vec::new(),
        reset: Vec::new(),
        reset_jac: Vec::new(),
        knot_position: Vec::new(),
        knot_grad: Vec::new(),
        init: KernelPlan::new("init".into(), dims.lens(0, 0, [n, 0, 0])),
        init_sens: KernelPlan::new("init_sens".into(), dims.lens(0, 0, [n * m, 0, 0])),
        outputs: KernelPlan::new("outputs".into(), dims.lens(n, 0, [dims.n_outputs, 0, 0])),
        output_jac: KernelPlan::new(
            "output_jac".into(),
            dims.lens(n, 0, [dims.n_outputs * n, dims.n_outputs * m, dims.n_outputs]),
        ),
    };

    for (mode_idx, (mode, mode_info)) in funcs.modes.iter().zip(&info.modes).enumerate() {
        let mut flow = KernelPlan::new(format!("mode{mode_idx}_flow"), dims.lens(n, 0, [n, 0, 0]));
        for (i, &f) in mode.flow.iter().enumerate() {
            flow.write(0, i, Term::Expr(f))?;
        }
        if with_flow_sens {
            plan.flow_sens.push(plan_mode_flow_sens(mode_idx, mode, &dims)?);
        }
        let mut guards = KernelPlan::new(
            format!("mode{mode_idx}_guards"),
            dims.lens(n, 0, [mode_info.events.len(), 0, 0]),
        );
        let mut speeds = KernelPlan::new(
            format!("mode{mode_idx}_guard_speeds"),
            dims.lens(n, n, [mode_info.events.len(), 0, 0]),
        );
        for (k, &ev) in mode_info.events.iter().enumerate() {
            let event = &funcs.events[ev];
            guards.write(0, k, Term::Expr(event.guard))?;
            // g_x f + g_t, the flow read from the `s` input: one dot product over the entries
            // of g_x that are not structurally zero.
            let products: Vec<(ExprId, u32)> = event
                .guard_x
                .entries
                .iter()
                .map(|&(i, e)| Ok((e, index_u32(&speeds.name, i as usize)?)))
                .collect::<Result<_, CodegenError>>()?;
            let bias = (funcs.store.node(event.guard_t).as_const() != Some(0.0)).then_some(event.guard_t);
            let term = if products.is_empty() && bias.is_none() {
                Term::Zero
            } else {
                Term::SensDot { products, bias }
            };
            speeds.write(0, k, term)?;
        }
        plan.flow.push(flow);
        plan.guards.push(guards);
        plan.guard_speeds.push(speeds);
    }

    for (ev_idx, ev) in funcs.events.iter().enumerate() {
        let mut gg = KernelPlan::new(format!("event{ev_idx}_guard_grad"), dims.lens(n, 0, [n, m, 0]));
        gg.prefill = [true, true, false];
        for &(i, e) in &ev.guard_x.entries {
            gg.write(0, i as usize, Term::Expr(e))?;
        }
        for &(param, e) in &ev.guard_p.entries {
            if let Some(c) = dims.grad_col[param as usize] {
                gg.write(1, c, Term::Expr(e))?;
            }
        }
        gg.ret = Some(ev.guard_t);

        let condition = ev.condition.map(|c| {
            let mut k = KernelPlan::new(format!("event{ev_idx}_condition"), dims.lens(n, 0, [0; 3]));
            k.ret = Some(c);
            k
        });

        let mut reset = KernelPlan::new(format!("event{ev_idx}_reset"), dims.lens(n, 0, [n, 0, 0]));
        for (i, &r) in ev.reset.iter().enumerate() {
            reset.write(0, i, Term::Expr(r))?;
        }

        // `R_x` as its structurally nonzero entries, in the order of `reset_x` (the pattern
        // `CompiledModel::reset_jac_pattern` gives): every one is written, so it needs no zero
        // fill, and a reset's Jacobian takes memory in its entries, not `n^2`.
        let nnz = ev.reset_x.entries.len();
        let mut rj = KernelPlan::new(format!("event{ev_idx}_reset_jac"), dims.lens(n, 0, [nnz, n * m, n]));
        rj.prefill = [false, true, true];
        for (k, &(_, _, e)) in ev.reset_x.entries.iter().enumerate() {
            rj.write(0, k, Term::Expr(e))?;
        }
        for &(i, param, e) in &ev.reset_p.entries {
            if let Some(c) = dims.grad_col[param as usize] {
                rj.write(1, c * n + i as usize, Term::Expr(e))?;
            }
        }
        for &(i, e) in &ev.reset_t.entries {
            rj.write(2, i as usize, Term::Expr(e))?;
        }

        plan.guard_grad.push(gg);
        plan.condition.push(condition);
        plan.reset.push(reset);
        plan.reset_jac.push(rj);
    }

    // The knots' kernels read the time and the parameters alone.
    for (k, knot) in funcs.knots.iter().enumerate() {
        let mut position = KernelPlan::new(format!("knots{k}_position"), dims.lens(0, 0, [0; N_OUTS]));
        position.ret = Some(knot.position);
        let mut grad = KernelPlan::new(format!("knots{k}_grad"), dims.lens(0, 0, [m, 0, 0]));
        grad.prefill[0] = true;
        for &(param, e) in &knot.position_p.entries {
            if let Some(c) = dims.grad_col[param as usize] {
                grad.write(0, c, Term::Expr(e))?;
            }
        }
        grad.ret = Some(knot.position_t);
        plan.knot_position.push(position);
        plan.knot_grad.push(grad);
    }

    for (i, &e) in funcs.init.iter().enumerate() {
        plan.init.write(0, i, Term::Expr(e))?;
    }
    plan.init_sens.prefill[0] = true;
    for &(i, param, e) in &funcs.init_p.entries {
        if let Some(c) = dims.grad_col[param as usize] {
            plan.init_sens.write(0, c * n + i as usize, Term::Expr(e))?;
        }
    }

    let k = dims.n_outputs;
    for (i, &e) in funcs.outputs.iter().enumerate() {
        plan.outputs.write(0, i, Term::Expr(e))?;
    }
    plan.output_jac.prefill = [true; 3];
    for &(i, c, e) in &funcs.output_x.entries {
        plan.output_jac.write(0, i as usize * n + c as usize, Term::Expr(e))?;
    }
    for &(i, param, e) in &funcs.output_p.entries {
        if let Some(c) = dims.grad_col[param as usize] {
            plan.output_jac.write(1, c * k + i as usize, Term::Expr(e))?;
        }
    }
    for &(i, e) in &funcs.output_t.entries {
        plan.output_jac.write(2, i as usize, Term::Expr(e))?;
    }

    for kernel in plan.iter_mut() {
        kernel.write_small_zeros();
        kernel.check(&funcs.store)?;
    }
    Ok(plan)
}

/// Every mode's `flow_sens`, checked: what [`plan_model`] leaves out of a large model, planned on
/// the first run with forward sensitivities.
pub(crate) fn plan_flow_sens(
    funcs: &ModelFunctions,
    info: &SystemInfo,
) -> Result<Vec<KernelPlan>, CodegenError> {
    let dims = check_shape(funcs, info)?;
    let mut plans = Vec::with_capacity(funcs.modes.len());
    for (mode_idx, mode) in funcs.modes.iter().enumerate() {
        let mut sens = plan_mode_flow_sens(mode_idx, mode, &dims)?;
        sens.write_small_zeros();
        sens.check(&funcs.store)?;
        plans.push(sens);
    }
    Ok(plans)
}

/// `mode{k}_flow_sens` (inputs `x` (n), `s` (n m)): the flow (n) and the sensitivities' right-hand
/// side `f_x S + f_p` (n m), each entry one `SensDot` over its row of `f_x`, columns ascending.
fn plan_mode_flow_sens(
    mode_idx: usize,
    mode: &ModeFunctions,
    dims: &Dims,
) -> Result<KernelPlan, CodegenError> {
    let (n, m) = (dims.n, dims.n_grad);
    let mut sens = KernelPlan::new(format!("mode{mode_idx}_flow_sens"), dims.lens(n, n * m, [n, n * m, 0]));
    for (i, &f) in mode.flow.iter().enumerate() {
        sens.write(0, i, Term::Expr(f))?;
    }
    let fx_rows = rows(&mode.flow_x, n);
    let fp_rows = rows(&mode.flow_p, n);
    for j in 0..m {
        for i in 0..n {
            let products: Vec<(ExprId, u32)> = fx_rows[i]
                .iter()
                .map(|&(k, e)| Ok((e, index_u32(&sens.name, j * n + k)?)))
                .collect::<Result<_, CodegenError>>()?;
            let bias =
                fp_rows[i].iter().find(|&&(param, _)| dims.grad_col[param] == Some(j)).map(|&(_, e)| e);
            let term = if products.is_empty() && bias.is_none() {
                Term::Zero
            } else {
                Term::SensDot { products, bias }
            };
            sens.write(1, j * n + i, term)?;
        }
    }
    Ok(sens)
}

/// The adjoint's kernels ([`plan_vjp`]) and what the host needs to finish their `gp`.
#[derive(Clone, Debug)]
pub(crate) struct VjpPlan {
    /// Per mode, `mode{k}_flow_vjp`.
    pub kernels: Vec<KernelPlan>,
    /// Per mode, the lookups whose `[c_L, pos]` pairs the kernel writes to its third output, in
    /// that order; the host scatters them (`expr::scatter_lookup`).
    pub lookups: Vec<Vec<Lookup>>,
    /// The sensitivity column of every parameter, `None` where it is not differentiated.
    pub columns: Vec<Option<usize>>,
    /// Per mode, the sensitivity columns of `gp` the kernel sums, in the order of its compact
    /// second output (the others are zero, or the scattered lookups').
    pub summed: Vec<Vec<usize>>,
}

/// The adjoint's kernels, one per mode ([`plan_flow_vjp`]). `CompiledModel` plans and compiles
/// them on the first `flow_vjp` call, into a module of their own: a forward run never pays for
/// them (in the model's module they doubled the compile time of a 1000-state chain).
pub(crate) fn plan_vjp(funcs: &ModelFunctions, info: &SystemInfo) -> Result<VjpPlan, CodegenError> {
    let dims = check_shape(funcs, info)?;
    let mut kernels = Vec::new();
    let mut lookups = Vec::new();
    let mut summed = Vec::new();
    for (k, mode) in funcs.modes.iter().enumerate() {
        let (mut plan, scattered, columns) = plan_flow_vjp(k, mode, &dims)?;
        // Every entry of the compact `gp` is written; `gx`'s zeros are written when few.
        plan.write_small_zeros_in(0..1);
        plan.check(&funcs.store)?;
        kernels.push(plan);
        lookups.push(scattered);
        summed.push(columns);
    }
    Ok(VjpPlan { kernels, lookups, columns: dims.grad_col, summed })
}

/// `mode{k}_flow_vjp` (inputs `x` (n), `s = w` (n)): `gx = f_x^T w` (n) and `gp = f_p^T w` (m,
/// by sensitivity column), each entry one `SensDot` over the structurally nonzero entries of
/// its column of `f_x` or `f_p`, rows ascending: the transpose of `flow_sens`'s products, so a
/// sparse model's products cost its Jacobian's entries, never `n^2`. Entries without one are
/// zero-filled (by the kernel when small, `write_small_zeros`).
///
/// A vector the flow reads through lookups only (`ModeFunctions::lookups`: a `pwl`/`pwc`
/// control) has no product in `gp`: its `f_p` holds an entry per element and row, of which at
/// most two per lookup are nonzero at any time. Instead the third output holds, per lookup `L`
/// with a differentiated element, the pair `[c_L, pos]`: `c_L = sum_i w_i df_i/dL` (a `SensDot`
/// over `L`'s rows) and `L`'s position, which the host scatters onto the elements `L` reads
/// there (returned, in the output's order). So the kernel's size does not grow with the knots.
///
/// `gp` is compact: one entry per sensitivity column that has products, in column order (the
/// columns returned), so that a caller accumulating into the parameters' cotangent touches those
/// and the scattered elements only, never all `m` (the adjoint's backward pass, at every stage).
fn plan_flow_vjp(
    mode_idx: usize,
    mode: &ModeFunctions,
    dims: &Dims,
) -> Result<(KernelPlan, Vec<Lookup>, Vec<usize>), CodegenError> {
    let (n, m) = (dims.n, dims.n_grad);
    let differentiated = |l: &Lookup| (l.base..l.base + l.len).any(|i| dims.grad_col[i as usize].is_some());
    let scattered: Vec<&crate::expr::FlowLookup> =
        mode.lookups.iter().filter(|fl| differentiated(&fl.lookup)).collect();
    let name = format!("mode{mode_idx}_flow_vjp");
    let by_lookup = |param: u32| mode.lookups.iter().any(|fl| fl.lookup.reads(param));
    let mut fp_cols: Vec<Vec<(ExprId, u32)>> = vec![Vec::new(); m];
    for &(i, param, e) in &mode.flow_p.entries {
        match dims.grad_col[param as usize] {
            Some(c) if !by_lookup(param) => fp_cols[c].push((e, i)),
            _ => {}
        }
    }
    let summed: Vec<usize> = (0..m).filter(|&c| !fp_cols[c].is_empty()).collect();
    let mut vjp = KernelPlan::new(name, dims.lens(n, n, [n, summed.len(), 2 * scattered.len()]));
    vjp.prefill = [true, false, false];
    // The entries are sorted by (row, column): grouped by column, each keeps its rows ascending.
    let mut fx_cols: Vec<Vec<(ExprId, u32)>> = vec![Vec::new(); n];
    for &(i, c, e) in &mode.flow_x.entries {
        fx_cols[c as usize].push((e, i));
    }
    for (j, products) in fx_cols.into_iter().enumerate() {
        if !products.is_empty() {
            vjp.write(0, j, Term::SensDot { products, bias: None })?;
        }
    }
    let compact = fp_cols.into_iter().filter(|products| !products.is_empty());
    for (q, products) in compact.enumerate() {
        vjp.write(1, q, Term::SensDot { products, bias: None })?;
    }
    for (q, fl) in scattered.iter().enumerate() {
        let products: Vec<(ExprId, u32)> = fl.flow_l.entries.iter().map(|&(i, e)| (e, i)).collect();
        vjp.write(2, 2 * q, Term::SensDot { products, bias: None })?;
        vjp.write(2, 2 * q + 1, Term::Expr(fl.position))?;
    }
    Ok((vjp, scattered.iter().map(|fl| fl.lookup).collect(), summed))
}

pub(crate) fn index_u32(what: &str, index: usize) -> Result<u32, CodegenError> {
    u32::try_from(index).map_err(|_| CodegenError::TooLarge { what: what.to_owned(), len: index })
}

/// The entries of a checked sparse matrix grouped by row: `(column, expression)` ascending.
pub(crate) fn rows(mat: &SparseMat, n_rows: usize) -> Vec<Vec<(usize, ExprId)>> {
    let mut rows = vec![Vec::new(); n_rows];
    for &(r, c, e) in &mat.entries {
        rows[r as usize].push((c as usize, e));
    }
    rows
}

/// Checks that `funcs` and `info` describe the same model and that every sparse entry is in
/// range and strictly ascending, so the builders above can index without further checks.
fn check_shape(funcs: &ModelFunctions, info: &SystemInfo) -> Result<Dims, CodegenError> {
    let n = info.n_states();
    let n_params = info.n_params();
    let n_outputs = info.n_outputs();
    let n_events = info.events.len();
    let count = |what: &str, expected: usize, found: usize| {
        if expected == found {
            Ok(())
        } else {
            Err(CodegenError::ShapeMismatch { what: what.to_owned(), expected, found })
        }
    };
    count("states", n, funcs.n_states as usize)?;
    count("parameters", n_params, funcs.n_params as usize)?;
    count("modes", info.modes.len(), funcs.modes.len())?;
    count("events", n_events, funcs.events.len())?;
    count("outputs", n_outputs, funcs.outputs.len())?;
    count("knot sets", info.knots.len(), funcs.knots.len())?;
    count("initial state", n, funcs.init.len())?;

    let mut grad_col = vec![None; n_params];
    for (c, &param) in info.grad_params.iter().enumerate() {
        match grad_col.get_mut(param) {
            None => {
                return Err(CodegenError::IndexOutOfRange {
                    what: "gradient parameter".into(),
                    index: param,
                    len: n_params,
                })
            }
            Some(Some(_)) => return Err(CodegenError::DuplicateGradParam { param }),
            Some(slot) => *slot = Some(c),
        }
    }

    for (idx, mode) in funcs.modes.iter().enumerate() {
        count(&format!("mode {idx} flow"), n, mode.flow.len())?;
        check_mat(&format!("mode {idx} flow_x"), &mode.flow_x, n, n)?;
        check_mat(&format!("mode {idx} flow_p"), &mode.flow_p, n, n_params)?;
        check_vec(&format!("mode {idx} flow_t"), &mode.flow_t, n)?;
        for &ev in &info.modes[idx].events {
            if ev >= n_events {
                return Err(CodegenError::IndexOutOfRange {
                    what: format!("mode {idx} event"),
                    index: ev,
                    len: n_events,
                });
            }
        }
    }
    for (idx, ev) in funcs.events.iter().enumerate() {
        check_vec(&format!("event {idx} guard_x"), &ev.guard_x, n)?;
        check_vec(&format!("event {idx} guard_p"), &ev.guard_p, n_params)?;
        count(&format!("event {idx} reset"), n, ev.reset.len())?;
        check_mat(&format!("event {idx} reset_x"), &ev.reset_x, n, n)?;
        check_mat(&format!("event {idx} reset_p"), &ev.reset_p, n, n_params)?;
        check_vec(&format!("event {idx} reset_t"), &ev.reset_t, n)?;
    }
    for (idx, knot) in funcs.knots.iter().enumerate() {
        check_vec(&format!("knot set {idx} position_p"), &knot.position_p, n_params)?;
    }
    check_mat("init_p", &funcs.init_p, n, n_params)?;
    check_mat("output_x", &funcs.output_x, n_outputs, n)?;
    check_mat("output_p", &funcs.output_p, n_outputs, n_params)?;
    check_vec("output_t", &funcs.output_t, n_outputs)?;

    Ok(Dims { n, n_params, n_grad: info.n_grad(), n_outputs, grad_col })
}

fn check_mat(what: &str, mat: &SparseMat, n_rows: usize, n_cols: usize) -> Result<(), CodegenError> {
    let shape = |expected: usize, found: u32| CodegenError::ShapeMismatch {
        what: what.to_owned(),
        expected,
        found: found as usize,
    };
    if mat.n_rows as usize != n_rows {
        return Err(shape(n_rows, mat.n_rows));
    }
    if mat.n_cols as usize != n_cols {
        return Err(shape(n_cols, mat.n_cols));
    }
    let keys = mat.entries.iter().map(|&(r, c, _)| (r as usize) * n_cols + c as usize);
    for &(r, c, _) in &mat.entries {
        let (index, len) = if r as usize >= n_rows { (r as usize, n_rows) } else { (c as usize, n_cols) };
        if index >= len {
            return Err(CodegenError::IndexOutOfRange { what: what.to_owned(), index, len });
        }
    }
    check_ascending(what, keys)
}

fn check_vec(what: &str, vec: &SparseVec, len: usize) -> Result<(), CodegenError> {
    if let Some(&(index, _)) = vec.entries.iter().find(|&&(i, _)| i as usize >= len) {
        return Err(CodegenError::IndexOutOfRange { what: what.to_owned(), index: index as usize, len });
    }
    check_ascending(what, vec.entries.iter().map(|&(i, _)| i as usize))
}

/// Sparse entries must be strictly ascending: a repeated entry would be written twice and the
/// second write would silently win.
fn check_ascending(what: &str, keys: impl Iterator<Item = usize>) -> Result<(), CodegenError> {
    let mut prev: Option<usize> = None;
    for (position, key) in keys.enumerate() {
        if prev.is_some_and(|p| p >= key) {
            return Err(CodegenError::UnsortedSparse { what: what.to_owned(), position });
        }
        prev = Some(key);
    }
    Ok(())
}
