//! Stage 5 (sim): the flow of one mode as the right-hand side a stepper integrates: the adapter
//! between the `HybridSystem` contract and `method/`'s `Rhs` seam, over `z = [x, S]`.

use super::method::stepper::Rhs;
use super::system::HybridSystem;

/// The flow of `mode` with its sensitivities as one right-hand side over `z = [x, S]`, with the
/// model's Jacobians for an implicit stepper.
pub(crate) struct ModeRhs<'a, S: HybridSystem + ?Sized> {
    sys: &'a S,
    p: &'a [f64],
    n: usize,
    mode: usize,
    /// The latest time the flow is read at: a step that ends on an input knot reads the input on
    /// the knot's earlier side at its end (a stage at `t0 + h` may round onto the knot, or past
    /// it), so that no stage of it sees the value that holds only from the knot on.
    ceiling: f64,
}

pub(crate) fn rhs_for<'a, S: HybridSystem + ?Sized>(
    sys: &'a S,
    p: &'a [f64],
    n: usize,
    mode: usize,
) -> ModeRhs<'a, S> {
    ModeRhs { sys, p, n, mode, ceiling: f64::INFINITY }
}

impl<S: HybridSystem + ?Sized> ModeRhs<'_, S> {
    /// The flow read at `ceiling` at the latest (a time just before the input knot a step ends
    /// on).
    pub(crate) fn with_ceiling(mut self, ceiling: f64) -> Self {
        self.ceiling = ceiling;
        self
    }

    #[inline(always)]
    fn at(&self, t: f64) -> f64 {
        if t > self.ceiling {
            self.ceiling
        } else {
            t
        }
    }
}

impl<S: HybridSystem + ?Sized> Rhs for ModeRhs<'_, S> {
    #[inline(always)]
    fn eval(&mut self, t: f64, z: &[f64], dz: &mut [f64]) {
        let t = self.at(t);
        let (x, s) = z.split_at(self.n);
        let (dx, ds) = dz.split_at_mut(self.n);
        self.sys.flow_sens(self.mode, t, x, s, self.p, dx, ds);
    }

    #[inline(always)]
    fn eval_states(&mut self, t: f64, z: &[f64], dz: &mut [f64]) {
        let t = self.at(t);
        self.sys.flow(self.mode, t, &z[..self.n], self.p, &mut dz[..self.n]);
    }

    fn jacobian(&mut self, t: f64, z: &[f64], fx: &mut [f64], ft: &mut [f64]) {
        let t = self.at(t);
        let (x, s) = z.split_at(self.n);
        let (ftx, fts) = ft.split_at_mut(self.n);
        self.sys.flow_jac(self.mode, t, x, s, self.p, fx, ftx, fts);
    }

    fn jac_pattern(&self) -> Option<(usize, &[(u32, u32)])> {
        self.sys.jac_pattern(self.mode).map(|p| (self.mode, p))
    }

    fn jacobian_values(&mut self, t: f64, z: &[f64], vals: &mut [f64], ft: &mut [f64]) {
        let t = self.at(t);
        let (x, s) = z.split_at(self.n);
        let (ftx, fts) = ft.split_at_mut(self.n);
        self.sys.flow_jac_values(self.mode, t, x, s, self.p, vals, ftx, fts);
    }

    fn sens_coupling(&mut self, t: f64, xv: &[f64], z: &[f64], out: &mut [f64]) {
        let t = self.at(t);
        self.sys.sens_dir(self.mode, t, xv, &z[self.n..], self.p, out);
    }

    fn prepare(&mut self) -> bool {
        self.sys.prepare_jacobians().is_ok()
    }
}
