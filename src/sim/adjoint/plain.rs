//! Stage 5 (sim): a model seen without its sensitivity columns, for the adjoint's forward run:
//! the same functions, `grad_params` empty, so the integrator carries the states alone and its
//! error test reads only them (the steps of a run with `sens_error_control` off).

use crate::interval::{Dual, Interval};
use crate::sim::system::{HybridSystem, SystemInfo};

/// `sys` with no differentiated parameter. The derivatives the integrator still asks for with
/// respect to the parameters (a guard's, a reset's, an output's) go to scratch and are dropped.
pub(crate) struct WithoutSens<'a, S: HybridSystem + ?Sized> {
    sys: &'a S,
    info: SystemInfo,
    /// The system's own number of sensitivity columns (the scratch's width).
    m: usize,
}

impl<'a, S: HybridSystem + ?Sized> WithoutSens<'a, S> {
    pub(crate) fn new(sys: &'a S) -> Self {
        let mut info = sys.info().clone();
        let m = info.n_grad();
        info.grad_params.clear();
        WithoutSens { sys, info, m }
    }
}

impl<S: HybridSystem + ?Sized> HybridSystem for WithoutSens<'_, S> {
    fn info(&self) -> &SystemInfo {
        &self.info
    }
    fn initial_state(&self, p: &[f64], x0: &mut [f64]) {
        self.sys.initial_state(p, x0)
    }
    fn initial_sens(&self, _p: &[f64], _s0: &mut [f64]) {}
    fn flow(&self, mode: usize, t: f64, x: &[f64], p: &[f64], dx: &mut [f64]) {
        self.sys.flow(mode, t, x, p, dx)
    }
    fn flow_sens(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        _s: &[f64],
        p: &[f64],
        dx: &mut [f64],
        _ds: &mut [f64],
    ) {
        self.sys.flow(mode, t, x, p, dx)
    }
    fn prepare_jacobians(&self) -> Result<(), String> {
        self.sys.prepare_jacobians()
    }
    fn flow_jac(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        _s: &[f64],
        p: &[f64],
        fx: &mut [f64],
        ft: &mut [f64],
        _st: &mut [f64],
    ) {
        let n = x.len();
        let (s, mut st) = (vec![0.0; n * self.m], vec![0.0; n * self.m]);
        self.sys.flow_jac(mode, t, x, &s, p, fx, ft, &mut st)
    }
    fn jac_pattern(&self, mode: usize) -> Option<&[(u32, u32)]> {
        self.sys.jac_pattern(mode)
    }
    fn flow_jac_values(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        _s: &[f64],
        p: &[f64],
        vals: &mut [f64],
        ft: &mut [f64],
        _st: &mut [f64],
    ) {
        let n = x.len();
        let (s, mut st) = (vec![0.0; n * self.m], vec![0.0; n * self.m]);
        self.sys.flow_jac_values(mode, t, x, &s, p, vals, ft, &mut st)
    }
    fn sens_dir(&self, _mode: usize, _t: f64, _xv: &[f64], _s: &[f64], _p: &[f64], _dir: &mut [f64]) {}
    fn guards(&self, mode: usize, t: f64, x: &[f64], p: &[f64], g: &mut [f64]) {
        self.sys.guards(mode, t, x, p, g)
    }
    fn guard_speeds(&self, mode: usize, t: f64, x: &[f64], f: &[f64], p: &[f64], dg: &mut [f64]) {
        self.sys.guard_speeds(mode, t, x, f, p, dg)
    }
    fn guard_grad(&self, event: usize, t: f64, x: &[f64], p: &[f64], gx: &mut [f64], _gp: &mut [f64]) -> f64 {
        let mut gp = vec![0.0; self.m];
        self.sys.guard_grad(event, t, x, p, gx, &mut gp)
    }
    fn guard_enclosure(
        &self,
        event: usize,
        t: Interval,
        x: &[Interval],
        dx: &[Interval],
        p: &[f64],
        scratch: &mut Vec<Dual>,
    ) -> Dual {
        self.sys.guard_enclosure(event, t, x, dx, p, scratch)
    }
    fn guard_states(&self, event: usize) -> Option<&[u32]> {
        self.sys.guard_states(event)
    }
    fn knot_position(&self, set: usize, t: f64, p: &[f64]) -> f64 {
        self.sys.knot_position(set, t, p)
    }
    fn knot_position_grad(&self, set: usize, t: f64, p: &[f64], _sp: &mut [f64]) -> f64 {
        let mut sp = vec![0.0; self.m];
        self.sys.knot_position_grad(set, t, p, &mut sp)
    }
    fn condition(&self, event: usize, t: f64, x: &[f64], p: &[f64]) -> bool {
        self.sys.condition(event, t, x, p)
    }
    fn reset(&self, event: usize, t: f64, x: &[f64], p: &[f64], r: &mut [f64]) {
        self.sys.reset(event, t, x, p, r)
    }
    fn reset_jac(
        &self,
        event: usize,
        t: f64,
        x: &[f64],
        p: &[f64],
        rx: &mut [f64],
        _rp: &mut [f64],
        rt: &mut [f64],
    ) {
        let mut rp = vec![0.0; x.len() * self.m];
        self.sys.reset_jac(event, t, x, p, rx, &mut rp, rt)
    }
    fn reset_jac_pattern(&self, event: usize) -> Option<&[(u32, u32)]> {
        self.sys.reset_jac_pattern(event)
    }
    fn reset_jac_values(
        &self,
        event: usize,
        t: f64,
        x: &[f64],
        p: &[f64],
        rx: &mut [f64],
        _rp: &mut [f64],
        rt: &mut [f64],
    ) {
        let mut rp = vec![0.0; x.len() * self.m];
        self.sys.reset_jac_values(event, t, x, p, rx, &mut rp, rt)
    }
    fn outputs(&self, t: f64, x: &[f64], p: &[f64], y: &mut [f64]) {
        self.sys.outputs(t, x, p, y)
    }
    fn output_jac(&self, t: f64, x: &[f64], p: &[f64], yx: &mut [f64], _yp: &mut [f64], yt: &mut [f64]) {
        let mut yp = vec![0.0; self.info.n_outputs() * self.m];
        self.sys.output_jac(t, x, p, yx, &mut yp, yt)
    }
}
