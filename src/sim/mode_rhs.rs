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
}

pub(crate) fn rhs_for<'a, S: HybridSystem + ?Sized>(
    sys: &'a S,
    p: &'a [f64],
    n: usize,
    mode: usize,
) -> ModeRhs<'a, S> {
    ModeRhs { sys, p, n, mode }
}

impl<S: HybridSystem + ?Sized> Rhs for ModeRhs<'_, S> {
    #[inline(always)]
    fn eval(&mut self, t: f64, z: &[f64], dz: &mut [f64]) {
        let (x, s) = z.split_at(self.n);
        let (dx, ds) = dz.split_at_mut(self.n);
        self.sys.flow_sens(self.mode, t, x, s, self.p, dx, ds);
    }

    #[inline(always)]
    fn eval_states(&mut self, t: f64, z: &[f64], dz: &mut [f64]) {
        self.sys.flow(self.mode, t, &z[..self.n], self.p, &mut dz[..self.n]);
    }

    fn jacobian(&mut self, t: f64, z: &[f64], fx: &mut [f64], ft: &mut [f64]) {
        let (x, s) = z.split_at(self.n);
        let (ftx, fts) = ft.split_at_mut(self.n);
        self.sys.flow_jac(self.mode, t, x, s, self.p, fx, ftx, fts);
    }

    fn jac_pattern(&self) -> Option<(usize, &[(u32, u32)])> {
        self.sys.jac_pattern(self.mode).map(|p| (self.mode, p))
    }

    fn jacobian_values(&mut self, t: f64, z: &[f64], vals: &mut [f64], ft: &mut [f64]) {
        let (x, s) = z.split_at(self.n);
        let (ftx, fts) = ft.split_at_mut(self.n);
        self.sys.flow_jac_values(self.mode, t, x, s, self.p, vals, ftx, fts);
    }

    fn sens_coupling(&mut self, t: f64, xv: &[f64], z: &[f64], out: &mut [f64]) {
        self.sys.sens_dir(self.mode, t, xv, &z[self.n..], self.p, out);
    }

    fn prepare(&mut self) -> bool {
        self.sys.prepare_jacobians().is_ok()
    }
}
