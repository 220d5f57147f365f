//! Stage 3b: checked model -> [`ModelFunctions`]: every model function as a DAG root with all its
//! symbolic derivatives. Knows `sema::Model` and `expr`; knows no spans (beyond ignoring them),
//! no IO and no Cranelift.
//!
//! Derivatives are taken with respect to every state, every parameter and `t`, and only entries
//! that do not simplify to the constant 0 are stored. One [`Differentiator`] is shared by the
//! whole model so Jacobian entries share structure with each other and with the functions.

mod events;
mod interp;
mod report;
mod single;

pub use events::classify_events;
pub use interp::Interpreter;
pub use report::{derive_report, derive_report_only, Only};
pub use single::{ExprPrinter, SHOWN_CHARS};

use std::collections::{HashMap, HashSet};

use crate::expr::eval::reachable;
use crate::expr::{
    BinaryOp, Differentiator, EventFunctions, ExprId, ExprStore, FlowLookup, KnotFunctions, Lookup,
    LookupKind, ModeFunctions, ModelFunctions, Node, SparseMat, SparseVec, UnaryOp, Var,
};
use crate::sema::{self, BinOp, CmpOp, Cond, Expr, Func, InputKind, Model, SharedDef};
use crate::sim::{self, SystemInfo};

/// Lowers every function of `model` and all their derivatives into one store.
pub fn lower(model: &Model) -> ModelFunctions {
    let n_states = model.n_states() as u32;
    let n_params = model.n_params() as u32;
    let mut cx = Lowerer::new(n_states, n_params);

    let init: Vec<ExprId> = model.states.iter().map(|s| cx.expr(&s.init)).collect();
    let init_p = cx.jacobian(&init, Jac::Params);

    let mut modes: Vec<ModeFunctions> = model
        .modes
        .iter()
        .map(|mode| {
            let flow: Vec<ExprId> = mode.flows.iter().map(|f| cx.expr(f)).collect();
            ModeFunctions {
                flow_x: cx.jacobian(&flow, Jac::States),
                flow_p: cx.jacobian(&flow, Jac::Params),
                flow_t: cx.time_derivative(&flow),
                // Filled last (below), so that their new nodes renumber none of the others.
                lookups: Vec::new(),
                flow,
            }
        })
        .collect();

    let events = model
        .events
        .iter()
        .map(|event| {
            let guard = cx.expr(&event.guard);
            let condition = event.condition.as_ref().map(|c| cx.cond(c));
            let mut reset: Vec<ExprId> = (0..n_states).map(|i| cx.store.state(i)).collect();
            for (state, e) in &event.resets {
                let value = cx.expr(e);
                if let Some(slot) = reset.get_mut(state.0 as usize) {
                    *slot = value;
                }
            }
            EventFunctions {
                guard_x: cx.gradient(guard, Jac::States),
                guard_p: cx.gradient(guard, Jac::Params),
                guard_t: cx.diff.diff(&mut cx.store, guard, Var::Time),
                guard,
                condition,
                reset_x: cx.jacobian(&reset, Jac::States),
                reset_p: cx.jacobian(&reset, Jac::Params),
                reset_t: cx.time_derivative(&reset),
                reset,
            }
        })
        .collect();

    // Each mode's input knots: the position the input's value reads (the same node), and its
    // derivatives, from which the integrator times the knots and moves them with the parameters.
    let knots = model
        .modes
        .iter()
        .flat_map(|mode| &mode.inputs)
        .map(|input| {
            let position = cx.expr(&input.position());
            KnotFunctions {
                position_p: cx.gradient(position, Jac::Params),
                position_t: cx.diff.diff(&mut cx.store, position, Var::Time),
                position,
            }
        })
        .collect();

    let outputs: Vec<ExprId> = model.outputs.iter().map(|o| cx.expr(&o.expr)).collect();
    let output_x = cx.jacobian(&outputs, Jac::States);
    let output_p = cx.jacobian(&outputs, Jac::Params);
    let output_t = cx.time_derivative(&outputs);

    for mode in &mut modes {
        mode.lookups = cx.flow_lookups(&mode.flow);
    }

    ModelFunctions {
        store: cx.store,
        n_states,
        n_params,
        modes,
        events,
        knots,
        init,
        init_p,
        outputs,
        output_x,
        output_p,
        output_t,
    }
}

