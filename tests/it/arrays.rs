//! Arrays of states, `const`s, `for` loops and event families (issue #41), against exact answers:
//! equal-mass particles in a box (elastic walls, velocity swaps at contact) are free particles
//! passing through each other, relabelled, so every event time and the final state are in
//! closed form; the W5 diffusion chain and a grid of thermostats written with arrays give their
//! flat models' events, values and gradients to round-off; gradients against central
//! differences.

use std::collections::BTreeMap;

use hybc::{Model, SimOptions};

use crate::support::chain::{diffusion_source, D_NAMES};
use crate::support::particle_box::{box_closed_form, box_source};

// ---- particles in a box ----------------------------------------------------------------------

fn counts(names: impl Iterator<Item = String>) -> BTreeMap<String, usize> {
    let mut out = BTreeMap::new();
    for n in names {
        *out.entry(n).or_insert(0) += 1;
    }
    out
}

fn check_box(n: usize, t_end: f64) {
    check_box_source(&box_source(n), n, t_end);
}

fn check_box_source(source: &str, n: usize, t_end: f64) {
    let model = Model::parse(source).expect("the box checks");
    let compiled = model.compile::<&str>(&[]).expect("compiles");
    let opts = SimOptions { t_end, rtol: 1e-10, atol: 1e-12, max_events: 100_000, ..SimOptions::default() };
    let run = compiled.simulate(&model.params(), &opts).expect("runs");
    let (want, last) = box_closed_form(n, t_end);
    let got: Vec<(f64, String)> = run.events().iter().map(|e| (e.time, e.name.to_string())).collect();
    // Exact counts, per event element.
    assert_eq!(
        counts(got.iter().map(|e| e.1.clone())),
        counts(want.iter().map(|e| e.1.clone())),
        "N = {n}: event counts"
    );
    assert!(want.len() > n, "N = {n}: only {} events, the test would be weak", want.len());
    // Every time, in order, to 1e-9 (the flow is linear and the guards affine: each time is
    // located to round-off, which accumulates over the events).
    for (k, (g, w)) in got.iter().zip(&want).enumerate() {
        assert!((g.0 - w.0).abs() < 1e-9, "N = {n}: event {k} at {} vs {} ({} vs {})", g.0, w.0, g.1, w.1);
    }
    for (i, (x, v)) in last.iter().enumerate() {
        let (gx, gv) =
            (run.state(&format!("x[{i}]")).expect("x[i]"), run.state(&format!("v[{i}]")).expect("v[i]"));
        assert!((gx - x).abs() < 1e-9, "N = {n}: x[{i}] = {gx} vs {x}");
        assert!((gv - v).abs() < 1e-12, "N = {n}: v[{i}] = {gv} vs {v}");
    }
    let ke: f64 = last.iter().map(|(_, v)| 0.5 * v * v).sum();
    assert!((run.output("ke").expect("ke") - ke).abs() < 1e-12 * ke.max(1.0), "N = {n}: kinetic energy");
}

#[test]
fn two_particles_in_a_box_are_free_particles_relabelled() {
    check_box(2, 5.0);
}

#[test]
fn ten_particles_in_a_box_are_free_particles_relabelled() {
    check_box(10, 2.0);
}

#[test]
fn a_hundred_particles_in_a_box_are_free_particles_relabelled() {
    check_box(100, 0.2);
}

/// The shipped `models/box.hyb` (8 particles, with masses for its kinetic energy) is the same box.
#[test]
fn the_shipped_box_is_free_particles_relabelled() {
    let source = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/models/box.hyb")).unwrap();
    let model = Model::parse(&source).expect("checks");
    assert_eq!(model.sim_options().t_end, 2.0);
    check_box_source(&source, 8, 2.0);
}

