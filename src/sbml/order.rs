//! Simultaneous events whose order SBML and hybc see differently, refused.
//!
//! Random order. SBML executes events of equal priority that fire at one instant in random order
//! (Level 3, "priorities"); hybc fires them in one fixed order. The order matters only where one
//! event changes what the other reads (its trigger, its assignments' values, its delay) or
//! assigns: then the fixed order is one draw of SBML's distribution and the simulation is not
//! SBML's. The rule, static and conservative: two events with equal constant priorities, either
//! of which assigns a symbol the other reads or assigns (reads followed through assignment rules,
//! reactions' rates and a concentration's compartment), are refused at the second's
//! `<priority>`. Whether their triggers can hold at one instant is not decided: events of equal
//! priority are written to compete.
//!
//! Judged at the trigger. SBML decides which events fire at an instant, and computes the values
//! of those that use trigger-time values, on the state before any executes; a persistent one
//! executes though an earlier one turned its trigger false. hybc judges each event on the state
//! the ones before it left. Where an earlier event that can fire with a later one (a shared
//! comparison in their triggers, or both firing at the start) changes the later one's values or
//! may turn its persistent trigger false, the later one is refused at its `<trigger>`.
//!
//! Fired again. SBML judges every trigger again after each execution at an instant, so a trigger
//! that events firing together set back and forth fires at each turn to true; hybc judges a
//! guard's crossing once. A trigger reading what two events that can fire together both assign
//! is refused.

use std::collections::{HashMap, HashSet};

use super::math::{fold, substitute, Math};
use super::read::{Event, Sbml};
use super::translate::Tr;

/// The SBML ids `m` reads directly.
pub(super) fn names(m: &Math, out: &mut Vec<String>) {
    match m {
        Math::Ci(id) | Math::RateOf(id) => out.push(id.clone()),
        Math::Apply(_, args, _) | Math::Call(_, args, _) => args.iter().for_each(|a| names(a, out)),
        Math::Piecewise(pieces, other) => {
            for (v, c) in pieces {
                names(v, out);
                names(c, out);
            }
            if let Some(o) = other {
                names(o, out);
            }
        }
        Math::Num(_) | Math::Bool(_) | Math::Time => {}
    }
}

/// What an id's value is computed from at the same instant: its assignment rule, a reaction's
/// rate, a concentration's compartment.
fn sources<'s>(sbml: &'s Sbml<'_, '_>) -> HashMap<&'s str, Vec<String>> {
    let mut out: HashMap<&str, Vec<String>> = HashMap::new();
    for r in &sbml.assignment_rules {
        names(&r.math, out.entry(&r.variable).or_default());
    }
    for r in &sbml.reactions {
        if let Some((_, law)) = &r.law {
            names(law, out.entry(&r.id).or_default());
        }
    }
    for s in &sbml.species {
        out.entry(&s.id).or_default().push(s.compartment.clone());
    }
    out
}

/// Every id the event reads, through the symbols computed from others.
fn reads(e: &Event<'_, '_>, sources: &HashMap<&str, Vec<String>>) -> HashSet<String> {
    let values = e.assignments.iter().map(|a| &a.math);
    closure(std::iter::once(&e.trigger).chain(values).chain(e.delay.as_ref().map(|(_, d)| d)), sources)
}

/// Refuses each pair of events whose equal constant priorities leave SBML's order random and
/// whose order changes the result (module doc).
pub(super) fn refuse_random_order(tr: &mut Tr<'_, '_, '_>) {
    let sbml = tr.sbml;
    let sources = sources(sbml);
    let events: Vec<_> = sbml
        .events
        .iter()
        .filter_map(|e| {
            let (node, m) = e.priority.as_ref()?;
            let Math::Num(p) = fold(m) else { return None };
            let writes: HashSet<String> = e.assignments.iter().map(|a| a.variable.clone()).collect();
            Some((e, *node, p, writes, reads(e, &sources)))
        })
        .collect();
    // One refusal per priority: a hundred competing pairs are one reason.
    let mut refused: Vec<f64> = Vec::new();
    for (k, (e, node, p, writes, reads)) in events.iter().enumerate() {
        if refused.contains(p) {
            continue;
        }
        let clash = events[..k].iter().find(|(_, _, q, w, r)| {
            q == p
                && (writes.iter().any(|x| r.contains(x) || w.contains(x))
                    || w.iter().any(|x| reads.contains(x)))
        });
        if let Some((first, ..)) = clash {
            refused.push(*p);
            let name = |e: &Event<'_, '_>| {
                e.id.clone().map_or_else(|| "an event".to_string(), |id| format!("`{id}`"))
            };
            tr.refuse(
                *node,
                format!(
                    "{} and {} have the same priority ({p}) and one assigns what the other reads or assigns: SBML executes them in random order when they fire together, hybc in one fixed order",
                    name(first),
                    name(e)
                ),
            );
        }
    }
}

