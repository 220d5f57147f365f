//! AST -> checked [`Model`]: builds the scopes, resolves every name, shares `let`s and runs every
//! semantic check, collecting all errors instead of stopping at the first.

use std::collections::HashMap;

use super::error::CheckError;
use super::model::*;
use super::names::{resolve_all_lets, resolve_names, Binding, ScopeId, Scopes};
use super::switches::add_flow_switches;
use crate::syntax::ast;
use crate::syntax::Span;

/// Checks a parsed file. Returns the model, or every error found.
pub fn check(original: &ast::File) -> Result<Model, Vec<CheckError>> {
    // Arrays, constants and loops become a flat file first; a file without them is used as is.
    let file = crate::expand::expand(original)
        .map_err(|errors| errors.into_iter().map(|e| CheckError::Expand(Box::new(e))).collect::<Vec<_>>())?;
    let flattened = matches!(file, std::borrow::Cow::Owned(_));
    let file = &*file;
    let mut cx = Checker::default();
    let mut model = cx.check_file(file);
    for event in &model.events {
        if super::switches::jumps(&event.guard) {
            cx.errors.push(CheckError::DiscontinuousGuard { event: event.name.clone(), span: event.span });
        } else if super::switches::reads_pwc(&event.guard) {
            cx.errors.push(CheckError::PwcInGuard { event: event.name.clone(), span: event.span });
        }
    }
    if cx.errors.is_empty() {
        add_flow_switches(&mut model);
        Ok(model)
    } else {
        cx.errors.sort_by_key(|e| e.span().start);
        // An item unrolled from a loop repeats its errors once per iteration, at one span.
        cx.errors.dedup_by(|a, b| a.span() == b.span() && a.to_string() == b.to_string());
        if flattened {
            name_loop_values(original, &mut cx.errors);
        }
        Err(cx.errors)
    }
}

/// Each error in an item unrolled from a loop, with the loop values where it first arose.
fn name_loop_values(original: &ast::File, errors: &mut [CheckError]) {
    let found: Vec<(Span, String)> = errors.iter().map(|e| (e.span(), e.to_string())).collect();
    let sites = crate::expand::loop_sites(original, &found);
    for (e, site) in errors.iter_mut().zip(sites) {
        if let Some(site) = site {
            let error = Box::new(std::mem::replace(e, CheckError::NoInitialMode { span: Span::new(0, 0) }));
            *e = CheckError::InLoop { error, at: site.at, within: site.within };
        }
    }
}

#[derive(Default)]
struct Checker<'a> {
    errors: Vec<CheckError>,
    scopes: Scopes<'a>,
}

/// An event as declared, before its parts are resolved.
struct PendingEvent<'a> {
    decl: &'a ast::EventDecl,
    owner: Option<ModeId>,
    scope: ScopeId,
}

