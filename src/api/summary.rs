//! What the command line prints about a model without running it: `hybc check`'s summary (names,
//! flows, events, flow switches, input knots, outputs) and `hybc derive`'s derivatives, through
//! the door, so that a front end needs neither `lower` nor the checked model's walkers.

use std::fmt::Write;

use super::Model;
use crate::lower::{derive_report, derive_report_only, lower, ExprPrinter, Only};
use crate::sema::{self, Direction, ModeId, ParamIdx};

impl Model {
    /// The summary `hybc check` prints for a valid model: counts, parameters (a vector on one
    /// line), states, each mode's flows, events, flow switches, input knots, outputs.
    pub fn summary(&self) -> String {
        summary(self.checked())
    }

    /// Every symbolic derivative of the model's functions with respect to `wrt`, as `hybc
    /// derive` prints them; only mode `mode`'s (and the model-level events) when given.
    pub fn derivatives(&self, wrt: &[ParamIdx], mode: Option<ModeId>) -> String {
        let checked = self.checked();
        derive_report(checked, &lower(checked), wrt, mode)
    }

    /// [`Self::derivatives`] of only the states, events and outputs `names` select (`hybc derive
    /// --only`): each name is a state, event or output (`v[3]`, `low[3]`, `ke`), an array or
    /// family whole (`v`, `low`), or elements by ranges, inclusive as `hybc check` prints them
    /// (`low[2..5]`, `T[1][0..2]`). A name that selects nothing is an error naming it.
    pub fn derivatives_only(
        &self,
        wrt: &[ParamIdx],
        mode: Option<ModeId>,
        names: &[&str],
    ) -> Result<String, String> {
        let checked = self.checked();
        let only = select(checked, names)?;
        Ok(derive_report_only(checked, &lower(checked), wrt, mode, &only))
    }
}

/// One bracket of a `--only` pattern: an index or an inclusive range.
type Bracket = std::ops::RangeInclusive<i64>;

/// `low[2..5]` -> `("low", [2..=5])`, `v[3]` -> `("v", [3..=3])`, `ke` -> `("ke", [])`; `None` if
/// the brackets do not read as indices or ranges.
fn pattern(text: &str) -> Option<(&str, Vec<Bracket>)> {
    let text = text.trim();
    let (base, mut rest) = text.split_once('[').map_or((text, ""), |(b, _)| (b, &text[b.len()..]));
    let mut brackets = Vec::new();
    while let Some(inner) = rest.strip_prefix('[') {
        let (inside, after) = inner.split_once(']')?;
        let int = |s: &str| s.trim().parse::<i64>().ok();
        brackets.push(match inside.split_once("..") {
            Some((lo, hi)) => int(lo)?..=int(hi)?,
            None => int(inside)?..=int(inside)?,
        });
        rest = after;
    }
    (rest.is_empty() && !base.trim().is_empty()).then_some((base.trim(), brackets))
}

/// The states, events and outputs `names` select, each list in the model's order.
fn select(model: &sema::Model, names: &[&str]) -> Result<Only, String> {
    let states: Vec<&str> = model.states.iter().map(|s| s.name.as_str()).collect();
    let events: Vec<&str> = model.events.iter().map(|e| e.name.as_str()).collect();
    let outputs: Vec<&str> = model.outputs.iter().map(|o| o.name.as_str()).collect();
    let mut picked: [std::collections::BTreeSet<usize>; 3] = Default::default();
    for &name in names {
        let Some((base, brackets)) = pattern(name) else {
            return Err(format!(
                "--only: `{name}` is not a name, an element (`v[3]`) or a range of elements (`low[2..5]`)"
            ));
        };
        let exact =
            brackets.is_empty() && [&states, &events, &outputs].iter().any(|l| l.contains(&name.trim()));
        let matches = |element: &str| {
            if exact || brackets.is_empty() {
                // A plain name: itself, or every element of the array or family it names.
                return element == base
                    || (!exact && pattern(element).is_some_and(|(b, i)| b == base && !i.is_empty()));
            }
            pattern(element).is_some_and(|(b, idx)| {
                b == base
                    && idx.len() == brackets.len()
                    && idx.iter().zip(&brackets).all(|(i, r)| r.contains(i.start()))
            })
        };
        let mut found = false;
        for (list, set) in [&states, &events, &outputs].into_iter().zip(picked.iter_mut()) {
            for (i, element) in list.iter().enumerate() {
                if matches(element) {
                    set.insert(i);
                    found = true;
                }
            }
        }
        if !found {
            return Err(format!(
                "--only: `{name}` names no state, event or output of model `{}`",
                model.name
            ));
        }
    }
    let [states, events, outputs] = picked.map(|p| p.into_iter().collect());
    Ok(Only { states, events, outputs })
}

