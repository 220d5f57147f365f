//! SBML events -> hybc events. A trigger is a truth value built from comparisons (its atoms)
//! with `and`, `or`, `not`, `xor`, `implies`; it fires when it goes from false to true. It can
//! do so only where one atom crosses, so each atom gives an event on its guard in each
//! direction in which its crossing can turn the trigger true, enabled where it does: for atom
//! `a` rising, `F[a := true] and not F[a := false]` (the other atoms as conditions). A trigger
//! with `initialValue="false"` that holds at the start fires there: one more event at `t >= 0`
//! enabled by the whole trigger. Constant priorities order the events (hybc fires simultaneous
//! events in declaration order).
//!
//! A delayed event is scheduled rather than executed: its trigger's events set a state
//! `e_due := t + delay` (and, with `useValuesFromTriggerTime`, states holding the assigned
//! values), and an event `t >= e_due` executes the assignments and sets `e_due` back to
//! [`IDLE`]. One execution can be pending per event: a trigger that fires again while one is
//! pending (SBML queues a second) stops the run at an event `e_queued`, never dropping it
//! silently. A non-persistent trigger that turns false while pending cancels the execution.

use super::math::{fold, Math, Op};
use super::translate::{has_jump, Kind, Storage, Tr};

/// `m` with the byte offsets cleared, so that equal atoms compare equal.
fn strip(m: &Math) -> Math {
    match m {
        Math::Apply(op, args, _) => Math::Apply(*op, args.iter().map(strip).collect(), 0),
        Math::Call(n, args, _) => Math::Call(n.clone(), args.iter().map(strip).collect(), 0),
        Math::Piecewise(p, o) => Math::Piecewise(
            p.iter().map(|(v, c)| (strip(v), strip(c))).collect(),
            o.as_ref().map(|o| Box::new(strip(o))),
        ),
        other => other.clone(),
    }
}

/// The comparisons a trigger is built from, or why it cannot be split into crossings.
pub(super) fn atoms(m: &Math, out: &mut Vec<Math>) -> Result<(), String> {
    match m {
        Math::Bool(_) => Ok(()),
        Math::Apply(Op::And | Op::Or | Op::Not | Op::Xor | Op::Implies, args, _) => {
            args.iter().try_for_each(|a| atoms(a, out))
        }
        Math::Apply(op @ (Op::Gt | Op::Lt | Op::Geq | Op::Leq), args, _) => {
            if args.iter().any(has_jump) {
                return Err(format!(
                    "a trigger compares an expression that jumps (a piecewise or a truth value inside <{}>): hybc's guards are continuous",
                    op.name()
                ));
            }
            let a = strip(m);
            if !out.contains(&a) {
                out.push(a);
            }
            Ok(())
        }
        Math::Apply(op @ (Op::Eq | Op::Neq), ..) => Err(format!(
            "a trigger with <{}>: an equality holds at isolated instants, which hybc cannot locate as a crossing",
            op.name()
        )),
        Math::Piecewise(..) => Err("a <piecewise> as a trigger's truth value is not supported".to_string()),
        _ => Err("a trigger must be a truth value built from comparisons".to_string()),
    }
}

/// `m` with the atom `atom` replaced by `value`, folded.
fn with_atom(m: &Math, atom: &Math, value: bool) -> Math {
    fn go(m: &Math, atom: &Math, value: bool) -> Math {
        match m {
            Math::Apply(op, args, at) => {
                if op.is_relational() && strip(m) == *atom {
                    return Math::Bool(value);
                }
                Math::Apply(*op, args.iter().map(|a| go(a, atom, value)).collect(), *at)
            }
            other => other.clone(),
        }
    }
    fold(&go(m, atom, value))
}

/// The time of no pending execution: far beyond any simulated time, so `t >= e_due` never
/// crosses; not so far that a guard's round-off (16 eps |e_due|) or an enclosure near it
/// overflows.
pub(super) const IDLE: &str = "1e30";

/// What a trigger's events need: their guard's sides, direction, and enabling condition.
struct Crossing {
    a: Math,
    b: Math,
    up: bool,
    enable: Math,
}

