//! The double integrator `p'' = u` under a `pwl(t, 0, 1, u)` control of `N` knots and its closed
//! form (`tests/it/optimize_many.rs`; `benches/measure/many_knots.rs` includes this file with
//! `#[path]`): the objective `(p(1) - 1)^2 + v(1)^2 + lam int u^2` is a quadratic in the knots,
//! computed here without hybc. With spacing `h = 1 / (N - 1)`, `p(1) = a . u`, `v(1) = b . u`
//! with `a_k = int (1 - s) phi_k(s) ds`, `b_k = int phi_k` over the hat functions `phi_k`
//! (`a_k = (1 - t_k) h` inside, `h / 2 - h^2 / 6` and `h^2 / 6` at the ends; `b_k = h` inside,
//! `h / 2` at the ends), and `int u^2 = u^T Q u` with the tridiagonal mass matrix `Q` (`2h/3`
//! inside, `h/3` at the ends, `h/6` beside the diagonal). The integrator computes these exactly
//! to round-off: between knots every integrand is a polynomial of degree at most 3.

/// The effort's weight.
pub const LAM: f64 = 0.01;

/// The model with `n` knots, each in `[-bound, bound]` (no range for an infinite bound).
pub fn source(n: usize, bound: f64) -> String {
    let range = if bound.is_finite() { format!(" in [-{bound}, {bound}]") } else { String::new() };
    format!(
        "model di\nparam u[{n}] = 0{range}\nparam lam = {LAM}\nstate p = 0\nstate v = 0\nstate c = 0\n\
         der(p) = v\nder(v) = pwl(t, 0, 1, u)\nder(c) = pwl(t, 0, 1, u)^2\n\
         output obj = (p - 1)^2 + v^2 + lam * c\nsimulate t_end = 1, rtol = 1e-10, atol = 1e-12\n"
    )
}

/// The weights of the closed form: `p(1) = a . u`, `v(1) = b . u`, `int u^2 = u^T Q u`.
pub struct Weights {
    pub a: Vec<f64>,
    pub b: Vec<f64>,
    /// Q's diagonal; its off-diagonal entries are all `h / 6`.
    pub q: Vec<f64>,
    pub h: f64,
}

impl Weights {
    pub fn new(n: usize) -> Weights {
        let h = 1.0 / (n - 1) as f64;
        let end = |k: usize| k == 0 || k == n - 1;
        let a = (0..n)
            .map(|k| match k {
                0 => h / 2.0 - h * h / 6.0,
                _ if k == n - 1 => h * h / 6.0,
                _ => (1.0 - k as f64 * h) * h,
            })
            .collect();
        let b = (0..n).map(|k| if end(k) { h / 2.0 } else { h }).collect();
        let q = (0..n).map(|k| if end(k) { h / 3.0 } else { 2.0 * h / 3.0 }).collect();
        Weights { a, b, q, h }
    }

    pub fn q_times(&self, u: &[f64]) -> Vec<f64> {
        let n = u.len();
        let off = self.h / 6.0;
        (0..n)
            .map(|k| {
                let mut v = self.q[k] * u[k];
                if k > 0 {
                    v += off * u[k - 1];
                }
                if k + 1 < n {
                    v += off * u[k + 1];
                }
                v
            })
            .collect()
    }

    /// The objective and its gradient at `u`, in closed form.
    pub fn objective(&self, u: &[f64]) -> (f64, Vec<f64>) {
        let p = dot(&self.a, u);
        let v = dot(&self.b, u);
        let qu = self.q_times(u);
        let f = (p - 1.0).powi(2) + v * v + LAM * dot(u, &qu);
        let g = (0..u.len())
            .map(|k| 2.0 * (p - 1.0) * self.a[k] + 2.0 * v * self.b[k] + 2.0 * LAM * qu[k])
            .collect();
        (f, g)
    }

