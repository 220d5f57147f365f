//! The models an orbit is searched with, derived from the checked model (sema in, sema out; the
//! door compiles them): the return map's model, with the section's K-th firing made a `stop`
//! event; that model with one parameter per state as its initial value, whose gradient with
//! respect to those parameters is the monodromy matrix; and the model as written, seeded the
//! same way, whose run verifies a fixed point. In all three the section's firings at the start
//! of a run are not returns ([`START_WINDOW`]).

use super::PeriodicError;
use crate::sema::{self, Expr, ParamIdx};

/// The most firings of the section an orbit may hold (`--section EVENT#K`).
pub const MAX_FIRING: usize = 1000;

/// `EVENT` (its first firing) or `EVENT#K` (its K-th, K from 1 to [`MAX_FIRING`]), the spelling
/// of `hybc fit --target`.
pub fn parse_section(text: &str) -> Result<(String, usize), PeriodicError> {
    match text.split_once('#') {
        None => Ok((text.trim().to_string(), 1)),
        Some((event, k)) => {
            let firing = k
                .trim()
                .parse::<usize>()
                .ok()
                .filter(|k| (1..=MAX_FIRING).contains(k))
                .ok_or_else(|| PeriodicError::BadSection { text: text.to_string() })?;
            Ok((event.trim().to_string(), firing))
        }
    }
}

/// The section's firings within this much (times `max(|t_start|, 1)`) of the start of a run are
/// not returns: the run starts right after the section, so a firing there (rule 5 of
/// docs/language.md, a guard that the start state sits on and the flow carries across) is the one
/// it starts after. The integrator's own floor for a time interval it resolves (its shortest
/// retried step, its margin near a breakpoint) is the same `1e-9 max(|t|, 1)`: an orbit shorter
/// than that would be a firing at the start by another name.
pub const START_WINDOW: f64 = 1e-9;

/// The time before which the section's firings are not returns, for runs from `t_start`.
pub fn returns_after(t_start: f64) -> f64 {
    t_start + START_WINDOW * t_start.abs().max(1.0)
}

/// The models of an orbit search, and where the section stops them.
#[derive(Clone, Debug)]
pub struct SectionModels {
    /// The model with the section's `firing`-th firing a `stop` event: the return map is a run
    /// of it, and its initial state and sensitivities with respect to the free parameters start
    /// every Newton iterate.
    pub stopping: sema::Model,
    /// `stopping` with one parameter per state as that state's initial value (named `NAME(0)`):
    /// compiled with those as its gradient parameters, a run's total derivatives are the
    /// monodromy matrix.
    pub seeded: sema::Model,
    /// The model as written, seeded the same way, its section no `stop` and counted the way a
    /// reader of its events would count it: the run that verifies a fixed point before it is
    /// reported (its states and its step-size control are `seeded`'s, so where the orbit is right
    /// the two runs agree to round-off).
    pub verifying: sema::Model,
    /// Those parameters, in state order (the same in `seeded` and `verifying`).
    pub seeds: Vec<ParamIdx>,
    /// Where the return map stops, and which states its orbit has.
    pub section: Section,
}

/// Where a return map stops and which states its orbit has.
#[derive(Clone, Debug)]
pub struct Section {
    /// The section event's name, as the user wrote it (for messages).
    pub name: String,
    /// Which of its firings closes the orbit (1-based).
    pub firing: usize,
    /// The index of the event that stops the return map in `stopping` and `seeded`.
    pub index: usize,
    /// The index of the section in `verifying` (and in the model as written).
    pub event: usize,
    /// The states of the orbit: every state of the model but the quadrature ones (a running cost
    /// that no flow, guard or other state reads grows from period to period and is no part of
    /// the orbit). A counter of the section's firings follows the model's own states in the
    /// derived models, outside the orbit too.
    pub orbit: Vec<usize>,
    /// The model's own states: the fixed point reports these.
    pub n_states: usize,
}

/// The models of an orbit through the `firing`-th firing of the event named `section`, for runs
/// from `t_start`.
pub fn section_models(
    model: &sema::Model,
    section: &str,
    firing: usize,
    t_start: f64,
) -> Result<SectionModels, PeriodicError> {
    let event = model.events.iter().position(|e| e.name == section && !e.implicit).ok_or_else(|| {
        let known: Vec<&str> = model.events.iter().filter(|e| !e.implicit).map(|e| e.name.as_str()).collect();
        PeriodicError::NoSection { name: section.to_string(), known: known.join(", ") }
    })?;
    if firing == 0 || firing > MAX_FIRING {
        return Err(PeriodicError::BadFiring { firing, max: MAX_FIRING });
    }
    let after_start = sema::Cond::Cmp(sema::CmpOp::Gt, Expr::Time, Expr::Num(returns_after(t_start)));
    let (stopping, index) = stop_at_firing(model, event, firing, &after_start);
    let (verifying, _) = seeded(&counting(model, event, firing, &after_start).0);
    let (seeded, seeds) = seeded(&stopping);
    let quadrature = sema::quadrature_states(model);
    let orbit = (0..model.states.len()).filter(|&i| !quadrature[i]).collect();
    let section =
        Section { name: section.to_string(), firing, index, event, orbit, n_states: model.states.len() };
    Ok(SectionModels { stopping, seeded, verifying, seeds, section })
}