/// `d x[i](T) / d s` and `d x[i](T) / d L` of the box against central differences (the event
/// sequence is the same at the perturbed points).
#[test]
fn box_gradients_match_central_differences() {
    let n = 10;
    let model = Model::parse(&box_source(n)).expect("checks");
    let compiled = model.compile(&["s", "L"]).expect("compiles");
    let opts = SimOptions { t_end: 2.0, rtol: 1e-11, atol: 1e-13, ..SimOptions::default() };
    let run = compiled.simulate(&model.params(), &opts).expect("runs");
    let h = 1e-6;
    for p in ["s", "L"] {
        let at = |d: f64| {
            let params = model.params().with(p, 1.0 + d).expect("in range");
            compiled.simulate(&params, &opts).expect("runs")
        };
        let (up, down) = (at(h), at(-h));
        assert_eq!(up.events().len(), run.events().len(), "the same events at {p} + h");
        assert_eq!(down.events().len(), run.events().len(), "the same events at {p} - h");
        for i in 0..n {
            let x = format!("x[{i}]");
            let cd = (up.state(&x).expect("x") - down.state(&x).expect("x")) / (2.0 * h);
            let g = run.dstate(&x, p).expect("a gradient");
            assert!((g - cd).abs() < 1e-6 * cd.abs().max(1.0), "d{x}/d{p}: {g} vs central {cd}");
        }
    }
}

// ---- the W5 chain ----------------------------------------------------------------------------

/// `diffusion_source(n, true)` written with an array and a loop: the same expressions, term for
/// term, so the two models' functions are the same trees.
fn chain_with_arrays(n: usize) -> String {
    format!(
        "model diffusion_chain
const N = {n}
param d[10] = 50 in [0.1, 1000]
param c = 0.1
for i in 0 .. N {{
    state x[i] = 1 - 0.5 * i / N
}}
der(x[0]) = -c * x[0] - d[0] * (x[0] - x[1])
for i in 1 .. N - 1 {{
    der(x[i]) = -c * x[i] + d[div(10 * (i - 1), N)] * (x[i - 1] - x[i]) - d[div(10 * i, N)] * (x[i] - x[i + 1])
}}
der(x[N - 1]) = -c * x[N - 1] + d[div(10 * (N - 2), N)] * (x[N - 2] - x[N - 1])
initial mode fill {{
    event top_up when x[0] <= 0.6 -> rest {{
        x[0] := x[0] + 0.3
    }}
}}
mode rest {{
}}
output y = x[N - 1]
"
    )
}

#[test]
fn the_w5_chain_with_arrays_is_its_flat_model() {
    // `models/chain.hyb` is the same chain of 20 cells, with comments.
    let file = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/models/chain.hyb")).unwrap();
    for (n, source) in [(10, chain_with_arrays(10)), (30, chain_with_arrays(30)), (20, file)] {
        let flat = Model::parse(&diffusion_source(n, true)).expect("flat checks");
        let arr = Model::parse(&source).expect("array checks");
        let opts = SimOptions { t_end: 10.0, rtol: 1e-8, atol: 1e-10, ..SimOptions::default() };
        let rf = flat.compile(&D_NAMES).expect("compiles").simulate(&flat.params(), &opts).expect("runs");
        let ra = arr.compile(&D_NAMES).expect("compiles").simulate(&arr.params(), &opts).expect("runs");
        assert_eq!(rf.events().len(), 1);
        assert_eq!(ra.events().len(), rf.events().len());
        assert_eq!(&*ra.events()[0].name, "top_up");
        let close = |a: f64, b: f64, what: &str| {
            assert!((a - b).abs() <= 1e-13 * b.abs().max(1e-3), "N = {n}, {what}: {a} vs {b}");
        };
        close(ra.events()[0].time, rf.events()[0].time, "t(top_up)");
        close(ra.output("y").expect("y"), rf.output("y").expect("y"), "y");
        for i in 0..n {
            let (xa, xf) = (format!("x[{i}]"), format!("x{i}"));
            close(ra.state(&xa).expect("x[i]"), rf.state(&xf).expect("xi"), &xa);
            for d in D_NAMES {
                close(
                    ra.dstate(&xa, d).expect("grad"),
                    rf.dstate(&xf, d).expect("grad"),
                    &format!("d{xa}/d{d}"),
                );
            }
        }
        for d in D_NAMES {
            close(
                ra.devent_time(0, d).expect("grad"),
                rf.devent_time(0, d).expect("grad"),
                &format!("dt/d{d}"),
            );
        }
    }
}