impl<'a> Checker<'a> {
    fn check_file(&mut self, file: &'a ast::File) -> Model {
        let global = ScopeId::GLOBAL;
        let mut params = Vec::new();
        let mut vectors = Vec::new();
        let mut states: Vec<(&ast::StateDecl, StateIdx)> = Vec::new();
        let mut mode_decls: Vec<&ast::ModeDecl> = Vec::new();
        let mut top_flows: Vec<&ast::DerEq> = Vec::new();
        let mut outputs: Vec<&ast::OutputDecl> = Vec::new();
        let mut events: Vec<PendingEvent> = Vec::new();
        let mut simulate = SimulateDefaults { t_end: None, rtol: None, atol: None };
        let mut simulate_span: Option<Span> = None;
        let mut output_names: HashMap<&str, Span> = HashMap::new();
        let mut mode_scopes: Vec<ScopeId> = Vec::new();

        // Pass 1: declare every name, so that order of declaration does not matter.
        for item in &file.items {
            match item {
                ast::Item::Param(p) => self.declare_param(p, &mut params, &mut vectors),
                ast::Item::State(s) => {
                    let idx = StateIdx(states.len() as u32);
                    self.scopes.push_state_name(&s.name.name);
                    self.declare(global, &s.name, Binding::State(idx), "state");
                    states.push((s, idx));
                }
                ast::Item::Let(l) => self.declare_let(global, l),
                ast::Item::Der(d) => top_flows.push(d),
                ast::Item::Output(o) => {
                    self.check_reserved(&o.name);
                    if let Some(&first) = output_names.get(o.name.name.as_str()) {
                        self.errors.push(CheckError::Duplicate {
                            name: o.name.name.clone(),
                            what: "output",
                            span: o.name.span,
                            first,
                        });
                    } else {
                        output_names.insert(&o.name.name, o.name.span);
                    }
                    outputs.push(o);
                }
                ast::Item::Event(e) => events.push(PendingEvent { decl: e, owner: None, scope: global }),
                ast::Item::Mode(m) => {
                    let id = ModeId(mode_decls.len() as u16);
                    let scope = self.scopes.child(global);
                    mode_scopes.push(scope);
                    for mi in &m.items {
                        match mi {
                            ast::ModeItem::Let(l) => self.declare_let(scope, l),
                            ast::ModeItem::Event(e) => {
                                events.push(PendingEvent { decl: e, owner: Some(id), scope })
                            }
                            ast::ModeItem::Der(_) => {}
                        }
                    }
                    mode_decls.push(m);
                }
                // `expand` has unrolled every loop and evaluated every constant.
                ast::Item::Const(_) | ast::Item::For(_) => {}
                ast::Item::Simulate(s) => {
                    if let Some(first) = simulate_span {
                        self.errors.push(CheckError::Duplicate {
                            name: "simulate".into(),
                            what: "simulate statement",
                            span: s.span,
                            first,
                        });
                    }
                    simulate_span = Some(s.span);
                    self.check_simulate(s, &mut simulate);
                }
            }
        }
        if states.is_empty() {
            self.errors.push(CheckError::EmptyModel { name: file.model.name.clone(), span: file.model.span });
        }

        // Modes: names, the initial one, and the flows of each.
        let mode_names = self.check_mode_names(&mode_decls);
        let initial_mode = self.find_initial_mode(&mode_decls, file.model.span);
        let n_states = states.len();
        let top_flow_slots = self.collect_flows(&top_flows, n_states, "every mode", None);
        let mut modes = Vec::new();
        if mode_decls.is_empty() {
            modes.push(self.build_mode("main", file.model.span, &top_flow_slots, &[], global));
        } else {
            for (k, m) in mode_decls.iter().enumerate() {
                let ders: Vec<&ast::DerEq> = m
                    .items
                    .iter()
                    .filter_map(|i| if let ast::ModeItem::Der(d) = i { Some(d) } else { None })
                    .collect();
                let scope = mode_scopes[k];
                modes.push(self.build_mode(&m.name.name, m.name.span, &top_flow_slots, &ders, scope));
            }
        }

        // Events, in declaration order.
        let mut checked_events = Vec::new();
        for (k, pe) in events.iter().enumerate() {
            let event = self.check_event(pe, &mode_names);
            let idx = EventIdx(k as u32);
            match pe.owner {
                Some(m) => modes[m.0 as usize].events.push(idx),
                None => modes.iter_mut().for_each(|m| m.events.push(idx)),
            }
            checked_events.push(event);
        }
        for m in &mut modes {
            m.events.sort();
        }
        resolve_all_lets(&mut self.scopes, &mut self.errors);

        let states = states
            .iter()
            .map(|(s, _)| State { name: s.name.name.clone(), init: self.resolve_init(s), span: s.span })
            .collect();
        let outputs = outputs
            .iter()
            .map(|o| Output { name: o.name.name.clone(), expr: self.resolve(&o.value, global), span: o.span })
            .collect();

        Model {
            name: file.model.name.clone(),
            params,
            vectors,
            states,
            modes,
            initial_mode,
            events: checked_events,
            outputs,
            simulate,
        }
    }

    fn check_reserved(&mut self, name: &ast::Ident) -> bool {
        let reserved = name.name == "t"
            || name.name == "pi"
            || Func::from_name(&name.name).is_some()
            || VectorFunc::from_name(&name.name).is_some()
            || InputKind::from_name(&name.name).is_some();
        if reserved {
            self.errors.push(CheckError::Reserved { name: name.name.clone(), span: name.span });
        }
        reserved
    }

