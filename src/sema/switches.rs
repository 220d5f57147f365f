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
//! `min`, `max` and `abs` are continuous, but where their arguments cross (`max(a, b)` at
//! `a - b = 0`, `abs(a)` at `a = 0`) the flow's derivatives jump, and so does the flow of the
//! sensitivities (`d max(ramp t - 0.1, 0) / d ramp` is `t` on one side, 0 on the other): a step
//! that straddles such a kink is as inaccurate as its error estimate is blind to it, and the error
//! control crept up on one in dozens of rejected steps. So each kink that moves is a switch too
//! (`Event::kink`), named `kink of mode M`: located, landed on, crossed; nothing jumps there.
//!
//! Inputs (`pwl`, `pwc`) in a mode's flows are not events: their knots are listed with the mode
//! (`Mode::inputs`), and the integrator keeps their times, computed from the parameters when a
//! run starts, as a queue of breakpoints (`sim::breakpoints`). A `pwc` knot is a flow switch at a
//! time known in advance (the flow jumps there, and a knot that moves with a parameter moves the
//! sensitivities by `(f- - f+) dt_k/dp`); a `pwl` knot is a kink: the steps land on it so that
//! none straddles it, and nothing jumps. Nothing per knot is made here, so a control of 10,000
//! knots costs the model what one of 10 does.

use std::convert::Infallible;
use std::ops::ControlFlow;

use super::model::{Direction, Event, EventIdx, Expr, Func, Input, InputKind, Model};
use super::walk::{Descend, Visit, Walk};

/// Appends the flow switches of every mode to `model.events` (after all declared events, so
/// declared events fire first at a shared instant) and to the mode's event list, and lists the
/// inputs its flows read in `Mode::inputs`.
pub(crate) fn add_flow_switches(model: &mut Model) {
    for m in 0..model.modes.len() {
        let (mut walk, mut switches) = (Walk::new(), Switches::new());
        for flow in &model.modes[m].flows {
            let _ = walk.expr(flow, &mut switches);
        }
        let switches_found = switches.found.len();
        let mut guards = switches.found;
        for kink in switches.kinks {
            // A kink on the surface of a switch already found (`max(0, -y)` beside `if y < 0`)
            // is crossed with it.
            if !guards.iter().any(|g| zero_set_form(g) == kink) {
                guards.push(kink);
            }
        }
        let mode = &model.modes[m];
        let kinks = guards.len() - switches_found;
        let name = |k: usize| {
            let (what, k, count) = if k < switches_found {
                ("flow switch", k, switches_found)
            } else {
                ("kink", k - switches_found, kinks)
            };
            if count == 1 {
                format!("{what} of mode {}", mode.name)
            } else {
                format!("{what} {} of mode {}", k + 1, mode.name)
            }
        };
        let new_events: Vec<Event> = guards
            .into_iter()
            .enumerate()
            .map(|(k, guard)| Event {
                name: name(k),
                guard,
                direction: Direction::Either,
                condition: None,
                resets: Vec::new(),
                target: None,
                is_stop: false,
                owner: Some(super::ModeId(m as u16)),
                span: mode.span,
                implicit: true,
                kink: k >= switches_found,
            })
            .collect();
        model.modes[m].inputs = switches.inputs;
        for event in new_events {
            model.modes[m].events.push(EventIdx(model.events.len() as u32));
            model.events.push(event);
        }
    }
}

/// `e` without what leaves the set where it is zero unchanged: a negation, and a zero added or
/// subtracted (`0 - -y` and `y - 0` are both `y`), so that a kink and a switch on one surface are
/// found to be one.
fn zero_set_form(e: &Expr) -> Expr {
    let zero = |e: &Expr| matches!(e, Expr::Num(v) if *v == 0.0);
    match e {
        Expr::Neg(a) => zero_set_form(a),
        Expr::Binary(super::BinOp::Sub | super::BinOp::Add, a, b) if zero(b) => zero_set_form(a),
        Expr::Binary(super::BinOp::Sub | super::BinOp::Add, a, b) if zero(a) => zero_set_form(b),
        _ => e.clone(),
    }
}