// ---- a grid of thermostats -------------------------------------------------------------------

const ROWS: usize = 3;
const COLS: usize = 4;

/// Cells exchange heat with their four neighbours (an insulated edge: an index clamped by
/// `min`/`max` reads the cell itself) and leak to 0; each has a heater `u` switched on below 19
/// and off above 21 (per-element hysteresis: the enabling condition reads the cell's own heater).
fn grid_with_arrays() -> String {
    format!(
        "model grid
const R = {ROWS}
const C = {COLS}
param k = 0.4
param a = 0.05
param P[R * C] = 3
for r in 0 .. R {{
    for c in 0 .. C {{
        state T[r][c] = 20 + 3 * sin(r * 1.7 + c * 0.9)
        state u[r][c] = 0
        let flux[r][c] = T[max(r - 1, 0)][c] + T[min(r + 1, R - 1)][c] + T[r][max(c - 1, 0)] + T[r][min(c + 1, C - 1)] - 4 * T[r][c]
        der(T[r][c]) = k * flux[r][c] - a * T[r][c] + P[r * C + c] * u[r][c]
        der(u[r][c]) = 0
        event on[r][c] when T[r][c] <= 19 if u[r][c] < 0.5 {{ u[r][c] := 1 }}
        event off[r][c] when T[r][c] >= 21 if u[r][c] > 0.5 {{ u[r][c] := 0 }}
    }}
}}
output total = sum(r in 0 .. R: sum(c in 0 .. C: T[r][c]))
"
    )
}

/// The same model written out cell by cell, `T_r_c` for `T[r][c]`.
fn grid_flat() -> String {
    let mut s = String::from("model grid\nparam k = 0.4\nparam a = 0.05\n");
    s.push_str(&format!("param P[{}] = 3\n", ROWS * COLS));
    let t = |r: usize, c: usize| format!("T_{r}_{c}");
    for r in 0..ROWS {
        for c in 0..COLS {
            s.push_str(&format!(
                "state T_{r}_{c} = 20 + 3 * sin({r} * 1.7 + {c} * 0.9)\nstate u_{r}_{c} = 0\n"
            ));
            let flux = format!(
                "{} + {} + {} + {} - 4 * {}",
                t(r.saturating_sub(1), c),
                t((r + 1).min(ROWS - 1), c),
                t(r, c.saturating_sub(1)),
                t(r, (c + 1).min(COLS - 1)),
                t(r, c)
            );
            s.push_str(&format!("let flux_{r}_{c} = {flux}\n"));
            s.push_str(&format!(
                "der(T_{r}_{c}) = k * flux_{r}_{c} - a * T_{r}_{c} + P[{}] * u_{r}_{c}\nder(u_{r}_{c}) = 0\n",
                r * COLS + c
            ));
            s.push_str(&format!(
                "event on_{r}_{c} when T_{r}_{c} <= 19 if u_{r}_{c} < 0.5 {{ u_{r}_{c} := 1 }}\n"
            ));
            s.push_str(&format!(
                "event off_{r}_{c} when T_{r}_{c} >= 21 if u_{r}_{c} > 0.5 {{ u_{r}_{c} := 0 }}\n"
            ));
        }
    }
    // The array model's nested sums are balanced trees over rows of cells; written the same way.
    let row = |r: usize| {
        let cells: Vec<String> = (0..COLS).map(|c| t(r, c)).collect();
        format!("(({} + {}) + ({} + {}))", cells[0], cells[1], cells[2], cells[3])
    };
    s.push_str(&format!("output total = {} + ({} + {})\n", row(0), row(1), row(2)));
    s
}

