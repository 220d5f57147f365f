//! [`Sbml`] -> `.hyb` text. Each SBML symbol gets a storage ([`Storage`]): a `param` (a constant
//! with a number), a `let` of parameters (a constant with an initial assignment), a `let` of the
//! state (an assignment rule), a `state` (anything a reaction, a rate rule or an event changes;
//! a species in concentration whose compartment changes is kept as its amount, with the
//! concentration a `let`), or a reaction's rate (a `let`). Names read in an initial value mean
//! the symbol's value at the start (`x_init` lets, made on demand); names elsewhere its value at
//! `t`.

use std::collections::{BTreeMap, HashMap, HashSet};

use roxmltree::Node;

use super::error::Refusal;
use super::math::{Math, Op};
use super::names::Names;
use super::print::{self, Scope};
use super::read::{Sbml, Stoichiometry};
use super::xml::Xml;

/// Which SBML component a symbol is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kind {
    Compartment(usize),
    Species(usize),
    Parameter(usize),
    /// A species reference with an id (Level 3): reaction, product?, index.
    SpeciesRef(usize, bool, usize),
    Reaction(usize),
}

/// How a symbol is held in the `.hyb` model.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Storage {
    /// `param NAME = value`.
    Param(f64),
    /// `let NAME = <initial value>`: constant, computed from parameters.
    Const,
    /// `let NAME = <assignment rule>`.
    Rule,
    /// `state NAME`.
    State,
    /// A species in concentration in a compartment that changes: `state AMOUNT` and
    /// `let NAME = AMOUNT / compartment`.
    Amount(String),
    /// A reaction: `let NAME = <kinetic law>`.
    Reaction,
}

/// A symbol of the model.
pub(super) struct Symbol<'a, 'i> {
    pub kind: Kind,
    pub storage: Storage,
    /// The `.hyb` name of the symbol's value.
    pub name: String,
    pub node: Node<'a, 'i>,
}

/// The translation's state: the symbols, names, the `let`s made along the way, refusals.
pub(super) struct Tr<'s, 'a, 'i> {
    pub xml: &'s Xml<'i>,
    pub sbml: &'s Sbml<'a, 'i>,
    pub names: Names,
    pub syms: HashMap<String, Symbol<'a, 'i>>,
    pub ia: HashMap<String, &'s Math>,
    pub rule: HashMap<String, &'s Math>,
    pub rate: HashMap<String, &'s Math>,
    /// Each state's flow (SBML ids), computed before anything is printed (`rateOf` reads them).
    pub flows: HashMap<String, Math>,
    /// `x_init` names made so far, and those still to declare.
    init_names: HashMap<String, String>,
    init_todo: Vec<String>,
    /// `x_rate` names of the states `rateOf` reads.
    rate_names: BTreeMap<String, String>,
    /// `let` lines hoisted out of long expressions, in order.
    pub lets: Vec<String>,
    pub out: Vec<Refusal>,
}

/// Where names are read: at `t` (with a reaction's local parameters) or at the start.
pub(super) struct Dynamic<'t, 's, 'a, 'i> {
    pub tr: &'t mut Tr<'s, 'a, 'i>,
    pub locals: Option<&'t HashMap<String, String>>,
}

pub(super) struct Initial<'t, 's, 'a, 'i> {
    pub tr: &'t mut Tr<'s, 'a, 'i>,
    pub locals: Option<&'t HashMap<String, String>>,
}

