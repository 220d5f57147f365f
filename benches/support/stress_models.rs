//! Generated models that stress the front end, shared by `tests/it/stress_frontend.rs` (which
//! checks their closed forms) and `benches/frontend.rs` (which measures them).
#![allow(dead_code)]

/// `n` chained lets `a_k = a_(k-1) + c` and `der(x) = a_(n-1)`: x(T) = n c T, dx/dc = n T.
/// `reversed` declares them last-first, so every use comes before its definition.
pub fn let_chain(n: usize, reversed: bool) -> String {
    let mut lets: Vec<String> = (1..n).map(|k| format!("let a{k} = a{} + c", k - 1)).collect();
    lets.insert(0, "let a0 = c".to_string());
    if reversed {
        lets.reverse();
    }
    format!(
        "model lets\nparam c = 1e-4\nstate x = 0\nder(x) = a{}\n{}\noutput y = a{}\nsimulate t_end = 1\n",
        n - 1,
        lets.join("\n"),
        n - 1
    )
}

/// `let d_k = d_(k-1) + p * d_(k-1)`, 60 times: as a tree, 2^60 nodes; as a DAG, about 120.
/// d_k = p (1 + p)^k.
pub fn doubling_lets(n: usize) -> String {
    let mut text = String::from("model doubling\nparam p = 1\nstate x = 1\nder(x) = 0\nlet d0 = p\n");
    for k in 1..n {
        text.push_str(&format!("let d{k} = d{} + p * d{}\n", k - 1, k - 1));
    }
    text.push_str(&format!("output big = d{}\nsimulate t_end = 1\n", n - 1));
    text
}

/// `der(x1) = -k x1`, `der(xi) = k (x(i-1) - xi)`, x1(0) = 1: xi(t) = (kt)^(i-1)/(i-1)! e^(-kt).
pub fn state_chain(n: usize) -> String {
    let mut text = String::from("model chain\nparam k = 1\nstate x1 = 1\n");
    for i in 2..=n {
        text.push_str(&format!("state x{i} = 0\n"));
    }
    text.push_str("der(x1) = -k * x1\n");
    for i in 2..=n {
        text.push_str(&format!("der(x{i}) = k * (x{} - x{i})\n", i - 1));
    }
    text.push_str("simulate t_end = 1\n");
    text
}

/// [`state_chain`] written with an array and two loops (`x[0]` for `x1`): flattening gives the
/// same model under element names, so the two compare the cost of `expand`.
pub fn state_chain_loop(n: usize) -> String {
    format!(
        "model chain\nconst N = {n}\nparam k = 1\nfor i in 0 .. 1 {{\n    state x[i] = 1\n    der(x[i]) = -k * x[i]\n}}\n\
         for i in 1 .. N {{\n    state x[i] = 0\n    der(x[i]) = k * (x[i - 1] - x[i])\n}}\nsimulate t_end = 1\n"
    )
}

/// `let a_k = a_(k-1) * a_(k-1) + c`, `n` times from `a0 = x`, and `der(x) = a_n`: each let uses
/// its predecessor twice, and the derivative `da_n/dc = 1 + 2 a_(n-1) (1 + 2 a_(n-2) (...))` nests
/// `n` deep (a text of `O(n)` characters, and `O(n^2)` if every partial text were kept). For
/// `0 <= x << 1` and `c < 1/4` the iteration reaches its fixed point `a* = (1 - sqrt(1 - 4c)) / 2`
/// within a few hundred lets, where `da*/dc = 1 / sqrt(1 - 4c)` and `da_n/dx` has underflowed to
/// 0: x(T) = a* T, dx/dc = T / sqrt(1 - 4c).
pub fn squaring_lets(n: usize) -> String {
    let mut text = String::from("model squares\nparam c = 0.01\nstate x = 0\nlet a0 = x\n");
    for k in 1..=n {
        text.push_str(&format!("let a{k} = a{} * a{} + c\n", k - 1, k - 1));
    }
    text.push_str(&format!("der(x) = a{n}\nsimulate t_end = 1\n"));
    text
}

/// `n` states that each read one shared sum of all of them: `der(x_i) = -k x_i + 0.001 s`,
/// `s = x_0 + ... + x_(n-1)` (written as partial sums of 100 terms, since a line holds at most
/// 4096 characters), x_i(0) = 1. The Jacobian `f_x` is dense, `n^2` entries. By symmetry every
/// x_i stays equal: x' = (-k + 0.001 n) x, so x_i(t) = exp((0.001 n - k) t) and
/// dx_i/dk = -t x_i(t).
pub fn shared_sum(n: usize) -> String {
    let mut text = String::from("model shared\nparam k = 1\n");
    for i in 0..n {
        text.push_str(&format!("state x{i} = 1\n"));
    }
    let chunks: Vec<Vec<usize>> =
        (0..n).step_by(100).map(|start| (start..n.min(start + 100)).collect()).collect();
    for (c, chunk) in chunks.iter().enumerate() {
        let terms: Vec<String> = chunk.iter().map(|i| format!("x{i}")).collect();
        text.push_str(&format!("let s{c} = {}\n", terms.join(" + ")));
    }
    let partial: Vec<String> = (0..chunks.len()).map(|c| format!("s{c}")).collect();
    text.push_str(&format!("let s = {}\n", partial.join(" + ")));
    for i in 0..n {
        text.push_str(&format!("der(x{i}) = -k * x{i} + 0.001 * s\n"));
    }
    text.push_str("simulate t_end = 1\n");
    text
}
