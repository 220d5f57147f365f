//! Vector parameters (`param u[N]`) against closed forms: `der(x) = dot(u, w)` gives
//! `x(T) = T sum_k u_k w_k`, `dx/du_k = T w_k`, `dx/dw_k = T u_k` exactly (a constant flow is
//! integrated without truncation error); an event at `x >= h` fires at `t_e = h / dot(u, w)`, with
//! `dt_e/du_k = -h w_k / dot(u, w)^2`. Also the `Params` API on vectors and the CLI's `--set`,
//! `--grad` and `--vary` on them.

use hybc::{Model, ParamError, SimOptions};

use crate::support::cli::hybc;

const DOT: &str = "model dot
param u[5] = 0 in [-5, 5]
param w[5] = 1
param h = 100
state x = u[0]
der(x) = dot(u, w)
output s = sum(u)
output ws = sum(w)
event hit when x >= h {
    stop
}
";

const U: [f64; 5] = [0.5, -1.0, 2.0, 3.0, -0.25];
const W: [f64; 5] = [1.0, 2.0, 3.0, 4.0, 5.0];

fn close(a: f64, b: f64, what: &str) {
    assert!((a - b).abs() <= 1e-10 * b.abs().max(1.0), "{what}: {a} vs {b}");
}

#[test]
fn dot_and_sum_match_their_closed_forms_with_exact_gradients() {
    let model = Model::parse(DOT).expect("checks");
    let names: Vec<String> =
        ["u", "w"].iter().flat_map(|v| (0..5).map(move |k| format!("{v}[{k}]"))).collect();
    let compiled = model.compile(&names).expect("compiles");
    let params = model.params().with_vector("u", &U).and_then(|p| p.with_vector("w", &W)).expect("in range");
    let t_end = 2.0;
    let run = compiled.simulate(&params, &SimOptions { t_end, ..SimOptions::default() }).expect("runs");
    let dot: f64 = U.iter().zip(&W).map(|(u, w)| u * w).sum();
    close(run.state("x").expect("x"), U[0] + t_end * dot, "x(T)");
    close(run.output("s").expect("s"), U.iter().sum(), "sum(u)");
    close(run.output("ws").expect("ws"), W.iter().sum(), "sum(w)");
    for k in 0..5 {
        let (u, w) = (format!("u[{k}]"), format!("w[{k}]"));
        let init = if k == 0 { 1.0 } else { 0.0 };
        close(run.dstate("x", &u).expect("dx/du"), init + t_end * W[k], &format!("dx/d{u}"));
        close(run.dstate("x", &w).expect("dx/dw"), t_end * U[k], &format!("dx/d{w}"));
        close(run.doutput("s", &u).expect("ds/du"), 1.0, &format!("ds/d{u}"));
        close(run.doutput("s", &w).expect("ds/dw"), 0.0, &format!("ds/d{w}"));
    }
}

#[test]
fn an_event_time_moves_with_every_element() {
    let model = Model::parse(DOT).expect("checks");
    let names: Vec<String> = (0..5).map(|k| format!("u[{k}]")).collect();
    let compiled = model.compile(&names).expect("compiles");
    // x starts at u[0] and rises at dot(u, w) to h: t_e = (h - u0) / dot.
    let u = [1.0, 2.0, 0.5, 1.0, 0.25];
    let params = model.params().with_vector("u", &u).expect("in range");
    let run =
        compiled.simulate(&params, &SimOptions { t_end: 100.0, ..SimOptions::default() }).expect("runs");
    let dot: f64 = u.iter().sum();
    let h = 100.0;
    assert_eq!(run.events().len(), 1);
    close(run.events()[0].time, (h - u[0]) / dot, "t_e");
    for (k, name) in names.iter().enumerate() {
        // d/du_k of (h - u0) / dot with w = 1: -(h - u0) / dot^2, and -1 / dot more for u0.
        let want = -(h - u[0]) / (dot * dot) - if k == 0 { 1.0 / dot } else { 0.0 };
        close(run.devent_time(0, name).expect("dt_e/du"), want, &format!("dt_e/d{name}"));
    }
}

