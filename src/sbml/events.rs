//! SBML events -> hybc events. A trigger is a truth value built from comparisons (its atoms)
//! with `and`, `or`, `not`, `xor`, `implies`; it fires when it goes from false to true. It can
//! do so only where one atom crosses, so each atom gives an event on its guard in each
//! direction in which its crossing can turn the trigger true, enabled where it does: for atom
//! `a` rising, `F[a := true] and not F[a := false]` (the other atoms as conditions). A trigger
//! with `initialValue="false"` that holds at the start fires there: one more event at `t >= 0`
//! enabled by the whole trigger. Constant priorities order the events (hybc fires simultaneous
//! events in declaration order).

use super::math::{fold, Math, Op};
use super::print;
use super::translate::{has_jump, Storage, Tr};

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
fn atoms(m: &Math, out: &mut Vec<Math>) -> Result<(), String> {
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

/// The hybc events of the model's SBML events, as lines of text.
pub(super) fn events(tr: &mut Tr<'_, '_, '_>) -> Option<Vec<String>> {
    let sbml = tr.sbml;
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
    let mut lines = Vec::new();
    for (i, _) in order {
        let e = &sbml.events[i];
        if let Some((node, _)) = &e.delay {
            tr.refuse(*node, "event delays are not translated yet");
            continue;
        }
        let base = match &e.id {
            Some(id) => tr.names.sbml(id),
            None => tr.names.fresh("event"),
        };
        let mut resets = Vec::new();
        for a in &e.assignments {
            let Some(sym) = tr.syms.get(&a.variable) else { continue };
            let (name, storage, kind) = (sym.name.clone(), sym.storage.clone(), sym.kind);
            let (target, value) = match storage {
                Storage::Amount(amount) => {
                    // A concentration set: the amount is the new concentration times the
                    // compartment's size after the event (set by this event too, or unchanged).
                    let super::translate::Kind::Species(k) = kind else { continue };
                    let c = &sbml.species[k].compartment;
                    let size = e
                        .assignments
                        .iter()
                        .find(|b| &b.variable == c)
                        .map_or(Math::Ci(c.clone()), |b| b.math.clone());
                    (amount, Math::Apply(Op::Times, vec![a.math.clone(), size], 0))
                }
                _ => (name, a.math.clone()),
            };
            let text = tr.dynamic(&value, a.node, None)?;
            resets.push(format!("    {target} := {text}"));
        }
        let block = if resets.is_empty() { String::new() } else { format!(" {{\n{}\n}}", resets.join("\n")) };
        let mut found = Vec::new();
        if let Err(reason) = atoms(&e.trigger, &mut found) {
            tr.refuse(e.trigger_node, reason);
            continue;
        }
        let mut first = true;
        for atom in &found {
            let Math::Apply(op, args, _) = atom else { continue };
            for rising in [true, false] {
                let enable = fold(&Math::Apply(
                    Op::And,
                    vec![
                        with_atom(&e.trigger, atom, rising),
                        Math::Apply(Op::Not, vec![with_atom(&e.trigger, atom, !rising)], 0),
                    ],
                    0,
                ));
                if enable == Math::Bool(false) {
                    continue;
                }
                // `a > b` turns true as `a - b` rises through 0, `a < b` as it falls.
                let up = matches!(op, Op::Gt | Op::Geq) == rising;
                let a = tr.dynamic(&args[0], e.trigger_node, None)?;
                let b = tr.dynamic(&args[1], e.trigger_node, None)?;
                let name = if first { base.clone() } else { tr.names.fresh(&base) };
                first = false;
                // Crossing onto the atom's inclusive side (`a >= b` rising, `a > b` falling): at the
                // start on a zero guard the atom already has its new value, so SBML compares it
                // with `initialValue` and fires there only through the `_start` event below.
                let inclusive = matches!(op, Op::Geq | Op::Leq) == rising;
                let enable = if inclusive {
                    let later = Math::Apply(Op::Gt, vec![Math::Time, Math::Num(0.0)], 0);
                    fold(&Math::Apply(Op::And, vec![later, enable], 0))
                } else {
                    enable
                };
                let cond = if enable == Math::Bool(true) {
                    String::new()
                } else {
                    format!(" if {}", tr.condition(&enable, e.trigger_node)?)
                };
                lines
                    .push(format!("event {name} when {a} {} {b}{cond}{block}", if up { ">=" } else { "<=" }));
            }
        }
        if !e.initial_value {
            let holds = fold(&e.trigger);
            if holds != Math::Bool(false) {
                let name = tr.names.fresh(&format!("{base}_start"));
                let cond = if holds == Math::Bool(true) {
                    String::new()
                } else {
                    format!(" if {}", tr.condition(&holds, e.trigger_node)?)
                };
                lines.push(format!(
                    "# `{base}` holds at the start with initialValue=\"false\": it fires at t = 0\nevent {name} when t >= 0{cond}{block}"
                ));
            }
        }
        let _ = print::MAX_TEXT;
    }
    Some(lines)
}