impl Scope for Dynamic<'_, '_, '_, '_> {
    fn name(&mut self, id: &str) -> Result<String, String> {
        if let Some(n) = self.locals.and_then(|l| l.get(id)) {
            return Ok(n.clone());
        }
        self.tr.syms.get(id).map(|s| s.name.clone()).ok_or_else(|| format!("unknown identifier `{id}`"))
    }
    fn time(&mut self) -> Result<String, String> {
        Ok("t".to_string())
    }
    fn rate_of(&mut self, id: &str) -> Result<String, String> {
        // A reaction's local parameter (or an event's held value) shadows the model's symbol
        // and does not change: its rate is 0 (the suite's 01460).
        if self.locals.is_some_and(|l| l.contains_key(id)) {
            return Ok("0".to_string());
        }
        let sym = self.tr.syms.get(id).ok_or_else(|| format!("rateOf of unknown identifier `{id}`"))?;
        match &sym.storage {
            Storage::Param(_) | Storage::Const => Ok("0".to_string()),
            Storage::State if self.tr.flows.contains_key(id) => {
                if let Some(n) = self.tr.rate_names.get(id) {
                    return Ok(n.clone());
                }
                let n = self.tr.names.fresh(&format!("{}_rate", sym.name));
                self.tr.rate_names.insert(id.to_string(), n.clone());
                Ok(n)
            }
            _ => Err(format!("rateOf(`{id}`): its rate is not a flow hybc integrates (an assignment rule or a species kept as its amount)")),
        }
    }
    fn hoist(&mut self, text: String) -> String {
        self.tr.hoist(text)
    }
}

impl Scope for Initial<'_, '_, '_, '_> {
    fn name(&mut self, id: &str) -> Result<String, String> {
        if let Some(n) = self.locals.and_then(|l| l.get(id)) {
            return Ok(n.clone());
        }
        let tr = &mut *self.tr;
        let sym = tr.syms.get(id).ok_or_else(|| format!("unknown identifier `{id}`"))?;
        match sym.storage {
            Storage::Param(_) | Storage::Const => Ok(sym.name.clone()),
            _ => Ok(tr.init_name(id)),
        }
    }
    fn time(&mut self) -> Result<String, String> {
        // SBML's initial values hold at time 0.
        Ok("0".to_string())
    }
    fn rate_of(&mut self, id: &str) -> Result<String, String> {
        Err(format!("rateOf(`{id}`) in an initial value is not supported"))
    }
    fn hoist(&mut self, text: String) -> String {
        self.tr.hoist(text)
    }
}

impl<'s, 'a, 'i> Tr<'s, 'a, 'i> {
    fn hoist(&mut self, text: String) -> String {
        let name = self.names.fresh("aux");
        self.lets.push(format!("let {name} = {text}"));
        name
    }

    /// The name of `id`'s value at the start, declared (later) as a `let`.
    fn init_name(&mut self, id: &str) -> String {
        if let Some(n) = self.init_names.get(id) {
            return n.clone();
        }
        let base = format!("{}_init", self.syms[id].name);
        let n = self.names.fresh(&base);
        self.init_names.insert(id.to_string(), n.clone());
        self.init_todo.push(id.to_string());
        n
    }

    /// A refusal at `node`.
    pub fn refuse(&mut self, node: Node<'_, '_>, reason: impl Into<String>) {
        let r = self.xml.refuse(node, reason);
        self.out.push(r);
    }

    /// `m` printed at `t`, or `None` after a refusal at `node`.
    pub fn dynamic(
        &mut self,
        m: &Math,
        node: Node<'_, '_>,
        locals: Option<&HashMap<String, String>>,
    ) -> Option<String> {
        let r = print::num(m, &mut Dynamic { tr: self, locals });
        self.settle(r.map(|t| t.s), node)
    }

    /// The condition `m` printed at `t`, or `None` after a refusal at `node`.
    pub fn condition(&mut self, m: &Math, node: Node<'_, '_>) -> Option<String> {
        let r = print::cond(m, &mut Dynamic { tr: self, locals: None });
        self.settle(r.map(|t| t.s), node)
    }

    /// `m` printed at the start, or `None` after a refusal at `node`.
    pub fn initial(
        &mut self,
        m: &Math,
        node: Node<'_, '_>,
        locals: Option<&HashMap<String, String>>,
    ) -> Option<String> {
        let r = print::num(m, &mut Initial { tr: self, locals });
        self.settle(r.map(|t| t.s), node)
    }

