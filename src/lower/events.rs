//! Stage 3b (lower): what the integrator needs to know about each event beyond its functions,
//! read off their symbolic form: the guard's shape (affine, a time event, or nonlinear) and
//! whether the event is a contact (its reset acts on the guard's motion).

use crate::expr::{ExprId, ModelFunctions, Node};
use crate::sim::{GuardShape, SystemInfo};

/// Fills `guard` and `contact` of every event of `info` (which must describe the model of
/// `funcs`).
pub fn classify_events(funcs: &ModelFunctions, info: &mut SystemInfo) {
    let store = &funcs.store;
    // Constant along a trajectory: reads neither the time nor a state (parameters are fixed).
    let is_const = |id: ExprId| {
        crate::expr::eval::reachable(store, &[id])
            .iter()
            .all(|&n| !matches!(store.node(n), Node::State(_) | Node::Time))
    };
    for (e, ev) in funcs.events.iter().enumerate() {
        if e >= info.events.len() {
            continue;
        }
        let affine = ev.guard_x.entries.iter().all(|&(_, d)| is_const(d)) && is_const(ev.guard_t);
        // A time event: `g_x` is zero and `g_t` a non-zero constant of the parameters (a literal
        // zero slope is never a time event; a slope that is zero for some parameter values has
        // its time computed as +-inf or NaN, which lands nowhere).
        let time_slope = store.node(ev.guard_t).as_const().is_none_or(|c| c != 0.0);
        let shape = match (affine, ev.guard_x.entries.is_empty(), time_slope) {
            (true, true, true) => GuardShape::Time,
            (true, _, _) => GuardShape::Affine,
            (false, _, _) => GuardShape::Nonlinear,
        };
        // The states the guard and its speed read: those of `g`, of `g_t`, and of the flow of
        // every state the guard reads, in every mode where the event is active.
        let mut read = vec![false; funcs.n_states as usize];
        let mut mark = |roots: &[ExprId]| {
            for id in crate::expr::eval::reachable(store, roots) {
                if let Node::State(i) = *store.node(id) {
                    if let Some(r) = read.get_mut(i as usize) {
                        *r = true;
                    }
                }
            }
        };
        mark(&[ev.guard, ev.guard_t]);
        for (m, mode) in info.modes.iter().enumerate() {
            if !mode.events.contains(&e) {
                continue;
            }
            if let Some(flows) = funcs.modes.get(m) {
                let flows: Vec<ExprId> = ev
                    .guard_x
                    .entries
                    .iter()
                    .filter_map(|&(i, _)| flows.flow.get(i as usize).copied())
                    .collect();
                mark(&flows);
            }
        }
        let assigns = |j: usize| ev.reset.get(j).is_some_and(|&r| *store.node(r) != Node::State(j as u32));
        let contact = (0..read.len()).any(|j| read[j] && assigns(j));
        info.events[e].guard = shape;
        info.events[e].contact = contact;
    }
}
