//! Stage 4 (codegen): lowers one checked [`KernelPlan`] to Cranelift IR, node by node. Knows the
//! DAG and Cranelift, but not the `HybridSystem` trait or how kernels are called.
//!
//! Every kernel has the same signature,
//! `extern "C" fn(t: f64, x: *const f64, s: *const f64, p: *const f64, out0: *mut f64,
//! out1: *mut f64, out2: *mut f64) -> f64`, and is one basic block: `Select` is a `select`
//! instruction, not a branch, so every value dominates every later use.

use std::collections::{HashMap, HashSet};

use cranelift_codegen::ir::immediates::Ieee64;
use cranelift_codegen::ir::{
    condcodes::FloatCC, types, AbiParam, FuncRef, InstBuilder, MemFlagsData, Signature, UserFuncName, Value,
};
use cranelift_codegen::Context;
use cranelift_frontend::{FunctionBuilder, FunctionBuilderContext};
use cranelift_jit::JITModule;
use cranelift_module::{FuncId, Linkage, Module};

use super::plan::{KernelPlan, Lens, Term, Write, N_OUTS};
use super::runtime::Callee;
use super::CodegenError;
use crate::expr::{BinaryOp, ExprId, ExprStore, Lookup, LookupKind, Node, UnaryOp};

/// The uniform kernel signature (see the module comment).
pub(crate) fn kernel_signature(module: &JITModule) -> Signature {
    let ptr = module.target_config().pointer_type();
    let mut sig = module.make_signature();
    sig.params.push(AbiParam::new(types::F64));
    sig.params.extend(std::iter::repeat_n(AbiParam::new(ptr), 3 + N_OUTS));
    sig.returns.push(AbiParam::new(types::F64));
    sig
}

/// Declares every host function once per module; kernels import them by id.
pub(crate) fn declare_callees(module: &mut JITModule) -> Result<HashMap<Callee, FuncId>, CodegenError> {
    let mut ids = HashMap::new();
    for callee in Callee::all() {
        let mut sig = module.make_signature();
        sig.params.extend(std::iter::repeat_n(AbiParam::new(types::F64), callee.arity()));
        sig.returns.push(AbiParam::new(types::F64));
        let name = callee.symbol();
        let id = module
            .declare_function(&name, Linkage::Import, &sig)
            .map_err(|source| CodegenError::Module { kernel: name.clone(), source: Box::new(source) })?;
        ids.insert(callee, id);
    }
    Ok(ids)
}

/// Generates, compiles and defines the kernel described by `plan`; returns its id in `module`.
/// The plan must have passed [`KernelPlan::check`]; state and parameter indices are checked here.
pub(crate) fn define_kernel(
    module: &mut JITModule,
    ctx: &mut Context,
    fn_ctx: &mut FunctionBuilderContext,
    callees: &HashMap<Callee, FuncId>,
    store: &ExprStore,
    plan: &KernelPlan,
) -> Result<FuncId, CodegenError> {
    let module_err = |source| CodegenError::Module { kernel: plan.name.clone(), source: Box::new(source) };
    let sig = kernel_signature(module);
    let id = module.declare_function(&plan.name, Linkage::Export, &sig).map_err(module_err)?;
    ctx.func.signature = sig;
    ctx.func.name = UserFuncName::user(0, id.as_u32());

    let result = {
        let mut b = FunctionBuilder::new(&mut ctx.func, fn_ctx);
        let params = enter_body(&mut b);
        let mut tr = Translator {
            b,
            module: &mut *module,
            callees,
            store,
            lens: plan.lens,
            t: params[0],
            x: params[1],
            s: params[2],
            p: params[3],
            outs: [params[4], params[5], params[6]],
            values: HashMap::new(),
            loads: HashMap::new(),
            consts: HashMap::new(),
            imported: HashMap::new(),
            finite: HashMap::new(),
        };
        let r = tr.translate_plan(plan);
        // A half-built function cannot be finalized (its block has no terminator); on error it
        // is simply dropped and the context cleared below.
        if r.is_ok() {
            let target = tr.module.target_config();
            tr.b.finalize(target);
        }
        r
    };
    if let Err(e) = result {
        module.clear_context(ctx);
        return Err(e);
    }
    let defined = module.define_function(id, ctx).map_err(module_err);
    module.clear_context(ctx);
    defined?;
    Ok(id)
}