    fn settle(&mut self, r: Result<String, String>, node: Node<'_, '_>) -> Option<String> {
        match r {
            Ok(s) => Some(s),
            Err(reason) => {
                self.refuse(node, reason);
                None
            }
        }
    }

    /// The SBML value of `id` at the start, as math over other symbols' starting values.
    fn init_math(&self, id: &str) -> Result<Math, String> {
        if let Some(m) = self.ia.get(id) {
            return Ok((*m).clone());
        }
        if let Some(m) = self.rule.get(id) {
            return Ok((*m).clone());
        }
        let sbml = self.sbml;
        match self.syms[id].kind {
            Kind::Compartment(i) => sbml.compartments[i]
                .size
                .map(Math::Num)
                .ok_or_else(|| format!("compartment `{id}` has no size")),
            Kind::Parameter(i) => sbml.parameters[i]
                .value
                .map(Math::Num)
                .ok_or_else(|| format!("parameter `{id}` has no value")),
            Kind::SpeciesRef(r, p, k) => {
                let refs = if p { &sbml.reactions[r].products } else { &sbml.reactions[r].reactants };
                refs[k]
                    .value
                    .map(Math::Num)
                    .ok_or_else(|| format!("species reference `{id}` has no stoichiometry"))
            }
            Kind::Reaction(i) => sbml.reactions[i]
                .law
                .as_ref()
                .map(|(_, m)| m.clone())
                .ok_or_else(|| format!("reaction `{id}` has no kinetic law")),
            Kind::Species(i) => {
                let s = &sbml.species[i];
                let c = Math::Ci(s.compartment.clone());
                match (s.only_substance, s.initial_amount, s.initial_concentration) {
                    (true, Some(a), _) | (false, None, Some(a)) => Ok(Math::Num(a)),
                    (true, None, Some(x)) => Ok(Math::Apply(Op::Times, vec![Math::Num(x), c], 0)),
                    (false, Some(a), _) => Ok(Math::Apply(Op::Divide, vec![Math::Num(a), c], 0)),
                    (_, None, None) => {
                        Err(format!("species `{id}` has no initial amount, concentration or assignment"))
                    }
                }
            }
        }
    }
}

/// What the door and the suite's runner need besides the text: each SBML id's `.hyb` expression.
pub(super) struct Quantities {
    pub value: BTreeMap<String, String>,
    pub amount: BTreeMap<String, String>,
    pub concentration: BTreeMap<String, String>,
}

/// What a translation gives: the `.hyb` text, where each SBML quantity is read, and the SBML
/// ids renamed (id, name).
pub(super) type Translation = (String, Quantities, Vec<(String, String)>);

/// Translates the model; `None` when anything was refused (the refusals are in `out`).
pub(super) fn translate(xml: &Xml<'_>, sbml: &Sbml<'_, '_>, out: &mut Vec<Refusal>) -> Option<Translation> {
    let mut ids: Vec<&str> = Vec::new();
    ids.extend(sbml.compartments.iter().map(|c| c.id.as_str()));
    ids.extend(sbml.species.iter().map(|s| s.id.as_str()));
    ids.extend(sbml.parameters.iter().map(|p| p.id.as_str()));
    for r in &sbml.reactions {
        ids.push(&r.id);
        ids.extend(r.reactants.iter().chain(&r.products).filter_map(|s| s.id.as_deref()));
    }
    ids.extend(sbml.events.iter().filter_map(|e| e.id.as_deref()));
    let mut tr = Tr {
        xml,
        sbml,
        names: Names::new(ids),
        syms: HashMap::new(),
        ia: sbml.initial_assignments.iter().map(|a| (a.variable.clone(), &a.math)).collect(),
        rule: sbml.assignment_rules.iter().map(|a| (a.variable.clone(), &a.math)).collect(),
        rate: sbml.rate_rules.iter().map(|a| (a.variable.clone(), &a.math)).collect(),
        flows: HashMap::new(),
        init_names: HashMap::new(),
        init_todo: Vec::new(),
        rate_names: BTreeMap::new(),
        lets: Vec::new(),
        out: Vec::new(),
    };
    declare(&mut tr);
    let text = if tr.out.is_empty() { write(&mut tr) } else { None };
    out.append(&mut tr.out);
    let text = text?;
    let q = quantities(&tr);
    let renamed = tr.names.renamed.iter().map(|(a, b)| (a.clone(), b.clone())).collect();
    if out.is_empty() {
        Some((text, q, renamed))
    } else {
        None
    }
}

