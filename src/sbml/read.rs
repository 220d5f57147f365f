//! SBML elements -> the importer's description of the model ([`Sbml`]): every component with its
//! attributes (SBML's defaults for its level applied), its math read and its function calls
//! inlined, and the XML node it came from (refusals point there). Constructs hybc cannot express
//! are refused here when the element alone says so (algebraic rules, fast reactions, required
//! packages); the translation refuses the rest.

use std::collections::HashMap;

use roxmltree::Node;

use super::error::Refusal;
use super::math::{self, Function, Math};
use super::xml::{child, elements, flag, list, number, Xml};

/// A compartment.
pub(super) struct Compartment<'a, 'i> {
    pub node: Node<'a, 'i>,
    pub id: String,
    pub size: Option<f64>,
    pub dims: f64,
    pub units: Option<String>,
}

/// A species.
pub(super) struct Species<'a, 'i> {
    pub node: Node<'a, 'i>,
    pub id: String,
    pub compartment: String,
    pub initial_amount: Option<f64>,
    pub initial_concentration: Option<f64>,
    pub only_substance: bool,
    pub boundary: bool,
    pub constant: bool,
    pub conversion_factor: Option<String>,
    pub units: Option<String>,
}

/// A global parameter.
pub(super) struct Parameter<'a, 'i> {
    pub node: Node<'a, 'i>,
    pub id: String,
    pub value: Option<f64>,
    pub units: Option<String>,
}

/// How much of a species a reaction consumes or produces per unit of its rate.
pub(super) enum Stoichiometry {
    /// A constant number.
    Number(f64),
    /// The value of the species reference's own id (Level 3: rules and events may change it).
    Symbol(String),
    /// Level 2's `stoichiometryMath`.
    Math(Math),
}

/// A reactant or product.
pub(super) struct SpeciesRef<'a, 'i> {
    pub node: Node<'a, 'i>,
    pub species: String,
    pub stoichiometry: Stoichiometry,
    /// The reference's id (Level 3) and its constant stoichiometry, for its use as a symbol.
    pub id: Option<String>,
    pub value: Option<f64>,
}

/// A reaction.
pub(super) struct Reaction<'a, 'i> {
    pub node: Node<'a, 'i>,
    pub id: String,
    pub reactants: Vec<SpeciesRef<'a, 'i>>,
    pub products: Vec<SpeciesRef<'a, 'i>>,
    pub law: Option<(Node<'a, 'i>, Math)>,
    /// Local parameters: id and value.
    pub locals: Vec<(String, f64)>,
}

/// A rule, an initial assignment or an event assignment: a variable and its math.
pub(super) struct Assignment<'a, 'i> {
    pub node: Node<'a, 'i>,
    pub variable: String,
    pub math: Math,
}

/// An event.
pub(super) struct Event<'a, 'i> {
    pub id: Option<String>,
    pub trigger: Math,
    pub trigger_node: Node<'a, 'i>,
    pub initial_value: bool,
    pub persistent: bool,
    pub delay: Option<(Node<'a, 'i>, Math)>,
    pub priority: Option<(Node<'a, 'i>, Math)>,
    pub use_trigger_values: bool,
    pub assignments: Vec<Assignment<'a, 'i>>,
}

/// The model as the SBML document states it.
pub(super) struct Sbml<'a, 'i> {
    pub level: u32,
    pub version: u32,
    pub id: Option<String>,
    pub name: Option<String>,
    pub compartments: Vec<Compartment<'a, 'i>>,
    pub species: Vec<Species<'a, 'i>>,
    pub parameters: Vec<Parameter<'a, 'i>>,
    pub reactions: Vec<Reaction<'a, 'i>>,
    pub assignment_rules: Vec<Assignment<'a, 'i>>,
    pub rate_rules: Vec<Assignment<'a, 'i>>,
    pub initial_assignments: Vec<Assignment<'a, 'i>>,
    pub events: Vec<Event<'a, 'i>>,
    pub conversion_factor: Option<String>,
}

