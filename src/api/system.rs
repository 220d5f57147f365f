//! A [`Compiled`] model is a [`HybridSystem`]: the analysis cores (`sweep`, `sobol`, `gradcheck`,
//! the trajectory writer) are generic over the system, and a front end hands them the door's
//! `Compiled` rather than reaching behind it for the native kernels.
//!
//! Every method is forwarded, the trait's provided ones included: the native code overrides
//! several of them (Jacobians, patterns, guard speeds), and a default left in place here would
//! silently fall back to finite differences.

use super::Compiled;
use crate::sim::{HybridSystem, SystemInfo};

impl HybridSystem for Compiled {
    fn info(&self) -> &SystemInfo {
        self.native.info()
    }

    fn initial_state(&self, p: &[f64], x0: &mut [f64]) {
        self.native.initial_state(p, x0)
    }

    fn initial_sens(&self, p: &[f64], s0: &mut [f64]) {
        self.native.initial_sens(p, s0)
    }

    fn flow(&self, mode: usize, t: f64, x: &[f64], p: &[f64], dx: &mut [f64]) {
        self.native.flow(mode, t, x, p, dx)
    }

    fn flow_sens(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        s: &[f64],
        p: &[f64],
        dx: &mut [f64],
        ds: &mut [f64],
    ) {
        self.native.flow_sens(mode, t, x, s, p, dx, ds)
    }

    fn prepare_jacobians(&self) -> Result<(), String> {
        self.native.prepare_jacobians()
    }

    fn flow_jac(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        s: &[f64],
        p: &[f64],
        fx: &mut [f64],
        ft: &mut [f64],
        st: &mut [f64],
    ) {
        self.native.flow_jac(mode, t, x, s, p, fx, ft, st)
    }

    fn jac_pattern(&self, mode: usize) -> Option<&[(u32, u32)]> {
        self.native.jac_pattern(mode)
    }

    fn flow_jac_values(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        s: &[f64],
        p: &[f64],
        vals: &mut [f64],
        ft: &mut [f64],
        st: &mut [f64],
    ) {
        self.native.flow_jac_values(mode, t, x, s, p, vals, ft, st)
    }

    fn sens_dir(&self, mode: usize, t: f64, xv: &[f64], s: &[f64], p: &[f64], dir: &mut [f64]) {
        self.native.sens_dir(mode, t, xv, s, p, dir)
    }

    fn guards(&self, mode: usize, t: f64, x: &[f64], p: &[f64], g: &mut [f64]) {
        self.native.guards(mode, t, x, p, g)
    }

    fn guard_speeds(&self, mode: usize, t: f64, x: &[f64], f: &[f64], p: &[f64], dg: &mut [f64]) {
        self.native.guard_speeds(mode, t, x, f, p, dg)
    }

    fn guard_grad(&self, event: usize, t: f64, x: &[f64], p: &[f64], gx: &mut [f64], gp: &mut [f64]) -> f64 {
        self.native.guard_grad(event, t, x, p, gx, gp)
    }

    fn condition(&self, event: usize, t: f64, x: &[f64], p: &[f64]) -> bool {
        self.native.condition(event, t, x, p)
    }

    fn reset(&self, event: usize, t: f64, x: &[f64], p: &[f64], r: &mut [f64]) {
        self.native.reset(event, t, x, p, r)
    }

    fn reset_jac(
        &self,
        event: usize,
        t: f64,
        x: &[f64],
        p: &[f64],
        rx: &mut [f64],
        rp: &mut [f64],
        rt: &mut [f64],
    ) {
        self.native.reset_jac(event, t, x, p, rx, rp, rt)
    }

    fn reset_jac_pattern(&self, event: usize) -> Option<&[(u32, u32)]> {
        self.native.reset_jac_pattern(event)
    }

    fn reset_jac_values(
        &self,
        event: usize,
        t: f64,
        x: &[f64],
        p: &[f64],
        rx: &mut [f64],
        rp: &mut [f64],
        rt: &mut [f64],
    ) {
        self.native.reset_jac_values(event, t, x, p, rx, rp, rt)
    }

    fn outputs(&self, t: f64, x: &[f64], p: &[f64], y: &mut [f64]) {
        self.native.outputs(t, x, p, y)
    }

    fn output_jac(&self, t: f64, x: &[f64], p: &[f64], yx: &mut [f64], yp: &mut [f64], yt: &mut [f64]) {
        self.native.output_jac(t, x, p, yx, yp, yt)
    }
}

#[cfg(test)]
mod tests {
    use crate::sim::{self, SimOptions};
    use crate::Model;

    #[test]
    fn a_compiled_model_runs_as_its_native_code_does_bit_for_bit() {
        // Rodas5P reads the Jacobian kernels and their patterns; the ball's bounces read the
        // guards and the resets: a method forwarded to a default would change the numbers.
        let text = "model ball\nparam g = 9.81\nparam e = 0.8\nstate h = 1\nstate v = 0\nder(h) = v\n\
                    der(v) = -g\nevent bounce when h <= 0 { v := -e * v }\noutput top = h + v * v / (2 * g)\n";
        let compiled = Model::parse(text).unwrap().compile(&["g", "e"]).unwrap();
        let p = compiled.params().values().to_vec();
        for method in sim::Method::ALL {
            let opts = SimOptions { t_end: 2.0, method, ..SimOptions::default() };
            let door = sim::run(&compiled, &p, &opts).unwrap();
            let native = sim::run(compiled.native(), &p, &opts).unwrap();
            assert_eq!(format!("{:?}", door), format!("{:?}", native), "{method:?}");
        }
    }
}