/// Every symbol with its storage.
fn declare(tr: &mut Tr<'_, '_, '_>) {
    let sbml = tr.sbml;
    let mut kinds: Vec<(String, Kind, Node<'_, '_>)> = Vec::new();
    for (i, c) in sbml.compartments.iter().enumerate() {
        kinds.push((c.id.clone(), Kind::Compartment(i), c.node));
    }
    for (i, s) in sbml.species.iter().enumerate() {
        kinds.push((s.id.clone(), Kind::Species(i), s.node));
    }
    for (i, p) in sbml.parameters.iter().enumerate() {
        kinds.push((p.id.clone(), Kind::Parameter(i), p.node));
    }
    for (i, r) in sbml.reactions.iter().enumerate() {
        kinds.push((r.id.clone(), Kind::Reaction(i), r.node));
        for (p, refs) in [(false, &r.reactants), (true, &r.products)] {
            for (k, sr) in refs.iter().enumerate() {
                if let Some(id) = &sr.id {
                    kinds.push((id.clone(), Kind::SpeciesRef(i, p, k), sr.node));
                }
            }
        }
    }
    let assigned: HashSet<&str> =
        sbml.events.iter().flat_map(|e| e.assignments.iter().map(|a| a.variable.as_str())).collect();
    let mut changed_by_reactions: HashSet<&str> = HashSet::new();
    for r in &sbml.reactions {
        for sr in r.reactants.iter().chain(&r.products) {
            changed_by_reactions.insert(&sr.species);
        }
    }
    let mut seen = HashSet::new();
    for (id, _, node) in &kinds {
        if id.is_empty() {
            tr.refuse(*node, "an element without an id");
        } else if !seen.insert(id.clone()) {
            tr.refuse(*node, format!("the id `{id}` is declared twice"));
        }
    }
    // Compartments first: a species' storage depends on whether its compartment changes.
    let storage_of = |tr: &Tr<'_, '_, '_>, id: &str, kind: Kind| -> Storage {
        if tr.rule.contains_key(id) {
            return Storage::Rule;
        }
        if tr.rate.contains_key(id) || assigned.contains(id) {
            return Storage::State;
        }
        let literal = match kind {
            Kind::Compartment(i) => sbml.compartments[i].size,
            Kind::Parameter(i) => sbml.parameters[i].value,
            Kind::SpeciesRef(r, p, k) => {
                let refs = if p { &sbml.reactions[r].products } else { &sbml.reactions[r].reactants };
                refs[k].value
            }
            Kind::Reaction(_) => return Storage::Reaction,
            Kind::Species(_) => None,
        };
        match literal {
            Some(v) if !tr.ia.contains_key(id) && v.is_finite() => Storage::Param(v),
            _ => Storage::Const,
        }
    };
    let mut varying_compartments = HashSet::new();
    for (id, kind, node) in &kinds {
        if let Kind::Compartment(_) = kind {
            let storage = storage_of(tr, id, *kind);
            if matches!(storage, Storage::Rule | Storage::State) {
                varying_compartments.insert(id.clone());
            }
            let name = tr.names.sbml(id);
            tr.syms.insert(id.clone(), Symbol { kind: *kind, storage, name, node: *node });
        }
    }
    for (id, kind, node) in &kinds {
        if tr.syms.contains_key(id) {
            continue;
        }
        let storage = match kind {
            Kind::Species(i) => {
                let s = &sbml.species[*i];
                let Some(c) = sbml.compartments.iter().find(|c| c.id == s.compartment) else {
                    tr.refuse(
                        *node,
                        format!("species `{id}` is in `{}`, which is no compartment", s.compartment),
                    );
                    continue;
                };
                let _ = c;
                let by_reactions = !s.boundary && !s.constant && changed_by_reactions.contains(id.as_str());
                if tr.rule.contains_key(id) {
                    Storage::Rule
                } else if !s.only_substance && varying_compartments.contains(&s.compartment) {
                    // Its amount changes only by reactions, rate rules or events; its
                    // concentration also by the compartment's size. A constant species too: what
                    // stays is its amount (the suite's 01117, 01118), diluted as the
                    // compartment grows.
                    Storage::Amount(tr.names.fresh(&format!("{id}_amount")))
                } else if tr.rate.contains_key(id) || assigned.contains(id.as_str()) || by_reactions {
                    Storage::State
                } else {
                    match (s.only_substance, s.initial_amount, s.initial_concentration) {
                        (true, Some(v), _) | (false, None, Some(v))
                            if !tr.ia.contains_key(id) && v.is_finite() =>
                        {
                            Storage::Param(v)
                        }
                        _ => Storage::Const,
                    }
                }
            }
            _ => storage_of(tr, id, *kind),
        };
        let name = tr.names.sbml(id);
        tr.syms.insert(id.clone(), Symbol { kind: *kind, storage, name, node: *node });
    }
    for (what, list) in [
        ("assignment rule", &sbml.assignment_rules),
        ("rate rule", &sbml.rate_rules),
        ("initial assignment", &sbml.initial_assignments),
    ] {
        for a in list {
            match tr.syms.get(&a.variable) {
                None => tr.refuse(a.node, format!("the {what}'s variable `{}` is no compartment, species, parameter or species reference", a.variable)),
                Some(s) if matches!(s.kind, Kind::Reaction(_)) => tr.refuse(a.node, format!("a {what} cannot set the reaction `{}`", a.variable)),
                _ => {}
            }
        }
    }
    for e in &sbml.events {
        for a in &e.assignments {
            match tr.syms.get(&a.variable).map(|s| &s.storage) {
                None => tr.refuse(a.node, format!("the event assignment's variable `{}` is no compartment, species, parameter or species reference", a.variable)),
                Some(Storage::Rule) => tr.refuse(a.node, format!("`{}` has an assignment rule; an event cannot set it", a.variable)),
                _ => {}
            }
        }
    }
}