/// Defines `name` as a kernel that calls the already declared kernels `parts` in order with its
/// own arguments and returns the last one's value: a big kernel cut into parts
/// (`KernelPlan::parts`) keeps one entry point, so callers pay nothing for the cut and small
/// kernels nothing at all.
pub(crate) fn define_driver(
    module: &mut JITModule,
    ctx: &mut Context,
    fn_ctx: &mut FunctionBuilderContext,
    name: &str,
    parts: &[FuncId],
) -> Result<FuncId, CodegenError> {
    let module_err = |source| CodegenError::Module { kernel: name.to_owned(), source: Box::new(source) };
    let sig = kernel_signature(module);
    let id = module.declare_function(name, Linkage::Export, &sig).map_err(module_err)?;
    ctx.func.signature = sig;
    ctx.func.name = UserFuncName::user(0, id.as_u32());
    {
        let mut b = FunctionBuilder::new(&mut ctx.func, fn_ctx);
        let args = enter_body(&mut b);
        let mut ret = b.ins().f64const(Ieee64::with_float(0.0));
        for &part in parts {
            let callee = module.declare_func_in_func(part, b.func);
            let call = b.ins().call(callee, &args);
            ret = b.inst_results(call)[0];
        }
        b.ins().return_(&[ret]);
        b.finalize(module.target_config());
    }
    let defined = module.define_function(id, ctx).map_err(module_err);
    module.clear_context(ctx);
    defined?;
    Ok(id)
}

/// Which input array a load reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Input {
    X,
    S,
    P,
}

struct Translator<'a, 'f> {
    b: FunctionBuilder<'f>,
    module: &'a mut JITModule,
    callees: &'a HashMap<Callee, FuncId>,
    store: &'a ExprStore,
    lens: Lens,
    t: Value,
    x: Value,
    s: Value,
    p: Value,
    outs: [Value; N_OUTS],
    /// The value of every node translated so far: each node is lowered once per kernel.
    values: HashMap<ExprId, Value>,
    /// Each input entry is loaded once (outputs never alias inputs, so the load stays valid).
    loads: HashMap<(Input, u32), Value>,
    consts: HashMap<u64, Value>,
    imported: HashMap<Callee, FuncRef>,
    /// Jacobian entries known to be finite at every finite input (or not).
    finite: HashMap<ExprId, bool>,
}

impl Translator<'_, '_> {
    /// Recipe: translate every node the plan needs in ascending id order (children first, so the
    /// DAG's sharing is the common-subexpression elimination), storing each output entry as soon
    /// as the last node it depends on exists (so finished values do not stay live and spill at
    /// `opt_level = none`, where nothing reschedules them), then return.
    fn translate_plan(&mut self, plan: &KernelPlan) -> Result<(), CodegenError> {
        // Writes ordered by the largest node id they need; `Zero` needs none.
        let mut writes: Vec<(Option<ExprId>, &Write)> =
            plan.writes.iter().map(|w| (ready_after(&w.term), w)).collect();
        writes.sort_by_key(|&(ready, _)| ready);
        let mut pending = writes.into_iter().peekable();
        while let Some((_, w)) = pending.next_if(|&(ready, _)| ready.is_none()) {
            self.translate_write(w, &plan.name)?;
        }
        for id in needed_nodes(self.store, plan.roots()) {
            let value = self.translate_node(id)?;
            self.values.insert(id, value);
            while let Some((_, w)) = pending.next_if(|&(ready, _)| ready == Some(id)) {
                self.translate_write(w, &plan.name)?;
            }
        }
        // Every write's dependencies are among the needed nodes, so none is left; storing any
        // stragglers anyway keeps the kernel complete if that ever changes.
        for (_, w) in pending {
            self.translate_write(w, &plan.name)?;
        }
        let ret = match plan.ret {
            Some(e) => self.value(e),
            None => self.constant(0.0f64.to_bits()),
        };
        self.b.ins().return_(&[ret]);
        Ok(())
    }

