//! The generated chain models shared by the benches, the examples and the tests
//! (`tests/it/support`): `chain_source` (`benches/jit.rs`), `diffusion_source` (workload W5),
//! `refill_source` (the W5 chain refilled: landing on events),
//! `hub_source` and `grid_source` (the sparse LU, `benches/measure/sparse_hub.rs`), and
//! `link_chain_source` (a conductance per link: the adjoint's measurements and tests).
// Each includer (benches, examples, tests) uses only some of the generators.
#![allow(dead_code)]

/// The ten conductances of the diffusion chain (and the hub, the grid), the parameters the
/// measurements differentiate.
pub const D_NAMES: [&str; 10] =
    ["d[0]", "d[1]", "d[2]", "d[3]", "d[4]", "d[5]", "d[6]", "d[7]", "d[8]", "d[9]"];

/// The best wall time in ms of `reps` calls of `f` (at least one), and the last result: the
/// examples' measurements.
pub fn best<T>(reps: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..reps {
        let start = std::time::Instant::now();
        let v = f();
        best = best.min(start.elapsed().as_secs_f64());
        out = Some(v);
    }
    (best * 1e3, out.expect("at least one repetition"))
}

/// A chain of `n` states: `x0` decays, each later state relaxes towards its predecessor with a
/// quadratic loss; one event resets the last state.
pub fn chain_source(n: usize) -> String {
    let mut s = String::from("model chain\nparam k = 0.5\nparam c = 0.1\nparam a = 1.0\n");
    s.push_str("state x0 = a\n");
    for i in 1..n {
        s.push_str(&format!("state x{i} = 0\n"));
    }
    s.push_str("der(x0) = -k * x0\n");
    for i in 1..n {
        s.push_str(&format!("der(x{i}) = k * (x{} - x{i}) - c * x{i} * x{i}\n", i - 1));
    }
    let last = n - 1;
    s.push_str(&format!("event full when x{last} >= 0.5 {{\n    x{last} := 0\n}}\n"));
    s.push_str(&format!("output y = x{last}\n"));
    s
}

/// Workload W5 of issue #25: a diffusion chain of `n` states, mildly stiff, with 10 parameters
/// and a guard on one state. Cell `i` exchanges with cell `i + 1` through the conductance
/// `d[j]` of its segment (`j = 10 i / n`, ten segments of equal length) and every cell leaks at
/// rate `c`: the eigenvalues lie in `[-(4 max d + c), -c]` (down to -200 at the defaults, so an
/// explicit method is held to steps of about 0.016 at any `n`). The cells start on a ramp,
/// `x_i(0) = 1 - i / (2 n)`; when cell 0 has leaked down to 0.6 (near t = 5) it is topped up by
/// 0.3 once (`top_up`, a falling guard on `x0`, then mode `rest`). Without the event
/// (`with_event = false`) the chain is linear, `x' = A(d) x`: its solution and derivatives are
/// a matrix exponential (the tests' closed form).
pub fn diffusion_source(n: usize, with_event: bool) -> String {
    assert!(n >= 2, "a chain has at least two cells");
    let mut s = diffusion_cells("diffusion_chain", n, |i| diffusion_start(i, n));
    if with_event {
        s.push_str("initial mode fill {\n    event top_up when x0 <= 0.6 -> rest {\n        x0 := x0 + 0.3\n    }\n}\nmode rest {\n}\n");
    }
    s.push_str(&format!("output y = x{}\n", n - 1));
    s
}

/// The W5 chain's flow from a full first cell (`x0 = 1`, the others empty), with `x0` refilled to 1
/// whenever it drains to 0.5 (`refill`, 19 times to t = 10 with 10 cells): the event landing
/// test's and `benches/measure/w5_accuracy.rs`'s model.
pub fn refill_source(n: usize) -> String {
    let mut s = diffusion_cells("refill_chain", n, |i| if i == 0 { 1.0 } else { 0.0 });
    s.push_str("event refill when x0 <= 0.5 {\n    x0 := 1\n}\n");
    s
}

/// The diffusion chain's declarations and flows (see [`diffusion_source`]) as model `name`, cell
/// `i` starting at `start(i)`.
fn diffusion_cells(name: &str, n: usize, start: impl Fn(usize) -> f64) -> String {
    let seg = |i: usize| 10 * i / n;
    let mut s = format!("model {name}\nparam d[10] = 50 in [0.1, 1000]\nparam c = 0.1\n");
    for i in 0..n {
        s.push_str(&format!("state x{i} = {}\n", start(i)));
    }
    for i in 0..n {
        let mut rhs = format!("-c * x{i}");
        if i > 0 {
            rhs.push_str(&format!(" + d[{}] * (x{} - x{i})", seg(i - 1), i - 1));
        }
        if i + 1 < n {
            rhs.push_str(&format!(" - d[{}] * (x{i} - x{})", seg(i), i + 1));
        }
        s.push_str(&format!("der(x{i}) = {rhs}\n"));
    }
    s
}

/// Cell `i`'s initial value in [`diffusion_source`] (as written in the model: `{}` of an `f64`
/// reads back exactly).
pub fn diffusion_start(i: usize, n: usize) -> f64 {
    1.0 - 0.5 * i as f64 / n as f64
}