/// The flow of every state, as math over SBML ids.
fn flows(tr: &mut Tr<'_, '_, '_>) {
    let sbml = tr.sbml;
    let mut sums: HashMap<&str, Vec<(bool, Math)>> = HashMap::new();
    for r in &sbml.reactions {
        for (product, refs) in [(false, &r.reactants), (true, &r.products)] {
            for sr in refs {
                let stoich = match &sr.stoichiometry {
                    Stoichiometry::Number(x) => Math::Num(*x),
                    Stoichiometry::Symbol(id) => Math::Ci(id.clone()),
                    Stoichiometry::Math(m) => m.clone(),
                };
                let rate = Math::Ci(r.id.clone());
                let term = if stoich == Math::Num(1.0) {
                    rate
                } else {
                    Math::Apply(Op::Times, vec![stoich, rate], 0)
                };
                sums.entry(sr.species.as_str()).or_default().push((product, term));
            }
        }
    }
    let ids: Vec<String> = tr.syms.keys().cloned().collect();
    for id in ids {
        let (kind, storage) = (tr.syms[&id].kind, tr.syms[&id].storage.clone());
        if !matches!(storage, Storage::State | Storage::Amount(_)) {
            continue;
        }
        if let Some(rate) = tr.rate.get(id.as_str()).copied() {
            let flow = match (&storage, kind) {
                (Storage::Amount(_), Kind::Species(i)) => {
                    // d(amount)/dt = d[S]/dt V + [S] dV/dt.
                    let c = &sbml.species[i].compartment;
                    let dv = match (tr.rate.get(c.as_str()), tr.syms[c].storage.clone()) {
                        (Some(m), _) => (*m).clone(),
                        (None, Storage::State) => Math::Num(0.0),
                        _ => {
                            let node = tr.syms[&id].node;
                            tr.refuse(node, format!("species `{id}` has a rate rule in concentration while its compartment `{c}` follows an assignment rule: hybc would need that rule's time derivative"));
                            continue;
                        }
                    };
                    let times = |a: Math, b: Math| Math::Apply(Op::Times, vec![a, b], 0);
                    Math::Apply(
                        Op::Plus,
                        vec![times(rate.clone(), Math::Ci(c.clone())), times(Math::Ci(id.clone()), dv)],
                        0,
                    )
                }
                _ => rate.clone(),
            };
            tr.flows.insert(id, flow);
            continue;
        }
        let Kind::Species(i) = kind else {
            tr.flows.insert(id, Math::Num(0.0));
            continue;
        };
        let s = &sbml.species[i];
        let terms = if s.boundary || s.constant { None } else { sums.get(id.as_str()) };
        let Some(terms) = terms else {
            tr.flows.insert(id, Math::Num(0.0));
            continue;
        };
        let mut acc: Option<Math> = None;
        for (product, term) in terms {
            acc = Some(match (acc, product) {
                (None, true) => term.clone(),
                (None, false) => Math::Apply(Op::Minus, vec![term.clone()], 0),
                (Some(a), true) => Math::Apply(Op::Plus, vec![a, term.clone()], 0),
                (Some(a), false) => Math::Apply(Op::Minus, vec![a, term.clone()], 0),
            });
        }
        let mut flow = acc.unwrap_or(Math::Num(0.0));
        if let Some(cf) = s.conversion_factor.as_ref().or(sbml.conversion_factor.as_ref()) {
            flow = Math::Apply(Op::Times, vec![Math::Ci(cf.clone()), flow], 0);
        }
        if storage == Storage::State && !s.only_substance {
            flow = Math::Apply(Op::Divide, vec![flow, Math::Ci(s.compartment.clone())], 0);
        }
        tr.flows.insert(id, flow);
    }
}

