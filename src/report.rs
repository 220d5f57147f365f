//! A finished run with names attached: the library's result of `hybc run`, printed by the CLI as
//! a table or as the JSON object whose field names are a documented contract (docs/cli.md).
//! Knows `sim`'s results and shapes; no IO.

use serde_json::{json, Map, Value};

use crate::sim::{EventRecord, Sample, SimResult, StopReason, SystemInfo};

/// The result of one run, with the names needed to report it. Made only by
/// [`Run::into_report`](crate::Run::into_report) (its fields are private and its maker is the
/// crate's), so every report of a run, the CLI's and Python's, says the same about it.
#[derive(Clone, Debug)]
pub struct RunReport {
    model: String,
    t_end: f64,
    info: SystemInfo,
    params: Vec<f64>,
    result: SimResult,
    compile_seconds: f64,
    run_seconds: f64,
}

/// A method's name as the command line and JSON spell it (`dopri5`, `rodas5p`, ...).
fn method_name(method: crate::sim::Method) -> String {
    serde_json::to_value(method).ok().and_then(|v| v.as_str().map(str::to_string)).unwrap_or_default()
}

impl RunReport {
    /// The report of `result`, a run of `model` (its shape `info`) at `params` to `t_end`: for
    /// `Run::into_report` only.
    pub(crate) fn new(
        model: String,
        t_end: f64,
        info: SystemInfo,
        params: Vec<f64>,
        result: SimResult,
        (compile_seconds, run_seconds): (f64, f64),
    ) -> RunReport {
        RunReport { model, t_end, info, params, result, compile_seconds, run_seconds }
    }

    /// The model's name.
    pub fn model(&self) -> &str {
        &self.model
    }

    /// The end time asked for.
    pub fn t_end(&self) -> f64 {
        self.t_end
    }

    /// The model's shape as the run saw it (names, modes, events, gradient columns).
    pub fn info(&self) -> &SystemInfo {
        &self.info
    }

    /// All parameter values of the run, in declaration order.
    pub fn params(&self) -> &[f64] {
        &self.params
    }

    /// The run's result (layouts in `sim::result`).
    pub fn result(&self) -> &SimResult {
        &self.result
    }

    /// Whether the run ended as asked (at `t_end` or a `stop` event) rather than early.
    pub fn is_complete(&self) -> bool {
        self.result.stopped_by.is_complete()
    }

    fn grad_names(&self) -> Vec<&str> {
        self.info.grad_params.iter().map(|&j| self.info.param_names[j].as_str()).collect()
    }

    fn mode_name(&self, mode: usize) -> &str {
        self.info.modes.get(mode).map(|m| m.name.as_str()).unwrap_or("?")
    }

    /// `{param: value}` for one row of a column-per-parameter array (`a[j * rows + i]`).
    fn by_param(&self, a: &[f64], rows: usize, i: usize) -> Value {
        let mut m = Map::new();
        for (j, name) in self.grad_names().into_iter().enumerate() {
            // A derivative that does not exist is NaN in the result and `null` here.
            let d = a[j * rows + i];
            m.insert(name.to_string(), if d.is_nan() { Value::Null } else { number_json(d) });
        }
        Value::Object(m)
    }

    /// `{name: {param: value}}` over the rows of `a` that the report holds (`keep`: all but
    /// those `SimOptions::of` left out, whose keys are absent).
    fn named_rows(&self, names: &[String], a: Option<&[f64]>, keep: impl Fn(usize) -> bool) -> Value {
        match a {
            None => Value::Null,
            Some(a) => Value::Object(
                names
                    .iter()
                    .enumerate()
                    .filter(|&(i, _)| keep(i))
                    .map(|(i, n)| (n.clone(), self.by_param(a, names.len(), i)))
                    .collect(),
            ),
        }
    }

    /// The final states' (`output` false) or outputs' rows of `a` the report holds.
    fn final_rows(&self, output: bool, a: Option<&[f64]>) -> Value {
        let names = if output { &self.info.output_names } else { &self.info.state_names };
        self.named_rows(names, a, |i| self.result.reports_gradient(output, i))
    }

