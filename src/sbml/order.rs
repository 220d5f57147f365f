//! Random event order, refused. SBML executes events of equal priority that fire at one instant
//! in random order (Level 3, "priorities"); hybc fires them in one fixed order. The order matters
//! only where one event changes what the other reads (its trigger, its assignments' values, its
//! delay) or assigns: then the fixed order is one draw of SBML's distribution and the simulation
//! is not SBML's. The rule, static and conservative: two events with equal constant priorities,
//! either of which assigns a symbol the other reads or assigns (reads followed through assignment
//! rules, reactions' rates and a concentration's compartment), are refused at the second's
//! `<priority>`. Whether their triggers can hold at one instant is not decided: events of equal
//! priority are written to compete, and a pair that cannot is rare (none in the suite).

use std::collections::{HashMap, HashSet};

use super::math::{fold, Math};
use super::read::{Event, Sbml};
use super::translate::Tr;

/// The SBML ids `m` reads directly.
fn names(m: &Math, out: &mut Vec<String>) {
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
    let mut todo = Vec::new();
    names(&e.trigger, &mut todo);
    for a in &e.assignments {
        names(&a.math, &mut todo);
    }
    if let Some((_, d)) = &e.delay {
        names(d, &mut todo);
    }
    let mut seen = HashSet::new();
    while let Some(id) = todo.pop() {
        if let Some(more) = sources.get(id.as_str()) {
            if !seen.contains(&id) {
                todo.extend(more.iter().cloned());
            }
        }
        seen.insert(id);
    }
    seen
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
