//! `hybc sobol FILE`: Sobol' indices of outputs over parameter priors. Compiles the model once,
//! runs it at the rows of a Saltelli design in parallel keeping only the asked outputs, and prints
//! first-order and total indices (optionally second order) with bootstrap intervals, as a table or
//! JSON. A thin layer over `crate::sobol`: flags to a design, files, exit codes.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::ValueEnum;
use serde_json::{json, Map, Value};

use super::options::{at_most, parameter_values, sim_options, SimFlags};
use super::sweep::progress_bar;
use super::{compile_model, load_model, usage_error, ModelArg, EXIT_SIM_STOPPED};
use crate::limits::{MAX_BOOTSTRAP, MAX_SOBOL_BASE_POINTS, MAX_SOBOL_VALUES, MAX_SWEEP_POINTS, MAX_THREADS};
use crate::plot::{SobolFigure, SobolPanel};
use crate::sobol::{
    self, Analysis, AnalysisError, Design, OnFail, Output, OutputIndices, Prior, VaryError, Z_95,
};
use crate::Model;

#[derive(Debug, Clone, Copy, ValueEnum)]
enum FormatArg {
    Table,
    Json,
}

#[derive(Debug, clap::Args)]
#[command(after_help = "Exit codes: 0 success; 1 the model has errors; 2 a usage error; 3 some rows \
                        have no value for an output under --on-fail error (the other outputs' \
                        indices are printed).")]
pub struct SobolArgs {
    #[command(flatten)]
    model: ModelArg,
    /// A parameter and its prior (repeatable, in the design's order): `P=LO:HI` (uniform), `P`
    /// (uniform on its declared range), `P=loguniform:LO:HI`, `P=normal:MU:SIGMA`,
    /// `P=lognormal:MU:SIGMA` (of log P).
    #[arg(long, value_name = "P=LO:HI|P|P=KIND:A:B", required = true)]
    vary: Vec<String>,
    /// The quantities to analyse, comma-separated: outputs or states (final values), `EVENT#K`
    /// (time of the K-th firing), `EVENT#last` (time of the last firing).
    #[arg(long, value_name = "NAME,EVENT#K,EVENT#last", required = true)]
    output: String,
    /// Base points of the design (a power of 2 keeps the Sobol' points balanced); the runs are
    /// N (D + 2), or N (2 D + 2) with --second-order.
    #[arg(short = 'n', value_name = "N", default_value_t = 1024)]
    n: usize,
    /// Seed of the scrambled Sobol' sequence and of the bootstrap.
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,
    /// Also estimate second-order indices (N (2 D + 2) runs).
    #[arg(long)]
    second_order: bool,
    /// Bootstrap resamples for the confidence intervals (0: none).
    #[arg(long, value_name = "R", default_value_t = 100)]
    bootstrap: usize,
    /// Rows without a value (a run that ended early, an event that did not fire, a value that is
    /// not finite): `error` (no indices for that output), `drop` (leave out their base points:
    /// indices of the output where it exists), or `value=X` (use X).
    #[arg(long, value_name = "error|drop|value=X", default_value = "error")]
    on_fail: String,
    /// Set a parameter for every row (repeatable); checked against its declared range.
    #[arg(long = "set", value_name = "P=VALUE")]
    set: Vec<String>,
    #[command(flatten)]
    sim: SimFlags,
    /// Worker threads (0: one per core).
    #[arg(long, value_name = "N", default_value_t = 0)]
    threads: usize,
    /// Output format.
    #[arg(long, value_enum, default_value = "table")]
    format: FormatArg,
    /// Also write the design's rows (the varied parameters, in SALib's row order: A, AB_1..AB_D,
    /// [BA_1..BA_D], B per base point) to this CSV file, to check the indices with SALib; `-`:
    /// standard output, the indices then to stderr.
    #[arg(long, value_name = "FILE.csv")]
    design_out: Option<PathBuf>,
    /// Draw the indices as bars with their intervals, a panel per output, into this file.
    #[arg(long, value_name = "FILE.svg|.png")]
    plot: Option<PathBuf>,
}

pub fn run(args: &SobolArgs) -> ExitCode {
    let model = match load_model(&args.model.file) {
        Ok(model) => model,
        Err(code) => return code,
    };
    match sobol_model(&model, args) {
        Ok(code) => code,
        Err(message) => usage_error(&message),
    }
}

/// The design the flags describe.
fn design(model: &Model, args: &SobolArgs) -> Result<Design, String> {
    let base = parameter_values(model, &args.set)?.values().to_vec();
    let mut varied: Vec<(usize, Prior)> = Vec::new();
    for text in &args.vary {
        let (name, prior) = sobol::parse_prior(text).map_err(|e| format!("--vary: {e}"))?;
        let (idx, prior) = sobol::vary(model, &name, prior).map_err(|e| match e {
            VaryError::Param(e) => format!("--vary: {e}"),
            VaryError::NoRange { .. } => format!("--vary {text}: {e} (--vary {name}=LO:HI)"),
            VaryError::OutsideRange { .. } => format!("--vary {text}: {e}"),
        })?;
        if varied.iter().any(|v| v.0 == idx) {
            return Err(format!("--vary: `{name}` is varied twice"));
        }
        if args.set.iter().any(|s| s.split_once('=').is_some_and(|(n, _)| n.trim() == name)) {
            return Err(format!("`{name}` is given both by --set and by --vary"));
        }
        varied.push((idx, prior));
    }
    Design::new(base, varied, args.n, args.second_order, args.seed).map_err(|e| format!("--vary: {e}"))
}

fn sobol_model(model: &Model, args: &SobolArgs) -> Result<ExitCode, String> {
    crate::limits::count("-n", args.n, 2, MAX_SOBOL_BASE_POINTS).map_err(|e| e.to_string())?;
    at_most("--bootstrap", args.bootstrap, MAX_BOOTSTRAP)?;
    at_most("--threads", args.threads, MAX_THREADS)?;
    if args.bootstrap == 1 {
        return Err("--bootstrap: 1 resample has no spread; give 0 (no intervals) or at least 2".into());
    }
    let on_fail = OnFail::parse(&args.on_fail).ok_or_else(|| {
        format!("--on-fail: expected error, drop or value=X with X a finite number, found `{}`", args.on_fail)
    })?;
    let design = design(model, args)?;
    let opts = sim_options(model, &args.sim)?;
    // Compiled without gradient parameters: indices need values only, and a run without
    // sensitivities is several times cheaper.
    let compiled = match compile_model(model, &[]) {
        Ok(c) => c,
        Err(code) => return Ok(code),
    };
    let info = compiled.info();
    let outputs: Vec<Output> = args
        .output
        .split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|s| Output::parse(s, info).map_err(|e| format!("--output: {e}")))
        .collect::<Result<_, _>>()?;
    if outputs.is_empty() {
        return Err("--output: name at least one output, state or EVENT#K".into());
    }
    let rows = design.rows().filter(|r| *r <= MAX_SWEEP_POINTS).ok_or_else(|| {
        format!("-n: {} base points of {} rows are more than {MAX_SWEEP_POINTS} runs", args.n, design.block())
    })?;
    if rows.saturating_mul(outputs.len()) > MAX_SOBOL_VALUES {
        return Err(format!(
            "-n: {rows} rows x {} outputs are more than the {MAX_SOBOL_VALUES} values an analysis keeps",
            outputs.len()
        ));
    }
    if !args.n.is_power_of_two() {
        eprintln!("note: -n {} is not a power of 2; the Sobol' points are balanced at powers of 2", args.n);
    }
    if let Some(path) = &args.plot {
        crate::plot::ImageFormat::from_path(path).map_err(|e| format!("--plot: {e}"))?;
    }
    // The design written to standard output (`-`) leaves it to the design: the report goes to
    // stderr.
    let report_to = super::output::report_stream(&[("--design-out", args.design_out.as_deref())])?;
    if let Some(path) = &args.design_out {
        write_design(&design, model, path)?;
    }

    let bar = progress_bar(rows);
    let evaluated =
        sobol::evaluate(compiled.system(), &design, &outputs, &opts, args.threads, &|| bar.inc(1));
    bar.finish_and_clear();
    let evaluated = evaluated.map_err(|e| format!("--threads: {}", super::error_chain(&e)))?;
    let how = Analysis {
        d: design.d(),
        second_order: args.second_order,
        on_fail,
        bootstrap: args.bootstrap,
        seed: args.seed,
    };
    let results: Vec<Result<OutputIndices, AnalysisError>> = outputs
        .iter()
        .enumerate()
        .map(|(k, o)| sobol::analyze(&o.label, &evaluated.values, outputs.len(), k, &how))
        .collect();
    let names: Vec<&str> = design.varied().iter().map(|(p, _)| info.param_names[*p].as_str()).collect();
    let head =
        Head { model: model.name(), names: &names, design: &design, rows, args, evaluated: &evaluated };
    let text = match args.format {
        FormatArg::Table => table(&head, &results),
        FormatArg::Json => json_report(&head, &results) + "\n",
    };
    super::print_to(report_to, &text);
    if let Some(path) = &args.plot {
        let conf = |v: &[f64], e: Option<&[f64]>| -> Vec<(f64, f64)> {
            v.iter().enumerate().map(|(i, v)| (*v, e.map_or(f64::NAN, |e| Z_95 * e[i]))).collect()
        };
        let panels = results
            .iter()
            .flatten()
            .map(|r| SobolPanel {
                name: r.label.clone(),
                s1: conf(&r.indices.s1, r.errors.as_ref().map(|e| e.s1.as_slice())),
                st: conf(&r.indices.st, r.errors.as_ref().map(|e| e.st.as_slice())),
            })
            .collect();
        let title = format!(
            "{}: Sobol' indices, S1 (blue) and ST (orange){}, N = {}",
            model.name(),
            if args.bootstrap > 0 { " with 95% intervals" } else { "" },
            design.n()
        );
        let figure = SobolFigure { title, params: names.iter().map(|n| n.to_string()).collect(), panels };
        crate::plot::plot_sobol(&figure, path).map_err(|e| format!("--plot: {e}"))?;
    }
    let failed: Vec<&AnalysisError> = results.iter().filter_map(|r| r.as_ref().err()).collect();
    for e in &failed {
        eprintln!("error: {e}");
    }
    Ok(if failed.is_empty() { ExitCode::SUCCESS } else { ExitCode::from(EXIT_SIM_STOPPED) })
}