/// The text `hybc check` prints for the checked model `model`.
fn summary(model: &sema::Model) -> String {
    let mut out = String::new();
    let plural = |n: usize, word: &str| format!("{n} {word}{}", if n == 1 { "" } else { "s" });
    let _ = writeln!(
        out,
        "model {}: {}, {}, {}, {}, {}",
        model.name,
        plural(model.states.len(), "state"),
        plural(model.params.len(), "parameter"),
        plural(model.modes.len(), "mode"),
        plural(model.events.iter().filter(|e| !e.implicit).count(), "event"),
        plural(model.outputs.len(), "output"),
    );
    // Arrays and event families in one line each (`x[0 .. 7]`); their elements follow below.
    let states = array_ranges(model.states.iter().map(|s| s.name.as_str()));
    let events = array_ranges(model.events.iter().filter(|e| !e.implicit).map(|e| e.name.as_str()));
    if !states.is_empty() {
        let _ = writeln!(out, "state arrays: {}", states.join(", "));
    }
    if !events.is_empty() {
        let _ = writeln!(out, "event families: {}", events.join(", "));
    }
    let show = ExprPrinter::new(model);
    let _ = writeln!(out, "parameters");
    // A vector is one line, as declared (its elements share default and range): a listing of
    // 1000 elements would bury the rest of the summary.
    let mut vectors = model.vectors.iter().peekable();
    let mut k = 0;
    while k < model.params.len() {
        let p = &model.params[k];
        let range = p.range.map(|(lo, hi)| format!("  in [{lo}, {hi}]")).unwrap_or_default();
        match vectors.next_if(|v| v.first.0 as usize == k) {
            Some(v) => {
                let last = v.len.saturating_sub(1);
                let _ =
                    writeln!(out, "  {}[{}] = {}{range}  ({0}[0] .. {0}[{last}])", v.name, v.len, p.default);
                k += v.len as usize;
            }
            None => {
                let _ = writeln!(out, "  {} = {}{range}", p.name, p.default);
                k += 1;
            }
        }
    }
    let _ = writeln!(out, "states");
    for s in &model.states {
        let _ = writeln!(out, "  {} = {}", s.name, show.show(&s.init));
    }
    let _ = writeln!(out, "modes");
    for (k, m) in model.modes.iter().enumerate() {
        let initial = if k == model.initial_mode.0 as usize { " (initial)" } else { "" };
        let _ = writeln!(out, "  {}{initial}", m.name);
        for (s, f) in model.states.iter().zip(&m.flows) {
            let _ = writeln!(out, "    der({}) = {}", s.name, show.show(f));
        }
    }
    let _ = writeln!(out, "events");
    for ev in model.events.iter().filter(|e| !e.implicit) {
        let dir = match ev.direction {
            Direction::Falling => "falling (from > 0 to <= 0)",
            Direction::Rising => "rising (from < 0 to >= 0)",
            Direction::Either => "either way",
        };
        let scope = match ev.owner {
            Some(m) => format!("in mode {}", model.modes[m.0 as usize].name),
            None => "in every mode".to_string(),
        };
        let _ = writeln!(out, "  {} ({scope}): guard {}, fires {dir}", ev.name, show.show(&ev.guard));
        if ev.condition.is_some() {
            let _ = writeln!(out, "    only if its condition holds");
        }
        for (s, e) in &ev.resets {
            let _ = writeln!(out, "    {} := {}", model.states[s.0 as usize].name, show.show(e));
        }
        if let Some(t) = ev.target {
            let _ = writeln!(out, "    -> {}", model.modes[t.0 as usize].name);
        }
        if ev.is_stop {
            let _ = writeln!(out, "    stop");
        }
    }
    // The implicit events, each kind under its heading: the switches, then the kinks.
    let kinds = [
        (false, "flow switches (where a flow jumps: located like events, the gradients jump there)"),
        (true, "kinks (of `min`, `max`, `abs`: located like events, steps land on them; nothing jumps)"),
    ];
    for (kink, heading) in kinds {
        let mut events = model.events.iter().filter(|e| e.implicit && e.kink == kink).peekable();
        if events.peek().is_some() {
            let _ = writeln!(out, "{heading}");
        }
        for ev in events {
            let _ = writeln!(out, "  {}: at {} = 0", ev.name, show.show(&ev.guard));
        }
    }
    // An input's knots are one line per input and mode (an input may have thousands).
    if model.modes.iter().any(|m| !m.inputs.is_empty()) {
        let _ = writeln!(out, "input knots (integrator breakpoints)");
        for mode in &model.modes {
            for input in &mode.inputs {
                let vector =
                    model.vectors.iter().find(|v| v.first == input.first).map_or("?", |v| v.name.as_str());
                let what = match input.kind {
                    sema::InputKind::Pwl => "kinks: steps land on them",
                    sema::InputKind::Pwc => "jumps: steps land on them, the gradients jump there",
                };
                let knots = input.knots();
                let _ = writeln!(
                    out,
                    "  {}(t, .., {vector}) in mode {}: knots {} .. {} at {} = k ({what})",
                    input.kind.name(),
                    mode.name,
                    knots.start,
                    knots.end.saturating_sub(1),
                    show.show(&input.position()),
                );
            }
        }
    }
    let _ = writeln!(out, "outputs");
    for o in &model.outputs {
        let _ = writeln!(out, "  {} = {}", o.name, show.show(&o.expr));
    }
    out
}