/// `own and extra`, or `extra` for an event without a condition.
fn and(own: &Option<sema::Cond>, extra: sema::Cond) -> Option<sema::Cond> {
    Some(match own {
        Some(c) => sema::Cond::And(Box::new(c.clone()), Box::new(extra)),
        None => extra,
    })
}

/// `model` with the section no `stop` and its firings in the start window passed over
/// (`after_start`). For a later firing than the first, a counter state (`der = 0`, starting at
/// 0, the last state) that the section adds 1 to: the return map's counter, here read by a
/// condition that always holds, so that the states, and which of them the step-size control
/// measures, are those of the return map's model. Returns the counter.
fn counting(
    model: &sema::Model,
    section: usize,
    firing: usize,
    after_start: &sema::Cond,
) -> (sema::Model, Option<sema::StateIdx>) {
    let mut m = model.clone();
    let ev = &mut m.events[section];
    ev.is_stop = false;
    ev.condition = and(&ev.condition, after_start.clone());
    if firing == 1 {
        return (m, None);
    }
    let count = sema::StateIdx(m.states.len() as u32);
    m.states.push(sema::State {
        name: format!("{}#count", m.events[section].name),
        init: Expr::Num(0.0),
        span: m.events[section].span,
    });
    for mode in &mut m.modes {
        mode.flows.push(Expr::Num(0.0));
    }
    let counted = &mut m.events[section];
    let always = sema::Cond::Cmp(sema::CmpOp::Gt, Expr::State(count), Expr::Num(-0.5));
    counted.condition = and(&counted.condition, always);
    let plus_one = Expr::Binary(sema::BinOp::Add, Box::new(Expr::State(count)), Box::new(Expr::Num(1.0)));
    counted.resets.push((count, plus_one));
    (m, Some(count))
}

/// `model` with the section's `firing`-th firing a `stop` event, and that event's index. Firings
/// in the start window are passed over (`after_start`). For the first, the section itself stops.
/// For a later one, the counter of [`counting`] counts the firings: the section fires as declared
/// (and adds 1) while fewer than `firing - 1` have fired, and a copy of it that stops fires
/// instead at the `firing`-th crossing (an enabling condition on the counter picks one of the
/// two). The copy is declared just before the section, so that at one instant it is judged
/// first, on the count before the section adds to it: judged after, at the `firing - 1`-th
/// crossing it saw the count the section had just raised and fired too (the kicked oscillator's
/// `kick#2` closed the orbit at its first kick, with the kick applied twice). A section declared
/// `stop` no longer stops before its `firing`-th firing.
fn stop_at_firing(
    model: &sema::Model,
    section: usize,
    firing: usize,
    after_start: &sema::Cond,
) -> (sema::Model, usize) {
    let (mut m, count) = counting(model, section, firing, after_start);
    let Some(count) = count else {
        m.events[section].is_stop = true;
        return (m, section);
    };
    // The counter is an integer: compare it half-way between two counts.
    let threshold = Expr::Num(firing as f64 - 1.5);
    let on_count = |op| sema::Cond::Cmp(op, Expr::State(count), threshold.clone());
    let declared = &model.events[section];
    let mut last = m.events[section].clone();
    last.condition = and(&and(&declared.condition, after_start.clone()), on_count(sema::CmpOp::Gt));
    last.resets = declared.resets.clone();
    last.is_stop = true;
    m.events[section].condition =
        and(&and(&declared.condition, after_start.clone()), on_count(sema::CmpOp::Lt));
    insert_event(&mut m, section, last);
    (m, section)
}

/// Inserts `event` at index `at`, just before the event there, in every mode that has that one:
/// the events after it move up by one (indices are declaration order, which orders the events
/// of one instant).
fn insert_event(m: &mut sema::Model, at: usize, event: sema::Event) {
    m.events.insert(at, event);
    for mode in &mut m.modes {
        let had = mode.events.contains(&sema::EventIdx(at as u32));
        for e in &mut mode.events {
            if e.0 as usize >= at {
                e.0 += 1;
            }
        }
        if had {
            mode.events.push(sema::EventIdx(at as u32));
            mode.events.sort();
        }
    }
}

/// The model with one parameter per state as its initial value (named `NAME(0)`): its
/// gradient with respect to those is the monodromy matrix.
fn seeded(model: &sema::Model) -> (sema::Model, Vec<ParamIdx>) {
    let mut m = model.clone();
    let mut seeds = Vec::with_capacity(m.states.len());
    for i in 0..m.states.len() {
        let idx = ParamIdx(m.params.len() as u32);
        m.params.push(sema::Param {
            name: format!("{}(0)", m.states[i].name),
            default: 0.0,
            range: None,
            span: m.states[i].span,
        });
        m.states[i].init = Expr::Param(idx);
        seeds.push(idx);
    }
    (m, seeds)
}