/// `T[2][3]` -> `T_2_3`, `on[1][0]` -> `on_1_0`.
fn flat_name(name: &str) -> String {
    name.replace("][", "_").replace('[', "_").replace(']', "")
}

#[test]
fn a_grid_of_thermostats_with_arrays_is_its_flat_model() {
    let arr = Model::parse(&grid_with_arrays()).expect("array checks");
    let flat = Model::parse(&grid_flat()).expect("flat checks");
    let grad = ["k", "a", "P[0]", "P[5]", "P[11]"];
    let opts = SimOptions { t_end: 40.0, rtol: 1e-9, atol: 1e-11, ..SimOptions::default() };
    let ra = arr.compile(&grad).expect("compiles").simulate(&arr.params(), &opts).expect("runs");
    let rf = flat.compile(&grad).expect("compiles").simulate(&flat.params(), &opts).expect("runs");
    assert!(
        ra.events().len() >= 2 * ROWS * COLS,
        "only {} events: the test would be weak",
        ra.events().len()
    );
    assert_eq!(ra.events().len(), rf.events().len());
    let close = |x: f64, y: f64, what: &str| {
        assert!((x - y).abs() <= 1e-12 * y.abs().max(1.0), "{what}: {x} vs {y}");
    };
    for (k, (ea, ef)) in ra.events().iter().zip(rf.events()).enumerate() {
        assert_eq!(flat_name(&ea.name), &*ef.name, "event {k}");
        close(ea.time, ef.time, &format!("event {k} time"));
        for p in grad {
            close(
                ra.devent_time(k, p).expect("grad"),
                rf.devent_time(k, p).expect("grad"),
                &format!("dt_{k}/d{p}"),
            );
        }
    }
    close(ra.output("total").expect("total"), rf.output("total").expect("total"), "total");
    for r in 0..ROWS {
        for c in 0..COLS {
            for s in ["T", "u"] {
                let (na, nf) = (format!("{s}[{r}][{c}]"), format!("{s}_{r}_{c}"));
                close(ra.state(&na).expect("state"), rf.state(&nf).expect("state"), &na);
                for p in grad {
                    let (ga, gf) = (ra.dstate(&na, p).expect("grad"), rf.dstate(&nf, p).expect("grad"));
                    close(ga, gf, &format!("d{na}/d{p}"));
                }
            }
        }
    }
}

/// The grid's gradients against central differences: `d total / d k`, `d T[1][2] / d P[6]`.
#[test]
fn grid_gradients_match_central_differences() {
    let model = Model::parse(&grid_with_arrays()).expect("checks");
    let grad = ["k", "P[6]"];
    let compiled = model.compile(&grad).expect("compiles");
    let opts = SimOptions { t_end: 40.0, rtol: 1e-11, atol: 1e-13, ..SimOptions::default() };
    let run = compiled.simulate(&model.params(), &opts).expect("runs");
    for (p, base, h) in [("k", 0.4, 1e-6), ("P[6]", 3.0, 1e-5)] {
        let at =
            |d: f64| compiled.simulate(&model.params().with(p, base + d).expect("ok"), &opts).expect("runs");
        let (up, down) = (at(h), at(-h));
        assert_eq!(up.events().len(), run.events().len());
        assert_eq!(down.events().len(), run.events().len());
        let cd = (up.output("total").expect("y") - down.output("total").expect("y")) / (2.0 * h);
        let g = run.doutput("total", p).expect("grad");
        assert!((g - cd).abs() < 1e-5 * cd.abs().max(1.0), "dtotal/d{p}: {g} vs central {cd}");
        let cd = (up.state("T[1][2]").expect("T") - down.state("T[1][2]").expect("T")) / (2.0 * h);
        let g = run.dstate("T[1][2]", p).expect("grad");
        assert!((g - cd).abs() < 1e-5 * cd.abs().max(1.0), "dT[1][2]/d{p}: {g} vs central {cd}");
    }
}