/// Element names (`x[3]`, `T[1][2]`) grouped by array in order of first appearance, each written
/// as its ranges, `x[0 .. 7]`, `T[0 .. 2][0 .. 3]`, with the count when some elements of the
/// ranges are missing. Names without brackets are left out.
fn array_ranges<'a>(names: impl Iterator<Item = &'a str>) -> Vec<String> {
    let mut order: Vec<(&str, Vec<u64>, usize)> = Vec::new();
    let mut at: std::collections::HashMap<&str, usize> = std::collections::HashMap::new();
    for name in names {
        let Some(open) = name.find('[') else { continue };
        let (base, mut rest) = name.split_at(open);
        let mut idx = Vec::new();
        while let Some(r) = rest.strip_prefix('[') {
            let Some(close) = r.find(']') else { break };
            let Ok(k) = r[..close].parse::<u64>() else { break };
            idx.push(k);
            rest = &r[close + 1..];
        }
        if idx.is_empty() || !rest.is_empty() {
            continue;
        }
        let k = *at.entry(base).or_insert_with(|| {
            order.push((base, vec![0; idx.len()], 0));
            order.len() - 1
        });
        let entry = &mut order[k];
        if entry.1.len() == idx.len() {
            entry.1.iter_mut().zip(&idx).for_each(|(m, &i)| *m = (*m).max(i));
            entry.2 += 1;
        }
    }
    order
        .into_iter()
        .map(|(base, max, count)| {
            let ranges: String = max.iter().map(|m| format!("[0 .. {m}]")).collect();
            let full: u64 = max.iter().map(|m| m + 1).product();
            if full == count as u64 {
                format!("{base}{ranges}")
            } else {
                format!("{base}{ranges} ({count} elements)")
            }
        })
        .collect()
}