    /// Per event record, whether the report holds its time's gradient (`SimOptions::of`).
    fn events_wanted(&self) -> Vec<bool> {
        self.result.reports_event_gradients(&self.info)
    }

    /// A message for a run that stopped early (Zeno, max events, stuck, a fault), naming the
    /// time, the mode and the states.
    pub fn failure(&self) -> Option<String> {
        let r = &self.result;
        r.stopped_by.describe(&self.info, &r.events, &r.final_state)
    }

    /// A warning naming the final states and outputs that are not finite numbers (NaN or
    /// infinite), for a run that ended as asked; `None` when all are finite.
    pub fn non_finite(&self) -> Option<String> {
        self.is_complete()
            .then(|| crate::sim::non_finite_finals(&self.info, &self.result.final_state))
            .flatten()
    }

    /// The JSON object documented in docs/cli.md, as one value (the library's and Python's
    /// `to_json`). `write_json` writes the same text without building it.
    pub fn to_json(&self) -> Value {
        let fields = self.json_fields();
        let map: Map<String, Value> = fields
            .into_iter()
            .map(|(key, field)| {
                let value = match field {
                    JsonField::Value(v) => v,
                    JsonField::Events => {
                        let wanted = self.events_wanted();
                        Value::Array(
                            self.result.events.iter().map(|e| self.event_json(e, wanted[e.index])).collect(),
                        )
                    }
                    JsonField::Samples => {
                        Value::Array(self.result.samples.iter().map(|s| self.sample_json(&s)).collect())
                    }
                };
                (key.to_string(), value)
            })
            .collect();
        Value::Object(map)
    }

    /// Writes the text of `to_json` (compact, as `Value`'s `Display` prints it), with `extra`
    /// fields appended, one event at a time: a run at the `--max-events` cap (10^6) holds its
    /// `SimResult` and one event's value, not a tree of 10^6 objects (about 4 KB each).
    pub fn write_json(&self, out: &mut impl std::io::Write, extra: &[(&str, Value)]) -> std::io::Result<()> {
        let fields = self.json_fields();
        let extra = extra.iter().map(|(key, value)| (*key, JsonField::Value(value.clone())));
        out.write_all(b"{")?;
        for (i, (key, field)) in fields.into_iter().chain(extra).enumerate() {
            if i > 0 {
                out.write_all(b",")?;
            }
            serde_json::to_writer(&mut *out, key)?;
            out.write_all(b":")?;
            match field {
                JsonField::Value(v) => serde_json::to_writer(&mut *out, &v)?,
                JsonField::Events => {
                    let wanted = self.events_wanted();
                    write_array(out, &self.result.events, |e| self.event_json(e, wanted[e.index]))?
                }
                JsonField::Samples => write_array(out, self.result.samples.iter(), |s| self.sample_json(&s))?,
            }
        }
        out.write_all(b"}")
    }

    /// One sample of the JSON contract (`--at`): values and derivatives at a fixed time.
    fn sample_json(&self, s: &Sample) -> Value {
        let of = self.result.gradients_of.as_ref();
        let keep = |output: bool, i: usize| of.is_none_or(|o| o.sample(output, i, s.time));
        let named = |names: &[String], v: &[f64]| -> Value {
            Value::Object(names.iter().zip(v).map(|(n, x)| (n.clone(), number_json(*x))).collect())
        };
        json!({
            "time": s.time,
            "reached": s.reached,
            "mode": if s.reached { json!(self.mode_name(s.mode)) } else { Value::Null },
            "after_events": s.after_events,
            "near_event": s.near_event,
            "state": named(&self.info.state_names, s.state),
            "dstate": self.named_rows(&self.info.state_names, s.dstate, |i| keep(false, i)),
            "outputs": named(&self.info.output_names, s.outputs),
            "doutputs": self.named_rows(&self.info.output_names, s.doutputs, |i| keep(true, i)),
        })
    }