/// The crossings at which `f` turns to `want` (true: the trigger fires; false: it stops holding),
/// each enabled where it does.
fn crossings(f: &Math, found: &[Math], want: bool) -> Vec<Crossing> {
    let mut out = Vec::new();
    for atom in found {
        let Math::Apply(op, args, _) = atom else { continue };
        for rising in [true, false] {
            let after = with_atom(f, atom, rising);
            let before = with_atom(f, atom, !rising);
            let (after, before) = if want { (after, before) } else { (not(after), not(before)) };
            let mut enable = fold(&Math::Apply(Op::And, vec![after, not(before)], 0));
            if enable == Math::Bool(false) {
                continue;
            }
            // `a > b` turns true as `a - b` rises through 0, `a < b` as it falls.
            let up = matches!(op, Op::Gt | Op::Geq) == rising;
            // Crossing onto the atom's inclusive side (`a >= b` rising, `a > b` falling): at the
            // start on a zero guard the atom already has its new value, so SBML compares it
            // with `initialValue` and fires there only through the `_start` event.
            if matches!(op, Op::Geq | Op::Leq) == rising && !apart_at_start(&args[0], &args[1]) {
                let later = Math::Apply(Op::Gt, vec![Math::Time, Math::Num(0.0)], 0);
                enable = fold(&Math::Apply(Op::And, vec![later, enable], 0));
            }
            out.push(Crossing { a: args[0].clone(), b: args[1].clone(), up, enable });
        }
    }
    out
}

/// Whether `a` and `b` differ at the start whatever the parameters (`t >= 0.99`: no guard on
/// zero at the start to worry about).
fn apart_at_start(a: &Math, b: &Math) -> bool {
    fn at_zero(m: &Math) -> Math {
        match m {
            Math::Time => Math::Num(0.0),
            Math::Apply(op, args, at) => Math::Apply(*op, args.iter().map(at_zero).collect(), *at),
            other => other.clone(),
        }
    }
    matches!((fold(&at_zero(a)), fold(&at_zero(b))), (Math::Num(x), Math::Num(y)) if x != y)
}

/// The symbols whose assignment rules jump, directly or through other rules: a guard that reads
/// one is not continuous (the suite's 00936: `S1 = piecewise(sin(10 t), t < 2, 1)`).
fn jumping_rules(sbml: &super::read::Sbml<'_, '_>) -> std::collections::HashSet<String> {
    let mut out = std::collections::HashSet::new();
    loop {
        let before = out.len();
        for r in &sbml.assignment_rules {
            let mut ids = Vec::new();
            super::order::names(&r.math, &mut ids);
            if has_jump(&r.math) || ids.iter().any(|id| out.contains(id)) {
                out.insert(r.variable.clone());
            }
        }
        if out.len() == before {
            return out;
        }
    }
}

/// The first symbol `atom` reads whose assignment rule jumps.
fn reads_jump(atom: &Math, jumps: &std::collections::HashSet<String>) -> Option<String> {
    let mut ids = Vec::new();
    super::order::names(atom, &mut ids);
    ids.into_iter().find(|id| jumps.contains(id))
}

fn not(m: Math) -> Math {
    fold(&Math::Apply(Op::Not, vec![m], 0))
}

/// What the events add to the model: event lines, and the states (with their flows) that
/// delayed events keep.
pub(super) struct Translated {
    pub events: Vec<String>,
    pub states: Vec<String>,
    pub ders: Vec<String>,
}

/// The `if` part of an event for `enable` (with `extra`, a condition text, and-ed to it).
fn enabling(
    tr: &mut Tr<'_, '_, '_>,
    enable: &Math,
    extra: Option<&str>,
    node: roxmltree::Node<'_, '_>,
) -> Option<String> {
    let mut parts = Vec::new();
    if *enable != Math::Bool(true) {
        let text = tr.condition(enable, node)?;
        // `or` binds loosest: a condition with one at its top is parenthesised before `and`.
        parts.push(if extra.is_some() && text.contains(" or ") { format!("({text})") } else { text });
    }
    parts.extend(extra.map(str::to_string));
    Some(if parts.is_empty() { String::new() } else { format!(" if {}", parts.join(" and ")) })
}