#[test]
fn params_take_a_vector_whole_or_by_element() {
    let model = Model::parse(DOT).expect("checks");
    let params = model.params().with_vector("u", &U).expect("in range").with("u[3]", 4.5).expect("in range");
    assert_eq!(params.vector("u"), Some(&[0.5, -1.0, 2.0, 4.5, -0.25][..]));
    assert_eq!(params.get("u[3]"), Some(4.5));
    assert_eq!(params.get("u[5]"), None);
    assert_eq!(params.get("u[03]"), None);
    let wrong = model.params().with_vector("u", &[1.0, 2.0]);
    assert!(matches!(wrong, Err(ParamError::VectorLength { len: 5, found: 2, .. })), "{wrong:?}");
    // One element out of range refuses the whole vector, leaving the values as they were.
    let mut p = model.params();
    let err = p.set_vector("u", &[0.0, 0.0, 9.0, 0.0, 0.0]).expect_err("9 is outside [-5, 5]");
    assert_eq!(err.to_string(), "u[2] = 9 is outside its range [-5, 5]");
    assert_eq!(p.vector("u"), Some(&[0.0; 5][..]));
    let err = model.params().with("u", 1.0).expect_err("a vector is not a scalar");
    assert_eq!(err.to_string(), "`u` is a vector of 5 parameters; name one element, `u[0]` .. `u[4]`");
    let err = model.params().with_vector("h", &[1.0]).expect_err("h is a scalar");
    assert!(matches!(err, ParamError::NotAVector { .. }), "{err:?}");
}

#[test]
fn a_parameter_list_expands_a_vector_once_and_refuses_a_name_twice() {
    let model = Model::parse(DOT).expect("checks");
    let list = model.param_list(&["h", "u", "w[2]"]).expect("known names");
    let names: Vec<&str> = list.iter().map(|p| model.checked().params[p.0 as usize].name.as_str()).collect();
    assert_eq!(names, ["h", "u[0]", "u[1]", "u[2]", "u[3]", "u[4]", "w[2]"]);
    let twice = model.param_list(&["u", "u[1]"]).expect_err("u[1] twice");
    assert_eq!(twice, ParamError::Duplicate { name: "u[1]".into() });
    assert!(matches!(model.param_list(&["v"]), Err(ParamError::Unknown { .. })));
    // Compiling reads its gradient names the same way: a vector's name is its elements.
    let compiled = model.compile(&["u"]).expect("compiles");
    assert_eq!(compiled.grad_names().collect::<Vec<_>>(), ["u[0]", "u[1]", "u[2]", "u[3]", "u[4]"]);
}

