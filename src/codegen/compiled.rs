//! Stage 4 (codegen): the safe face of the JIT. Owns the Cranelift module and the native kernels,
//! checks every slice length before entering native code, and implements `sim::HybridSystem`.
//! Knows nothing of how kernels are generated beyond the plans' declared lengths.

use std::sync::{Mutex, OnceLock};

use cranelift_codegen::settings::{self, Configurable};
use cranelift_frontend::FunctionBuilderContext;
use cranelift_jit::{JITBuilder, JITModule};
use cranelift_module::{default_libcall_names, FuncId, Module};

use super::plan::{plan_flow_sens, plan_model, plan_vjp, KernelPlan, Lens, ModelKernels, N_OUTS};
use super::runtime::Callee;
use super::stiff::{plan_stiff, plan_vjp_dir};
use super::translate::{declare_callees, define_driver, define_kernel};
use super::{
    CodegenError, CompileOptions, OptLevel, RegAlloc, AUTO_REGALLOC_LIMIT, AUTO_REGALLOC_NODE_LIMIT,
};
use crate::expr::{scatter_lookup, Enclosure, Lookup, ModelFunctions};
use crate::interval::{Dual, Interval};
use crate::sim::{HybridSystem, SystemInfo};

/// The native signature shared by every kernel (see `lower`).
type KernelFn =
    unsafe extern "C" fn(f64, *const f64, *const f64, *const f64, *mut f64, *mut f64, *mut f64) -> f64;

/// A finalized kernel with the exact slice lengths it was generated for.
#[derive(Clone, Copy)]
struct Kernel {
    f: KernelFn,
    lens: Lens,
    prefill: [bool; N_OUTS],
}

impl Kernel {
    /// Calls the kernel if every slice has the length it was generated for. Otherwise nothing
    /// native runs, the outputs are filled with NaN (so a caller's bug shows up in its results
    /// rather than as memory corruption) and `None` is returned. Inlined: the checks are a
    /// handful of compares, comparable to the cost of a small kernel itself.
    #[inline]
    fn call(&self, t: f64, x: &[f64], s: &[f64], p: &[f64], outs: [&mut [f64]; N_OUTS]) -> Option<f64> {
        let fits = x.len() == self.lens.x
            && s.len() == self.lens.s
            && p.len() == self.lens.p
            && outs.iter().zip(self.lens.out).all(|(o, len)| o.len() == len);
        if !fits {
            for o in outs {
                o.fill(f64::NAN);
            }
            return None;
        }
        let [o0, o1, o2] = outs;
        if self.prefill != [false; N_OUTS] {
            for (o, prefill) in [&mut *o0, &mut *o1, &mut *o2].into_iter().zip(self.prefill) {
                if prefill {
                    o.fill(0.0);
                }
            }
        }
        // SAFETY: `f` was finalized by the module this model owns and is freed only in `Drop`,
        // which cannot run while `&self` is borrowed. The plan of this kernel was checked to read
        // `x`, `s`, `p` and write `out*` only below `self.lens` (`KernelPlan::check` and
        // `Translator::translate_load`), and the lengths were just compared exactly. Outputs are
        // `&mut` borrows, so they alias neither each other nor the inputs, as the kernel's cached
        // loads assume. The kernel touches no other memory: its only calls are the pure
        // wrappers in `runtime`.
        let r = unsafe {
            (self.f)(t, x.as_ptr(), s.as_ptr(), p.as_ptr(), o0.as_mut_ptr(), o1.as_mut_ptr(), o2.as_mut_ptr())
        };
        Some(r)
    }
}