    fn declare(&mut self, scope: ScopeId, name: &'a ast::Ident, binding: Binding, what: &'static str) {
        if self.check_reserved(name) {
            return;
        }
        if let Some((first, first_what)) = self.scopes.lookup_decl(scope, &name.name) {
            self.errors.push(CheckError::Duplicate {
                name: name.name.clone(),
                what: first_what,
                span: name.span,
                first,
            });
            return;
        }
        self.scopes.insert(scope, name, binding, what);
    }

    fn declare_let(&mut self, scope: ScopeId, decl: &'a ast::LetDecl) {
        let id = self.scopes.add_let(decl, scope);
        self.declare(scope, &decl.name, Binding::Let(id), "let");
    }

    /// Declares a scalar parameter, or a vector's `len` elements (consecutive indices, named
    /// `u[0]` ..) and the vector's name, which only `u[k]`, `sum` and `dot` may use. A length out of
    /// bounds, or one that would pass `MAX_PARAMS`, is reported and the name declared with no
    /// elements, so its uses raise no further errors.
    fn declare_param(
        &mut self,
        p: &'a ast::ParamDecl,
        params: &mut Vec<Param>,
        vectors: &mut Vec<ParamVector>,
    ) {
        let first = ParamIdx(params.len() as u32);
        let param = self.check_param(p);
        let Some(size) = &p.size else {
            if params.len() >= MAX_PARAMS {
                self.too_many_params(p.name.span);
                // Declared without elements, so its uses raise no further errors.
                self.declare(ScopeId::GLOBAL, &p.name, Binding::Vector { first, len: 0 }, "parameter");
                return;
            }
            self.declare(ScopeId::GLOBAL, &p.name, Binding::Param(first), "parameter");
            params.push(param);
            return;
        };
        let mut len = 0;
        if size.len == 0 || size.len > MAX_PARAMS as u64 {
            self.errors.push(CheckError::BadVectorLength {
                name: p.name.name.clone(),
                len: size.text.clone(),
                span: size.span,
            });
        } else if params.len() + size.len as usize > MAX_PARAMS {
            self.too_many_params(size.span);
        } else {
            len = size.len as u32;
        }
        self.declare(ScopeId::GLOBAL, &p.name, Binding::Vector { first, len }, "vector parameter");
        params.extend((0..len).map(|k| Param { name: element_name(&param.name, k), ..param.clone() }));
        vectors.push(ParamVector { name: param.name, first, len, span: p.span });
    }

    /// Reported once: every later declaration would repeat it.
    fn too_many_params(&mut self, span: Span) {
        if !self.errors.iter().any(|e| matches!(e, CheckError::TooManyParams { .. })) {
            self.errors.push(CheckError::TooManyParams { span });
        }
    }

    fn check_param(&mut self, p: &ast::ParamDecl) -> Param {
        let default = p.default.value;
        let range = p.range.as_ref().map(|r| (r.lo.value, r.hi.value));
        if let (Some((lo, hi)), Some(r)) = (range, &p.range) {
            if lo > hi {
                self.errors.push(CheckError::EmptyRange { lo, hi, span: r.span });
            } else if !(lo..=hi).contains(&default) {
                self.errors.push(CheckError::RangeExcludesDefault {
                    name: p.name.name.clone(),
                    default,
                    lo,
                    hi,
                    span: p.default.span,
                });
            }
        }
        Param { name: p.name.name.clone(), default, range, span: p.span }
    }