/// The design's rows as SALib's `X`: the varied parameters in flag order, one row per run.
fn write_design(design: &Design, model: &Model, path: &std::path::Path) -> Result<(), String> {
    let fail = |e: std::io::Error| format!("--design-out: cannot write `{}`: {e}", path.display());
    let mut w = super::output::create(path).map_err(fail)?;
    let written = write_design_rows(design, model, &mut w);
    super::output::closed_pipe_is_done(path, written).map_err(fail)
}

/// The rows of [`write_design`], to `w`.
fn write_design_rows(design: &Design, model: &Model, w: &mut dyn Write) -> std::io::Result<()> {
    let names: Vec<&str> =
        design.varied().iter().map(|(p, _)| model.checked().params[*p].name.as_str()).collect();
    writeln!(w, "{}", names.join(","))?;
    let mut p = vec![0.0; design.width()];
    let mut line = String::new();
    for r in 0..design.rows().unwrap_or(0) {
        design.fill(r, &mut p);
        line.clear();
        for (i, (param, _)) in design.varied().iter().enumerate() {
            if i > 0 {
                line.push(',');
            }
            line.push_str(&p[*param].to_string());
        }
        line.push('\n');
        w.write_all(line.as_bytes())?;
    }
    w.flush()
}

/// What every report starts with.
struct Head<'a> {
    model: &'a str,
    names: &'a [&'a str],
    design: &'a Design,
    rows: usize,
    args: &'a SobolArgs,
    evaluated: &'a sobol::Evaluated,
}