/// The shape of `model` as the integrator sees it, differentiating `grad_params` (sensitivity
/// columns in the order given).
pub fn system_info(model: &Model, grad_params: &[sema::ParamIdx]) -> SystemInfo {
    SystemInfo {
        quadrature: sema::quadrature_states(model),
        state_names: model.states.iter().map(|s| s.name.clone()).collect(),
        output_names: model.outputs.iter().map(|o| o.name.clone()).collect(),
        param_names: model.params.iter().map(|p| p.name.clone()).collect(),
        grad_params: grad_params.iter().map(|p| p.0 as usize).collect(),
        modes: model
            .modes
            .iter()
            .map(|m| sim::ModeInfo {
                name: m.name.clone(),
                events: m.events.iter().map(|e| e.0 as usize).collect(),
            })
            .collect(),
        events: model
            .events
            .iter()
            .map(|e| sim::EventInfo {
                name: e.name.as_str().into(),
                direction: match e.direction {
                    sema::Direction::Falling => sim::Direction::Falling,
                    sema::Direction::Rising => sim::Direction::Rising,
                    sema::Direction::Either => sim::Direction::Either,
                },
                target_mode: e.target.map(|m| m.0 as usize),
                is_stop: e.is_stop,
                has_condition: e.condition.is_some(),
                implicit: e.implicit,
                kink: e.kink,
                // Filled from the lowered functions by `classify_events` (the compiled model and
                // the interpreter call it); until then the cautious defaults.
                guard: sim::GuardShape::Nonlinear,
                contact: false,
            })
            .collect(),
        knots: model
            .modes
            .iter()
            .enumerate()
            .flat_map(|(m, mode)| mode.inputs.iter().map(move |input| (m, input)))
            .map(|(m, input)| {
                let vector =
                    model.vectors.iter().find(|v| v.first == input.first).map_or("?", |v| v.name.as_str());
                sim::KnotSet {
                    name: format!("{}(t, .., {vector})", input.kind.name()).into(),
                    mode: m,
                    jumps: input.kind == InputKind::Pwc,
                    knots: input.knots(),
                }
            })
            .collect(),
        initial_mode: model.initial_mode.0 as usize,
    }
}

/// The parents of each node of `under` (a row's reachable nodes) among them.
fn parents_of(store: &ExprStore, under: &[ExprId]) -> HashMap<ExprId, Vec<ExprId>> {
    let mut parents: HashMap<ExprId, Vec<ExprId>> = HashMap::new();
    for &id in under {
        for c in store.node(id).children() {
            parents.entry(c).or_default().push(id);
        }
    }
    parents
}

/// The nodes that depend on a variable whose leaves are `leaves`: the leaves and everything
/// above them, ascending (the root last), as `Differentiator::diff_along` takes them.
fn path_above(parents: &HashMap<ExprId, Vec<ExprId>>, leaves: Vec<ExprId>) -> Vec<ExprId> {
    let mut seen: HashSet<ExprId> = leaves.iter().copied().collect();
    let mut path = leaves;
    let mut at = 0;
    while at < path.len() {
        for &p in parents.get(&path[at]).map(Vec::as_slice).unwrap_or(&[]) {
            if seen.insert(p) {
                path.push(p);
            }
        }
        at += 1;
    }
    path.sort_unstable();
    path
}

/// Which variables a Jacobian's columns are.
#[derive(Clone, Copy)]
enum Jac {
    States,
    Params,
}

struct Lowerer {
    store: ExprStore,
    diff: Differentiator,
    n_states: u32,
    n_params: u32,
    /// The node of each shared `let` definition lowered so far: a definition is lowered once,
    /// however many uses it has.
    shared: HashMap<*const SharedDef, ExprId>,
}

impl Lowerer {
    fn new(n_states: u32, n_params: u32) -> Lowerer {
        Lowerer {
            store: ExprStore::new(),
            diff: Differentiator::new(),
            n_states,
            n_params,
            shared: HashMap::new(),
        }
    }

    fn vars(&self, jac: Jac) -> (u32, fn(u32) -> Var) {
        match jac {
            Jac::States => (self.n_states, Var::State),
            Jac::Params => (self.n_params, Var::Param),
        }
    }

