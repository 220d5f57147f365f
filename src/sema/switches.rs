//! Flow switches: the surfaces where a mode's flow jumps, as implicit events.
//!
//! A flow with `if C then A else B` or `sign(a)` is discontinuous where a comparison of `C` or
//! `a` changes sign. When that surface moves with the parameters, the sensitivities jump there by
//! `(f- - f+) dt/dp`, exactly as at a mode switch; integrating through without that jump gives a
//! silently wrong gradient. So every such switch function that depends on `t` or a state becomes
//! an event of its mode: guard `lhs - rhs` (or `a`), either direction, no reset, no mode change.
//! The integrator locates it like any event and applies the saltation with the flow on each side
//! (`sim::EventInfo::implicit`), but does not report it as an event.
//!
//! `min`, `max` and `abs` are continuous: their kinks change no sensitivity and need no event.

use super::model::{Cond, Direction, Event, EventIdx, Expr, Func, Model};

/// Appends the flow switches of every mode to `model.events` (after all declared events, so
/// declared events fire first at a shared instant) and to the mode's event list.
pub(crate) fn add_flow_switches(model: &mut Model) {
    for m in 0..model.modes.len() {
        let mut guards: Vec<Expr> = Vec::new();
        for flow in &model.modes[m].flows {
            collect(flow, &mut guards);
        }
        let mode = &model.modes[m];
        let count = guards.len();
        let new_events: Vec<Event> = guards
            .into_iter()
            .enumerate()
            .map(|(k, guard)| Event {
                name: if count == 1 {
                    format!("flow switch of mode {}", mode.name)
                } else {
                    format!("flow switch {} of mode {}", k + 1, mode.name)
                },
                guard,
                direction: Direction::Either,
                condition: None,
                resets: Vec::new(),
                target: None,
                is_stop: false,
                owner: Some(super::ModeId(m as u16)),
                span: mode.span,
                implicit: true,
            })
            .collect();
        for event in new_events {
            model.modes[m].events.push(EventIdx(model.events.len() as u32));
            model.events.push(event);
        }
    }
}

/// Whether `e` jumps somewhere in time or the state: it has an `if` comparison or a `sign`
/// argument that moves with them (a guard like that is refused, see `check`).
pub(crate) fn jumps(e: &Expr) -> bool {
    let mut found = Vec::new();
    collect(e, &mut found);
    !found.is_empty()
}

/// The switch functions in `e` that move with time or state, without repeats.
fn collect(e: &Expr, out: &mut Vec<Expr>) {
    match e {
        Expr::Num(_) | Expr::State(_) | Expr::Param(_) | Expr::Time => {}
        Expr::Neg(a) => collect(a, out),
        Expr::Binary(_, a, b) => {
            collect(a, out);
            collect(b, out);
        }
        Expr::Call(func, args) => {
            if let (Func::Sign, Some(a)) = (func, args.first()) {
                push(a.clone(), out);
            }
            for a in args {
                collect(a, out);
            }
        }
        Expr::If(c, a, b) => {
            collect_cond(c, out);
            collect(a, out);
            collect(b, out);
        }
    }
}

fn collect_cond(c: &Cond, out: &mut Vec<Expr>) {
    match c {
        Cond::Cmp(_, l, r) => {
            collect(l, out);
            collect(r, out);
            push(Expr::Binary(super::BinOp::Sub, Box::new(l.clone()), Box::new(r.clone())), out);
        }
        Cond::And(a, b) | Cond::Or(a, b) => {
            collect_cond(a, out);
            collect_cond(b, out);
        }
        Cond::Not(a) => collect_cond(a, out),
    }
}

fn push(guard: Expr, out: &mut Vec<Expr>) {
    if moves(&guard) && !out.contains(&guard) {
        out.push(guard);
    }
}

/// Whether `e` mentions `t` or a state (a switch of parameters alone never moves in time).
fn moves(e: &Expr) -> bool {
    match e {
        Expr::Num(_) | Expr::Param(_) => false,
        Expr::State(_) | Expr::Time => true,
        Expr::Neg(a) => moves(a),
        Expr::Binary(_, a, b) => moves(a) || moves(b),
        Expr::Call(_, args) => args.iter().any(moves),
        Expr::If(c, a, b) => cond_moves(c) || moves(a) || moves(b),
    }
}

fn cond_moves(c: &Cond) -> bool {
    match c {
        Cond::Cmp(_, l, r) => moves(l) || moves(r),
        Cond::And(a, b) | Cond::Or(a, b) => cond_moves(a) || cond_moves(b),
        Cond::Not(a) => cond_moves(a),
    }
}