    /// `(lam Q)^-1 r` by the Thomas algorithm (Q is diagonally dominant).
    pub fn solve_lam_q(&self, r: &[f64]) -> Vec<f64> {
        let n = r.len();
        let off = LAM * self.h / 6.0;
        let mut c = vec![0.0; n];
        let mut d = vec![0.0; n];
        let mut denominator = LAM * self.q[0];
        c[0] = off / denominator;
        d[0] = r[0] / denominator;
        for k in 1..n {
            denominator = LAM * self.q[k] - off * c[k - 1];
            c[k] = off / denominator;
            d[k] = (r[k] - off * d[k - 1]) / denominator;
        }
        let mut x = vec![0.0; n];
        x[n - 1] = d[n - 1];
        for k in (0..n - 1).rev() {
            x[k] = d[k] - c[k] * x[k + 1];
        }
        x
    }

    /// The optimum without bounds: `(A + U U^T) u = a` with `A = lam Q`, `U = [a b]`, by
    /// Woodbury: `u = A^-1 a - A^-1 U (I + U^T A^-1 U)^-1 U^T A^-1 a`.
    pub fn unconstrained_optimum(&self) -> Vec<f64> {
        let ia = self.solve_lam_q(&self.a);
        let ib = self.solve_lam_q(&self.b);
        // S = I + U^T A^-1 U, 2 x 2; rhs = U^T A^-1 a.
        let (s11, s12, s22) = (1.0 + dot(&self.a, &ia), dot(&self.a, &ib), 1.0 + dot(&self.b, &ib));
        let (r1, r2) = (dot(&self.a, &ia), dot(&self.b, &ia));
        let det = s11 * s22 - s12 * s12;
        let z1 = (s22 * r1 - s12 * r2) / det;
        let z2 = (s11 * r2 - s12 * r1) / det;
        (0..ia.len()).map(|k| ia[k] - ia[k] * z1 - ib[k] * z2).collect()
    }
}

pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a * b).sum()
}

/// The KKT conditions at `u` in `[-bound, bound]` by the closed-form gradient: the projected
/// gradient (all of it on a free knot; on a knot at a bound only the part that would move it
/// into the box) as its largest entry relative to the gradient at the start `u = 0`, and its
/// 2-norm; and the multipliers of the knots at a bound (the gradient signed to point out of the
/// box: >= 0 where the bound holds).
pub struct ByHand {
    pub worst: f64,
    pub norm: f64,
    pub multipliers: Vec<f64>,
}

pub fn kkt_by_hand(w: &Weights, u: &[f64], bound: f64) -> ByHand {
    let (_, g0) = w.objective(&vec![0.0; u.len()]);
    let scale = g0.iter().fold(0.0_f64, |m, g| m.max(g.abs()));
    let (_, g) = w.objective(u);
    let mut residual = Vec::new();
    let mut multipliers = Vec::new();
    for (&u, &g) in u.iter().zip(&g) {
        if u == -bound {
            multipliers.push(g / scale);
            residual.push(g.min(0.0));
        } else if u == bound {
            multipliers.push(-g / scale);
            residual.push(g.max(0.0));
        } else {
            assert!(u > -bound && u < bound, "{u} outside the box");
            residual.push(g);
        }
    }
    ByHand {
        worst: residual.iter().fold(0.0_f64, |m, r| m.max(r.abs())) / scale,
        norm: dot(&residual, &residual).sqrt(),
        multipliers,
    }
}

/// How far a point with the projected-gradient 2-norm `norm` can be from the optimum: the
/// objective is strongly convex with modulus `mu = lam h / 3` (its Hessian is at least
/// `2 lam Q`, and Q's least eigenvalue is at least `h / 6` by Gershgorin's discs), and then
/// `mu |u - u*|^2 <= grad f(u) . (u - u*) <= |P grad f(u)| |u - u*|` over a box.
pub fn distance_bound(w: &Weights, norm: f64) -> f64 {
    norm / (LAM * w.h / 3.0)
}