// ---- rules of the language -------------------------------------------------------------------

fn err(src: &str) -> String {
    match hybc::check_source(src) {
        Ok(_) => panic!("accepted:\n{src}"),
        Err(e) => e.render("m.hyb", src),
    }
}

#[test]
fn index_arithmetic_and_whole_declarations() {
    // `div` and `mod` are Euclidean; a whole array takes one initial value; an expression of
    // loop variables alone is a number.
    let src = "model m
const N = 7
state x[N] = 2
for i in 0 .. N {
    der(x[i]) = -x[mod(i - 1, N)] + div(-7, 2) + i
}
output y = sum(x)
";
    let model = Model::parse(src).expect("checks");
    let compiled = model.compile::<&str>(&[]).expect("compiles");
    let names = compiled.info().state_names.clone();
    assert_eq!(names, (0..7).map(|k| format!("x[{k}]")).collect::<Vec<_>>());
    let run = compiled
        .simulate(&model.params(), &SimOptions { t_end: 1e-3, ..SimOptions::default() })
        .expect("runs");
    // x' at t = 0: -2 + (-4) + i, so x(h) ~ 2 + h (i - 6) to O(h^2).
    for i in 0..7 {
        let x = run.state(&format!("x[{i}]")).expect("x");
        let want = 2.0 + 1e-3 * (i as f64 - 6.0);
        assert!((x - want).abs() < 1e-5, "x[{i}] = {x} vs {want}");
    }
}

#[test]
fn flat_models_are_left_alone() {
    // A model without arrays is checked as it was: its vector parameter keeps sema's own error.
    let rendered = err("model m\nparam u[3] = 1\nstate x = u[3]\nder(x) = 0\n");
    assert!(rendered.contains("expected an integer from 0 to 2"), "{rendered}");
}

#[test]
fn errors_name_the_loop_values() {
    let rendered =
        err("model m\nconst N = 8\nstate x[N] = 0\nfor i in 0 .. N {\n    der(x[i]) = -x[i + 1]\n}\n");
    assert!(rendered.contains("in `x[i + 1]` at `i = 7`: index 8 is outside `x[0 .. 7]`"), "{rendered}");
    let rendered = err("model m\nconst N = 8\nstate x[N] = 0\nfor i in 0 .. N {\n    der(x[i + 5]) = 0\n}\n");
    assert!(rendered.contains("in `der(x[i + 5])` at `i = 3`: index 8 is outside `x[0 .. 7]`"), "{rendered}");
    let rendered = err("model m\nstate x[3] = 0\nfor i in 0 .. 3 {\n    for j in 0 .. i {\n        der(x[i + j]) = 0\n    }\n}\n");
    assert!(rendered.contains("at `i = 2, j = 1`: index 3 is outside `x[0 .. 2]`"), "{rendered}");
}

#[test]
fn loop_variables_and_constants_shadow_nothing() {
    for (src, what) in [
        ("model m\nstate x[2] = 0\nfor t in 0 .. 2 {\n    der(x[t]) = t\n}\n", "`t` is already a built-in name"),
        ("model m\nconst N = 2\nstate x[N] = 0\nfor N in 0 .. 2 {\n    der(x[N]) = 0\n}\n", "`N` is already a const"),
        ("model m\nstate x[2] = 0\nfor x in 0 .. 2 {\n    der(x[x]) = 0\n}\n", "`x` is already declared in the model"),
        (
            "model m\nstate x[2][2] = 0\nfor i in 0 .. 2 {\n    for i in 0 .. 2 {\n        der(x[i][i]) = 0\n    }\n}\n",
            "`i` is already an enclosing loop variable",
        ),
        ("model m\nconst x = 2\nstate x = 0\nder(x) = 0\n", "`x` is already a const"),
    ] {
        let rendered = err(src);
        assert!(rendered.contains(what), "{src}: {rendered}");
    }
}