    /// Recipe: compute the entry's value and store it at a constant offset (range-checked
    /// against the output's length by `KernelPlan::check`).
    fn translate_write(&mut self, w: &Write, kernel: &str) -> Result<(), CodegenError> {
        let value = match &w.term {
            Term::Expr(e) => self.value(*e),
            Term::Zero => self.constant(0.0f64.to_bits()),
            Term::SensDot { products, bias } => self.translate_sens_dot(products, *bias)?,
        };
        let offset = byte_offset(w.index, kernel)?;
        self.b.ins().store(MemFlagsData::trusted(), value, self.outs[w.out], offset);
        Ok(())
    }

    fn translate_node(&mut self, id: ExprId) -> Result<Value, CodegenError> {
        Ok(match *self.store.node(id) {
            Node::Const(bits) => self.constant(bits),
            Node::State(i) => self.translate_load(Input::X, i)?,
            Node::Param(j) => self.translate_load(Input::P, j)?,
            Node::Time => self.t,
            Node::Unary(op, a) => self.translate_unary(op, a)?,
            Node::Binary(op, a, b) => self.translate_binary(op, a, b)?,
            Node::Select(c, a, b) => self.translate_select(c, a, b),
            Node::Lookup(l, pos) => self.translate_lookup(l, pos)?,
        })
    }

    /// Recipe: a vector parameter read at a run-time index (`apply_lookup`, bit for bit). The
    /// vector `p[base .. base + len]` is checked against the parameters' length here, at compile
    /// time; the index `k` is the position truncated with saturation (NaN gives 0) and clamped
    /// with integer `smax`/`smin` into `[0, last]` before any load, so no position, however
    /// large, infinite or NaN, can read outside the vector. Then one or two loads at `p + 8 k`.
    fn translate_lookup(&mut self, l: Lookup, pos: ExprId) -> Result<Value, CodegenError> {
        let end = l.base as usize + l.len as usize;
        if l.len < 2 || end > self.lens.p {
            return Err(CodegenError::IndexOutOfRange {
                what: "input vector".into(),
                index: end,
                len: self.lens.p,
            });
        }
        let pos = self.value(pos);
        let ptr = self.module.target_config().pointer_type();
        let last = match l.kind {
            LookupKind::Pwc => l.len - 1,
            LookupKind::Pwl | LookupKind::PwlSlope => l.len - 2,
        };
        let k = self.b.ins().fcvt_to_sint_sat(ptr, pos);
        let lo = self.b.ins().iconst(ptr, 0);
        let hi = self.b.ins().iconst(ptr, i64::from(last));
        let k = self.b.ins().smax(k, lo);
        let k = self.b.ins().smin(k, hi);
        let bytes = self.b.ins().ishl_imm_u(k, 3);
        let addr = self.b.ins().iadd(self.p, bytes);
        let flags = MemFlagsData::trusted().with_readonly();
        let at = byte_offset(l.base, "input vector")?;
        let u_k = self.b.ins().load(types::F64, flags, addr, at);
        let value = match l.kind {
            LookupKind::Pwc => u_k,
            LookupKind::Pwl | LookupKind::PwlSlope => {
                let next = byte_offset(l.base + 1, "input vector")?;
                let u_next = self.b.ins().load(types::F64, flags, addr, next);
                if l.kind == LookupKind::Pwl {
                    // w = pos - k, clamped to [0, 1]; then (1 - w) u_k + w u_next.
                    let kf = self.b.ins().fcvt_from_sint(types::F64, k);
                    let w = self.b.ins().fsub(pos, kf);
                    let (zero, one) = (self.constant(0.0f64.to_bits()), self.constant(1.0f64.to_bits()));
                    let below = self.b.ins().fcmp(FloatCC::LessThan, w, zero);
                    let w = self.b.ins().select(below, zero, w);
                    let above = self.b.ins().fcmp(FloatCC::GreaterThan, w, one);
                    let w = self.b.ins().select(above, one, w);
                    let rest = self.b.ins().fsub(one, w);
                    let a = self.b.ins().fmul(rest, u_k);
                    let b = self.b.ins().fmul(w, u_next);
                    self.b.ins().fadd(a, b)
                } else {
                    // Inside [0, len - 1) the segment's rise, else 0.
                    let zero = self.constant(0.0f64.to_bits());
                    let top = self.constant(f64::from(l.len - 1).to_bits());
                    let rise = self.b.ins().fsub(u_next, u_k);
                    let from_start = self.b.ins().fcmp(FloatCC::GreaterThanOrEqual, pos, zero);
                    let before_end = self.b.ins().fcmp(FloatCC::LessThan, pos, top);
                    let inside = self.b.ins().band(from_start, before_end);
                    self.b.ins().select(inside, rise, zero)
                }
            }
        };
        // A NaN position gives NaN.
        let nan = self.b.ins().fcmp(FloatCC::Unordered, pos, pos);
        Ok(self.b.ins().select(nan, pos, value))
    }