    /// Structurally non-zero `d rows[i] / d var_k`, ascending by row then column. Only the
    /// variables a row mentions are tried, so the cost follows the number of non-zeros rather
    /// than rows x columns; and each is differentiated along the nodes between its leaf and the
    /// row only (`Differentiator::diff_along`), so a row that reads many variables through one
    /// sum (`sum(u)` of a vector parameter) costs the sum's depth per entry, not its size.
    fn jacobian(&mut self, rows: &[ExprId], jac: Jac) -> SparseMat {
        let (n_cols, var) = self.vars(jac);
        let mut entries = Vec::new();
        for (i, &row) in rows.iter().enumerate() {
            let under = reachable(&self.store, &[row]);
            let parents = parents_of(&self.store, &under);
            let mut mentioned: Vec<(u32, ExprId)> = Vec::new();
            for &id in &under {
                match (*self.store.node(id), jac) {
                    (Node::State(k), Jac::States) | (Node::Param(k), Jac::Params) if k < n_cols => {
                        mentioned.push((k, id))
                    }
                    // A lookup reads its vector's parameters without them being nodes below it:
                    // it is the leaf of each of them.
                    (Node::Lookup(l, _), Jac::Params) => {
                        mentioned.extend((l.base..l.base + l.len).filter(|&k| k < n_cols).map(|k| (k, id)))
                    }
                    _ => {}
                }
            }
            mentioned.sort_unstable();
            let mut at_leaf = 0;
            while at_leaf < mentioned.len() {
                // A variable may have several leaves (a parameter and a lookup reading it).
                let k = mentioned[at_leaf].0;
                let leaves: Vec<ExprId> =
                    mentioned[at_leaf..].iter().take_while(|m| m.0 == k).map(|m| m.1).collect();
                at_leaf += leaves.len();
                let path = path_above(&parents, leaves);
                debug_assert_eq!(path.last(), Some(&row));
                let d =
                    self.diff.diff_along(&mut self.store, &path, var(k)).expect("the leaf is on the path");
                if !self.store.is_zero(d) {
                    entries.push((i as u32, k, d));
                }
            }
        }
        SparseMat { n_rows: rows.len() as u32, n_cols, entries }
    }

    /// The lookups of `flow` whose vectors it reads through lookups only, each with the flow's
    /// derivative with respect to its value (`ModeFunctions::lookups`). A vector is read through
    /// lookups only when none of its elements is a `Param` node under the flow (`sum`, `dot`, an
    /// element written out, a knot window made of its elements) and no lookup of another range
    /// overlaps it (sema makes none: a lookup reads a whole vector).
    fn flow_lookups(&mut self, flow: &[ExprId]) -> Vec<FlowLookup> {
        let under = reachable(&self.store, flow);
        let mut read = HashSet::new();
        let mut lookups = Vec::new();
        for &id in &under {
            match *self.store.node(id) {
                Node::Param(i) => {
                    read.insert(i);
                }
                Node::Lookup(l, pos) => lookups.push((id, l, pos)),
                _ => {}
            }
        }
        let range = |l: &Lookup| l.base..l.base + l.len;
        let only_looked_up = |l: &Lookup| {
            range(l).all(|i| !read.contains(&i))
                && lookups.iter().all(|(_, o, _)| {
                    (o.base, o.len) == (l.base, l.len) || o.base >= l.base + l.len || l.base >= o.base + o.len
                })
        };
        let chosen: Vec<(ExprId, Lookup, ExprId)> =
            lookups.iter().filter(|(_, l, _)| only_looked_up(l)).copied().collect();
        let mut flow_l = vec![Vec::new(); chosen.len()];
        if !chosen.is_empty() {
            for (i, &row) in flow.iter().enumerate() {
                let under = reachable(&self.store, &[row]);
                let parents = parents_of(&self.store, &under);
                for (q, &(node, _, _)) in chosen.iter().enumerate() {
                    if under.binary_search(&node).is_err() {
                        continue;
                    }
                    // Along the nodes above the lookup only, as `jacobian` differentiates.
                    let path = path_above(&parents, vec![node]);
                    let d = self
                        .diff
                        .diff_along(&mut self.store, &path, Var::Node(node))
                        .expect("the lookup is on the path");
                    if !self.store.is_zero(d) {
                        flow_l[q].push((i as u32, d));
                    }
                }
            }
        }
        chosen
            .into_iter()
            .zip(flow_l)
            .filter(|(_, entries)| !entries.is_empty())
            .map(|((node, lookup, position), entries)| FlowLookup {
                node,
                lookup,
                position,
                flow_l: SparseVec { entries },
            })
            .collect()
    }

    fn gradient(&mut self, f: ExprId, jac: Jac) -> SparseVec {
        let m = self.jacobian(&[f], jac);
        SparseVec { entries: m.entries.into_iter().map(|(_, k, d)| (k, d)).collect() }
    }

