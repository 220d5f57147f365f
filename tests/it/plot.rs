//! `--plot` on `hybc run` and `hybc sweep`: the files exist, are SVG or PNG of the documented
//! size, and hold one line per event and panel, one band per mode stretch, one marker per sweep
//! point and the tangents; tangent slopes are the gradients (checked against central
//! differences). Elements are counted by their colours, which `hybc::plot` exports.

use crate::support::cli::hybc;

use std::path::PathBuf;

use approx::assert_relative_eq;
use hybc::codegen::{compile, CompileOptions};
use hybc::lower::{lower, system_info};
use hybc::plot::{self, SweepFigure, DATA_COLOR, EVENT_COLOR, TANGENT_COLOR};
use hybc::sema::ParamIdx;
use hybc::sim::{self, SimOptions};
use hybc::sweep;
use plotters::style::RGBColor;
use serde_json::Value;

/// A fresh directory, removed when the returned guard drops, and `name` inside it.
fn temp(name: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join(name);
    (dir, path)
}

fn hex(c: RGBColor) -> String {
    format!("#{:02X}{:02X}{:02X}", c.0, c.1, c.2)
}

/// An SVG file's text, after checks that it is one well-nested SVG document.
fn svg(path: &PathBuf) -> String {
    let text = std::fs::read_to_string(path).expect("plot written");
    assert!(text.starts_with("<svg"), "{}", &text[..text.len().min(100)]);
    assert!(text.trim_end().ends_with("</svg>"));
    assert_eq!(text.matches("<svg").count(), 1);
    assert_eq!(text.matches("<text").count(), text.matches("</text>").count());
    text
}

/// Polylines drawn with stroke colour `c`.
fn lines_of(svg: &str, c: RGBColor) -> usize {
    svg.split("<polyline")
        .skip(1)
        .filter(|el| el.split('>').next().unwrap_or("").contains(&format!("stroke=\"{}\"", hex(c))))
        .count()
}