/// Whether `e` jumps somewhere in time or the state: it has an `if` comparison or a `sign`
/// argument that moves with them (a guard like that is refused, see `check`).
pub(crate) fn jumps(e: &Expr) -> bool {
    let mut switches = Switches::new();
    let _ = Walk::new().expr(e, &mut switches);
    !switches.found.is_empty()
}

/// Whether `e` reads a `pwc` input (a guard like that jumps at its knots and is refused).
pub(crate) fn reads_pwc(e: &Expr) -> bool {
    let mut switches = Switches::new();
    let _ = Walk::new().expr(e, &mut switches);
    switches.inputs.iter().any(|i| i.kind == InputKind::Pwc)
}

/// The switch functions found so far, without repeats, and what has been learnt about shared
/// `let` definitions: each is searched once (the [`Walk`] a caller keeps across a mode's flows),
/// and whether it moves is answered once (`moving`, kept across every candidate), so a model
/// whose `let`s share subexpressions costs its size, not the size of the expanded tree.
struct Switches {
    found: Vec<Expr>,
    /// Where a `min`, `max` or `abs` that moves has its kink: the flow is continuous there, but
    /// its derivatives jump (the sensitivities' flow too), so a step that straddles one is as
    /// inaccurate as its error estimate is blind to it, and the error control crept up on the
    /// engine's throttle kink in 75 rejected steps. They are switches whose jump is zero.
    kinks: Vec<Expr>,
    /// The inputs found, without repeats: their knots are the mode's breakpoints.
    inputs: Vec<Input>,
    moving: Walk<()>,
}

impl Switches {
    fn new() -> Switches {
        Switches { found: Vec::new(), kinks: Vec::new(), inputs: Vec::new(), moving: Walk::new() }
    }

    fn push(&mut self, guard: Expr) {
        if self.moves(&guard) && !self.found.contains(&guard) {
            self.found.push(guard);
        }
    }

    fn push_kink(&mut self, guard: Expr) {
        let guard = zero_set_form(&guard);
        if self.moves(&guard) && !self.kinks.contains(&guard) {
            self.kinks.push(guard);
        }
    }

    /// Whether `e` mentions `t`, a state or an input (a switch of parameters alone never moves
    /// in time).
    fn moves(&mut self, e: &Expr) -> bool {
        struct Moves;
        impl Visit for Moves {
            type Break = ();
            fn expr(&mut self, e: &Expr) -> ControlFlow<(), Descend> {
                match e {
                    Expr::State(_) | Expr::Time | Expr::Input(_) => ControlFlow::Break(()),
                    _ => ControlFlow::Continue(Descend::Into),
                }
            }
        }
        self.moving.expr(e, &mut Moves).is_break()
    }
}

impl Visit for Switches {
    type Break = Infallible;

    fn expr(&mut self, e: &Expr) -> ControlFlow<Infallible, Descend> {
        match e {
            Expr::Call(Func::Sign, args) => {
                if let Some(a) = args.first() {
                    self.push(a.clone());
                }
            }
            Expr::Call(Func::Abs, args) => {
                if let Some(a) = args.first() {
                    self.push_kink(a.clone());
                }
            }
            Expr::Call(Func::Min | Func::Max, args) => {
                if let [a, b] = &args[..] {
                    self.push_kink(Expr::Binary(super::BinOp::Sub, Box::new(a.clone()), Box::new(b.clone())));
                }
            }
            // An input's knots are its switches; its window reads parameters only.
            Expr::Input(input) => {
                // A `pwc` of one value never jumps: it has no knots.
                if !input.knots().is_empty() && !self.inputs.contains(input) {
                    self.inputs.push((**input).clone());
                }
                return ControlFlow::Continue(Descend::Over);
            }
            _ => {}
        }
        ControlFlow::Continue(Descend::Into)
    }

    fn comparison(&mut self, lhs: &Expr, rhs: &Expr) -> ControlFlow<Infallible> {
        self.push(Expr::Binary(super::BinOp::Sub, Box::new(lhs.clone()), Box::new(rhs.clone())));
        ControlFlow::Continue(())
    }
}
