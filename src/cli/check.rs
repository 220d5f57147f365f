//! `hybc check FILE`: validate a model and summarise it.

use std::fmt::Write;
use std::process::ExitCode;

use super::{load_model, ModelArg};
use crate::sema::{Direction, Model};

#[derive(Debug, clap::Args)]
pub struct CheckArgs {
    #[command(flatten)]
    model: ModelArg,
}

pub fn run(args: &CheckArgs) -> ExitCode {
    match load_model(&args.model.file) {
        Ok(model) => {
            eprint!("{}", model.warnings());
            super::print_out(&summary(model.checked()));
            ExitCode::SUCCESS
        }
        Err(code) => code,
    }
}

/// The text `hybc check` prints for a valid model.
pub fn summary(model: &Model) -> String {
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
    let show = crate::lower::ExprPrinter::new(model);
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
    let switches: Vec<_> = model.events.iter().filter(|e| e.implicit && e.knot.is_none()).collect();
    if !switches.is_empty() {
        let _ = writeln!(
            out,
            "flow switches (where a flow jumps: located like events, the gradients jump there)"
        );
        for ev in switches {
            let _ = writeln!(out, "  {}: at {} = 0", ev.name, show.show(&ev.guard));
        }
    }
    // An input's knots are one line per input and mode (an input may have thousands).
    let knots: Vec<_> = model.events.iter().filter_map(|e| Some((e, e.knot.as_ref()?))).collect();
    if !knots.is_empty() {
        let _ = writeln!(out, "input knots (integrator breakpoints)");
        let mut start = 0;
        while start < knots.len() {
            let (ev, first) = knots[start];
            let same = |&(e, k): &(&crate::sema::Event, &crate::sema::Knot)| {
                e.owner == ev.owner && k.position == first.position && k.kind == first.kind
            };
            let run = knots[start..].iter().take_while(|e| same(e)).count();
            let last = knots[start + run - 1].1;
            let mode = ev.owner.map_or("?", |m| model.modes[m.0 as usize].name.as_str());
            let what = match first.kind {
                crate::sema::InputKind::Pwl => "kinks: steps land on them",
                crate::sema::InputKind::Pwc => "jumps: located like flow switches",
            };
            let _ = writeln!(
                out,
                "  {}(t, .., {}) in mode {mode}: knots {} .. {} at {} = k ({what})",
                first.kind.name(),
                first.vector,
                first.k,
                last.k,
                show.show(&first.position),
            );
            start += run;
        }
    }
    let _ = writeln!(out, "outputs");
    for o in &model.outputs {
        let _ = writeln!(out, "  {} = {}", o.name, show.show(&o.expr));
    }
    out
}
