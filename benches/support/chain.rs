//! The generated chain models shared by the benches, the examples and the tests
//! (`tests/it/support`): `chain_source` (`benches/jit.rs`), `diffusion_source` (workload W5).
// Each includer (benches, examples, tests) uses only some of the generators.
#![allow(dead_code)]

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
/// `d[j]` of its segment (`j = 10 i / n`, ten segments of equal length), every cell leaks at
/// rate `c`; the eigenvalues lie in `[-(4 max d + c), -c]` (about -200 at the defaults: an
/// explicit method is held to steps of 0.02 over the whole run, at any `n`). Cell 0 starts full
/// and is refilled (`x0 := 1`) each time it drains to half (`refill`, a falling guard on `x0`).
/// Without the event (`with_event = false`) the chain is linear, `x' = A(d) x`: its solution
/// and derivatives are a matrix exponential (the tests' closed form).
pub fn diffusion_source(n: usize, with_event: bool) -> String {
    assert!(n >= 2, "a chain has at least two cells");
    let seg = |i: usize| 10 * i / n;
    let mut s = String::from("model diffusion_chain\nparam d[10] = 50 in [0.1, 1000]\nparam c = 0.1\n");
    s.push_str("state x0 = 1\n");
    for i in 1..n {
        s.push_str(&format!("state x{i} = 0\n"));
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
    if with_event {
        s.push_str("event refill when x0 <= 0.5 {\n    x0 := 1\n}\n");
    }
    s.push_str(&format!("output y = x{}\n", n - 1));
    s
}