/// A model compiled to native code.
///
/// `Send + Sync` without any `unsafe impl`: the kernels are plain function pointers, and the
/// `JITModule` (which is `Send` but not `Sync`) sits behind a `Mutex` that is only ever locked
/// in `Drop`; sharing `&CompiledModel` between threads only shares the pure kernels.
pub struct CompiledModel {
    info: SystemInfo,
    kernels: ModelKernels<Kernel>,
    /// Each event's `R_x` entries, in the order its `reset_jac` kernel writes their values.
    reset_patterns: Vec<Vec<(u32, u32)>>,
    /// Each event's guard as interval code (`HybridSystem::guard_enclosure`).
    enclosures: Vec<Enclosure>,
    n_kernels: usize,
    module: Mutex<Option<JITModule>>,
    /// The model's functions, kept to compile the stiff and the adjoint's kernels on demand
    /// (their compile time is never repaid by the runs that do not use them).
    source: Mutex<Option<ModelFunctions>>,
    opts: CompileOptions,
    /// Each mode's `flow_sens` kernel: compiled with the model when small, otherwise on the first
    /// `prepare_sensitivities` or `flow_sens` call (`plan::EAGER_FLOW_SENS_LIMIT`), into a module
    /// freed in `Drop`. Either way a call finds it behind one `OnceLock::get`.
    flow_sens: OnceLock<Result<Vec<Kernel>, String>>,
    flow_sens_module: Mutex<Option<JITModule>>,
    /// The stiff kernels once built (or why they could not be); their module is freed in `Drop`.
    stiff: OnceLock<Result<StiffKernels, String>>,
    stiff_module: Mutex<Option<JITModule>>,
    /// Each mode's `flow_vjp` kernel once built (`HybridSystem::flow_vjp`'s first call); their
    /// module is freed in `Drop`.
    vjp: OnceLock<Result<VjpKernels, String>>,
    vjp_module: Mutex<Option<JITModule>>,
    /// Each mode's `flow_vjp_dir` kernel once built (`HybridSystem::flow_vjp_dir`'s first call:
    /// the adjoint through a Rosenbrock step); their module is freed in `Drop`.
    vjp_dir: OnceLock<Result<Vec<Kernel>, String>>,
    vjp_dir_module: Mutex<Option<JITModule>>,
}

/// The adjoint's kernels, per mode, with what the host scatters after each (`plan::VjpPlan`).
struct VjpKernels {
    flow_vjp: Vec<Kernel>,
    /// Per mode, the lookups whose `[c_L, pos]` pairs `flow_vjp` writes to its third output.
    lookups: Vec<Vec<Lookup>>,
    /// The sensitivity column of every parameter.
    columns: Vec<Option<usize>>,
    /// Per mode, the sensitivity columns of the kernel's compact `gp`, in its order.
    summed: Vec<Vec<usize>>,
}

/// The kernels a Rosenbrock stepper needs, per mode (see `codegen::stiff`).
struct StiffKernels {
    jac: Vec<Kernel>,
    dir: Vec<Kernel>,
    /// Each mode's `f_x` entries, in the order `jac` writes their values.
    patterns: Vec<Vec<(u32, u32)>>,
}

impl std::fmt::Debug for CompiledModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CompiledModel")
            .field("info", &self.info)
            .field("n_kernels", &self.n_kernels)
            .finish_non_exhaustive()
    }
}

impl CompiledModel {
    /// `gx = f_x^T w` and `acc += f_p^T w` (m), the latter touching only the columns the kernel
    /// sums and the elements the scattered lookups read (checked indices, safe code): what both
    /// `flow_vjp` (on a zeroed `acc`) and `flow_vjp_add` are. False when the kernel cannot be had
    /// or a length is wrong.
    #[allow(clippy::too_many_arguments)]
    fn vjp_into(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        w: &[f64],
        p: &[f64],
        gx: &mut [f64],
        acc: &mut [f64],
    ) -> bool {
        let Ok(v) = self.vjp_kernels() else { return false };
        let (Some(k), Some(lookups), Some(summed)) =
            (v.flow_vjp.get(mode), v.lookups.get(mode), v.summed.get(mode))
        else {
            return false;
        };
        if acc.len() != self.info.n_grad() {
            return false;
        }
        // The kernel writes the summed columns compactly and `[c_L, pos]` per scattered lookup.
        let mut small = [0.0; 32];
        let mut large = Vec::new();
        let (len_g, len_l) = (summed.len(), 2 * lookups.len());
        let buf = if len_g + len_l <= small.len() {
            &mut small[..len_g + len_l]
        } else {
            large.resize(len_g + len_l, 0.0);
            &mut large[..]
        };
        let (compact, pairs) = buf.split_at_mut(len_g);
        if k.call(t, x, w, p, [gx, compact, pairs]).is_none() {
            return false;
        }
        for (&c, &g) in summed.iter().zip(compact.iter()) {
            if let Some(a) = acc.get_mut(c) {
                *a += g;
            }
        }
        for (l, pair) in lookups.iter().zip(pairs.chunks_exact(2)) {
            scatter_lookup(*l, pair[1], pair[0], &v.columns, acc);
        }
        true
    }

