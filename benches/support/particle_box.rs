//! Particles in a box (issue #41), shared by `tests/it/arrays.rs` and the 1,000-particle
//! measurement (`benches/measure/particle_box.rs`): the model written with arrays, loops and event
//! families, and its closed form. Equal masses with elastic walls and velocity swaps at contact
//! move as free particles passing through each other, relabelled, so every wall and pair event
//! time and the final state follow from the free motion folded into the box.
// Each includer uses only some of the items.
#![allow(dead_code)]

/// The box of the issue: `N` particles on `[0, L]`, spread unevenly, with uneven velocities (so
/// no two events share an instant), speeds scaled by `s`.
pub fn box_source(n: usize) -> String {
    format!(
        "model box
const N = {n}
param L = 1
param s = 1
for i in 0 .. N {{
    state x[i] = L * (i + 0.5 + 0.3 * sin(1.3 * i * i + 0.7)) / N
    state v[i] = s * sin(2.1 * i * i + 0.4)
    der(x[i]) = v[i]
    der(v[i]) = 0
    event low[i] when x[i] <= 0 {{ v[i] := -v[i] }}
    event high[i] when x[i] >= L {{ v[i] := -v[i] }}
}}
for i in 0 .. N - 1 {{
    event hit[i] when x[i + 1] - x[i] <= 0 {{
        v[i] := v[i + 1]
        v[i + 1] := v[i]
    }}
}}
output ke = sum(k in 0 .. N: 0.5 * v[k]^2)
"
    )
}

/// A free particle folded into `[0, l]` by the walls: position and velocity at `t`.
pub fn folded(p0: f64, v: f64, l: f64, t: f64) -> (f64, f64) {
    let m = (p0 + v * t).rem_euclid(2.0 * l);
    if m <= l {
        (m, v)
    } else {
        (2.0 * l - m, -v)
    }
}

/// Event times with the names of the elements that fire.
pub type Events = Vec<(f64, String)>;
/// Positions with velocities, in order along the box.
pub type Particles = Vec<(f64, f64)>;

/// The free particles' wall and pair events to `t_end`, named as the relabelled model names
/// them, sorted by time; and the final positions and velocities in order.
pub fn box_closed_form(n: usize, t_end: f64) -> (Events, Particles) {
    let l = 1.0;
    let x0: Vec<f64> = (0..n)
        .map(|i| {
            let i = i as f64;
            l * (i + 0.5 + 0.3 * (1.3 * i * i + 0.7).sin()) / n as f64
        })
        .collect();
    let v0: Vec<f64> = (0..n).map(|i| i as f64).map(|i| (2.1 * i * i + 0.4).sin()).collect();
    let mut events = Vec::new();
    // Wall hits of each ghost: its unfolded path crosses k L. The leftmost particle takes every
    // hit of the floor, the rightmost every hit of the ceiling.
    let mut walls: Vec<Vec<f64>> = vec![Vec::new(); n];
    for j in 0..n {
        let (p, v) = (x0[j], v0[j]);
        let mut k = if v > 0.0 { (p / l).floor() + 1.0 } else { (p / l).ceil() - 1.0 };
        loop {
            let t = (k * l - p) / v;
            if t > t_end {
                break;
            }
            walls[j].push(t);
            let name =
                if (k as i64).rem_euclid(2) == 0 { "low[0]".to_string() } else { format!("high[{}]", n - 1) };
            events.push((t, name));
            k += v.signum();
        }
    }
    // Pair crossings: on each piece where both ghosts move linearly.
    for a in 0..n {
        for b in a + 1..n {
            let mut cuts: Vec<f64> = [0.0, t_end]
                .into_iter()
                .chain(walls[a].iter().copied())
                .chain(walls[b].iter().copied())
                .collect();
            cuts.sort_by(f64::total_cmp);
            for w in cuts.windows(2) {
                let (t0, t1) = (w[0], w[1]);
                let mid = 0.5 * (t0 + t1);
                let (_, sa) = folded(x0[a], v0[a], l, mid);
                let (_, sb) = folded(x0[b], v0[b], l, mid);
                if sa == sb {
                    continue;
                }
                let ya = folded(x0[a], v0[a], l, mid).0;
                let yb = folded(x0[b], v0[b], l, mid).0;
                let t = mid + (yb - ya) / (sa - sb);
                if t > t0 && t < t1 && t > 0.0 {
                    let y = folded(x0[a], v0[a], l, t).0;
                    let rank =
                        (0..n).filter(|&c| c != a && c != b && folded(x0[c], v0[c], l, t).0 < y).count();
                    events.push((t, format!("hit[{rank}]")));
                }
            }
        }
    }
    events.sort_by(|p, q| p.0.total_cmp(&q.0));
    let mut last: Vec<(f64, f64)> = (0..n).map(|j| folded(x0[j], v0[j], l, t_end)).collect();
    last.sort_by(|p, q| p.0.total_cmp(&q.0));
    (events, last)
}
