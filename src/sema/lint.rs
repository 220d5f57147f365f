//! Warnings about valid models that may not mean what they say (`hybc check` prints them).
//!
//! One today: events on the same guard fire as one group, in declaration order, and each
//! enabling condition is judged when its event's turn comes, after the resets of the events
//! before it (docs/language.md, `if C`). A condition that reads a state an earlier event on the
//! same guard resets therefore sees the reset value: intended for a flag, a surprise for the
//! bounce/settle pair written bounce first.

use super::model::{Event, Model};
use super::walk::{StatesRead, Walk};
use crate::diag::Diagnostic;

/// The warnings for a checked model, in declaration order of the events they are about.
pub fn warnings(model: &Model) -> Vec<Diagnostic> {
    let declared: Vec<&Event> = model.events.iter().filter(|e| !e.implicit).collect();
    let mut out = Vec::new();
    for (j, later) in declared.iter().enumerate() {
        let Some(cond) = &later.condition else { continue };
        let mut read = StatesRead::new(model.states.len());
        let _ = Walk::new().cond(cond, &mut read);
        for earlier in &declared[..j] {
            let shares_a_mode =
                earlier.owner.is_none() || later.owner.is_none() || earlier.owner == later.owner;
            // After a stop, or a switch to a mode without the later event, it is never judged.
            let leaves =
                earlier.is_stop || matches!((earlier.target, later.owner), (Some(m), Some(o)) if m != o);
            if !shares_a_mode || leaves || earlier.guard != later.guard {
                continue;
            }
            let reset: Vec<&str> = earlier
                .resets
                .iter()
                .filter(|(s, _)| read.by[s.0 as usize])
                .map(|(s, _)| model.states[s.0 as usize].name.as_str())
                .collect();
            if reset.is_empty() {
                continue;
            }
            let names = reset.iter().map(|n| format!("`{n}`")).collect::<Vec<_>>().join(", ");
            out.push(Diagnostic {
                message: format!(
                    "the condition of event `{}` reads {names}, which event `{}` on the same guard resets before it",
                    later.name, earlier.name
                ),
                span: later.span,
                label: format!("judged after `{}` fires at the same instant", earlier.name),
                notes: vec![format!(
                    "events on one guard fire in declaration order, each condition judged on the state the \
                     events before it left; declare `{}` before `{}` if its condition should see the state \
                     before the instant",
                    later.name, earlier.name
                )],
            });
        }
    }
    out
}