/// Whether `a` and `b` can fire at one instant: their triggers turn true at the crossing of one
/// comparison, or both fire at the start (`initialValue="false"`).
fn together(a: &Event<'_, '_>, b: &Event<'_, '_>) -> bool {
    let (mut x, mut y) = (Vec::new(), Vec::new());
    if super::events::atoms(&a.trigger, &mut x).is_err() || super::events::atoms(&b.trigger, &mut y).is_err()
    {
        return false;
    }
    (!a.initial_value && !b.initial_value) || x.iter().any(|m| y.contains(m))
}

/// The ids `ms` read, through the symbols computed from others.
fn closure<'m>(ms: impl Iterator<Item = &'m Math>, sources: &HashMap<&str, Vec<String>>) -> HashSet<String> {
    let mut ids = Vec::new();
    ms.for_each(|m| names(m, &mut ids));
    let mut seen = HashSet::new();
    while let Some(id) = ids.pop() {
        if let Some(more) = sources.get(id.as_str()) {
            if !seen.contains(&id) {
                ids.extend(more.iter().cloned());
            }
        }
        seen.insert(id);
    }
    seen
}

/// Whether `first`, executed before `later` at one instant, changes what SBML fixes when
/// `later` fires and hybc reads later, on the state `first` left: `later`'s values if computed
/// at the trigger time, its trigger's truth if persistent (SBML executes it though `first` turned
/// it false). A persistent trigger that `first`'s constant values leave true is unchanged.
fn disturbs(first: &Event<'_, '_>, later: &Event<'_, '_>, sources: &HashMap<&str, Vec<String>>) -> bool {
    let writes = |ids: &HashSet<String>| first.assignments.iter().any(|a| ids.contains(&a.variable));
    if later.use_trigger_values && writes(&closure(later.assignments.iter().map(|a| &a.math), sources)) {
        return true;
    }
    if later.persistent && writes(&closure(std::iter::once(&later.trigger), sources)) {
        let bound: HashMap<&str, &Math> =
            first.assignments.iter().map(|a| (a.variable.as_str(), &a.math)).collect();
        return fold(&substitute(&later.trigger, &bound)) != Math::Bool(true);
    }
    false
}

/// Refuses an event that fires with an earlier one (in hybc's order, `order`) that disturbs it
/// ([`disturbs`]): SBML judges all the events that fire at one instant on the state before any
/// executes, hybc each on the state the ones before it left (the suite's 00935, 01330, 01333,
/// 01337). Non-persistent triggers and values computed at execution are judged alike by both.
pub(super) fn refuse_sequential(tr: &mut Tr<'_, '_, '_>, order: &[(usize, Option<f64>)]) {
    let sbml = tr.sbml;
    let sources = sources(sbml);
    for (k, &(j, _)) in order.iter().enumerate() {
        let later = &sbml.events[j];
        if later.delay.is_some() {
            continue;
        }
        let earlier = order[..k]
            .iter()
            .map(|&(i, _)| &sbml.events[i])
            .find(|e| e.delay.is_none() && together(e, later) && disturbs(e, later, &sources));
        if let Some(first) = earlier {
            let name = |e: &Event<'_, '_>| {
                e.id.clone().map_or_else(|| "an event".to_string(), |id| format!("`{id}`"))
            };
            tr.refuse(
                later.trigger_node,
                format!(
                    "{} fires with {} and executes after it, which changes what {} fixes when it fires (a persistent trigger's truth or values from the trigger time): SBML judges both on the state before either executes, hybc the second on the state the first left",
                    name(later),
                    name(first),
                    name(later)
                ),
            );
        }
    }
}

/// Refuses an event whose trigger reads a symbol that two other events, firing together, both
/// assign: SBML judges the trigger again after each execution, so at one instant it can turn
/// true, false and true again and execute several times (the suite's 00978); hybc judges it on
/// the guard's crossing, once.
pub(super) fn refuse_retrigger(tr: &mut Tr<'_, '_, '_>) {
    let sbml = tr.sbml;
    let sources = sources(sbml);
    for e in &sbml.events {
        let read = closure(std::iter::once(&e.trigger), &sources);
        let setters: Vec<&Event<'_, '_>> = sbml
            .events
            .iter()
            .filter(|f| !std::ptr::eq(*f, e) && f.assignments.iter().any(|a| read.contains(&a.variable)))
            .collect();
        let pair = setters
            .iter()
            .enumerate()
            .find_map(|(k, a)| setters[k + 1..].iter().find(|b| together(a, b)).map(|b| (*a, *b)));
        if let Some((a, b)) = pair {
            let name = |e: &Event<'_, '_>| {
                e.id.clone().map_or_else(|| "an event".to_string(), |id| format!("`{id}`"))
            };
            tr.refuse(
                e.trigger_node,
                format!(
                    "this trigger reads what {} and {} both assign when they fire together: SBML judges it after each, so it can fire more than once at that instant; hybc judges it once",
                    name(a),
                    name(b)
                ),
            );
        }
    }
}