fn block(lines: &[String]) -> String {
    if lines.is_empty() {
        String::new()
    } else {
        format!(" {{\n{}\n}}", lines.iter().map(|l| format!("    {l}")).collect::<Vec<_>>().join("\n"))
    }
}

/// The hybc events of the model's SBML events.
pub(super) fn events(tr: &mut Tr<'_, '_, '_>) -> Option<Translated> {
    let sbml = tr.sbml;
    super::order::refuse_random_order(tr);
    let mut order: Vec<(usize, Option<f64>)> = Vec::new();
    for (i, e) in sbml.events.iter().enumerate() {
        let priority = match &e.priority {
            // Priorities only order events that fire together; one event has nothing to order.
            Some((node, m)) if sbml.events.len() > 1 => match fold(m) {
                Math::Num(p) if p.is_finite() => Some(p),
                _ => {
                    tr.refuse(*node, "a priority that is not a constant number: hybc orders simultaneous events by declaration, once");
                    None
                }
            },
            _ => None,
        };
        order.push((i, priority));
    }
    // Higher priorities first; events without one after them, in document order (SBML leaves
    // their order open).
    order.sort_by(|a, b| match (a.1, b.1) {
        (Some(x), Some(y)) => y.total_cmp(&x),
        (Some(_), None) => std::cmp::Ordering::Less,
        (None, Some(_)) => std::cmp::Ordering::Greater,
        (None, None) => std::cmp::Ordering::Equal,
    });
    super::order::refuse_sequential(tr, &order);
    super::order::refuse_retrigger(tr);
    let jumps = jumping_rules(sbml);
    let mut out = Translated { events: Vec::new(), states: Vec::new(), ders: Vec::new() };
    for (i, _) in order {
        let e = &sbml.events[i];
        let node = e.trigger_node;
        let mut found = Vec::new();
        if let Err(reason) = atoms(&e.trigger, &mut found) {
            tr.refuse(node, reason);
            continue;
        }
        if let Some(id) = found.iter().find_map(|a| reads_jump(a, &jumps)) {
            tr.refuse(node, format!("a trigger compares `{id}`, whose assignment rule jumps (a piecewise or a truth value): hybc's guards are continuous"));
            continue;
        }
        let base = match &e.id {
            Some(id) => tr.names.sbml(id),
            None => tr.names.fresh("event"),
        };
        // Each assignment: its target's name, its value, and (a concentration kept as an
        // amount) the compartment size it is multiplied by.
        let mut assigns: Vec<(String, Math, Option<Math>, roxmltree::Node<'_, '_>)> = Vec::new();
        for a in &e.assignments {
            let Some(sym) = tr.syms.get(&a.variable) else { continue };
            match (&sym.storage, sym.kind) {
                (Storage::Amount(amount), Kind::Species(k)) => {
                    // The amount is the value times the compartment's size before the event,
                    // even where the same event sets the size: SBML computes every assignment
                    // on the state before any (the suite's 01506, 01779, 01780).
                    let size = Math::Ci(sbml.species[k].compartment.clone());
                    assigns.push((amount.clone(), a.math.clone(), Some(size), a.node));
                }
                _ => assigns.push((sym.name.clone(), a.math.clone(), None, a.node)),
            }
        }
        let times = |v: Math, size: &Option<Math>| match size {
            Some(s) => Math::Apply(Op::Times, vec![v, s.clone()], 0),
            None => v,
        };
        // What the trigger's events do (execute, or schedule), and the pending test.
        let mut at_trigger = Vec::new();
        let mut pending = None;
        if let Some((dnode, delay)) = &e.delay {
            let due = tr.names.fresh(&format!("{base}_due"));
            out.states
                .push(format!("state {due} = {IDLE}  # when `{base}` executes ({IDLE}: nothing pending)"));
            out.ders.push(format!("der({due}) = 0"));
            let d = tr.dynamic(delay, *dnode, None)?;
            at_trigger.push(format!("{due} := t + {d}"));
            let mut exec = Vec::new();
            // The held values' names, read by the executing event's assignments.
            let mut held_names = std::collections::HashMap::new();
            for (k, (target, value, size, anode)) in assigns.iter().enumerate() {
                let value = if e.use_trigger_values {
                    let held = tr.names.fresh(&format!("{base}_value{}", k + 1));
                    out.states.push(format!(
                        "state {held} = 0  # `{target}` as `{base}` computed it when triggered"
                    ));
                    out.ders.push(format!("der({held}) = 0"));
                    let v = tr.dynamic(value, *anode, None)?;
                    at_trigger.push(format!("{held} := {v}"));
                    held_names.insert(held.clone(), held.clone());
                    Math::Ci(held)
                } else {
                    value.clone()
                };
                let v = tr.dynamic(&times(value, size), *anode, Some(&held_names))?;
                exec.push(format!("{target} := {v}"));
            }
            exec.push(format!("{due} := {IDLE}"));
            let name = tr.names.fresh(&format!("{base}_exec"));
            out.events.push(format!("# `{base}` executes its delayed assignments"));
            out.events.push(format!("event {name} when t >= {due}{}", block(&exec)));
            if !e.persistent {
                // A non-persistent trigger that stops holding cancels the pending execution.
                for c in crossings(&e.trigger, &found, false) {
                    let a = tr.dynamic(&c.a, node, None)?;
                    let b = tr.dynamic(&c.b, node, None)?;
                    let cond = enabling(tr, &c.enable, Some(&format!("{due} < {IDLE}")), node)?;
                    let name = tr.names.fresh(&format!("{base}_cancel"));
                    out.events.push(format!(
                        "event {name} when {a} {} {b}{cond}{}",
                        if c.up { ">=" } else { "<=" },
                        block(&[format!("{due} := {IDLE}")])
                    ));
                }
            }
            pending = Some(due);
        } else {
            for (target, value, size, anode) in &assigns {
                let v = tr.dynamic(&times(value.clone(), size), *anode, None)?;
                at_trigger.push(format!("{target} := {v}"));
            }
        }
        let idle = pending.as_ref().map(|due| format!("{due} > {IDLE} / 2"));
        let busy = pending.as_ref().map(|due| format!("{due} < {IDLE} / 2"));
        let mut first = true;
        for c in crossings(&e.trigger, &found, true) {
            let a = tr.dynamic(&c.a, node, None)?;
            let b = tr.dynamic(&c.b, node, None)?;
            let op = if c.up { ">=" } else { "<=" };
            let name = if first { base.clone() } else { tr.names.fresh(&base) };
            first = false;
            // The second-execution test first: events at one instant are judged in declaration
            // order, each on the state the ones before it left, and the scheduling event below
            // makes its own execution pending.
            if busy.is_some() {
                let cond = enabling(tr, &c.enable, busy.as_deref(), node)?;
                let queued = tr.names.fresh(&format!("{base}_queued"));
                out.events.push(format!(
                    "# `{base}` fires again before its pending execution: SBML queues a second one, hybc holds one\nevent {queued} when {a} {op} {b}{cond} {{\n    stop\n}}"
                ));
            }
            let cond = enabling(tr, &c.enable, idle.as_deref(), node)?;
            out.events.push(format!("event {name} when {a} {op} {b}{cond}{}", block(&at_trigger)));
        }
        if !e.initial_value {
            let holds = fold(&e.trigger);
            if holds != Math::Bool(false) {
                let name = tr.names.fresh(&format!("{base}_start"));
                let cond = enabling(tr, &holds, None, node)?;
                out.events.push(format!(
                    "# `{base}` holds at the start with initialValue=\"false\": it fires at t = 0"
                ));
                out.events.push(format!("event {name} when t >= 0{cond}{}", block(&at_trigger)));
            }
        }
    }
    Some(out)
}