    /// One event record of the JSON contract; `dtime` absent where `SimOptions::of` left it
    /// out (`wanted` false).
    fn event_json(&self, e: &EventRecord, wanted: bool) -> Value {
        let mut v = json!({
            "index": e.index,
            "name": e.name,
            "time": e.time,
            "mode_before": self.mode_name(e.mode_before),
            "mode_after": self.mode_name(e.mode_after),
            "dtime": e.dtime.as_ref().map(|d| self.by_param(d, 1, 0)),
            "grazing": e.grazing,
            "margin": e.margin,
            "denominator": e.denominator,
        });
        if !wanted {
            if let Value::Object(m) = &mut v {
                m.remove("dtime");
            }
        }
        v
    }

    /// The JSON contract's top-level fields in their order, the events left to the writer: the one
    /// definition behind `to_json` and `write_json`.
    fn json_fields(&self) -> Vec<(&'static str, JsonField)> {
        let r = &self.result;
        let f = &r.final_state;
        let grad = self.grad_names();
        let params: Map<String, Value> =
            self.info.param_names.iter().zip(&self.params).map(|(n, v)| (n.clone(), json!(v))).collect();
        let named = |names: &[String], v: &[f64]| -> Value {
            Value::Object(names.iter().zip(v).map(|(n, x)| (n.clone(), number_json(*x))).collect())
        };
        let mut fin = json!({
            "time": f.time,
            "mode": self.mode_name(f.mode),
            "state": named(&self.info.state_names, &f.state),
            "dstate": self.final_rows(false, f.dstate.as_deref()),
            "outputs": named(&self.info.output_names, &f.outputs),
            "doutputs": self.final_rows(true, f.doutputs.as_deref()),
        });
        if let StopReason::Event { .. } = r.stopped_by {
            fin["dstate_total"] = self.final_rows(false, f.dstate_total.as_deref());
            fin["doutputs_total"] = self.final_rows(true, f.doutputs_total.as_deref());
        }
        if let Some(c) = &r.end_cusp {
            // The other side of a cusp at t_end: the final values had the events there not fired.
            let events: Vec<&str> = c.events.iter().map(|&ev| self.info.events[ev].name.as_ref()).collect();
            fin["without_end_events"] = json!({
                "events": events,
                "state": named(&self.info.state_names, &c.state),
                "dstate": self.final_rows(false, c.dstate.as_deref()),
                "outputs": named(&self.info.output_names, &c.outputs),
                "doutputs": self.final_rows(true, c.doutputs.as_deref()),
            });
        }
        let stopped_by = json!(r.stopped_by.name());
        let mut warnings: Vec<String> = r.warnings.iter().map(|w| w.to_string()).collect();
        warnings.extend(self.failure());
        warnings.extend(self.non_finite());
        let mut fields = vec![
            ("model", JsonField::Value(json!(self.model))),
            ("t_end", JsonField::Value(json!(self.t_end))),
            ("params", JsonField::Value(Value::Object(params))),
            ("grad", JsonField::Value(json!(grad))),
            ("events", JsonField::Events),
            ("final", JsonField::Value(fin)),
            ("stopped_by", JsonField::Value(stopped_by)),
            ("warnings", JsonField::Value(json!(warnings))),
            (
                "stats",
                JsonField::Value(json!({
                    "steps": r.stats.steps,
                    "rejected": r.stats.rejected,
                    "rhs_calls": r.stats.rhs_calls,
                    "events": r.stats.events,
                    "switches": r.stats.switches,
                    "sens": r.stats.sens.map(|s| s.name()),
                    "compile_seconds": self.compile_seconds,
                    "run_seconds": self.run_seconds,
                })),
            ),
            ("methods", JsonField::Value(json!(r.methods))),
        ];
        // Only when asked for (`--at`): the contract of a run without samples is unchanged.
        if !r.samples.is_empty() {
            fields.insert(6, ("samples", JsonField::Samples));
        }
        fields
    }

    /// The human-readable table `hybc run` prints by default.
    pub fn to_table(&self) -> String {
        let mut out = String::new();
        let _ = self.write_table(&mut out);
        out
    }