    /// A value already translated; `needed_nodes` guarantees children come first.
    fn value(&self, id: ExprId) -> Value {
        self.values[&id]
    }

    fn constant(&mut self, bits: u64) -> Value {
        if let Some(&v) = self.consts.get(&bits) {
            return v;
        }
        let v = self.b.ins().f64const(Ieee64::with_bits(bits));
        self.consts.insert(bits, v);
        v
    }

    /// Recipe: check the index against the array's length (a compile-time constant), then one
    /// trusted read-only load at a constant offset, cached for the rest of the kernel.
    fn translate_load(&mut self, input: Input, index: u32) -> Result<Value, CodegenError> {
        if let Some(&v) = self.loads.get(&(input, index)) {
            return Ok(v);
        }
        let (base, len, what) = match input {
            Input::X => (self.x, self.lens.x, "state"),
            Input::S => (self.s, self.lens.s, "sensitivity"),
            Input::P => (self.p, self.lens.p, "parameter"),
        };
        if index as usize >= len {
            return Err(CodegenError::IndexOutOfRange { what: what.into(), index: index as usize, len });
        }
        let offset = byte_offset(index, what)?;
        let flags = MemFlagsData::trusted().with_readonly();
        let v = self.b.ins().load(types::F64, flags, base, offset);
        self.loads.insert((input, index), v);
        Ok(v)
    }

    /// Recipe: negation, square root and absolute value are native instructions; `Sign` and
    /// `Not` are compare-and-select chains; everything transcendental calls its host wrapper.
    fn translate_unary(&mut self, op: UnaryOp, a: ExprId) -> Result<Value, CodegenError> {
        let a = self.value(a);
        Ok(match op {
            UnaryOp::Neg => self.b.ins().fneg(a),
            UnaryOp::Sqrt => self.b.ins().sqrt(a),
            UnaryOp::Abs => self.b.ins().fabs(a),
            UnaryOp::Sign => self.translate_sign(a),
            UnaryOp::Not => {
                let zero = self.constant(0.0f64.to_bits());
                let is_zero = self.b.ins().fcmp(FloatCC::Equal, a, zero);
                self.bool_to_f64(is_zero)
            }
            _ => self.translate_call(Callee::for_unary(op), &[a])?,
        })
    }

    /// Recipe: `Sign` is 1 above zero, -1 below, +0 at either zero and the NaN itself otherwise.
    /// Selecting innermost-first lets the ordered comparisons (false for NaN) fall through to x.
    fn translate_sign(&mut self, a: Value) -> Value {
        let zero = self.constant(0.0f64.to_bits());
        let one = self.constant(1.0f64.to_bits());
        let minus_one = self.constant((-1.0f64).to_bits());
        let is_zero = self.b.ins().fcmp(FloatCC::Equal, a, zero);
        let is_neg = self.b.ins().fcmp(FloatCC::LessThan, a, zero);
        let is_pos = self.b.ins().fcmp(FloatCC::GreaterThan, a, zero);
        let r = self.b.ins().select(is_zero, zero, a);
        let r = self.b.ins().select(is_neg, minus_one, r);
        self.b.ins().select(is_pos, one, r)
    }

