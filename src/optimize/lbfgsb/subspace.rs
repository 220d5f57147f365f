//! Subspace minimisation (Byrd, Lu, Nocedal and Zhu 1995, section 5.1, the direct primal method):
//! from the Cauchy point, minimise the quadratic model over the variables it left free, the
//! others held at their bounds. The reduced model's Newton step comes from the compact form by
//! the Sherman-Morrison-Woodbury formula (a `2k x 2k` solve, `O(m^2 n)`), and is then projected
//! onto the box; should the projected point not be a descent direction from `x_k`, the step is
//! cut back along itself to the box instead (Morales and Nocedal 2011, the remark on Algorithm
//! 778 that L-BFGS-B 3.0 follows).

use nalgebra::DMatrix;

use super::cauchy::CauchyPoint;
use super::memory::Memory;

/// The point the line search aims at: the Cauchy point with its free variables moved to the
/// reduced model's minimiser, within the box.
pub(super) fn subspace_point(
    x: &[f64],
    g: &[f64],
    bounds: &[(f64, f64)],
    memory: &Memory,
    cp: &CauchyPoint,
) -> Vec<f64> {
    let free: Vec<usize> = (0..x.len()).filter(|&i| !cp.at_bound[i]).collect();
    if free.is_empty() {
        return cp.x.clone();
    }
    let theta = memory.theta();
    let middle = memory.middle();
    // The reduced gradient at the Cauchy point: r = Z^T (g + B (x_cp - x)), with
    // B (x_cp - x) = theta (x_cp - x) - W M c.
    let mc = middle * &cp.c;
    let r: Vec<f64> = free
        .iter()
        .map(|&i| {
            let wmc = if memory.len() > 0 { memory.w_row(i).dot(&mc) } else { 0.0 };
            g[i] + theta * (cp.x[i] - x[i]) - wmc
        })
        .collect();
    // du = -(1/theta) r - (1/theta^2) Z^T W N^-1 M W^T Z r, N = I - (1/theta) M W^T Z Z^T W.
    let mut du: Vec<f64> = r.iter().map(|v| -v / theta).collect();
    if memory.len() > 0 {
        let mut r_full = vec![0.0; x.len()];
        for (&i, &v) in free.iter().zip(&r) {
            r_full[i] = v;
        }
        let v = middle * memory.w_t_over(&free, &r_full);
        let n = DMatrix::identity(v.len(), v.len()) - middle * memory.w_t_w_over(&free) / theta;
        match n.lu().solve(&v) {
            Some(v) if v.iter().all(|e| e.is_finite()) => {
                for (k, &i) in free.iter().enumerate() {
                    du[k] -= memory.w_row(i).dot(&v) / (theta * theta);
                }
            }
            // A singular reduced system: no step beyond the Cauchy point.
            _ => return cp.x.clone(),
        }
    }
    // Projected onto the box, the free variables' minimiser.
    let mut target = cp.x.clone();
    for (k, &i) in free.iter().enumerate() {
        let (lo, hi) = bounds[i];
        target[i] = (cp.x[i] + du[k]).clamp(lo, hi);
    }
    let slope: f64 = (0..x.len()).map(|i| (target[i] - x[i]) * g[i]).sum();
    if slope < 0.0 {
        return target;
    }
    // Not a descent direction: the longest step along du from the Cauchy point within the box.
    let mut alpha: f64 = 1.0;
    for (k, &i) in free.iter().enumerate() {
        let (lo, hi) = bounds[i];
        if du[k] > 0.0 {
            alpha = alpha.min((hi - cp.x[i]) / du[k]);
        } else if du[k] < 0.0 {
            alpha = alpha.min((lo - cp.x[i]) / du[k]);
        }
    }
    let alpha = alpha.max(0.0);
    let mut truncated = cp.x.clone();
    for (k, &i) in free.iter().enumerate() {
        let (lo, hi) = bounds[i];
        truncated[i] = (cp.x[i] + alpha * du[k]).clamp(lo, hi);
    }
    truncated
}

#[cfg(test)]
mod tests {
    use super::super::cauchy::cauchy_point;
    use super::*;

    const FREE: (f64, f64) = (f64::NEG_INFINITY, f64::INFINITY);

    #[test]
    fn without_bounds_the_step_is_the_quasi_newton_step() {
        // With nothing at a bound the subspace point is x - B^-1 g, whatever the Cauchy point.
        let mut memory = Memory::new(5);
        assert!(memory.push(vec![1.0, 0.0, 0.0], vec![3.0, 0.5, 0.0]));
        assert!(memory.push(vec![0.0, 1.0, 0.5], vec![0.5, 2.0, 0.6]));
        let x = [0.2, -0.1, 0.4];
        let g = [0.3, -0.2, 0.1];
        let cp = cauchy_point(&x, &g, &[FREE; 3], &memory);
        let target = subspace_point(&x, &g, &[FREE; 3], &memory, &cp);
        let step: Vec<f64> = (0..3).map(|i| target[i] - x[i]).collect();
        // B step = -g.
        let b_step = memory.times(&step);
        for i in 0..3 {
            approx::assert_relative_eq!(b_step[i], -g[i], max_relative = 1e-10, epsilon = 1e-14);
        }
    }

    #[test]
    fn a_held_variable_stays_and_the_others_minimise_the_reduced_model() {
        // x_0 held at its lower bound 0 by the Cauchy point, the model in x_1 alone,
        // g_1 d_1 + (B_10 d_0 d_1 + B_11 d_1^2 / 2) with d = z - x, is least at
        // d_1 = -(g_1 + B_10 d_0) / B_11, d_0 = -x_0.
        let mut memory = Memory::new(5);
        assert!(memory.push(vec![1.0, 0.0], vec![2.0, 1.0]));
        assert!(memory.push(vec![0.0, 1.0], vec![1.0, 2.0]));
        let x = [0.1, 1.0];
        let g = [5.0, 1.0];
        let bounds = [(0.0, 10.0), FREE];
        let cp = cauchy_point(&x, &g, &bounds, &memory);
        assert!(cp.at_bound[0] && !cp.at_bound[1]);
        let target = subspace_point(&x, &g, &bounds, &memory, &cp);
        assert_eq!(target[0], 0.0);
        let column = memory.times(&[0.0, 1.0]);
        let expected = x[1] - (g[1] + column[0] * (0.0 - x[0])) / column[1];
        approx::assert_relative_eq!(target[1], expected, max_relative = 1e-12);
    }
}