/// A trailing comment with the units, if SBML names them.
fn units(tr: &Tr<'_, '_, '_>, id: &str) -> String {
    let u = match tr.syms[id].kind {
        Kind::Compartment(i) => tr.sbml.compartments[i].units.clone(),
        Kind::Species(i) => tr.sbml.species[i].units.clone(),
        Kind::Parameter(i) => tr.sbml.parameters[i].units.clone(),
        _ => None,
    };
    u.map_or_else(String::new, |u| format!("  # {u}"))
}

/// The whole `.hyb` text.
fn write(tr: &mut Tr<'_, '_, '_>) -> Option<String> {
    flows(tr);
    let sbml = tr.sbml;
    let mut params = Vec::new();
    let mut consts = Vec::new();
    let mut rules = Vec::new();
    let mut reactions = Vec::new();
    let mut ders = Vec::new();
    // Declaration order: the document's.
    let mut order: Vec<String> = Vec::new();
    order.extend(sbml.compartments.iter().map(|c| c.id.clone()));
    order.extend(sbml.species.iter().map(|s| s.id.clone()));
    order.extend(sbml.parameters.iter().map(|p| p.id.clone()));
    for r in &sbml.reactions {
        order.extend(r.reactants.iter().chain(&r.products).filter_map(|s| s.id.clone()));
        order.push(r.id.clone());
    }
    let mut states: Vec<String> = Vec::new();
    for id in &order {
        let Some(sym) = tr.syms.get(id) else { continue };
        let (name, node, storage) = (sym.name.clone(), sym.node, sym.storage.clone());
        match storage {
            Storage::Param(v) => {
                params.push(format!("param {name} = {}{}", print::number(v).ok()?.s, units(tr, id)))
            }
            Storage::Const => {
                let m = tr.init_math(id).map_err(|e| tr.refuse(node, e)).ok()?;
                let text = tr.initial(&m, node, None)?;
                consts.push(format!("let {name} = {text}{}", units(tr, id)));
            }
            Storage::Rule => {
                let m = tr.rule[id.as_str()];
                let rnode = sbml.assignment_rules.iter().find(|a| &a.variable == id).map_or(node, |a| a.node);
                let text = tr.dynamic(m, rnode, None)?;
                rules.push(format!("let {name} = {text}"));
            }
            Storage::State | Storage::Amount(_) => states.push(id.clone()),
            Storage::Reaction => {
                let Kind::Reaction(i) = sym.kind else { continue };
                let r = &sbml.reactions[i];
                let Some((law_node, law)) = &r.law else {
                    if r.reactants.is_empty() && r.products.is_empty() {
                        continue;
                    }
                    tr.refuse(node, format!("reaction `{id}` has no kinetic law"));
                    return None;
                };
                let mut locals = HashMap::new();
                for (lid, v) in &r.locals {
                    let lname = tr.names.fresh(&format!("{}_{lid}", name));
                    params.push(format!(
                        "param {lname} = {}  # local to reaction {id}",
                        print::number(*v).ok()?.s
                    ));
                    locals.insert(lid.clone(), lname);
                }
                let text = tr.dynamic(law, *law_node, Some(&locals))?;
                reactions.push(format!("let {name} = {text}"));
            }
        }
    }
    for id in &states {
        let sym = &tr.syms[id];
        let (name, node, storage, kind) = (sym.name.clone(), sym.node, sym.storage.clone(), sym.kind);
        let flow = tr.flows.get(id).cloned().unwrap_or(Math::Num(0.0));
        let rnode = sbml.rate_rules.iter().find(|a| &a.variable == id).map_or(node, |a| a.node);
        let text = tr.dynamic(&flow, rnode, None)?;
        let target = match &storage {
            Storage::Amount(amount) => {
                let Kind::Species(i) = kind else { continue };
                let c = tr.syms[&sbml.species[i].compartment].name.clone();
                rules.push(format!("let {name} = {amount} / {c}"));
                amount.clone()
            }
            _ => name.clone(),
        };
        ders.push((id.clone(), target, text));
    }
    let translated = super::events::events(tr)?;
    let events = translated.events;
    // Flows that `rateOf` reads are `let`s (printed after the events: they may ask for more).
    let mut der_lines = Vec::new();
    for (id, target, text) in ders {
        match tr.rate_names.get(&id) {
            Some(rate) => {
                rules.push(format!("let {rate} = {text}"));
                der_lines.push(format!("der({target}) = {rate}"));
            }
            None => der_lines.push(format!("der({target}) = {text}")),
        }
    }
    // Initial values last: everything above may have asked for a symbol's start value.
    let mut state_lines = Vec::new();
    for id in &states {
        let sym = &tr.syms[id];
        let (name, node, storage, kind) = (sym.name.clone(), sym.node, sym.storage.clone(), sym.kind);
        let text = match (&storage, kind) {
            (Storage::Amount(_), Kind::Species(i)) => {
                let s = &sbml.species[i];
                let m = match (s.initial_amount, tr.ia.contains_key(id.as_str())) {
                    (Some(a), false) => Math::Num(a),
                    _ => {
                        let conc = tr.init_math(id).map_err(|e| tr.refuse(node, e)).ok()?;
                        Math::Apply(Op::Times, vec![conc, Math::Ci(s.compartment.clone())], 0)
                    }
                };
                tr.initial(&m, node, None)?
            }
            _ => match tr.init_names.get(id) {
                Some(n) => n.clone(),
                None => {
                    let m = tr.init_math(id).map_err(|e| tr.refuse(node, e)).ok()?;
                    tr.initial(&m, node, None)?
                }
            },
        };
        let target = match &storage {
            Storage::Amount(a) => a.clone(),
            _ => name,
        };
        state_lines.push(format!("state {target} = {text}{}", units(tr, id)));
    }
    let mut init_lines = Vec::new();
    while let Some(id) = tr.init_todo.pop() {
        let name = tr.init_names[&id].clone();
        let node = tr.syms[&id].node;
        let locals: Option<HashMap<String, String>> = match tr.syms[&id].kind {
            Kind::Reaction(i) => Some(
                sbml.reactions[i]
                    .locals
                    .iter()
                    .map(|(l, _)| (l.clone(), format!("{}_{l}", tr.syms[&id].name)))
                    .collect(),
            ),
            _ => None,
        };
        let m = tr.init_math(&id).map_err(|e| tr.refuse(node, e)).ok()?;
        let text = tr.initial(&m, node, locals.as_ref())?;
        init_lines.push(format!("let {name} = {text}"));
    }
    if !tr.out.is_empty() {
        return None;
    }
    let mut text = String::new();
    let level = format!("SBML Level {} Version {}", sbml.level, sbml.version);
    let model_id = sbml.id.clone().unwrap_or_else(|| "sbml_model".to_string());
    text.push_str(&format!("# Imported by `hybc import` from {level}, model `{model_id}`"));
    if let Some(n) = &sbml.name {
        text.push_str(&format!(" ({n})"));
    }
    text.push('\n');
    if !tr.names.renamed.is_empty() {
        let list: Vec<String> = tr.names.renamed.iter().map(|(a, b)| format!("{a} -> {b}")).collect();
        text.push_str(&format!("# SBML ids renamed (hybc reserves them): {}\n", list.join(", ")));
    }
    let model_name = tr.names.fresh(&model_id);
    text.push_str(&format!("model {model_name}\n"));
    let mut section = |title: &str, lines: &[String]| {
        if !lines.is_empty() {
            text.push_str(&format!("\n# {title}\n"));
            for l in lines {
                text.push_str(l);
                text.push('\n');
            }
        }
    };
    section("Parameters (constant compartments, species and parameters)", &params);
    section("Constants computed from parameters (initial assignments)", &consts);
    section("Initial values read by other initial values", &init_lines);
    state_lines.extend(translated.states);
    der_lines.extend(translated.ders);
    if state_lines.is_empty() {
        // hybc integrates at least one state; a model of rules alone gets one that stays 0.
        let name = tr.names.fresh("no_states");
        state_lines.push(format!("state {name} = 0  # the SBML model has no state; hybc needs one"));
        der_lines.push(format!("der({name}) = 0"));
    }
    section("States", &state_lines);
    section("Assignment rules", &rules);
    section("Reaction rates (substance per time)", &reactions);
    let hoisted = std::mem::take(&mut tr.lets);
    section("Subexpressions", &hoisted);
    section("Flows", &der_lines);
    section("Events", &events);
    Some(text)
}

