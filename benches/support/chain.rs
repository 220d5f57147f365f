//! The generated chain model shared by `benches/jit.rs` and `examples/jit_options.rs`.

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