    /// Writes the text of `to_table` a line at a time (a run at the `--max-events` cap prints
    /// 10^6 event lines, about 90 MB, better not held whole).
    pub fn write_table<W: std::fmt::Write>(&self, out: &mut W) -> std::fmt::Result {
        let r = &self.result;
        let f = &r.final_state;
        let grad = self.grad_names();
        let params: Vec<String> = self
            .info
            .param_names
            .iter()
            .zip(&self.params)
            .map(|(n, v)| format!("{n} = {}", num(*v)))
            .collect();
        writeln!(out, "model {}   t_end = {}   {}", self.model, num(self.t_end), params.join(", "))?;
        let dcols: String = grad.iter().map(|p| format!("  {:>18}", format!("dt/d{p}"))).collect();
        writeln!(out, "\nevents: {}", r.events.len())?;
        if !r.events.is_empty() {
            writeln!(out, "  {:>4}  {:>18}  {:<14}  {:<22}{dcols}", "#", "time", "event", "mode")?;
        }
        let wanted = self.events_wanted();
        // A gradient `SimOptions::of` left out is blank; one that does not exist is `-`.
        let blank: String = grad.iter().map(|_| format!("  {:>18}", "")).collect();
        for e in &r.events {
            let (before, after) = (self.mode_name(e.mode_before), self.mode_name(e.mode_after));
            let mode = if before == after { before.to_string() } else { format!("{before} -> {after}") };
            let d: String = match &e.dtime {
                _ if !wanted[e.index] => blank.clone(),
                Some(d) => d.iter().map(|v| format!("  {:>18}", grad_text(*v))).collect(),
                None => grad.iter().map(|_| format!("  {:>18}", "-")).collect(),
            };
            let flag = match (e.grazing, e.margin) {
                (true, _) => format!("  GRAZING (d = {:e})", e.denominator),
                (false, Some(margin)) => format!("  near-grazing (margin {margin:e})"),
                (false, None) => String::new(),
            };
            writeln!(out, "  {:>4}  {:>18}  {:<14}  {:<22}{d}{flag}", e.index, num(e.time), e.name, mode)?;
        }
        let dcols: String = grad.iter().map(|p| format!("  {:>18}", format!("d/d{p}"))).collect();
        writeln!(out, "\nfinal: t = {}, mode {}", num(f.time), self.mode_name(f.mode))?;
        writeln!(out, "  {:<14}  {:>18}{dcols}", "", "value")?;
        // The final states' (`output` false) or outputs' rows.
        let rows = |out: &mut W, output: bool, v: &[f64], d: &Option<Vec<f64>>| -> std::fmt::Result {
            let names = if output { &self.info.output_names } else { &self.info.state_names };
            for (i, (n, x)) in names.iter().zip(v).enumerate() {
                let ds: String = match d {
                    _ if !r.reports_gradient(output, i) => blank.clone(),
                    Some(d) => (0..grad.len())
                        .map(|j| format!("  {:>18}", grad_text(d[j * names.len() + i])))
                        .collect(),
                    None => grad.iter().map(|_| format!("  {:>18}", "-")).collect(),
                };
                writeln!(out, "  {n:<14}  {:>18}{ds}", num(*x))?;
            }
            Ok(())
        };
        rows(out, false, &f.state, &f.dstate)?;
        rows(out, true, &f.outputs, &f.doutputs)?;
        if let Some(c) = &r.end_cusp {
            let names: Vec<&str> = c.events.iter().map(|&ev| self.info.events[ev].name.as_ref()).collect();
            writeln!(
                out,
                "\na cusp: {} fired at t_end; had it not (a parameter change that moves it later), the final \
                 values would be:",
                names.join(", ")
            )?;
            rows(out, false, &c.state, &c.dstate)?;
            rows(out, true, &c.outputs, &c.doutputs)?;
        }
        if let StopReason::Event { name, .. } = &r.stopped_by {
            writeln!(out, "\nstopped by event {name}; total derivatives at the stopping instant:")?;
            rows(out, false, &f.state, &f.dstate_total)?;
            rows(out, true, &f.outputs, &f.doutputs_total)?;
        }
        if !r.samples.is_empty() {
            self.write_samples_table(out)?;
        }
        let switches = match r.stats.switches {
            0 => String::new(),
            1 => ", 1 flow switch crossed".to_string(),
            k => format!(", {k} flow switches crossed"),
        };
        // The method that integrated the run, or (`auto` having switched) each stretch's.
        let methods = match &r.methods[..] {
            [one] => format!(", method {}", method_name(one.method)),
            all => {
                let parts: Vec<String> = all
                    .iter()
                    .map(|s| {
                        let name = method_name(s.method);
                        format!(
                            "{name} from {} to {} ({} steps, {} rejected)",
                            s.from, s.to, s.steps, s.rejected
                        )
                    })
                    .collect();
                format!("\nmethods: {}", parts.join(", "))
            }
        };
        let sens =
            if r.stats.sens == Some(crate::sim::Sens::Adjoint) { ", gradients by the adjoint" } else { "" };
        writeln!(
            out,
            "\n{} steps ({} rejected), {} kernel calls{switches}{sens}, compile {:.2} ms, run {:.1} us{methods}",
            r.stats.steps,
            r.stats.rejected,
            r.stats.rhs_calls,
            self.compile_seconds * 1e3,
            self.run_seconds * 1e6
        )
    }
}