    /// Checks `funcs` against `info`, generates every kernel and finalizes them. Derivatives are
    /// compiled for `info.grad_params` only; all parameter values stay run-time inputs.
    pub fn compile(
        funcs: &ModelFunctions,
        mut info: SystemInfo,
        opts: &CompileOptions,
    ) -> Result<CompiledModel, CodegenError> {
        // The events' guard shapes and contact flags come from the same functions as the code.
        crate::lower::classify_events(funcs, &mut info);
        let plan = plan_model(funcs, &info)?;
        let parts = plan.try_map(|k| Ok::<_, CodegenError>((k.name.clone(), k.parts(opts.max_part_size))))?;
        let all_parts = || parts.iter().flat_map(|(_, p)| p);
        let largest = all_parts().map(KernelPlan::size).max().unwrap_or(0);
        let most_nodes = all_parts()
            .map(|k| super::translate::needed_nodes(&funcs.store, k.roots()).len())
            .max()
            .unwrap_or(0);
        let mut module = new_module(opts, largest, most_nodes)?;
        match build_kernels(&mut module, funcs, &parts) {
            Ok(mut kernels) => Ok(CompiledModel {
                // Planned with the model (small), or left to first use.
                flow_sens: if kernels.flow_sens.len() == funcs.modes.len() {
                    OnceLock::from(Ok(std::mem::take(&mut kernels.flow_sens)))
                } else {
                    OnceLock::new()
                },
                flow_sens_module: Mutex::new(None),
                info,
                reset_patterns: funcs
                    .events
                    .iter()
                    .map(|ev| ev.reset_x.entries.iter().map(|&(i, c, _)| (i, c)).collect())
                    .collect(),
                enclosures: funcs.events.iter().map(|ev| Enclosure::new(&funcs.store, ev.guard)).collect(),
                // A kernel cut into parts is the parts plus their driver.
                n_kernels: parts.iter().map(|(_, p)| if p.len() > 1 { p.len() + 1 } else { 1 }).sum(),
                kernels,
                module: Mutex::new(Some(module)),
                source: Mutex::new(Some(funcs.clone())),
                opts: *opts,
                stiff: OnceLock::new(),
                stiff_module: Mutex::new(None),
                vjp: OnceLock::new(),
                vjp_module: Mutex::new(None),
                vjp_dir: OnceLock::new(),
                vjp_dir_module: Mutex::new(None),
            }),
            Err(e) => {
                // SAFETY: no pointer into the module's memory was handed out: `build_kernels`
                // failed before returning any kernel.
                unsafe { module.free_memory() };
                Err(e)
            }
        }
    }

    /// Number of native functions generated with the model (the kernels built on demand, the
    /// stiff ones, the adjoint's and a large model's forward sensitivity kernels, not counted).
    pub fn n_kernels(&self) -> usize {
        self.n_kernels
    }

    /// The stiff kernels, compiled on first use: every mode's flow Jacobian with the
    /// sensitivities' time derivative, and the directional derivative of the sensitivity
    /// right-hand side (`codegen::stiff`). An error says why they could not be built.
    fn stiff_kernels(&self) -> Result<&StiffKernels, &str> {
        self.stiff
            .get_or_init(|| self.build_stiff().map_err(|e| e.to_string()))
            .as_ref()
            .map_err(String::as_str)
    }

    fn build_stiff(&self) -> Result<StiffKernels, CodegenError> {
        // A copy: the plan adds the second derivatives to its store.
        let mut funcs = lock(&self.source)
            .clone()
            .ok_or(CodegenError::Internal { reason: "model functions already consumed" })?;
        let plan = plan_stiff(&mut funcs, &self.info)?;
        let (module, mut kernels) = build_module(&self.opts, &funcs, &[&plan.jac, &plan.dir], "stiff")?;
        *lock(&self.stiff_module) = Some(module);
        let dir = kernels.pop().unwrap_or_default();
        let jac = kernels.pop().unwrap_or_default();
        Ok(StiffKernels { jac, dir, patterns: plan.patterns })
    }