#[test]
fn the_flattened_size_is_capped_before_any_work() {
    let start = std::time::Instant::now();
    let rendered = err("model m\nfor i in 0 .. 1000000000 {\n    state x[i] = 0\n}\n");
    assert!(rendered.contains("a range of 1000000000 values"), "{rendered}");
    // Nested loops whose product is huge stop at the cap, not after it.
    let rendered = err(
        "model m\nfor i in 0 .. 100000 {\n    for j in 0 .. 100000 {\n        state x[i][j] = 0\n    }\n}\n",
    );
    assert!(rendered.contains("the flattened model would exceed"), "{rendered}");
    assert!(start.elapsed().as_secs() < 20, "the cap took {:?}", start.elapsed());
}

// ---- element names on the command line -------------------------------------------------------

fn json_of(out: &std::process::Output) -> serde_json::Value {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("not JSON ({e}): {}", String::from_utf8_lossy(&out.stdout)))
}

fn num(v: &serde_json::Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// `tests/data/run/drops.hyb`: ball `i` falls from `h[i] (i + 1)`, so its first floor event is
/// at `sqrt(2 h_i (i + 1) / g)`, with `dt/dh_i = t / (2 h_i)`.
#[test]
fn element_names_work_in_set_grad_at_and_json() {
    let out = crate::support::cli::hybc(&[
        "run",
        "tests/data/run/drops.hyb",
        "--set",
        "h[1]=2",
        "--grad",
        "h",
        "--at",
        "0.25",
        "--format",
        "json",
    ]);
    let json = json_of(&out);
    let g = 9.81;
    assert_eq!(num(&json["params"]["h[1]"]), 2.0);
    assert_eq!(json["grad"], serde_json::json!(["h[0]", "h[1]", "h[2]"]));
    let h = [1.0, 2.0, 1.0];
    let events = json["events"].as_array().expect("events");
    for (i, &hi) in h.iter().enumerate() {
        let name = format!("floor[{i}]");
        let t = (2.0 * hi * (i + 1) as f64 / g).sqrt();
        let ev = events.iter().find(|e| e["name"] == name.as_str()).unwrap_or_else(|| panic!("no {name}"));
        assert!((num(&ev["time"]) - t).abs() < 1e-9, "{name} at {} vs {t}", ev["time"]);
        let dt = num(&ev["dtime"][format!("h[{i}]")]);
        assert!((dt - t / (2.0 * hi)).abs() < 1e-7, "d{name}/dh[{i}]: {dt} vs {}", t / (2.0 * hi));
    }
    let y1 = num(&json["samples"][0]["state"]["y[1]"]);
    assert!((y1 - (4.0 - 0.5 * g * 0.0625)).abs() < 1e-9, "y[1]@0.25 = {y1}");
    assert_eq!(num(&json["samples"][0]["dstate"]["y[1]"]["h[1]"]), 2.0);
}

/// `EVENT#K` and `NAME@TIME` with element names: fit `h[2]` so that `floor[2]` first fires at
/// 0.5 (`h[2] = 0.25 g / 6`), then `h[0]` so that `y[0]@0.25 = 0.5`.
#[test]
fn element_names_work_in_event_and_time_targets() {
    let g = 9.81;
    for (free, target, want) in
        [("h[2]", "floor[2]#1=0.5", 0.25 * g / 6.0), ("h[0]", "y[0]@0.25=0.5", 0.5 + 0.5 * g * 0.0625)]
    {
        let out = crate::support::cli::hybc(&[
            "fit",
            "tests/data/run/drops.hyb",
            "--free",
            free,
            "--target",
            target,
            "--format",
            "json",
        ]);
        let json = json_of(&out);
        assert_eq!(json["converged"], serde_json::Value::Bool(true), "{json}");
        let got = num(&json["params"][free]);
        assert!((got - want).abs() < 1e-7, "{free} = {got} vs {want}");
    }
}

#[test]
fn check_prints_arrays_and_families_compactly() {
    let out = crate::support::cli::hybc(&["check", "tests/data/parse_ok/arrays_box.hyb"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("model box: 16 states, 9 parameters, 1 mode, 23 events, 1 output"), "{text}");
    assert!(text.contains("state arrays: x[0 .. 7], v[0 .. 7]\n"), "{text}");
    assert!(text.contains("event families: low[0 .. 7], high[0 .. 7], hit[0 .. 6]\n"), "{text}");
    assert!(text.contains("m[8] = 1  (m[0] .. m[7])"), "{text}");
    // A flat model has neither line.
    let out = crate::support::cli::hybc(&["check", "models/ball.hyb"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(!text.contains("arrays") && !text.contains("families"), "{text}");
}

// ---- whole arrays where a list is meant ------------------------------------------------------

/// `--set h=1.2,2,0.5` sets a vector parameter whole, here the initial heights of the drops (a state
/// array's initial values are set through parameters): each ball's first floor event moves to
/// `sqrt(2 h_i (i + 1) / g)`. `--of y` asks for the gradients of every element of the state
/// array `y` (and of nothing else): the same numbers as the full report's; `--of y@0.25` every
/// element at 0.25, where `dy_i/dh_i = i + 1` before any bounce.
#[test]
fn whole_arrays_work_in_set_and_of() {
    let g = 9.81;
    let h = [1.2, 2.0, 0.5];
    let run = |extra: &[&str]| {
        let mut args = vec![
            "run",
            "tests/data/run/drops.hyb",
            "--set",
            "h=1.2,2,0.5",
            "--grad",
            "h",
            "--format",
            "json",
        ];
        args.extend_from_slice(extra);
        json_of(&crate::support::cli::hybc(&args))
    };
    let full = run(&[]);
    let events = full["events"].as_array().expect("events");
    for (i, &hi) in h.iter().enumerate() {
        assert_eq!(num(&full["params"][format!("h[{i}]")]), hi);
        let t = (2.0 * hi * (i + 1) as f64 / g).sqrt();
        let name = format!("floor[{i}]");
        let ev = events.iter().find(|e| e["name"] == name.as_str()).unwrap_or_else(|| panic!("no {name}"));
        assert!((num(&ev["time"]) - t).abs() < 1e-9, "{name} at {} vs {t}", ev["time"]);
    }
    let some = run(&["--of", "y"]);
    let dstate = some["final"]["dstate"].as_object().expect("dstate");
    let keys: Vec<&str> = dstate.keys().map(String::as_str).collect();
    assert_eq!(keys, ["y[0]", "y[1]", "y[2]"], "--of y: every element of y, nothing else");
    for k in keys {
        assert_eq!(dstate[k], full["final"]["dstate"][k], "d{k}: --of y against the full report");
    }
    let at = run(&["--of", "y@0.25"]);
    let sample = &at["samples"][0]["dstate"];
    for i in 0..3 {
        let row = &sample[format!("y[{i}]")];
        for j in 0..3 {
            let want = if i == j { (i + 1) as f64 } else { 0.0 };
            assert_eq!(num(&row[format!("h[{j}]")]), want, "dy[{i}]/dh[{j}] at 0.25");
        }
    }
    assert!(sample.get("v[0]").is_none_or(|v| v.is_null()), "--of y@0.25 asks for no v: {sample}");
    // An element and a name that is neither: as before.
    let one = run(&["--of", "y[1]"]);
    let keys: Vec<&String> = one["final"]["dstate"].as_object().expect("dstate").keys().collect();
    assert_eq!(keys, ["y[1]"]);
    let out = crate::support::cli::hybc(&["run", "tests/data/run/drops.hyb", "--grad", "h", "--of", "w"]);
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
}

// ---- `hybc derive --only` --------------------------------------------------------------------

fn derive_only(only: &str) -> (Option<i32>, String, String) {
    let out = crate::support::cli::hybc(&["derive", "models/box.hyb", "--wrt", "s,L", "--only", only]);
    let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
    (out.status.code(), text(&out.stdout), text(&out.stderr))
}

/// Block titles of a derive report, in order.
fn titles(report: &str) -> Vec<&str> {
    report
        .lines()
        .filter(|l| {
            ["state ", "event ", "output ", "mode ", "top-level"]
                .iter()
                .any(|p| l.trim_start().starts_with(p))
        })
        .map(str::trim)
        .collect()
}

#[test]
fn derive_only_shows_the_elements_asked_for() {
    let (code, text, err) = derive_only("x[3],low[3]");
    assert_eq!(code, Some(0), "{err}");
    assert!(text.starts_with("model box\nonly: x[3], low[3]\ndifferentiated: s, L\n"), "{text}");
    assert_eq!(titles(&text), ["state x[3]", "mode main", "top-level", "event low[3] (falling)"], "{text}");
    // x[3]' = v[3]: one entry of f_x, no parameter; x[3](0) = L (3.5 + 0.3 sin(12.4)) / 8, so
    // dx[3](0)/dL = x[3](0) at L = 1; low[3]'s guard is x[3], its reset flips v[3] alone.
    let x0 = (3.5 + 0.3 * 12.4f64.sin()) / 8.0;
    let x0_l: f64 =
        text.lines().find_map(|l| l.strip_prefix("  x0_L = ")).expect("x0_L").parse().expect("a number");
    assert!((x0_l - x0).abs() < 1e-15, "x0_L = {x0_l} vs {x0}");
    let lines: Vec<&str> = text.lines().map(str::trim).collect();
    for line in [
        "x0_s = 0",
        "f = v[3]",
        "f_x = {v[3]: 1}",
        "f_s = 0",
        "f_L = 0",
        "g = x[3]",
        "(6) x[3]: 1",
        "(7) v[3]: -v[3]",
    ] {
        assert_eq!(lines.iter().filter(|l| **l == line).count(), 1, "`{line}` once in\n{text}");
    }
    // Its lines are those of the whole report (the event's block is the same text).
    let whole = crate::support::cli::hybc(&["derive", "models/box.hyb", "--wrt", "s,L"]);
    let whole = String::from_utf8_lossy(&whole.stdout);
    let event = text.split("event low[3]").nth(1).expect("the event block");
    assert!(whole.contains(event.trim_end()), "the event block differs from the whole report's");

    // A range, inclusive as `hybc check` prints it; a whole array; an output.
    let (code, text, _) = derive_only("low[2..5]");
    assert_eq!(code, Some(0));
    let events: Vec<&str> = titles(&text).into_iter().filter(|t| t.starts_with("event")).collect();
    assert_eq!(
        events,
        [
            "event low[2] (falling)",
            "event low[3] (falling)",
            "event low[4] (falling)",
            "event low[5] (falling)"
        ]
    );
    let (_, text, _) = derive_only("v,ke");
    let states: Vec<&str> = titles(&text).into_iter().filter(|t| t.starts_with("state")).collect();
    assert_eq!(states, (0..8).map(|i| format!("state v[{i}]")).collect::<Vec<_>>());
    assert!(titles(&text).last() == Some(&"output ke"), "{text}");
    // Two indices: hit[i] has one; hit[0..1][0] asks for two and matches nothing.
    for (bad, says) in [
        ("nope", "`nope` names no state, event or output of model `box`"),
        ("hit[0..1][0]", "`hit[0..1][0]` names no state"),
        ("low[2..", "`low[2..` is not a name, an element"),
        ("low[a]", "`low[a]` is not a name"),
    ] {
        let (code, _, err) = derive_only(bad);
        assert_eq!(code, Some(2), "{bad}: {err}");
        assert!(err.contains(says), "{bad}: {err}");
    }
}