    fn check_simulate(&mut self, s: &ast::SimulateDecl, out: &mut SimulateDefaults) {
        let mut seen: Vec<(&str, Span)> = Vec::new();
        for setting in &s.settings {
            let v = setting.value.value;
            let name = setting.name.name.as_str();
            if let Some(&(_, first)) = seen.iter().find(|(n, _)| *n == name) {
                self.errors.push(CheckError::DuplicateSetting {
                    name: name.to_string(),
                    span: setting.name.span,
                    first,
                });
                continue;
            }
            seen.push((name, setting.name.span));
            let slot = match setting.name.name.as_str() {
                "t_end" => &mut out.t_end,
                "rtol" => &mut out.rtol,
                "atol" => &mut out.atol,
                other => {
                    self.errors.push(CheckError::UnknownSetting {
                        name: other.to_string(),
                        span: setting.name.span,
                    });
                    continue;
                }
            };
            if v <= 0.0 || (setting.name.name == "rtol" && v >= 1.0) {
                self.errors.push(CheckError::BadSetting {
                    name: setting.name.name.clone(),
                    value: v,
                    expected: if setting.name.name == "rtol" {
                        "a number in (0, 1)"
                    } else {
                        "a positive number"
                    },
                    span: setting.value.span,
                });
            }
            *slot = Some(v);
        }
    }

    fn check_mode_names(&mut self, modes: &[&ast::ModeDecl]) -> HashMap<String, ModeId> {
        let mut names: HashMap<String, ModeId> = HashMap::new();
        for (k, m) in modes.iter().enumerate() {
            if let Some(first) = names.get(&m.name.name) {
                self.errors.push(CheckError::Duplicate {
                    name: m.name.name.clone(),
                    what: "mode",
                    span: m.name.span,
                    first: modes[first.0 as usize].name.span,
                });
            } else {
                names.insert(m.name.name.clone(), ModeId(k as u16));
            }
        }
        names
    }

    fn find_initial_mode(&mut self, modes: &[&ast::ModeDecl], model_span: Span) -> ModeId {
        let mut initial: Option<usize> = None;
        for (k, m) in modes.iter().enumerate() {
            if !m.is_initial {
                continue;
            }
            match initial {
                Some(first) => self.errors.push(CheckError::SecondInitialMode {
                    name: m.name.name.clone(),
                    span: m.name.span,
                    first: modes[first].name.span,
                }),
                None => initial = Some(k),
            }
        }
        if !modes.is_empty() && initial.is_none() {
            self.errors.push(CheckError::NoInitialMode { span: model_span });
        }
        ModeId(initial.unwrap_or(0) as u16)
    }