    /// Every mode's `flow_sens` kernel, compiled on first use when the model did not include them.
    /// The fast path, once they exist, is the `OnceLock`'s one load and compare; the build is
    /// kept out of line so that `flow_sens` stays small enough to inline into the stage loop.
    #[inline]
    fn flow_sens_kernels(&self) -> Result<&[Kernel], &str> {
        match self.flow_sens.get() {
            Some(built) => built.as_ref().map(Vec::as_slice).map_err(String::as_str),
            None => self.init_flow_sens(),
        }
    }

    #[cold]
    #[inline(never)]
    fn init_flow_sens(&self) -> Result<&[Kernel], &str> {
        self.flow_sens
            .get_or_init(|| self.build_flow_sens().map_err(|e| e.to_string()))
            .as_ref()
            .map(Vec::as_slice)
            .map_err(String::as_str)
    }

    fn build_flow_sens(&self) -> Result<Vec<Kernel>, CodegenError> {
        let source = lock(&self.source);
        let funcs =
            source.as_ref().ok_or(CodegenError::Internal { reason: "model functions already consumed" })?;
        let plans = plan_flow_sens(funcs, &self.info)?;
        let (module, mut kernels) = build_module(&self.opts, funcs, &[&plans], "flow_sens")?;
        *lock(&self.flow_sens_module) = Some(module);
        Ok(kernels.pop().unwrap_or_default())
    }

    /// The adjoint's kernels, compiled on first use: every mode's `flow_vjp` (`plan::plan_vjp`).
    fn vjp_kernels(&self) -> Result<&VjpKernels, &str> {
        self.vjp.get_or_init(|| self.build_vjp().map_err(|e| e.to_string())).as_ref().map_err(String::as_str)
    }

    fn build_vjp(&self) -> Result<VjpKernels, CodegenError> {
        let source = lock(&self.source);
        let funcs =
            source.as_ref().ok_or(CodegenError::Internal { reason: "model functions already consumed" })?;
        let plan = plan_vjp(funcs, &self.info)?;
        let (module, mut kernels) = build_module(&self.opts, funcs, &[&plan.kernels], "flow_vjp")?;
        *lock(&self.vjp_module) = Some(module);
        Ok(VjpKernels {
            flow_vjp: kernels.pop().unwrap_or_default(),
            lookups: plan.lookups,
            columns: plan.columns,
            summed: plan.summed,
        })
    }
}

impl CompiledModel {
    /// The adjoint's second-order kernels, compiled on first use (`stiff::plan_vjp_dir`).
    fn vjp_dir_kernels(&self) -> Result<&[Kernel], &str> {
        self.vjp_dir
            .get_or_init(|| self.build_vjp_dir().map_err(|e| e.to_string()))
            .as_ref()
            .map(Vec::as_slice)
            .map_err(String::as_str)
    }

    fn build_vjp_dir(&self) -> Result<Vec<Kernel>, CodegenError> {
        // A copy: the plan adds the second derivatives to its store.
        let mut funcs = lock(&self.source)
            .clone()
            .ok_or(CodegenError::Internal { reason: "model functions already consumed" })?;
        let plan = plan_vjp_dir(&mut funcs, &self.info)?;
        let (module, mut kernels) = build_module(&self.opts, &funcs, &[&plan], "flow_vjp_dir")?;
        *lock(&self.vjp_dir_module) = Some(module);
        Ok(kernels.pop().unwrap_or_default())
    }
}