    /// Recipe: add, multiply and divide are native; comparisons are ordered `fcmp`s (false on
    /// NaN, like Rust's `<`); `And`/`Or` combine two `!= 0` tests (NaN counts as true, the `!=`
    /// being unordered-or-not-equal); the rest call host wrappers. Min and max are calls because
    /// Cranelift's `fmin`/`fmax` propagate NaN while `f64::min`/`max` do not.
    fn translate_binary(&mut self, op: BinaryOp, a: ExprId, b: ExprId) -> Result<Value, CodegenError> {
        // `a + (-c)` is `a - c` bit for bit (IEEE 754 defines subtraction so), and the
        // simplifier spells every subtraction as an added negation: one `fsub` instead of a
        // sign-mask constant, an `xor` and an `fadd`. The then unused `fneg` is dead code.
        if op == BinaryOp::Add {
            let minuend_subtrahend = match (self.negated(a), self.negated(b)) {
                (_, Some(c)) => Some((a, c)),
                (Some(c), None) => Some((b, c)),
                (None, None) => None,
            };
            if let Some((x, c)) = minuend_subtrahend {
                let (x, c) = (self.value(x), self.value(c));
                return Ok(self.b.ins().fsub(x, c));
            }
        }
        // `x^2` is `x * x` by definition (`apply_binary`): a multiply instead of a libm call,
        // in every kinetic energy, drag and spring law.
        if op == BinaryOp::Pow && self.store.node(b).as_const() == Some(2.0) {
            let x = self.value(a);
            return Ok(self.b.ins().fmul(x, x));
        }
        let (a, b) = (self.value(a), self.value(b));
        Ok(match op {
            BinaryOp::Add => self.b.ins().fadd(a, b),
            BinaryOp::Mul => self.b.ins().fmul(a, b),
            BinaryOp::Div => self.b.ins().fdiv(a, b),
            BinaryOp::Lt => {
                let c = self.b.ins().fcmp(FloatCC::LessThan, a, b);
                self.bool_to_f64(c)
            }
            BinaryOp::Le => {
                let c = self.b.ins().fcmp(FloatCC::LessThanOrEqual, a, b);
                self.bool_to_f64(c)
            }
            BinaryOp::And | BinaryOp::Or => {
                let zero = self.constant(0.0f64.to_bits());
                let ca = self.b.ins().fcmp(FloatCC::NotEqual, a, zero);
                let cb = self.b.ins().fcmp(FloatCC::NotEqual, b, zero);
                let c =
                    if op == BinaryOp::And { self.b.ins().band(ca, cb) } else { self.b.ins().bor(ca, cb) };
                self.bool_to_f64(c)
            }
            _ => self.translate_call(Callee::for_binary(op), &[a, b])?,
        })
    }

    /// The operand of `id` when `id` is a negation.
    fn negated(&self, id: ExprId) -> Option<ExprId> {
        match *self.store.node(id) {
            Node::Unary(UnaryOp::Neg, c) => Some(c),
            _ => None,
        }
    }

    /// Recipe: `Select(c, a, b)` is `a` where `c != 0` (unordered-or-not-equal, so a NaN
    /// condition picks `a`). Both branches are already computed: the DAG is pure.
    fn translate_select(&mut self, c: ExprId, a: ExprId, b: ExprId) -> Value {
        let (c, a, b) = (self.value(c), self.value(a), self.value(b));
        let zero = self.constant(0.0f64.to_bits());
        let cond = self.b.ins().fcmp(FloatCC::NotEqual, c, zero);
        self.b.ins().select(cond, a, b)
    }

    /// Recipe: import the host wrapper into this function on first use, then a plain call.
    fn translate_call(&mut self, callee: Option<Callee>, args: &[Value]) -> Result<Value, CodegenError> {
        let callee = callee.ok_or(CodegenError::Internal {
            reason: "operation without a native lowering or a host wrapper",
        })?;
        let func_ref = match self.imported.get(&callee) {
            Some(&f) => f,
            None => {
                let id = *self
                    .callees
                    .get(&callee)
                    .ok_or(CodegenError::Internal { reason: "host wrapper not declared in the module" })?;
                let f = self.module.declare_func_in_func(id, self.b.func);
                self.imported.insert(callee, f);
                f
            }
        };
        let call = self.b.ins().call(func_ref, args);
        Ok(self.b.inst_results(call)[0])
    }