/// Reads the document; every refusal found is collected.
pub(super) fn read<'a, 'i>(xml: &'a Xml<'i>, out: &mut Vec<Refusal>) -> Option<Sbml<'a, 'i>> {
    let root = xml.doc.root_element();
    if root.tag_name().name() != "sbml" {
        out.push(xml.refuse(root, "the document is not SBML: its root element is not <sbml>"));
        return None;
    }
    let level: u32 = root.attribute("level").and_then(|v| v.trim().parse().ok()).unwrap_or(0);
    let version: u32 = root.attribute("version").and_then(|v| v.trim().parse().ok()).unwrap_or(0);
    if !(2..=3).contains(&level) {
        out.push(xml.refuse(root, format!("SBML Level {level} is not supported (Levels 2 and 3 are)")));
        return None;
    }
    // A package the model declares required changes its meaning; hybc knows none of them.
    for a in root.attributes() {
        if a.name() == "required" && a.namespace().is_some() && matches!(a.value().trim(), "true" | "1") {
            let package = a.namespace().unwrap_or("").split('/').rev().nth(1).unwrap_or("?").to_string();
            out.push(xml.refuse(
                root,
                format!(
                    "the SBML package `{package}` is required by this model and hybc does not support it"
                ),
            ));
        }
    }
    let Some(model) = child(root, "model") else {
        out.push(xml.refuse(root, "an <sbml> document without a <model>"));
        return None;
    };
    let l2 = level == 2;
    let mut functions: HashMap<String, Function> = HashMap::new();
    for f in list(model, "listOfFunctionDefinitions", "functionDefinition") {
        let Some(m) = child(f, "math") else {
            out.push(xml.refuse(f, "a function definition without <math>"));
            continue;
        };
        match math::read_lambda(xml, m) {
            Ok(func) => {
                functions.insert(f.attribute("id").unwrap_or("").to_string(), func);
            }
            Err(r) => out.push(r),
        }
    }
    // Math read and inlined, with refusals collected: `None` where it failed.
    let read_math = |node: Node<'a, 'i>, out: &mut Vec<Refusal>| -> Option<Math> {
        let Some(m) = child(node, "math") else {
            out.push(xml.refuse(node, "an element without its <math>"));
            return None;
        };
        let raw = match math::read_math(xml, m) {
            Ok(raw) => raw,
            Err(r) => {
                out.push(r);
                return None;
            }
        };
        match math::inline(&raw, &functions, 0) {
            Ok(m) => Some(math::fold(&m)),
            Err((reason, _)) => {
                out.push(xml.refuse(node, reason));
                None
            }
        }
    };
    // Level 3 Version 2 lets a rule or an assignment leave out its math: it then has no effect.
    let no_math = |n: Node<'_, '_>| (level, version) >= (3, 2) && child(n, "math").is_none();
    let id = |n: Node<'_, '_>| n.attribute("id").unwrap_or("").trim().to_string();
    let mut compartments = Vec::new();
    for c in list(model, "listOfCompartments", "compartment") {
        // Level 1's `volume` is Level 2's `size`.
        let size = match (number(xml, c, "size"), number(xml, c, "volume")) {
            (Ok(Some(s)), _) | (Ok(None), Ok(Some(s))) => Some(s),
            (Err(r), _) | (Ok(None), Err(r)) => {
                out.push(r);
                None
            }
            (Ok(None), Ok(None)) => None,
        };
        let dims = number(xml, c, "spatialDimensions").ok().flatten().unwrap_or(3.0);
        // A compartment without dimensions has no size; its species are amounts (below), and
        // its symbol reads 1.
        let size = if dims == 0.0 { size.or(Some(1.0)) } else { size };
        compartments.push(Compartment {
            node: c,
            id: id(c),
            size,
            dims,
            units: c.attribute("units").map(str::to_string),
        });
    }
    let mut species = Vec::new();
    for s in list(model, "listOfSpecies", "species") {
        let amount = number(xml, s, "initialAmount").unwrap_or_else(|r| {
            out.push(r);
            None
        });
        let conc = number(xml, s, "initialConcentration").unwrap_or_else(|r| {
            out.push(r);
            None
        });
        species.push(Species {
            node: s,
            id: id(s),
            compartment: s.attribute("compartment").unwrap_or("").to_string(),
            initial_amount: amount,
            initial_concentration: conc,
            only_substance: flag(s, "hasOnlySubstanceUnits").unwrap_or(false),
            boundary: flag(s, "boundaryCondition").unwrap_or(false),
            constant: flag(s, "constant").unwrap_or(false),
            conversion_factor: s.attribute("conversionFactor").map(str::to_string),
            units: s.attribute("substanceUnits").map(str::to_string),
        });
    }
    // A species in a compartment without dimensions has no concentration: its symbol is its
    // amount whatever `hasOnlySubstanceUnits` says (as SBML's test suite expects).
    for s in &mut species {
        if compartments.iter().any(|c| c.id == s.compartment && c.dims == 0.0) {
            s.only_substance = true;
        }
    }
    let mut parameters = Vec::new();
    for p in list(model, "listOfParameters", "parameter") {
        let value = number(xml, p, "value").unwrap_or_else(|r| {
            out.push(r);
            None
        });
        parameters.push(Parameter {
            node: p,
            id: id(p),
            value,
            units: p.attribute("units").map(str::to_string),
        });
    }
    let mut reactions = Vec::new();
    for r in list(model, "listOfReactions", "reaction") {
        if flag(r, "fast") == Some(true) {
            out.push(xml.refuse(
                r,
                "a fast reaction (`fast=\"true\"`) is an algebraic constraint (its equilibrium held at every instant), which hybc does not solve",
            ));
        }
        let refs = |listname: &str, out: &mut Vec<Refusal>| -> Vec<SpeciesRef<'a, 'i>> {
            let mut v = Vec::new();
            for sr in list(r, listname, "speciesReference") {
                let value = number(xml, sr, "stoichiometry").unwrap_or_else(|e| {
                    out.push(e);
                    None
                });
                let sid = sr.attribute("id").map(str::to_string);
                let stoichiometry = if let Some(sm) = child(sr, "stoichiometryMath") {
                    match read_math(sm, out) {
                        Some(m) => Stoichiometry::Math(m),
                        None => continue,
                    }
                } else if let Some(sid) = &sid {
                    Stoichiometry::Symbol(sid.clone())
                } else {
                    // Level 2's default; Level 3 leaves it undefined, and every model sets it.
                    Stoichiometry::Number(value.unwrap_or(1.0))
                };
                v.push(SpeciesRef {
                    node: sr,
                    species: sr.attribute("species").unwrap_or("").to_string(),
                    stoichiometry,
                    id: sid,
                    value: value.or(if l2 { Some(1.0) } else { None }),
                });
            }
            v
        };
        let reactants = refs("listOfReactants", out);
        let products = refs("listOfProducts", out);
        let mut locals = Vec::new();
        let law = child(r, "kineticLaw").and_then(|k| {
            for lp in list(k, "listOfLocalParameters", "localParameter").into_iter().chain(list(
                k,
                "listOfParameters",
                "parameter",
            )) {
                match number(xml, lp, "value") {
                    Ok(Some(v)) => locals.push((id(lp), v)),
                    Ok(None) => out.push(xml.refuse(lp, "a local parameter without a value")),
                    Err(e) => out.push(e),
                }
            }
            read_math(k, out).map(|m| (k, m))
        });
        reactions.push(Reaction { node: r, id: id(r), reactants, products, law, locals });
    }
    let mut assignment_rules = Vec::new();
    let mut rate_rules = Vec::new();
    if let Some(rules) = child(model, "listOfRules") {
        for rule in elements(rules) {
            let kind = rule.tag_name().name();
            match kind {
                "assignmentRule" | "rateRule" => {
                    if no_math(rule) {
                        continue;
                    }
                    let Some(m) = read_math(rule, out) else { continue };
                    let a = Assignment { node: rule, variable: rule.attribute("variable").unwrap_or("").to_string(), math: m };
                    if kind == "rateRule" {
                        rate_rules.push(a);
                    } else {
                        assignment_rules.push(a);
                    }
                }
                "algebraicRule" => out.push(xml.refuse(
                    rule,
                    "an algebraic rule (0 = f(x)) makes the model a DAE, which hybc does not solve; write the variable it determines as an assignment rule",
                )),
                other => out.push(xml.refuse(rule, format!("the rule <{other}> is not supported"))),
            }
        }
    }
    let mut initial_assignments = Vec::new();
    for ia in list(model, "listOfInitialAssignments", "initialAssignment") {
        if no_math(ia) {
            continue;
        }
        if let Some(m) = read_math(ia, out) {
            initial_assignments.push(Assignment {
                node: ia,
                variable: ia.attribute("symbol").unwrap_or("").to_string(),
                math: m,
            });
        }
    }
    let mut events = Vec::new();
    for e in list(model, "listOfEvents", "event") {
        let Some(trigger_node) = child(e, "trigger") else {
            out.push(xml.refuse(e, "an event without a <trigger>"));
            continue;
        };
        let Some(trigger) = read_math(trigger_node, out) else { continue };
        let delay = child(e, "delay").and_then(|d| read_math(d, out).map(|m| (d, m)));
        let priority = child(e, "priority").and_then(|p| read_math(p, out).map(|m| (p, m)));
        let mut assignments = Vec::new();
        for ea in list(e, "listOfEventAssignments", "eventAssignment") {
            if no_math(ea) {
                continue;
            }
            if let Some(m) = read_math(ea, out) {
                assignments.push(Assignment {
                    node: ea,
                    variable: ea.attribute("variable").unwrap_or("").to_string(),
                    math: m,
                });
            }
        }
        events.push(Event {
            id: e.attribute("id").map(str::to_string),
            trigger,
            trigger_node,
            // Level 2 has neither trigger attribute: its triggers behave as
            // `initialValue="true"`, `persistent="true"` (the conversion to Level 3 writes so).
            initial_value: flag(trigger_node, "initialValue").unwrap_or(true),
            persistent: flag(trigger_node, "persistent").unwrap_or(true),
            use_trigger_values: flag(e, "useValuesFromTriggerTime").unwrap_or(true),
            delay,
            priority,
            assignments,
        });
    }
    Some(Sbml {
        level,
        version,
        id: model.attribute("id").map(str::to_string),
        name: model.attribute("name").map(str::to_string),
        compartments,
        species,
        parameters,
        reactions,
        assignment_rules,
        rate_rules,
        initial_assignments,
        events,
        conversion_factor: model.attribute("conversionFactor").map(str::to_string),
    })
}
