//! The generalized Cauchy point (Byrd, Lu, Nocedal and Zhu 1995, section 4, "Algorithm CP"): the
//! first local minimiser of the quadratic model `m(x) = g . (x - x_k) + (x - x_k)^T B (x - x_k) / 2`
//! along the projected steepest-descent path `P(x_k - t g)`, `t >= 0`. The path is piecewise
//! linear, bending where a variable reaches its bound; the model's slope and curvature along it
//! are updated segment by segment in `O(m^2)` each from the compact form of `B`, so the point
//! costs `O(m n + n log n)`. The variables at a bound there are the active set the subspace step
//! keeps fixed.

use nalgebra::DVector;

use super::memory::Memory;

/// The Cauchy point and what the subspace step needs of it.
pub(super) struct CauchyPoint {
    /// The point.
    pub x: Vec<f64>,
    /// `c = W^T (x_cp - x_k)` (`2k`).
    pub c: DVector<f64>,
    /// Per variable: on a bound at the Cauchy point (held by the subspace step).
    pub at_bound: Vec<bool>,
}

/// The Cauchy point from `x` (inside `bounds`) with gradient `g` and the model `memory`.
pub(super) fn cauchy_point(x: &[f64], g: &[f64], bounds: &[(f64, f64)], memory: &Memory) -> CauchyPoint {
    let n = x.len();
    let theta = memory.theta();
    let middle = memory.middle();
    // Breakpoints: where each variable moving along -g meets its bound.
    let mut d = vec![0.0; n];
    let mut breaks: Vec<(f64, usize)> = Vec::new();
    let mut xcp = x.to_vec();
    let mut at_bound = vec![false; n];
    for i in 0..n {
        let (lo, hi) = bounds[i];
        let t = if g[i] < 0.0 {
            (x[i] - hi) / g[i]
        } else if g[i] > 0.0 {
            (x[i] - lo) / g[i]
        } else {
            f64::INFINITY
        };
        if t > 0.0 {
            d[i] = -g[i];
            if t.is_finite() {
                breaks.push((t, i));
            }
        } else {
            // On its bound with the gradient pointing out (t = 0): it does not move.
            at_bound[i] = x[i] <= lo || x[i] >= hi;
        }
    }
    breaks.sort_by(|a, b| a.0.total_cmp(&b.0));
    let all: Vec<usize> = (0..n).collect();
    let mut p = memory.w_t_over(&all, &d);
    let mut c = DVector::zeros(p.len());
    // Slope and curvature of the model along d at t = 0.
    let mut f1: f64 = -d.iter().map(|v| v * v).sum::<f64>();
    if f1 == 0.0 {
        return CauchyPoint { x: xcp, c, at_bound };
    }
    let f2_start = -theta * f1 - p.dot(&(middle * &p));
    let mut f2 = f2_start;
    let mut dt_min = -f1 / f2;
    let mut t_old = 0.0;
    let mut next = 0;
    while next < breaks.len() {
        let (t, b) = breaks[next];
        let dt = t - t_old;
        if dt_min < dt {
            break;
        }
        next += 1;
        // Move to the breakpoint: variable b reaches its bound and stops.
        let (lo, hi) = bounds[b];
        xcp[b] = if d[b] > 0.0 { hi } else { lo };
        at_bound[b] = true;
        let z_b = xcp[b] - x[b];
        c += dt * &p;
        let w_b = memory.w_row(b);
        let m_w = middle * &w_b;
        let gb = g[b];
        f1 += dt * f2 + gb * gb + theta * gb * z_b - gb * m_w.dot(&c);
        f2 += -theta * gb * gb - 2.0 * gb * m_w.dot(&p) - gb * gb * m_w.dot(&w_b);
        // Round-off must not turn the curvature (positive: B is) negative.
        f2 = f2.max(f64::EPSILON * f2_start);
        p += gb * w_b;
        d[b] = 0.0;
        dt_min = -f1 / f2;
        t_old = t;
    }
    let dt_min = dt_min.max(0.0);
    let t = t_old + dt_min;
    for i in 0..n {
        if d[i] != 0.0 {
            xcp[i] = x[i] + t * d[i];
        }
    }
    c += dt_min * p;
    CauchyPoint { x: xcp, c, at_bound }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FREE: (f64, f64) = (f64::NEG_INFINITY, f64::INFINITY);

    #[test]
    fn without_bounds_and_memory_it_is_the_steepest_descent_minimiser_of_the_unit_model() {
        // B = I: m(x - t g) = -t |g|^2 + t^2 |g|^2 / 2, least at t = 1.
        let cp = cauchy_point(&[1.0, 2.0], &[0.5, -1.0], &[FREE; 2], &Memory::new(5));
        assert_eq!(cp.x, vec![0.5, 3.0]);
        assert_eq!(cp.at_bound, vec![false, false]);
    }

    #[test]
    fn a_bound_on_the_path_bends_it_and_holds_its_variable() {
        // From (1, 1) along -g = (-2, -0.5): x_0 meets 0.5 at t = 0.25, then only x_1 moves; with
        // B = I the model along the second segment is least at t = 1 (x_1 = 0.5).
        let cp = cauchy_point(&[1.0, 1.0], &[2.0, 0.5], &[(0.5, 2.0), FREE], &Memory::new(5));
        assert_eq!(cp.x, vec![0.5, 0.5]);
        assert_eq!(cp.at_bound, vec![true, false]);
        // A variable on its bound with the gradient pointing out does not move.
        let cp = cauchy_point(&[0.5, 1.0], &[2.0, 0.5], &[(0.5, 2.0), FREE], &Memory::new(5));
        assert_eq!(cp.x, vec![0.5, 0.5]);
        assert_eq!(cp.at_bound, vec![true, false]);
    }

    #[test]
    fn with_memory_the_point_minimises_the_compact_model_along_the_path() {
        // B from two pairs; no bound is reached, so the Cauchy point is x - t* g with
        // t* = |g|^2 / g^T B g, and c = W^T (x_cp - x).
        let mut memory = Memory::new(5);
        assert!(memory.push(vec![1.0, 0.0, 0.0], vec![3.0, 0.5, 0.0]));
        assert!(memory.push(vec![0.0, 1.0, 0.5], vec![0.5, 2.0, 0.6]));
        let g = [0.3, -0.2, 0.1];
        let bg = memory.times(&g);
        let gg: f64 = g.iter().map(|v| v * v).sum();
        let t = gg / g.iter().zip(&bg).map(|(a, b)| a * b).sum::<f64>();
        let x = [0.0, 0.0, 0.0];
        let cp = cauchy_point(&x, &g, &[FREE; 3], &memory);
        for (x, g) in cp.x.iter().zip(g) {
            approx::assert_relative_eq!(*x, -t * g, max_relative = 1e-12);
        }
        let c = memory.w_t_over(&[0, 1, 2], &cp.x);
        approx::assert_relative_eq!(cp.c, c, max_relative = 1e-12);
    }
}