/// A JIT module of its own for kernels compiled on demand: every list of `lists` defined (cut
/// into parts), finalized, and its kernels fetched, list by list. The caller keeps the module
/// alive as long as the kernels (and frees it in `Drop`); on an error it is freed here.
fn build_module(
    opts: &CompileOptions,
    funcs: &ModelFunctions,
    lists: &[&[KernelPlan]],
    what: &str,
) -> Result<(JITModule, Vec<Vec<Kernel>>), CodegenError> {
    let cut: Vec<Vec<(String, Vec<KernelPlan>)>> = lists
        .iter()
        .map(|ks| ks.iter().map(|k| (k.name.clone(), k.parts(opts.max_part_size))).collect())
        .collect();
    let all_parts = || cut.iter().flatten().flat_map(|(_, p)| p);
    let largest = all_parts().map(KernelPlan::size).max().unwrap_or(0);
    let most_nodes =
        all_parts().map(|k| super::translate::needed_nodes(&funcs.store, k.roots()).len()).max().unwrap_or(0);
    let mut module = new_module(opts, largest, most_nodes)?;
    let built = (|| {
        let callees = declare_callees(&mut module)?;
        let mut ctx = module.make_context();
        let mut fn_ctx = FunctionBuilderContext::new();
        let ids = cut
            .iter()
            .map(|list| {
                list.iter()
                    .map(|entry| define_entry(&mut module, &mut ctx, &mut fn_ctx, &callees, funcs, entry))
                    .collect::<Result<Vec<_>, CodegenError>>()
            })
            .collect::<Result<Vec<_>, CodegenError>>()?;
        module.finalize_definitions().map_err(|source| CodegenError::Module {
            kernel: format!("finalize {what}"),
            source: Box::new(source),
        })?;
        Ok(ids.iter().map(|list| list.iter().map(|e| finalized(&module, e)).collect()).collect())
    })();
    match built {
        Ok(kernels) => Ok((module, kernels)),
        Err(e) => {
            // SAFETY: no pointer into the module's memory was handed out: the kernels are
            // dropped with the error.
            unsafe { module.free_memory() };
            Err(e)
        }
    }
}

/// Locks a mutex that only this module's code locks, none of it while panicking: a poisoned
/// lock still guards consistent data.
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

impl Drop for CompiledModel {
    fn drop(&mut self) {
        // The model's module, then those of the kernels compiled on demand (`self.stiff`,
        // `self.flow_sens`, `self.vjp`, `self.vjp_dir`).
        let slots = [
            &mut self.module,
            &mut self.stiff_module,
            &mut self.flow_sens_module,
            &mut self.vjp_module,
            &mut self.vjp_dir_module,
        ];
        for slot in slots {
            let slot = match slot.get_mut() {
                Ok(slot) => slot,
                // Nothing ever panics while holding these locks, but a poisoned lock still owns
                // its module, and the code must be freed either way.
                Err(poisoned) => poisoned.into_inner(),
            };
            if let Some(module) = slot.take() {
                // SAFETY: `&mut self` proves no kernel is running, and the pointers into this
                // module (in `self.kernels` or the `OnceLock` beside its slot) are never used
                // after this: they are private and die with `self`.
                unsafe { module.free_memory() };
            }
        }
    }
}

/// A JIT module with the chosen flags (the register allocator may depend on the size of the
/// largest kernel part and on the most expression nodes one part computes) and every host
/// wrapper registered, so no import can stay unresolved (which would panic inside
/// `finalize_definitions`).
fn new_module(
    opts: &CompileOptions,
    largest_kernel: usize,
    most_nodes: usize,
) -> Result<JITModule, CodegenError> {
    let mut flags = settings::builder();
    let opt_level = match opts.opt_level {
        OptLevel::None => "none",
        OptLevel::Speed => "speed",
        OptLevel::SpeedAndSize => "speed_and_size",
    };
    let regalloc = match opts.regalloc {
        RegAlloc::Backtracking => "backtracking",
        RegAlloc::SinglePass => "single_pass",
        RegAlloc::Auto if largest_kernel > AUTO_REGALLOC_LIMIT || most_nodes > AUTO_REGALLOC_NODE_LIMIT => {
            "single_pass"
        }
        RegAlloc::Auto => "backtracking",
    };
    let verifier = if opts.verifier { "true" } else { "false" };
    for (name, value) in [
        ("opt_level", opt_level),
        ("regalloc_algorithm", regalloc),
        ("enable_verifier", verifier),
        // JITModule::new asserts non-PIC code; colocated libcalls could be out of range.
        ("is_pic", "false"),
        ("use_colocated_libcalls", "false"),
    ] {
        flags.set(name, value).map_err(CodegenError::Setting)?;
    }
    let isa = cranelift_native::builder()
        .map_err(|reason| CodegenError::UnsupportedHost { reason })?
        .finish(settings::Flags::new(flags))
        .map_err(CodegenError::Target)?;
    let mut builder = JITBuilder::with_isa(isa, default_libcall_names());
    for callee in Callee::all() {
        let address =
            callee.address().ok_or(CodegenError::Internal { reason: "host wrapper without an address" })?;
        builder.symbol(callee.symbol(), address);
    }
    Ok(JITModule::new(builder))
}