    fn time_derivative(&mut self, rows: &[ExprId]) -> SparseVec {
        let mut entries = Vec::new();
        for (i, &row) in rows.iter().enumerate() {
            let d = self.diff.diff(&mut self.store, row, Var::Time);
            if !self.store.is_zero(d) {
                entries.push((i as u32, d));
            }
        }
        SparseVec { entries }
    }

    fn expr(&mut self, e: &Expr) -> ExprId {
        match e {
            Expr::Num(v) => self.store.constant(*v),
            Expr::State(i) => self.store.state(i.0),
            Expr::Param(i) => self.store.param(i.0),
            Expr::Time => self.store.time(),
            Expr::Shared(s) => {
                if let Some(&id) = self.shared.get(&s.key()) {
                    return id;
                }
                let id = crate::stack::deep(|| self.expr(s.expr()));
                self.shared.insert(s.key(), id);
                id
            }
            Expr::Neg(a) => {
                let a = self.expr(a);
                self.store.neg(a)
            }
            Expr::Binary(op, a, b) => {
                let (a, b) = (self.expr(a), self.expr(b));
                match op {
                    BinOp::Add => self.store.add(a, b),
                    BinOp::Sub => self.store.sub(a, b),
                    BinOp::Mul => self.store.mul(a, b),
                    BinOp::Div => self.store.div(a, b),
                    BinOp::Pow => self.store.pow(a, b),
                }
            }
            Expr::Call(func, args) => self.call(*func, args),
            Expr::Input(input) => {
                let pos = self.expr(&input.position());
                let kind = match input.kind {
                    InputKind::Pwl => LookupKind::Pwl,
                    InputKind::Pwc => LookupKind::Pwc,
                };
                self.store.lookup(Lookup { kind, base: input.first.0, len: input.len }, pos)
            }
            Expr::If(c, a, b) => {
                let c = self.cond(c);
                let (a, b) = (self.expr(a), self.expr(b));
                self.store.select(c, a, b)
            }
        }
    }

    /// A function call. `sema` checks arities; a missing argument (never produced by `sema`)
    /// reads as 0 rather than panicking.
    fn call(&mut self, func: Func, args: &[Expr]) -> ExprId {
        let arg = |cx: &mut Self, k: usize| match args.get(k) {
            Some(e) => cx.expr(e),
            None => cx.store.zero(),
        };
        let unary = match func {
            Func::Sin => Some(UnaryOp::Sin),
            Func::Cos => Some(UnaryOp::Cos),
            Func::Tan => Some(UnaryOp::Tan),
            Func::Asin => Some(UnaryOp::Asin),
            Func::Acos => Some(UnaryOp::Acos),
            Func::Atan => Some(UnaryOp::Atan),
            Func::Sinh => Some(UnaryOp::Sinh),
            Func::Cosh => Some(UnaryOp::Cosh),
            Func::Tanh => Some(UnaryOp::Tanh),
            Func::Exp => Some(UnaryOp::Exp),
            Func::Log => Some(UnaryOp::Log),
            Func::Sqrt => Some(UnaryOp::Sqrt),
            Func::Abs => Some(UnaryOp::Abs),
            Func::Sign => Some(UnaryOp::Sign),
            Func::Atan2 | Func::Min | Func::Max | Func::Pow | Func::Hypot => None,
        };
        if let Some(op) = unary {
            let a = arg(self, 0);
            return self.store.unary(op, a);
        }
        let op = match func {
            Func::Atan2 => BinaryOp::Atan2,
            Func::Min => BinaryOp::Min,
            Func::Max => BinaryOp::Max,
            Func::Hypot => BinaryOp::Hypot,
            _ => BinaryOp::Pow,
        };
        let a = arg(self, 0);
        let b = arg(self, 1);
        self.store.binary(op, a, b)
    }

    fn cond(&mut self, c: &Cond) -> ExprId {
        match c {
            Cond::Cmp(op, a, b) => {
                let (a, b) = (self.expr(a), self.expr(b));
                match op {
                    CmpOp::Lt => self.store.lt(a, b),
                    CmpOp::Le => self.store.le(a, b),
                    CmpOp::Gt => self.store.gt(a, b),
                    CmpOp::Ge => self.store.ge(a, b),
                }
            }
            Cond::And(a, b) => {
                let (a, b) = (self.cond(a), self.cond(b));
                self.store.and(a, b)
            }
            Cond::Or(a, b) => {
                let (a, b) = (self.cond(a), self.cond(b));
                self.store.or(a, b)
            }
            Cond::Not(a) => {
                let a = self.cond(a);
                self.store.not(a)
            }
        }
    }
}

#[cfg(test)]
mod tests;
