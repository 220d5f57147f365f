//! The ball pushed by a control of many knots, shared by the adjoint's measurements
//! (`adjoint_knots`, `sens_rule`).

/// The bouncing ball pushed by a force `pwl(t, 0, 2.5, u)` of `k` knots (2 states, `k`
/// parameters read two at a time), with its energy as an output.
pub fn pushed_ball_source(k: usize) -> String {
    format!(
        "model pushed_ball\nparam g = 9.81\nparam e = 0.8\nparam u[{k}] = 0.5\n\
         state y = 1\nstate v = 0\n\
         der(y) = v\nder(v) = -g + pwl(t, 0, 2.5, u)\n\
         event touchdown when y <= 0 {{\n v := -e * v\n}}\n\
         output energy = 0.5 * v^2 + g * y\n"
    )
}