impl RunReport {
    /// The `--at` samples as a table: time, then every output and state (their derivatives are
    /// in the JSON and `--samples-out`). A sample at an event instant is marked `+` (after its
    /// events), one within an event's time resolution `~` (a cusp: its derivatives hold on one
    /// side), one the run did not reach shows `-`.
    fn write_samples_table<W: std::fmt::Write>(&self, out: &mut W) -> std::fmt::Result {
        let r = &self.result;
        let names: Vec<&String> = self.info.output_names.iter().chain(&self.info.state_names).collect();
        writeln!(
            out,
            "\nsamples: {} (+ after an event at that instant, ~ within an event's time resolution)",
            r.samples.len()
        )?;
        let head: String = names.iter().map(|n| format!("  {n:>18}")).collect();
        writeln!(out, "  {:>18}  {:<2}{head}", "time", "")?;
        for s in r.samples.iter() {
            let flag = match (s.after_events, s.near_event) {
                (true, _) => "+",
                (false, Some(_)) => "~",
                _ => "",
            };
            let values: String = s
                .outputs
                .iter()
                .chain(s.state)
                .map(|v| format!("  {:>18}", if s.reached { num(*v) } else { "-".to_string() }))
                .collect();
            writeln!(out, "  {:>18}  {flag:<2}{values}", num(s.time))?;
        }
        Ok(())
    }
}

/// Writes `items` as a JSON array, one value at a time (never the whole tree in memory).
fn write_array<T>(
    out: &mut impl std::io::Write,
    items: impl IntoIterator<Item = T>,
    value: impl Fn(T) -> Value,
) -> std::io::Result<()> {
    out.write_all(b"[")?;
    for (k, item) in items.into_iter().enumerate() {
        if k > 0 {
            out.write_all(b",")?;
        }
        serde_json::to_writer(&mut *out, &value(item))?;
    }
    out.write_all(b"]")
}

/// A top-level field of the JSON contract: a value, or the events or samples (written one at a
/// time).
enum JsonField {
    Value(Value),
    Events,
    Samples,
}

/// A derivative as the table prints it: `-` where it does not exist (NaN).
fn grad_text(v: f64) -> String {
    if v.is_nan() {
        "-".to_string()
    } else {
        num(v)
    }
}

/// A value as the JSON contract writes it: a number, or the strings `"NaN"`, `"inf"` and `"-inf"`
/// for values that are not finite (JSON has no such numbers, and `null` is reserved for "this
/// derivative does not exist").
pub fn number_json(v: f64) -> Value {
    match non_finite_name(v) {
        Some(name) => Value::String(name.to_string()),
        None => json!(v),
    }
}

/// `"NaN"`, `"inf"` or `"-inf"` for a value that is not finite; `None` for a finite one.
pub fn non_finite_name(v: f64) -> Option<&'static str> {
    if v.is_nan() {
        Some("NaN")
    } else if v == f64::INFINITY {
        Some("inf")
    } else if v == f64::NEG_INFINITY {
        Some("-inf")
    } else {
        None
    }
}

/// A number with ten significant digits, without trailing zeros.
pub fn num(v: f64) -> String {
    crate::sim::short(v)
}