fn stdout(args: &[&str]) -> (i32, String, String) {
    let out = hybc(args);
    let code = out.status.code().expect("exit code");
    (
        code,
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn the_cli_sets_and_differentiates_vectors_by_name() {
    let dir = std::env::temp_dir().join(format!("hybc-vector-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let file = dir.join("dot.hyb");
    std::fs::write(&file, DOT).expect("written");
    let path = file.to_str().expect("utf-8 path");
    let (code, json, err) = stdout(&[
        "run",
        path,
        "--format",
        "json",
        "--t-end",
        "2",
        "--grad",
        "u,w[4]",
        "--set",
        "u=0.5,-1,2,3,-0.25",
        "--set",
        "w[4]=5",
        "--set",
        "w=1,2,3,4,5",
    ]);
    // `w` and `w[4]` both set: refused, the second would silently win.
    assert_eq!(code, 2, "{err}");
    assert_eq!(err.trim(), "error: --set: `w[4]` is set twice (`--set w=...` sets every element)");
    assert!(json.is_empty());
    let (code, json, err) = stdout(&[
        "run",
        path,
        "--format",
        "json",
        "--t-end",
        "2",
        "--grad",
        "u,w[4]",
        "--set",
        "u=0.5,-1,2,3,-0.25",
        "--set",
        "w=1,2,3,4,5",
    ]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&json).expect("json");
    let grad: Vec<&str> =
        v["grad"].as_array().expect("grad").iter().map(|g| g.as_str().expect("name")).collect();
    assert_eq!(grad, ["u[0]", "u[1]", "u[2]", "u[3]", "u[4]", "w[4]"]);
    let dot: f64 = U.iter().zip(&W).map(|(u, w)| u * w).sum();
    close(v["final"]["state"]["x"].as_f64().expect("x"), U[0] + 2.0 * dot, "x(T)");
    close(v["final"]["dstate"]["x"]["u[3]"].as_f64().expect("dx/du3"), 2.0 * W[3], "dx/du[3]");
    close(v["final"]["dstate"]["x"]["w[4]"].as_f64().expect("dx/dw4"), 2.0 * U[4], "dx/dw[4]");
    let (code, _, err) = stdout(&["run", path, "--set", "u=1,2,3"]);
    assert_eq!(code, 2);
    assert_eq!(
        err.trim(),
        "error: --set u: expected 5 comma-separated values, one per element of `u`, found 3"
    );
    let (code, _, err) = stdout(&["run", path, "--set", "u[5]=1"]);
    assert_eq!(code, 2);
    assert!(err.contains("has no parameter `u[5]`") && err.contains("u[0] .. u[4]"), "{err}");
    let (code, _, err) = stdout(&["run", path, "--grad", "u,u[1]"]);
    assert_eq!(code, 2);
    assert_eq!(err.trim(), "error: --grad: `u[1]` is named twice");
    // A sweep varies one element; its column is named like the element.
    let (code, csv, err) = stdout(&["sweep", path, "--vary", "u[2]=0:1:3", "--t-end", "1"]);
    assert_eq!(code, 0, "{err}");
    assert!(csv.lines().next().expect("header").starts_with("u[0],u[1],u[2],u[3],u[4],w[0]"), "{csv}");
    assert_eq!(csv.lines().count(), 4, "{csv}");
    let (code, _, err) = stdout(&["sweep", path, "--vary", "u=0:1:3"]);
    assert_eq!(code, 2);
    assert!(err.contains("`u` is a vector of 5 parameters"), "{err}");
    // `hybc fit --free u` fits every element: sum(u) to 2 (underdetermined: the damped steps
    // move all elements alike from equal starts, to 0.4 each).
    let (code, json, err) =
        stdout(&["fit", path, "--free", "u", "--target", "s=2", "--format", "json", "--t-end", "1"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&json).expect("json");
    let free: Vec<&str> =
        v["free"].as_array().expect("free").iter().map(|f| f.as_str().expect("name")).collect();
    assert_eq!(free, ["u[0]", "u[1]", "u[2]", "u[3]", "u[4]"]);
    for k in 0..5 {
        let value = v["params"][format!("u[{k}]")].as_f64().expect("fitted value");
        assert!((value - 0.4).abs() < 1e-6, "u[{k}] = {value}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn check_lists_a_vector_on_one_line() {
    let model = hybc::check_source(DOT).expect("checks");
    assert_eq!(model.params.len(), 11);
    assert_eq!(model.vectors.len(), 2);
    assert_eq!(model.params[7].name, "w[2]");
    let dir = std::env::temp_dir().join(format!("hybc-vector-check-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let file = dir.join("dot.hyb");
    std::fs::write(&file, DOT).expect("written");
    let (code, out, _) = stdout(&["check", file.to_str().expect("utf-8")]);
    assert_eq!(code, 0);
    assert!(
        out.contains("  u[5] = 0  in [-5, 5]  (u[0] .. u[4])\n  w[5] = 1  (w[0] .. w[4])\n  h = 100\n"),
        "{out}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