fn ended_early(head: &Head<'_>) -> String {
    if head.evaluated.ended_early.is_empty() {
        return "none".into();
    }
    let parts: Vec<String> = head.evaluated.ended_early.iter().map(|(w, c)| format!("{w} {c}")).collect();
    format!(
        "{} (the first is row {})",
        parts.join(", "),
        head.evaluated.first_ended_early.map_or(0, |r| r + 1)
    )
}

fn table(head: &Head<'_>, results: &[Result<OutputIndices, AnalysisError>]) -> String {
    let d = head.design;
    let mut s = format!(
        "sobol: model {}, {} parameters ({}), N = {} base points, {} runs ({} per base point), seed {}\n",
        head.model,
        d.d(),
        head.names.join(", "),
        d.n(),
        head.rows,
        d.block(),
        head.args.seed
    );
    s += &format!("runs that ended early: {}\n", ended_early(head));
    let conf = head.args.bootstrap > 0;
    if conf {
        s += &format!(
            "intervals: +/- 1.96 bootstrap standard errors ({} resamples of the base points), 95%\n",
            head.args.bootstrap
        );
    }
    let width = head.names.iter().map(|n| n.len()).max().unwrap_or(0).max(9);
    let num = |v: f64| if v.is_finite() { format!("{v:>10.4}") } else { format!("{:>10}", "-") };
    for result in results {
        s.push('\n');
        let r = match result {
            Ok(r) => r,
            Err(e) => {
                s += &format!("error: {e}\n");
                continue;
            }
        };
        s += &format!(
            "output {}: {} base points used, {} dropped, {} rows without a value, variance {}\n",
            r.label,
            r.used_points,
            r.dropped_points,
            r.failed_rows,
            crate::sim::short(r.indices.variance)
        );
        s += &format!("  {:<width$} {:>10}", "parameter", "S1");
        if conf {
            s += &format!(" {:>10}", "S1_conf");
        }
        s += &format!(" {:>10}", "ST");
        if conf {
            s += &format!(" {:>10}", "ST_conf");
        }
        s.push('\n');
        for (i, name) in head.names.iter().enumerate() {
            s += &format!("  {name:<width$} {}", num(r.indices.s1[i]));
            if let Some(e) = &r.errors {
                s += &format!(" {}", num(Z_95 * e.s1[i]));
            }
            s += &format!(" {}", num(r.indices.st[i]));
            if let Some(e) = &r.errors {
                s += &format!(" {}", num(Z_95 * e.st[i]));
            }
            s.push('\n');
        }
        for (k, (i, j, v)) in r.indices.s2.iter().enumerate() {
            s += &format!("  S2 {} {}: {}", head.names[*i], head.names[*j], num(*v).trim_start());
            if let Some(e) = &r.errors {
                s += &format!(" +/- {}", num(Z_95 * e.s2[k].2).trim_start());
            }
            s.push('\n');
        }
    }
    s
}

