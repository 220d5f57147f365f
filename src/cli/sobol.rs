//! `hybc sobol FILE`: Sobol' indices of outputs over parameter priors (first order, total,
//! optionally second order, with bootstrap intervals), as a table or JSON. Flags to a design and
//! a `SobolRequest`, its report printed; the design's rows to a file, the plot, exit codes.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::ValueEnum;

use super::options::{at_most, parameter_values, sim_options, SimFlags};
use super::sweep::progress_bar;
use super::{compile_model, error_chain, load_model, usage_error, ModelArg, EXIT_SIM_STOPPED};
use crate::limits::{MAX_BOOTSTRAP, MAX_SOBOL_BASE_POINTS, MAX_THREADS};
use crate::plot::{SobolFigure, SobolPanel};
use crate::sobol::{self, Design, Prior, SobolReport, Z_95};
use crate::{Error, Model, SobolFailure, SobolRequest, VaryPriorError};

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
        let (idx, prior) = SobolRequest::vary(model, &name, prior).map_err(|e| match e {
            VaryPriorError::Param(e) => format!("--vary: {e}"),
            VaryPriorError::NoRange { .. } => format!("--vary {text}: {e} (--vary {name}=LO:HI)"),
            VaryPriorError::OutsideRange { .. } => format!("--vary {text}: {e}"),
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

/// A refusal of the request as a usage error, named by the flag it is about.
fn refused(e: Error) -> String {
    match e {
        Error::Sobol(e @ (SobolFailure::NoOutputs | SobolFailure::Output(_))) => format!("--output: {e}"),
        Error::Sobol(e @ (SobolFailure::TooManyRuns { .. } | SobolFailure::TooManyValues { .. })) => {
            format!("-n: {e}")
        }
        Error::Sobol(SobolFailure::OnFail { text }) => {
            format!("--on-fail: expected error, drop or value=X with X a finite number, found `{text}`")
        }
        Error::Sobol(SobolFailure::Pool(e)) => format!("--threads: {}", error_chain(&e)),
        e => error_chain(&e),
    }
}

fn sobol_model(model: &Model, args: &SobolArgs) -> Result<ExitCode, String> {
    crate::limits::count("-n", args.n, 2, MAX_SOBOL_BASE_POINTS).map_err(|e| e.to_string())?;
    at_most("--bootstrap", args.bootstrap, MAX_BOOTSTRAP)?;
    at_most("--threads", args.threads, MAX_THREADS)?;
    if args.bootstrap == 1 {
        return Err("--bootstrap: 1 resample has no spread; give 0 (no intervals) or at least 2".into());
    }
    SobolRequest::on_fail(&args.on_fail).map_err(|e| refused(e.into()))?;
    let design = design(model, args)?;
    let opts = sim_options(model, &args.sim)?;
    // Compiled without gradient parameters: indices need values only, and a run without
    // sensitivities is several times cheaper.
    let compiled = match compile_model(model, &[]) {
        Ok(c) => c,
        Err(code) => return Ok(code),
    };
    let outputs: Vec<String> =
        args.output.split(',').filter(|s| !s.trim().is_empty()).map(String::from).collect();
    let request = SobolRequest {
        design,
        seed: args.seed,
        outputs: &outputs,
        on_fail: &args.on_fail,
        bootstrap: args.bootstrap,
        sim: opts,
        threads: args.threads,
    };
    request.outputs(&compiled).map_err(refused)?;
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
        write_design(&request.design, model, path)?;
    }

    let bar = progress_bar(SobolRequest::rows(&request.design).map_err(|e| refused(e.into()))?);
    let report = request.run(&compiled, &|| bar.inc(1));
    bar.finish_and_clear();
    let report = report.map_err(refused)?;
    let text = match args.format {
        FormatArg::Table => report.to_table(),
        FormatArg::Json => report.to_json().to_string() + "\n",
    };
    super::print_to(report_to, &text);
    if let Some(path) = &args.plot {
        plot(&report, path)?;
    }
    let mut failed = false;
    for e in report.failures() {
        eprintln!("error: {e}");
        failed = true;
    }
    Ok(if failed { ExitCode::from(EXIT_SIM_STOPPED) } else { ExitCode::SUCCESS })
}

/// The indices as bars with their intervals, a panel per output that has them.
fn plot(report: &SobolReport, path: &std::path::Path) -> Result<(), String> {
    let conf = |v: &[f64], e: Option<&[f64]>| -> Vec<(f64, f64)> {
        v.iter().enumerate().map(|(i, v)| (*v, e.map_or(f64::NAN, |e| Z_95 * e[i]))).collect()
    };
    let panels = report
        .outputs
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
        report.model,
        if report.bootstrap > 0 { " with 95% intervals" } else { "" },
        report.n
    );
    let figure = SobolFigure { title, params: report.params.clone(), panels };
    crate::plot::plot_sobol(&figure, path).map_err(|e| format!("--plot: {e}"))
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