/// Defines every planned kernel (a big one as its parts and a driver that calls them, see
/// `KernelPlan::parts`), finalizes the module and fetches the function pointers.
fn build_kernels(
    module: &mut JITModule,
    funcs: &ModelFunctions,
    parts: &ModelKernels<(String, Vec<KernelPlan>)>,
) -> Result<ModelKernels<Kernel>, CodegenError> {
    let callees = declare_callees(module)?;
    let mut ctx = module.make_context();
    let mut fn_ctx = FunctionBuilderContext::new();
    let ids = parts.try_map(|entry| define_entry(module, &mut ctx, &mut fn_ctx, &callees, funcs, entry))?;
    module
        .finalize_definitions()
        .map_err(|source| CodegenError::Module { kernel: "finalize".into(), source: Box::new(source) })?;
    ids.try_map(|entry| Ok(finalized(module, entry)))
}

/// Defines one planned kernel: its single part, or its parts and a driver that calls them.
fn define_entry(
    module: &mut JITModule,
    ctx: &mut cranelift_codegen::Context,
    fn_ctx: &mut FunctionBuilderContext,
    callees: &std::collections::HashMap<Callee, FuncId>,
    funcs: &ModelFunctions,
    (name, kernel_parts): &(String, Vec<KernelPlan>),
) -> Result<(FuncId, Lens, [bool; N_OUTS]), CodegenError> {
    let first = kernel_parts.first().ok_or(CodegenError::Internal { reason: "kernel without parts" })?;
    let ids = kernel_parts
        .iter()
        .map(|part| define_kernel(module, ctx, fn_ctx, callees, &funcs.store, part))
        .collect::<Result<Vec<FuncId>, CodegenError>>()?;
    let entry = match ids.as_slice() {
        [single] => *single,
        _ => define_driver(module, ctx, fn_ctx, name, &ids)?,
    };
    Ok((entry, first.lens, first.prefill))
}

/// The callable kernel of a defined entry, after `finalize_definitions`.
fn finalized(module: &JITModule, &(id, lens, prefill): &(FuncId, Lens, [bool; N_OUTS])) -> Kernel {
    let code = module.get_finalized_function(id);
    // SAFETY: `code` is the finalized entry of a function defined with `kernel_signature`,
    // which is exactly `KernelFn` under the host's default (C) calling convention.
    let f = unsafe { std::mem::transmute::<*const u8, KernelFn>(code) };
    Kernel { f, lens, prefill }
}

/// Fills every output with NaN when a mode or event index is out of range: the trait has no
/// error channel, and NaN makes the caller's bug visible.
fn poison(outs: [&mut [f64]; N_OUTS]) {
    for o in outs {
        o.fill(f64::NAN);
    }
}

impl HybridSystem for CompiledModel {
    fn info(&self) -> &SystemInfo {
        &self.info
    }

    fn initial_state(&self, p: &[f64], x0: &mut [f64]) {
        // Initial values depend on parameters only; `t` is never read.
        self.kernels.init.call(0.0, &[], &[], p, [x0, &mut [], &mut []]);
    }

    fn initial_sens(&self, p: &[f64], s0: &mut [f64]) {
        self.kernels.init_sens.call(0.0, &[], &[], p, [s0, &mut [], &mut []]);
    }

    fn flow(&self, mode: usize, t: f64, x: &[f64], p: &[f64], dx: &mut [f64]) {
        match self.kernels.flow.get(mode) {
            Some(k) => {
                k.call(t, x, &[], p, [dx, &mut [], &mut []]);
            }
            None => poison([dx, &mut [], &mut []]),
        }
    }