    /// Recipe: one entry of `f_x S + f_p`: multiply-accumulate over the structurally non-zero
    /// `f_x` entries of the row in ascending column order, then add the `f_p` entry last.
    /// `c s`, and `0` where `s` is exactly 0 when the Jacobian entry `c` can be infinite or NaN at
    /// a finite state: a sensitivity that is zero stays unaffected by a singular derivative (the
    /// drag `c hypot(vx, vy) vx` of a body at rest has the derivative 0/0 in `vx` there, and a
    /// parameter that has not acted yet has zero sensitivities).
    fn translate_sens_product(&mut self, c: ExprId, s: Value) -> Value {
        let value = self.value(c);
        let product = self.b.ins().fmul(value, s);
        let store = self.store;
        if *self.finite.entry(c).or_insert_with(|| crate::expr::finite_at_finite_inputs(store, c)) {
            return product;
        }
        let zero = self.constant(0.0f64.to_bits());
        let is_zero = self.b.ins().fcmp(FloatCC::Equal, s, zero);
        self.b.ins().select(is_zero, zero, product)
    }

    fn translate_sens_dot(
        &mut self,
        products: &[(ExprId, u32)],
        bias: Option<ExprId>,
    ) -> Result<Value, CodegenError> {
        // Negated factors become subtractions, as in `translate_binary`: `sum + (-c) s` is
        // `sum - c s` bit for bit (rounding is symmetric in sign).
        let mut acc: Option<Value> = None;
        for &(a, s_index) in products {
            let s = self.translate_load(Input::S, s_index)?;
            let (factor, negated) = match self.negated(a) {
                Some(c) => (c, true),
                None => (a, false),
            };
            let term = self.translate_sens_product(factor, s);
            acc = Some(match (acc, negated) {
                (Some(sum), true) => self.b.ins().fsub(sum, term),
                (Some(sum), false) => self.b.ins().fadd(sum, term),
                (None, true) => self.b.ins().fneg(term),
                (None, false) => term,
            });
        }
        if let Some(bias) = bias {
            acc = Some(match (acc, self.negated(bias)) {
                (Some(sum), Some(c)) => {
                    let c = self.value(c);
                    self.b.ins().fsub(sum, c)
                }
                (Some(sum), None) => {
                    let bias = self.value(bias);
                    self.b.ins().fadd(sum, bias)
                }
                (None, _) => self.value(bias),
            });
        }
        Ok(match acc {
            Some(v) => v,
            None => self.constant(0.0f64.to_bits()),
        })
    }

    fn bool_to_f64(&mut self, cond: Value) -> Value {
        let one = self.constant(1.0f64.to_bits());
        let zero = self.constant(0.0f64.to_bits());
        self.b.ins().select(cond, one, zero)
    }
}

/// Opens a function's single block, taking the signature's parameters, and returns them.
fn enter_body(b: &mut FunctionBuilder) -> Vec<Value> {
    let block = b.create_block();
    b.append_block_params_for_function_params(block);
    b.switch_to_block(block);
    b.seal_block(block);
    b.block_params(block).to_vec()
}

/// The largest node id a term needs, i.e. the point in the ascending walk where it can be stored.
fn ready_after(term: &Term) -> Option<ExprId> {
    match term {
        Term::Expr(e) => Some(*e),
        Term::Zero => None,
        Term::SensDot { products, bias } => products.iter().map(|&(e, _)| e).chain(*bias).max(),
    }
}

/// The nodes reachable from `roots`, ascending by id: a valid evaluation order because children
/// have smaller ids than their parents.
pub(crate) fn needed_nodes(store: &ExprStore, roots: impl Iterator<Item = ExprId>) -> Vec<ExprId> {
    // A set sized by the kernel, not by the store: a model with many events compiles many small
    // kernels against one large store.
    let mut seen = HashSet::new();
    let mut stack: Vec<ExprId> = roots.collect();
    while let Some(id) = stack.pop() {
        if seen.insert(id) {
            stack.extend(store.node(id).children());
        }
    }
    let mut needed: Vec<ExprId> = seen.into_iter().collect();
    needed.sort_unstable();
    needed
}

/// Byte offset of entry `index` of an f64 array, as Cranelift's 32-bit immediate.
fn byte_offset(index: u32, what: &str) -> Result<i32, CodegenError> {
    i32::try_from(u64::from(index) * 8)
        .map_err(|_| CodegenError::TooLarge { what: what.to_owned(), len: index as usize })
}