/// A hub of `n` states (a thermal network with an ambient node): the hub `x0` exchanges with
/// each leaf `x1 ..= x(n-1)` through the conductance `d[j]` of the leaf's tenth (`j = 10 (i - 1)
/// / (n - 1)`), the leaves leak at rate `c`: `der(x_i) = -d (x_i - x0) - c x_i`, `der(x0) =
/// sum_i d (x_i - x0)`. `f_x` is an arrowhead (no narrow band fits it: the hub's row and column
/// span the matrix); the hub's own rate is about `-d n`, stiff for large `n`. The leaves start
/// on a ramp, the hub at 0.5; with `with_event`, leaf `x1` is topped up by 0.3 once when it has
/// drained to 0.6 (near t = 2).
pub fn hub_source(n: usize, with_event: bool) -> String {
    assert!(n >= 3, "a hub and at least two leaves");
    let seg = |i: usize| 10 * (i - 1) / (n - 1);
    let mut s = String::from("model hub\nparam d[10] = 50 in [0.1, 1000]\nparam c = 0.1\nstate x0 = 0.5\n");
    for i in 1..n {
        s.push_str(&format!("state x{i} = {}\n", diffusion_start(i, n)));
    }
    for i in 1..n {
        s.push_str(&format!("der(x{i}) = -d[{}] * (x{i} - x0) - c * x{i}\n", seg(i)));
    }
    // The hub's sum in parts of 50 leaves (`let`s: a line holds at most 4096 characters).
    let leaves: Vec<usize> = (1..n).collect();
    let mut parts = Vec::new();
    for (k, group) in leaves.chunks(50).enumerate() {
        let terms: Vec<String> = group.iter().map(|&i| format!("d[{}] * (x{i} - x0)", seg(i))).collect();
        s.push_str(&format!("let hub{k} = {}\n", terms.join(" + ")));
        parts.push(format!("hub{k}"));
    }
    s.push_str(&format!("der(x0) = {}\n", parts.join(" + ")));
    if with_event {
        s.push_str("initial mode fill {\n    event top_up when x1 <= 0.6 -> rest {\n        x1 := x1 + 0.3\n    }\n}\nmode rest {\n}\n");
    }
    s.push_str("output y = x0\n");
    s
}

/// A `side x side` grid of cells (`n = side^2` states, cell `(x, y)` is `x(y side + x)`), each
/// exchanging with its four neighbours through the conductance `d[j]` of its band of rows
/// (`j = 10 y / side`) and leaking at rate `c`; the cells start on a ramp and, with
/// `with_event`, cell 0 is topped up by 0.3 once when it has drained to 0.6 (as
/// [`diffusion_source`]). Reverse Cuthill-McKee gives it a band of about `side`.
pub fn grid_source(side: usize, with_event: bool) -> String {
    assert!(side >= 2, "a grid of at least 2 x 2");
    let n = side * side;
    let id = |x: usize, y: usize| y * side + x;
    let mut s = String::from("model grid\nparam d[10] = 50 in [0.1, 1000]\nparam c = 0.1\n");
    for i in 0..n {
        s.push_str(&format!("state x{i} = {}\n", diffusion_start(i, n)));
    }
    for y in 0..side {
        for x in 0..side {
            let i = id(x, y);
            let mut rhs = format!("-c * x{i}");
            let mut link =
                |j: usize, row: usize| rhs.push_str(&format!(" + d[{}] * (x{j} - x{i})", 10 * row / side));
            if x > 0 {
                link(id(x - 1, y), y);
            }
            if x + 1 < side {
                link(id(x + 1, y), y);
            }
            if y > 0 {
                link(id(x, y - 1), y - 1);
            }
            if y + 1 < side {
                link(id(x, y + 1), y);
            }
            s.push_str(&format!("der(x{i}) = {rhs}\n"));
        }
    }
    if with_event {
        s.push_str("initial mode fill {\n    event top_up when x0 <= 0.6 -> rest {\n        x0 := x0 + 0.3\n    }\n}\nmode rest {\n}\n");
    }
    s.push_str(&format!("output y = x{}\n", n - 1));
    s
}

/// A chain of `n` cells with a conductance per link, `d[i] = d` between cells i and i + 1 (`n - 1`
/// parameters), every cell leaking at rate `c = 0.1`; cell 0 starts at 1 and is topped up by 0.3
/// when it has leaked down to 0.6: once (then mode `rest`), or every time (`top_up_again`). The
/// shape whose forward sensitivity kernel grows as `n m` and whose gradient the adjoint gets at
/// the cost of a few plain runs.
pub fn link_chain_source(n: usize, d: f64, top_up_again: bool) -> String {
    let mut s = format!("model link_chain\nparam d[{}] = {d} in [0.1, 1000]\nparam c = 0.1\n", n - 1);
    for i in 0..n {
        s.push_str(&format!("state x{i} = {}\n", if i == 0 { 1.0 } else { 0.0 }));
    }
    for i in 0..n {
        let mut rhs = format!("-c * x{i}");
        if i > 0 {
            rhs.push_str(&format!(" + d[{}] * (x{} - x{i})", i - 1, i - 1));
        }
        if i + 1 < n {
            rhs.push_str(&format!(" - d[{i}] * (x{i} - x{})", i + 1));
        }
        s.push_str(&format!("der(x{i}) = {rhs}\n"));
    }
    let after = if top_up_again { "fill" } else { "rest" };
    s.push_str(&format!(
        "initial mode fill {{\n    event top_up when x0 <= 0.6 -> {after} {{\n        x0 := x0 + 0.3\n    }}\n}}\n"
    ));
    if !top_up_again {
        s.push_str("mode rest {\n}\n");
    }
    s.push_str(&format!("output y = x{}\n", n - 1));
    s
}
