//! The models an orbit is searched with, derived from the checked model (sema in, sema out; the
//! door compiles them): the return map's model, with the section's K-th firing made a `stop`
//! event, and that model with one parameter per state as its initial value, whose gradient with
//! respect to those parameters is the monodromy matrix.

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

/// The two models of an orbit search, and where the section stops them.
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
    /// Those parameters, in state order.
    pub seeds: Vec<ParamIdx>,
    /// Where the return map stops, and which states its orbit has.
    pub section: Section,
}

/// Where a return map stops and which states its orbit has.
#[derive(Clone, Debug)]
pub struct Section {
    /// The section event's name, as the user wrote it (for messages).
    pub name: String,
    /// The index of the event that stops the return map, in both derived models.
    pub index: usize,
    /// The states of the orbit: every state of the model but the quadrature ones (a running cost
    /// that no flow, guard or other state reads grows from period to period and is no part of
    /// the orbit). A counter of the section's firings follows the model's own states in the
    /// derived models, outside the orbit too.
    pub orbit: Vec<usize>,
    /// The model's own states: the fixed point reports these.
    pub n_states: usize,
}

/// The models of an orbit through the `firing`-th firing of the event named `section`.
pub fn section_models(
    model: &sema::Model,
    section: &str,
    firing: usize,
) -> Result<SectionModels, PeriodicError> {
    let event = model.events.iter().position(|e| e.name == section).ok_or_else(|| {
        let known: Vec<&str> = model.events.iter().filter(|e| !e.implicit).map(|e| e.name.as_str()).collect();
        PeriodicError::NoSection { name: section.to_string(), known: known.join(", ") }
    })?;
    if firing == 0 || firing > MAX_FIRING {
        return Err(PeriodicError::BadFiring { firing, max: MAX_FIRING });
    }
    let (stopping, index) = stop_at_firing(model, event, firing);
    let (seeded, seeds) = seeded(&stopping);
    let quadrature = sema::quadrature_states(model);
    let orbit = (0..model.states.len()).filter(|&i| !quadrature[i]).collect();
    let section = Section { name: section.to_string(), index, orbit, n_states: model.states.len() };
    Ok(SectionModels { stopping, seeded, seeds, section })
}

/// `model` with the section's `firing`-th firing a `stop` event, and that event's index. For the
/// first, the section itself stops. For a later one, a counter state (`der = 0`, starting at 0)
/// counts the firings: the section fires as declared (and adds 1) while fewer than `firing - 1`
/// have fired, and a copy of it that stops fires instead at the `firing`-th crossing (an
/// enabling condition on the counter, evaluated just before the event, picks one of the two).
/// The counter is the last state; the analysis leaves it out of the orbit. A section declared
/// `stop` no longer stops before its `firing`-th firing.
fn stop_at_firing(model: &sema::Model, section: usize, firing: usize) -> (sema::Model, usize) {
    let mut m = model.clone();
    if firing == 1 {
        m.events[section].is_stop = true;
        return (m, section);
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
    // The counter is an integer: compare it half-way between two counts.
    let threshold = Expr::Num(firing as f64 - 1.5);
    let enabled = |op, own: &Option<sema::Cond>| {
        let on_count = sema::Cond::Cmp(op, Expr::State(count), threshold.clone());
        Some(match own {
            Some(c) => sema::Cond::And(Box::new(c.clone()), Box::new(on_count)),
            None => on_count,
        })
    };
    let mut last = m.events[section].clone();
    last.condition = enabled(sema::CmpOp::Gt, &last.condition);
    last.is_stop = true;
    let counted = &mut m.events[section];
    // A section declared `stop` walks on until its `firing`-th firing, which the copy stops.
    counted.is_stop = false;
    counted.condition = enabled(sema::CmpOp::Lt, &counted.condition);
    let plus_one = Expr::Binary(sema::BinOp::Add, Box::new(Expr::State(count)), Box::new(Expr::Num(1.0)));
    counted.resets.push((count, plus_one));
    let stop = m.events.len();
    m.events.push(last);
    let stop_idx = sema::EventIdx(stop as u32);
    for mode in &mut m.modes {
        if mode.events.contains(&sema::EventIdx(section as u32)) {
            mode.events.push(stop_idx);
        }
    }
    (m, stop)
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