fn run_json(args: &[&str]) -> Value {
    let mut all = vec!["run"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--format", "json"]);
    serde_json::from_slice(&hybc(&all).stdout).expect("json")
}

#[test]
fn run_plot_has_a_panel_per_variable_and_a_line_per_event() {
    let (_dir, path) = temp("ball.svg");
    let out = hybc(&["run", "models/ball.hyb", "--quiet", "--plot", path.to_str().expect("utf-8")]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = svg(&path);
    let events = run_json(&["models/ball.hyb"])["events"].as_array().expect("events").len();
    assert_eq!(events, 4);
    let panels = 3; // y, v, energy
    assert!(text.starts_with(&format!(
        "<svg width=\"{}\" height=\"{}\"",
        plot::WIDTH,
        plot::PANEL_HEIGHT * panels
    )));
    assert_eq!(lines_of(&text, EVENT_COLOR), events * panels as usize);
    // Curves are broken at every event: events + 1 pieces per panel.
    assert_eq!(lines_of(&text, DATA_COLOR), (events + 1) * panels as usize);
    for name in [">y<", ">v<", ">energy<"] {
        assert!(text.replace('\n', "").contains(name), "axis label {name} missing");
    }
    // One mode: no bands.
    assert!(!text.contains("opacity=\"0.15\""));
}

#[test]
fn run_plot_shades_a_band_per_stretch_in_one_mode() {
    let (_dir, path) = temp("thermostat.svg");
    let out = hybc(&["run", "models/thermostat.hyb", "--quiet", "--plot", path.to_str().expect("utf-8")]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = svg(&path);
    // Every thermostat event switches the mode: events + 1 stretches, in each of two panels.
    let events = run_json(&["models/thermostat.hyb"])["events"].as_array().expect("events").len();
    assert!(events > 10);
    assert_eq!(text.matches("opacity=\"0.15\"").count(), 2 * (events + 1));
    assert_eq!(lines_of(&text, EVENT_COLOR), 2 * events);
    let flat = text.replace('\n', "");
    assert!(flat.contains(">heating<") && flat.contains(">cooling<"), "legend names the modes");
}

#[test]
fn png_plots_decode_to_the_documented_size() {
    for (args, panels) in [
        (vec!["run", "models/ball.hyb", "--quiet"], 3),
        (vec!["sweep", "models/ball.hyb", "--vary", "e=0.75:0.95:9", "--grad", "e"], 1),
    ] {
        let (_dir, path) = temp(&format!("{}.png", args[0]));
        let mut all = args.clone();
        all.extend(["--plot", path.to_str().expect("utf-8")]);
        let out = hybc(&all);
        assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
        let bytes = std::fs::read(&path).expect("written");
        assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"), "PNG signature");
        let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = decoder.read_info().expect("PNG header");
        let mut pixels = vec![0; reader.output_buffer_size()];
        let frame = reader.next_frame(&mut pixels).expect("PNG data");
        assert_eq!((frame.width, frame.height), plot::size(panels));
        // Not blank: more than one colour.
        assert!(pixels.chunks(3).any(|p| p != &pixels[..3]), "{args:?}: blank image");
    }
}

#[test]
fn sweep_plot_marks_every_point_and_draws_tangents_with_or_without_grad() {
    for grad in [&["--grad", "e,h0"][..], &[]] {
        let (_dir, path) = temp(&format!("sweep{}.svg", grad.len()));
        let mut args = vec!["sweep", "models/ball.hyb", "--vary", "e=0.75:0.95:11"];
        args.extend_from_slice(grad);
        args.extend(["--plot", path.to_str().expect("utf-8")]);
        let out = hybc(&args);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let text = svg(&path);
        assert!(text.starts_with(&format!(
            "<svg width=\"{}\" height=\"{}\"",
            plot::WIDTH,
            plot::PANEL_HEIGHT
        )));
        assert_eq!(text.matches("<circle").count(), 11, "one marker per point");
        assert_eq!(lines_of(&text, TANGENT_COLOR), 5, "five tangents");
        // The table does not change when the plot had to compute its own gradients.
        let mut plain = vec!["sweep", "models/ball.hyb", "--vary", "e=0.75:0.95:11"];
        plain.extend_from_slice(grad);
        assert_eq!(out.stdout, hybc(&plain).stdout);
    }
}

#[test]
fn tangent_slopes_are_central_differences_of_the_plotted_values() {
    let model = hybc::check_source(include_str!("../../models/ball.hyb")).expect("ball");
    let funcs = lower(&model);
    // Differentiate h0 and e (in that order), so that the tangent must pick the right column.
    let grad = [ParamIdx(2), ParamIdx(1)];
    let compiled = compile(&funcs, system_info(&model, &grad), &CompileOptions::default()).expect("compiles");
    let info = hybc::sim::HybridSystem::info(&compiled);
    let opts = SimOptions { t_end: 2.5, rtol: 1e-12, atol: 1e-14, ..SimOptions::default() };
    let base: Vec<f64> = model.params.iter().map(|p| p.default).collect();
    let points = sweep::full_grid(&base, &[(1, sweep::linspace(0.75, 0.95, 9))]);
    let results = sweep::run_points(&compiled, &points, &opts, 2, &|| ()).expect("pool");
    let mut figure = SweepFigure::new("ball", info, 1, &points, &results, true);
    let at = SweepFigure::tangent_points(&points, &results, 1, 3);
    assert_eq!(at, vec![0, 4, 8], "spread over the range, ends included");
    let at_points: Vec<Vec<f64>> = at.iter().map(|&i| points[i].clone()).collect();
    let at_results: Vec<_> = at.iter().map(|&i| results[i].clone()).collect();
    figure.add_tangents(info, 1, &at_points, &at_results).expect("e is differentiated");
    let energy = &figure.series[0];
    assert_eq!(energy.name, "energy");
    assert_eq!(energy.points.len(), 9);
    assert_eq!(energy.tangents.len(), 3);
    // Central differences, h = 1e-5: truncation ~ h^2 E''' ~ 1e-8, round-off ~ 1e-12 / h.
    let h = 1e-5;
    for t in &energy.tangents {
        let at = |e: f64| {
            let mut p = base.clone();
            p[1] = e;
            sim::run(&compiled, &p, &opts).expect("runs").final_state.outputs[0]
        };
        assert_relative_eq!(t.slope, (at(t.x + h) - at(t.x - h)) / (2.0 * h), max_relative = 1e-6);
        assert_eq!(t.y, at(t.x));
    }
    // Without a gradient for the parameter there are no tangents to add.
    let h0_only =
        compile(&funcs, system_info(&model, &[ParamIdx(2)]), &CompileOptions::default()).expect("compiles");
    let h0_info = hybc::sim::HybridSystem::info(&h0_only);
    assert!(figure.add_tangents(h0_info, 1, &at_points, &at_results).is_err());
}

/// `--show` picks the panels: states as well as outputs, by name, each with the tangents of its
/// own gradient row; a state's tangent is the central difference of that state.
#[test]
fn shown_states_get_their_own_values_and_tangents() {
    use hybc::plot::Shown;
    let model = hybc::check_source(include_str!("../../models/ball.hyb")).expect("ball");
    let funcs = lower(&model);
    let grad = [ParamIdx(2)];
    let compiled = compile(&funcs, system_info(&model, &grad), &CompileOptions::default()).expect("compiles");
    let info = hybc::sim::HybridSystem::info(&compiled);
    let opts = SimOptions { t_end: 0.45, rtol: 1e-12, atol: 1e-14, ..SimOptions::default() };
    let base: Vec<f64> = model.params.iter().map(|p| p.default).collect();
    let points = sweep::full_grid(&base, &[(2, sweep::linspace(0.8, 1.2, 5))]);
    let results = sweep::run_points(&compiled, &points, &opts, 2, &|| ()).expect("pool");
    let shown = vec![Shown::by_name(info, "v").unwrap(), Shown::by_name(info, "energy").unwrap()];
    assert_eq!(shown, [Shown::State(1), Shown::Output(0)]);
    assert_eq!(Shown::by_name(info, "nope"), None);
    let mut figure = SweepFigure::showing("ball", info, 2, &points, &results, true, shown);
    figure.add_tangents(info, 2, &points, &results).expect("h0 is differentiated");
    assert_eq!(figure.series.iter().map(|s| s.name.as_str()).collect::<Vec<_>>(), ["v", "energy"]);
    let h = 1e-6;
    let v_at = |h0: f64| {
        let mut p = base.clone();
        p[2] = h0;
        sim::run(&compiled, &p, &opts).expect("runs").final_state.state[1]
    };
    for t in &figure.series[0].tangents {
        assert_eq!(t.y, v_at(t.x));
        assert_relative_eq!(
            t.slope,
            (v_at(t.x + h) - v_at(t.x - h)) / (2.0 * h),
            max_relative = 1e-6,
            epsilon = 1e-8
        );
    }
    let out = hybc(&[
        "sweep",
        "models/ball.hyb",
        "--vary",
        "h0=0.8:1.2:3",
        "--plot",
        "/nonexistent/x.svg",
        "--show",
        "y,bogus",
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--show: `bogus` is not an output or state of the model (it has energy, y, v)"),
        "{err}"
    );
}

#[test]
fn unknown_plot_formats_are_usage_errors_and_write_nothing() {
    for args in [
        vec!["run", "models/ball.hyb", "--plot"],
        vec!["sweep", "models/ball.hyb", "--vary", "e=0.8,0.9", "--plot"],
    ] {
        for name in ["out.pdf", "out", "out.svg.txt"] {
            let (_dir, path) = temp(name);
            let mut all = args.clone();
            all.push(path.to_str().expect("utf-8"));
            let out = hybc(&all);
            assert_eq!(out.status.code(), Some(2), "{all:?}");
            assert!(String::from_utf8_lossy(&out.stderr).contains("must end in .svg or .png"));
            assert!(out.stdout.is_empty(), "nothing runs before the flag is checked");
            assert!(!path.exists());
        }
    }
}
