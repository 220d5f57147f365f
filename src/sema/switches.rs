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
//!
//! Inputs (`pwl`, `pwc`) in a mode's flows add one implicit event per knot, guard `s - k` on the
//! input's knot position `s` (`Input::position`), which is a time event: its time
//! `t0 + k (t1 - t0) / spacings` is a breakpoint computed from the parameters at the run's start.
//! A `pwc` knot is a flow switch (the flow jumps there, and a knot that moves with a parameter
//! moves the sensitivities by `(f- - f+) dt_k/dp`); a `pwl` knot is a kink (`Event::kink`): the
//! steps land on it so that none straddles it, and nothing jumps.

use std::collections::{HashMap, HashSet};

use super::model::{
    Cond, Direction, Event, EventIdx, Expr, Func, Input, InputKind, Knot, ModeId, Model, Shared, SharedDef,
};

/// Appends the flow switches of every mode to `model.events` (after all declared events, so
/// declared events fire first at a shared instant) and to the mode's event list.
pub(crate) fn add_flow_switches(model: &mut Model) {
    for m in 0..model.modes.len() {
        let mut switches = Switches::default();
        for flow in &model.modes[m].flows {
            switches.collect(flow);
        }
        let guards = switches.found;
        let mode = &model.modes[m];
        let count = guards.len();
        let mut new_events: Vec<Event> = guards
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
                knot: None,
            })
            .collect();
        for input in &switches.inputs {
            new_events.extend(knot_events(model, ModeId(m as u16), input));
        }
        for event in new_events {
            model.modes[m].events.push(EventIdx(model.events.len() as u32));
            model.events.push(event);
        }
    }
}

/// The knots of `input` in `mode`'s flows as implicit time events (see the module comment).
fn knot_events(model: &Model, mode: ModeId, input: &Input) -> Vec<Event> {
    let vector = model.vectors.iter().find(|v| v.first == input.first).map_or("?", |v| v.name.as_str());
    let (func, mode_name, span) =
        (input.kind.name(), &model.modes[mode.0 as usize].name, model.modes[mode.0 as usize].span);
    // One position for all the knots, lowered once; the value's own is the same node (hash-consing),
    // so the guards and the value agree on the side of every knot to the last bit.
    let position = Expr::Shared(Shared::new(input.position()));
    input
        .knots()
        .map(|k| Event {
            name: format!("knot {k} of {func}(t, .., {vector}) in mode {mode_name}"),
            guard: Expr::Binary(
                super::BinOp::Sub,
                Box::new(position.clone()),
                Box::new(Expr::Num(f64::from(k))),
            ),
            direction: Direction::Either,
            condition: None,
            resets: Vec::new(),
            target: None,
            is_stop: false,
            owner: Some(mode),
            span,
            implicit: true,
            knot: Some(Knot { kind: input.kind, k, position: position.clone(), vector: vector.to_string() }),
        })
        .collect()
}

/// Whether `e` jumps somewhere in time or the state: it has an `if` comparison or a `sign`
/// argument that moves with them (a guard like that is refused, see `check`).
pub(crate) fn jumps(e: &Expr) -> bool {
    let mut switches = Switches::default();
    switches.collect(e);
    !switches.found.is_empty()
}

/// Whether `e` reads a `pwc` input (a guard like that jumps at its knots and is refused).
pub(crate) fn reads_pwc(e: &Expr) -> bool {
    let mut switches = Switches::default();
    switches.collect(e);
    switches.inputs.iter().any(|i| i.kind == InputKind::Pwc)
}

/// The switch functions found so far, without repeats, and what has been learnt about shared
/// `let` definitions: each is searched once and its `moves` answer kept, so a model whose `let`s
/// share subexpressions costs its size, not the size of the expanded tree.
#[derive(Default)]
struct Switches {
    found: Vec<Expr>,
    /// The inputs found, without repeats: their knots are implicit events too.
    inputs: Vec<Input>,
    searched: HashSet<*const SharedDef>,
    moving: HashMap<*const SharedDef, bool>,
}

impl Switches {
    fn collect(&mut self, e: &Expr) {
        match e {
            Expr::Num(_) | Expr::State(_) | Expr::Param(_) | Expr::Time => {}
            Expr::Shared(s) => {
                if self.searched.insert(s.key()) {
                    crate::stack::deep(|| self.collect(s.expr()));
                }
            }
            Expr::Neg(a) => self.collect(a),
            Expr::Binary(_, a, b) => {
                self.collect(a);
                self.collect(b);
            }
            Expr::Call(func, args) => {
                if let (Func::Sign, Some(a)) = (func, args.first()) {
                    self.push(a.clone());
                }
                for a in args {
                    self.collect(a);
                }
            }
            Expr::If(c, a, b) => {
                self.collect_cond(c);
                self.collect(a);
                self.collect(b);
            }
            Expr::Input(input) => {
                if !self.inputs.contains(input) {
                    self.inputs.push((**input).clone());
                }
            }
        }
    }

    fn collect_cond(&mut self, c: &Cond) {
        match c {
            Cond::Cmp(_, l, r) => {
                self.collect(l);
                self.collect(r);
                self.push(Expr::Binary(super::BinOp::Sub, Box::new(l.clone()), Box::new(r.clone())));
            }
            Cond::And(a, b) | Cond::Or(a, b) => {
                self.collect_cond(a);
                self.collect_cond(b);
            }
            Cond::Not(a) => self.collect_cond(a),
        }
    }

    fn push(&mut self, guard: Expr) {
        if self.moves(&guard) && !self.found.contains(&guard) {
            self.found.push(guard);
        }
    }

    /// Whether `e` mentions `t` or a state (a switch of parameters alone never moves in time).
    fn moves(&mut self, e: &Expr) -> bool {
        match e {
            Expr::Num(_) | Expr::Param(_) => false,
            Expr::State(_) | Expr::Time => true,
            Expr::Shared(s) => {
                if let Some(&known) = self.moving.get(&s.key()) {
                    return known;
                }
                let known = crate::stack::deep(|| self.moves(s.expr()));
                self.moving.insert(s.key(), known);
                known
            }
            Expr::Neg(a) => self.moves(a),
            Expr::Binary(_, a, b) => self.moves(a) || self.moves(b),
            Expr::Call(_, args) => args.iter().any(|a| self.moves(a)),
            Expr::If(c, a, b) => self.cond_moves(c) || self.moves(a) || self.moves(b),
            Expr::Input(_) => true,
        }
    }

    fn cond_moves(&mut self, c: &Cond) -> bool {
        match c {
            Cond::Cmp(_, l, r) => self.moves(l) || self.moves(r),
            Cond::And(a, b) | Cond::Or(a, b) => self.cond_moves(a) || self.cond_moves(b),
            Cond::Not(a) => self.cond_moves(a),
        }
    }
}