fn quantities(tr: &Tr<'_, '_, '_>) -> Quantities {
    let mut q =
        Quantities { value: BTreeMap::new(), amount: BTreeMap::new(), concentration: BTreeMap::new() };
    for (id, sym) in &tr.syms {
        q.value.insert(id.clone(), sym.name.clone());
        if let Kind::Species(i) = sym.kind {
            let s = &tr.sbml.species[i];
            let c = tr.syms.get(&s.compartment).map_or_else(|| "1".to_string(), |c| c.name.clone());
            let (amount, conc) = match (&sym.storage, s.only_substance) {
                (_, true) => (sym.name.clone(), format!("{} / {c}", sym.name)),
                (Storage::Amount(a), false) => (a.clone(), sym.name.clone()),
                (_, false) => (format!("{} * {c}", sym.name), sym.name.clone()),
            };
            q.amount.insert(id.clone(), amount);
            q.concentration.insert(id.clone(), conc);
        }
    }
    q
}

/// Whether `m` reads a name hybc cannot put in an event's guard: the guard must be continuous.
pub(super) fn has_jump(m: &Math) -> bool {
    match m {
        Math::Piecewise(..) => true,
        Math::Apply(op, args, _) => op.is_boolean() || args.iter().any(has_jump),
        _ => false,
    }
}