    /// Assigns flow equations to state slots, reporting unknown targets and duplicates.
    fn collect_flows(
        &mut self,
        ders: &[&'a ast::DerEq],
        n_states: usize,
        mode_name: &str,
        base: Option<&[Option<&'a ast::DerEq>]>,
    ) -> Vec<Option<&'a ast::DerEq>> {
        let mut slots: Vec<Option<&ast::DerEq>> = match base {
            Some(b) => b.to_vec(),
            None => vec![None; n_states],
        };
        for d in ders {
            let Some(idx) = self.expect_state(&d.state, ScopeId::GLOBAL) else { continue };
            let slot = &mut slots[idx.0 as usize];
            if let Some(first) = slot {
                self.errors.push(CheckError::DuplicateFlow {
                    state: d.state.name.clone(),
                    mode: mode_name.to_string(),
                    span: d.state.span,
                    first: first.state.span,
                });
            } else {
                *slot = Some(d);
            }
        }
        slots
    }

    fn build_mode(
        &mut self,
        name: &str,
        span: Span,
        top: &[Option<&'a ast::DerEq>],
        own: &[&'a ast::DerEq],
        scope: ScopeId,
    ) -> Mode {
        let slots = self.collect_flows(own, top.len(), name, Some(top));
        let mut flows = Vec::with_capacity(slots.len());
        for (i, slot) in slots.iter().enumerate() {
            match slot {
                Some(d) => {
                    // Model-level flows resolve in the model scope, a mode's own in the mode's.
                    let is_own = own.iter().any(|o| std::ptr::eq(*o, *d));
                    flows.push(self.resolve(&d.rhs, if is_own { scope } else { ScopeId::GLOBAL }));
                }
                None => {
                    self.errors.push(CheckError::MissingFlow {
                        state: self.scopes.state_name(i).to_string(),
                        mode: name.to_string(),
                        span,
                    });
                    flows.push(Expr::Num(0.0));
                }
            }
        }
        Mode { name: name.to_string(), flows, events: Vec::new(), inputs: Vec::new(), span }
    }

    fn expect_state(&mut self, name: &ast::Ident, scope: ScopeId) -> Option<StateIdx> {
        match self.scopes.lookup(scope, &name.name) {
            Some(Binding::State(i)) => Some(i),
            Some(other) => {
                self.errors.push(CheckError::WrongKind {
                    name: name.name.clone(),
                    found: other.kind_name(),
                    expected: "state",
                    span: name.span,
                });
                None
            }
            None => {
                let suggestion = self.scopes.suggest_state(&name.name);
                self.errors.push(CheckError::UnknownName {
                    name: name.name.clone(),
                    span: name.span,
                    suggestion,
                });
                None
            }
        }
    }

    fn check_event(&mut self, pe: &PendingEvent<'a>, mode_names: &HashMap<String, ModeId>) -> Event {
        let d = pe.decl;
        let lhs = self.resolve(&d.lhs, pe.scope);
        let rhs = self.resolve(&d.rhs, pe.scope);
        let guard = Expr::Binary(BinOp::Sub, Box::new(lhs), Box::new(rhs));
        let direction = match d.op {
            ast::GuardOp::Le | ast::GuardOp::Lt => Direction::Falling,
            ast::GuardOp::Ge | ast::GuardOp::Gt => Direction::Rising,
            ast::GuardOp::Crosses => Direction::Either,
        };
        let condition = d.condition.as_ref().map(|c| self.resolve_cond(c, pe.scope));
        let target = d.target.as_ref().and_then(|t| match mode_names.get(&t.name) {
            Some(&m) => Some(m),
            None => {
                let suggestion = super::names::closest(&t.name, mode_names.keys().map(String::as_str));
                self.errors.push(CheckError::UnknownMode { name: t.name.clone(), span: t.span, suggestion });
                None
            }
        });
        // The event's own `let`s are visible in its resets only.
        let scope = self.scopes.child(pe.scope);
        for s in &d.body {
            if let ast::EventStmt::Let(l) = s {
                self.declare_let(scope, l);
            }
        }
        let mut resets: Vec<(StateIdx, Expr)> = Vec::new();
        let mut first_reset: HashMap<StateIdx, Span> = HashMap::new();
        let mut is_stop = false;
        for s in &d.body {
            match s {
                ast::EventStmt::Reset { state, value, .. } => {
                    let value = self.resolve(value, scope);
                    let Some(idx) = self.expect_state(state, scope) else { continue };
                    if let Some(&first) = first_reset.get(&idx) {
                        self.errors.push(CheckError::DoubleReset {
                            state: state.name.clone(),
                            event: d.name.name.clone(),
                            span: state.span,
                            first,
                        });
                        continue;
                    }
                    first_reset.insert(idx, state.span);
                    resets.push((idx, value));
                }
                ast::EventStmt::Let(_) => {}
                ast::EventStmt::Stop { .. } => is_stop = true,
            }
        }
        resets.sort_by_key(|(i, _)| *i);
        Event {
            name: d.name.name.clone(),
            guard,
            direction,
            condition,
            resets,
            target,
            is_stop,
            owner: pe.owner,
            span: d.name.span,
            implicit: false,
            kink: false,
        }
    }

    fn resolve(&mut self, e: &ast::Expr, scope: ScopeId) -> Expr {
        resolve_names(&mut self.scopes, &mut self.errors, e, scope)
    }

    fn resolve_cond(&mut self, c: &ast::Cond, scope: ScopeId) -> Cond {
        super::names::resolve_cond(&mut self.scopes, &mut self.errors, c, scope)
    }

    /// Initial values may use parameters (directly or through `let`s) but not `t` or states.
    fn resolve_init(&mut self, s: &ast::StateDecl) -> Expr {
        let expr = self.resolve(&s.init, ScopeId::GLOBAL);
        if let Some(what) = self.scopes.non_constant(&expr) {
            self.errors.push(CheckError::InitNotConstant {
                state: s.name.name.clone(),
                what,
                span: s.init.span,
            });
        }
        expr
    }
}