    // Inlined into the integrator's stage loop, which calls it for every stage (about 130 times
    // in a bouncing-ball run): measured 3% faster. The other methods gained nothing from it.
    #[inline]
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
        match self.flow_sens_kernels().ok().and_then(|k| k.get(mode)) {
            Some(k) => {
                k.call(t, x, s, p, [dx, ds, &mut []]);
            }
            None => poison([dx, ds, &mut []]),
        }
    }

    fn prepare_sensitivities(&self) -> Result<(), String> {
        self.flow_sens_kernels().map(|_| ()).map_err(str::to_owned)
    }

    #[allow(clippy::too_many_arguments)]
    fn flow_vjp(&self, mode: usize, t: f64, x: &[f64], w: &[f64], p: &[f64], gx: &mut [f64], gp: &mut [f64]) {
        gp.fill(0.0);
        if !self.vjp_into(mode, t, x, w, p, gx, gp) {
            poison([gx, gp, &mut []]);
        }
    }

    fn flow_vjp_add(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        w: &[f64],
        p: &[f64],
        gx: &mut [f64],
        pbar: &mut [f64],
    ) {
        if !self.vjp_into(mode, t, x, w, p, gx, pbar) {
            poison([gx, pbar, &mut []]);
        }
    }

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
        let n = x.len();
        let (mut gx, mut gp) = (vec![0.0; n], vec![0.0; pbar.len()]);
        match self.vjp_dir_kernels().ok().and_then(|k| k.get(mode)) {
            Some(k) if v.len() == n => {
                let mut xva = Vec::with_capacity(2 * n + 1);
                xva.extend_from_slice(x);
                xva.extend_from_slice(v);
                xva.push(a);
                k.call(t, &xva, w, p, [&mut gx, &mut gp, &mut []]);
            }
            _ => poison([&mut gx, &mut gp, &mut []]),
        }
        for (o, g) in xbar.iter_mut().zip(&gx) {
            *o += g;
        }
        for (o, g) in pbar.iter_mut().zip(&gp) {
            *o += g;
        }
    }

    fn prepare_jacobians(&self) -> Result<(), String> {
        self.stiff_kernels().map(|_| ()).map_err(str::to_owned)
    }

    fn flow_jac(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        s: &[f64],
        p: &[f64],
        fx: &mut [f64],
        ft: &mut [f64],
        st: &mut [f64],
    ) {
        let kernels = self.stiff_kernels().ok();
        match kernels.and_then(|k| Some((k.jac.get(mode)?, k.patterns.get(mode)?))) {
            Some((k, pattern)) if fx.len() == x.len() * x.len() => {
                // The kernel writes the pattern's values; small models take them as a matrix.
                let mut vals = vec![0.0; pattern.len()];
                k.call(t, x, s, p, [&mut vals, ft, st]);
                fx.fill(0.0);
                let n = x.len();
                for (&(r, c), v) in pattern.iter().zip(vals) {
                    fx[r as usize * n + c as usize] = v;
                }
            }
            _ => poison([fx, ft, st]),
        }
    }

    fn jac_pattern(&self, mode: usize) -> Option<&[(u32, u32)]> {
        self.stiff_kernels().ok()?.patterns.get(mode).map(Vec::as_slice)
    }

    fn flow_jac_values(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        s: &[f64],
        p: &[f64],
        vals: &mut [f64],
        ft: &mut [f64],
        st: &mut [f64],
    ) {
        match self.stiff_kernels().ok().and_then(|k| k.jac.get(mode)) {
            Some(k) => {
                k.call(t, x, s, p, [vals, ft, st]);
            }
            None => poison([vals, ft, st]),
        }
    }

    fn sens_dir(&self, mode: usize, t: f64, xv: &[f64], s: &[f64], p: &[f64], dir: &mut [f64]) {
        match self.stiff_kernels().ok().and_then(|k| k.dir.get(mode)) {
            Some(k) => {
                k.call(t, xv, s, p, [dir, &mut [], &mut []]);
            }
            None => poison([dir, &mut [], &mut []]),
        }
    }

    fn guards(&self, mode: usize, t: f64, x: &[f64], p: &[f64], g: &mut [f64]) {
        match self.kernels.guards.get(mode) {
            Some(k) => {
                k.call(t, x, &[], p, [g, &mut [], &mut []]);
            }
            None => poison([g, &mut [], &mut []]),
        }
    }

    fn guard_speeds(&self, mode: usize, t: f64, x: &[f64], f: &[f64], p: &[f64], dg: &mut [f64]) {
        match self.kernels.guard_speeds.get(mode) {
            Some(k) => {
                k.call(t, x, f, p, [dg, &mut [], &mut []]);
            }
            None => poison([dg, &mut [], &mut []]),
        }
    }

    fn guard_grad(&self, event: usize, t: f64, x: &[f64], p: &[f64], gx: &mut [f64], gp: &mut [f64]) -> f64 {
        match self.kernels.guard_grad.get(event) {
            Some(k) => k.call(t, x, &[], p, [gx, gp, &mut []]).unwrap_or(f64::NAN),
            None => {
                poison([gx, gp, &mut []]);
                f64::NAN
            }
        }
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
        match self.enclosures.get(event) {
            // The interval code reads only the guard's states and parameters, by index; the
            // slices must be long enough (the integrator passes the model's lengths).
            Some(e)
                if x.len() >= self.info.n_states()
                    && dx.len() >= x.len()
                    && p.len() >= self.info.n_params() =>
            {
                e.eval(t, x, dx, p, scratch)
            }
            _ => Dual { v: Interval::ENTIRE, d: Interval::ENTIRE },
        }
    }

    fn guard_states(&self, event: usize) -> Option<&[u32]> {
        self.enclosures.get(event).map(Enclosure::states)
    }

    fn knot_position(&self, set: usize, t: f64, p: &[f64]) -> f64 {
        self.kernels
            .knot_position
            .get(set)
            .and_then(|k| k.call(t, &[], &[], p, [&mut [], &mut [], &mut []]))
            .unwrap_or(f64::NAN)
    }

    fn knot_position_grad(&self, set: usize, t: f64, p: &[f64], sp: &mut [f64]) -> f64 {
        match self.kernels.knot_grad.get(set) {
            Some(k) => k.call(t, &[], &[], p, [sp, &mut [], &mut []]).unwrap_or(f64::NAN),
            None => {
                poison([sp, &mut [], &mut []]);
                f64::NAN
            }
        }
    }

    fn condition(&self, event: usize, t: f64, x: &[f64], p: &[f64]) -> bool {
        match self.kernels.condition.get(event) {
            // Same rule as `Select`: any value other than 0.0 (NaN included) is true.
            Some(Some(k)) => k.call(t, x, &[], p, [&mut [], &mut [], &mut []]).is_some_and(|c| c != 0.0),
            Some(None) => true,
            None => false,
        }
    }

    fn reset(&self, event: usize, t: f64, x: &[f64], p: &[f64], r: &mut [f64]) {
        match self.kernels.reset.get(event) {
            Some(k) => {
                k.call(t, x, &[], p, [r, &mut [], &mut []]);
            }
            None => poison([r, &mut [], &mut []]),
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
        // The kernel writes `R_x`'s entries; the dense matrix is for callers that want it (the
        // integrator asks for the entries).
        let n = self.info.n_states();
        match (self.kernels.reset_jac.get(event), self.reset_patterns.get(event)) {
            (Some(k), Some(pattern)) if rx.len() == n * n => {
                let mut vals = vec![0.0; pattern.len()];
                if k.call(t, x, &[], p, [&mut vals, rp, rt]).is_some() {
                    rx.fill(0.0);
                    for (&(r, c), v) in pattern.iter().zip(vals) {
                        rx[r as usize * n + c as usize] = v;
                    }
                } else {
                    rx.fill(f64::NAN);
                }
            }
            _ => poison([rx, rp, rt]),
        }
    }

    fn reset_jac_pattern(&self, event: usize) -> Option<&[(u32, u32)]> {
        self.reset_patterns.get(event).map(Vec::as_slice)
    }

    fn reset_jac_values(
        &self,
        event: usize,
        t: f64,
        x: &[f64],
        p: &[f64],
        rx: &mut [f64],
        rp: &mut [f64],
        rt: &mut [f64],
    ) {
        match self.kernels.reset_jac.get(event) {
            Some(k) => {
                k.call(t, x, &[], p, [rx, rp, rt]);
            }
            None => poison([rx, rp, rt]),
        }
    }

    fn outputs(&self, t: f64, x: &[f64], p: &[f64], y: &mut [f64]) {
        self.kernels.outputs.call(t, x, &[], p, [y, &mut [], &mut []]);
    }

    fn output_jac(&self, t: f64, x: &[f64], p: &[f64], yx: &mut [f64], yp: &mut [f64], yt: &mut [f64]) {
        self.kernels.output_jac.call(t, x, &[], p, [yx, yp, yt]);
    }
}