fn json_report(head: &Head<'_>, results: &[Result<OutputIndices, AnalysisError>]) -> String {
    let d = head.design;
    let mut top = Map::new();
    top.insert("model".into(), json!(head.model));
    top.insert("parameters".into(), json!(head.names));
    top.insert("n".into(), json!(d.n()));
    top.insert("runs".into(), json!(head.rows));
    top.insert("second_order".into(), json!(d.second_order()));
    top.insert("seed".into(), json!(head.args.seed));
    top.insert("bootstrap".into(), json!(head.args.bootstrap));
    top.insert("conf_level".into(), json!(0.95));
    top.insert("on_fail".into(), json!(head.args.on_fail.trim()));
    let early: Map<String, Value> =
        head.evaluated.ended_early.iter().map(|(w, c)| (w.to_string(), json!(c))).collect();
    top.insert("ended_early".into(), Value::Object(early));
    top.insert("first_ended_early_row".into(), json!(head.evaluated.first_ended_early.map(|r| r + 1)));
    let conf = |v: &[f64]| -> Value { v.iter().map(|s| json!(Z_95 * s)).collect() };
    let outputs: Vec<Value> = results
        .iter()
        .map(|result| match result {
            Err(e) => {
                let label = match e {
                    AnalysisError::Failed { label, .. } | AnalysisError::TooFewPoints { label, .. } => label,
                };
                json!({ "name": label, "error": e.to_string() })
            }
            Ok(r) => {
                let mut o = Map::new();
                o.insert("name".into(), json!(r.label));
                o.insert("failed_rows".into(), json!(r.failed_rows));
                o.insert("dropped_base_points".into(), json!(r.dropped_points));
                o.insert("base_points".into(), json!(r.used_points));
                o.insert("variance".into(), json!(r.indices.variance));
                o.insert("S1".into(), json!(r.indices.s1));
                o.insert("ST".into(), json!(r.indices.st));
                if let Some(e) = &r.errors {
                    o.insert("S1_conf".into(), conf(&e.s1));
                    o.insert("ST_conf".into(), conf(&e.st));
                }
                if d.second_order() {
                    // A D x D matrix with null off the upper triangle, as SALib's S2.
                    let matrix = |pick: &dyn Fn(usize) -> f64| -> Value {
                        let mut m = vec![vec![Value::Null; d.d()]; d.d()];
                        for (k, (i, j, _)) in r.indices.s2.iter().enumerate() {
                            m[*i][*j] = json!(pick(k));
                        }
                        json!(m)
                    };
                    o.insert("S2".into(), matrix(&|k| r.indices.s2[k].2));
                    if let Some(e) = &r.errors {
                        o.insert("S2_conf".into(), matrix(&|k| Z_95 * e.s2[k].2));
                    }
                }
                Value::Object(o)
            }
        })
        .collect();
    top.insert("outputs".into(), Value::Array(outputs));
    Value::Object(top).to_string()
}
