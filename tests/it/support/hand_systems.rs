//! Integrator tests: hand-written `HybridSystem` implementations whose functions and Jacobians
//! are computed by hand, so that the integrator is tested without the parser, DAG or JIT.

use hybc::sim::{Direction, EventInfo, GuardShape, HybridSystem, ModeInfo, SystemInfo};

fn names(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

/// Vertical bouncing ball: state `[y, v]`, parameters `[g, e, h0]` (all differentiated),
/// `der(y) = v, der(v) = -g`, floor event `y` falling with `v := -e v`, output the specific
/// energy `E = v^2/2 + g y`. Optionally a ceiling event (guard `c - y`, falling, `v := -v`).
pub struct Ball {
    info: SystemInfo,
    /// Initial upward speed (not a parameter).
    pub v0: f64,
    pub ceiling: f64,
    /// The ceiling's enabling condition (false: the event never fires but is still detected).
    pub ceiling_enabled: bool,
}

impl Ball {
    pub fn new() -> Ball {
        Ball::build(None, false, 0.0)
    }
    /// The floor event stops the run (after its reset).
    pub fn stopping() -> Ball {
        Ball::build(None, true, 0.0)
    }
    pub fn with_ceiling(v0: f64, ceiling: f64, enabled: bool) -> Ball {
        let mut b = Ball::build(Some(ceiling), false, v0);
        b.ceiling_enabled = enabled;
        b
    }
    fn build(ceiling: Option<f64>, floor_stop: bool, v0: f64) -> Ball {
        let mut events = vec![EventInfo {
            name: "floor".into(),
            direction: Direction::Falling,
            target_mode: None,
            is_stop: floor_stop,
            has_condition: false,
            implicit: false,
            kink: false,
            guard: GuardShape::Affine,
            contact: true,
        }];
        let mut mode_events = vec![0];
        if ceiling.is_some() {
            events.push(EventInfo {
                name: "ceiling".into(),
                direction: Direction::Falling,
                target_mode: None,
                is_stop: false,
                has_condition: true,
                implicit: false,
                kink: false,
                guard: GuardShape::Affine,
                contact: true,
            });
            mode_events.push(1);
        }
        Ball {
            info: SystemInfo {
                state_names: names(&["y", "v"]),
                output_names: names(&["E"]),
                param_names: names(&["g", "e", "h0"]),
                grad_params: vec![0, 1, 2],
                modes: vec![ModeInfo { name: "fly".into(), events: mode_events }],
                events,
                initial_mode: 0,
                quadrature: Vec::new(),
                knots: Vec::new(),
            },
            v0,
            ceiling: ceiling.unwrap_or(0.0),
            ceiling_enabled: true,
        }
    }
}

impl Default for Ball {
    fn default() -> Self {
        Ball::new()
    }
}

impl HybridSystem for Ball {
    fn info(&self) -> &SystemInfo {
        &self.info
    }
    fn initial_state(&self, p: &[f64], x0: &mut [f64]) {
        x0[0] = p[2];
        x0[1] = self.v0;
    }
    fn initial_sens(&self, _p: &[f64], s0: &mut [f64]) {
        s0.fill(0.0);
        s0[2 * 2] = 1.0; // dy0/dh0
    }
    fn flow(&self, _mode: usize, _t: f64, x: &[f64], p: &[f64], dx: &mut [f64]) {
        dx[0] = x[1];
        dx[1] = -p[0];
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
        self.flow(mode, t, x, p, dx);
        for j in 0..3 {
            ds[2 * j] = s[2 * j + 1];
            ds[2 * j + 1] = if j == 0 { -1.0 } else { 0.0 };
        }
    }
    fn guards(&self, _mode: usize, _t: f64, x: &[f64], _p: &[f64], g: &mut [f64]) {
        g[0] = x[0];
        if g.len() > 1 {
            g[1] = self.ceiling - x[0];
        }
    }
    fn guard_grad(
        &self,
        event: usize,
        _t: f64,
        _x: &[f64],
        _p: &[f64],
        gx: &mut [f64],
        gp: &mut [f64],
    ) -> f64 {
        gp.fill(0.0);
        gx[0] = if event == 0 { 1.0 } else { -1.0 };
        gx[1] = 0.0;
        0.0
    }
    fn condition(&self, event: usize, _t: f64, _x: &[f64], _p: &[f64]) -> bool {
        event == 0 || self.ceiling_enabled
    }
    fn reset(&self, event: usize, _t: f64, x: &[f64], p: &[f64], r: &mut [f64]) {
        r[0] = x[0];
        r[1] = if event == 0 { -p[1] * x[1] } else { -x[1] };
    }
    fn reset_jac(
        &self,
        event: usize,
        _t: f64,
        x: &[f64],
        p: &[f64],
        rx: &mut [f64],
        rp: &mut [f64],
        rt: &mut [f64],
    ) {
        rx.copy_from_slice(&[1.0, 0.0, 0.0, if event == 0 { -p[1] } else { -1.0 }]);
        rp.fill(0.0);
        if event == 0 {
            rp[2 + 1] = -x[1]; // dv+/de
        }
        rt.fill(0.0);
    }
    fn outputs(&self, _t: f64, x: &[f64], p: &[f64], y: &mut [f64]) {
        y[0] = 0.5 * x[1] * x[1] + p[0] * x[0];
    }
    fn output_jac(&self, _t: f64, x: &[f64], p: &[f64], yx: &mut [f64], yp: &mut [f64], yt: &mut [f64]) {
        yx.copy_from_slice(&[p[0], x[1]]);
        yp.copy_from_slice(&[x[0], 0.0, 0.0]);
        yt[0] = 0.0;
    }
}

/// Thermostat: state `[T]`, parameters `[k, T_out, P, T_lo, T_hi]` (all differentiated), modes
/// heating (0) and cooling (1), `der(T) = -k (T - T_out) + P [heating]`; `off` when `T - T_hi`
/// rises through zero (heating -> cooling), `on` when `T - T_lo` falls (cooling -> heating).
/// Starts at `T0` (not a parameter) in heating.
pub struct Thermostat {
    info: SystemInfo,
    pub t0: f64,
}

impl Thermostat {
    pub fn new(t0: f64) -> Thermostat {
        let ev = |name: &str, direction, target| EventInfo {
            name: name.into(),
            direction,
            target_mode: Some(target),
            is_stop: false,
            has_condition: false,
            implicit: false,
            kink: false,
            guard: GuardShape::Affine,
            contact: false,
        };
        Thermostat {
            info: SystemInfo {
                state_names: names(&["T"]),
                output_names: names(&[]),
                param_names: names(&["k", "T_out", "P", "T_lo", "T_hi"]),
                grad_params: vec![0, 1, 2, 3, 4],
                modes: vec![
                    ModeInfo { name: "heating".into(), events: vec![0] },
                    ModeInfo { name: "cooling".into(), events: vec![1] },
                ],
                events: vec![ev("off", Direction::Rising, 1), ev("on", Direction::Falling, 0)],
                initial_mode: 0,
                quadrature: Vec::new(),
                knots: Vec::new(),
            },
            t0,
        }
    }
}

impl HybridSystem for Thermostat {
    fn info(&self) -> &SystemInfo {
        &self.info
    }
    fn initial_state(&self, _p: &[f64], x0: &mut [f64]) {
        x0[0] = self.t0;
    }
    fn initial_sens(&self, _p: &[f64], s0: &mut [f64]) {
        s0.fill(0.0);
    }
    fn flow(&self, mode: usize, _t: f64, x: &[f64], p: &[f64], dx: &mut [f64]) {
        let heat = if mode == 0 { p[2] } else { 0.0 };
        dx[0] = -p[0] * (x[0] - p[1]) + heat;
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
        self.flow(mode, t, x, p, dx);
        let fp = [-(x[0] - p[1]), p[0], if mode == 0 { 1.0 } else { 0.0 }, 0.0, 0.0];
        for j in 0..5 {
            ds[j] = -p[0] * s[j] + fp[j];
        }
    }
    fn guards(&self, mode: usize, _t: f64, x: &[f64], p: &[f64], g: &mut [f64]) {
        g[0] = if mode == 0 { x[0] - p[4] } else { x[0] - p[3] };
    }
    fn guard_grad(
        &self,
        event: usize,
        _t: f64,
        _x: &[f64],
        _p: &[f64],
        gx: &mut [f64],
        gp: &mut [f64],
    ) -> f64 {
        gx[0] = 1.0;
        gp.fill(0.0);
        gp[if event == 0 { 4 } else { 3 }] = -1.0;
        0.0
    }
    fn condition(&self, _event: usize, _t: f64, _x: &[f64], _p: &[f64]) -> bool {
        true
    }
    fn reset(&self, _event: usize, _t: f64, x: &[f64], _p: &[f64], r: &mut [f64]) {
        r.copy_from_slice(x);
    }
    fn reset_jac(
        &self,
        _event: usize,
        _t: f64,
        _x: &[f64],
        _p: &[f64],
        rx: &mut [f64],
        rp: &mut [f64],
        rt: &mut [f64],
    ) {
        rx[0] = 1.0;
        rp.fill(0.0);
        rt.fill(0.0);
    }
    fn outputs(&self, _t: f64, _x: &[f64], _p: &[f64], _y: &mut [f64]) {}
    fn output_jac(&self, _t: f64, _x: &[f64], _p: &[f64], _yx: &mut [f64], _yp: &mut [f64], _yt: &mut [f64]) {
    }
}

/// Two events on one guard: state `[x, c]`, `der(x) = -a`, `der(c) = 0`, parameter `[a]`.
/// Event `A` (declared first): `x := 0, c := c + 1`; event `B`: `c := 10 c`. Both fire when `x`
/// falls through zero, so declaration order gives `c = 10`, the reverse would give 1.
pub struct Counter {
    info: SystemInfo,
    pub x0: f64,
}

impl Counter {
    pub fn new(x0: f64) -> Counter {
        let ev = |name: &str| EventInfo {
            name: name.into(),
            direction: Direction::Falling,
            target_mode: None,
            is_stop: false,
            has_condition: false,
            implicit: false,
            kink: false,
            guard: GuardShape::Affine,
            contact: false,
        };
        Counter {
            info: SystemInfo {
                state_names: names(&["x", "c"]),
                output_names: names(&[]),
                param_names: names(&["a"]),
                grad_params: vec![0],
                modes: vec![ModeInfo { name: "only".into(), events: vec![0, 1] }],
                events: vec![ev("A"), ev("B")],
                initial_mode: 0,
                quadrature: Vec::new(),
                knots: Vec::new(),
            },
            x0,
        }
    }
}

impl HybridSystem for Counter {
    fn info(&self) -> &SystemInfo {
        &self.info
    }
    fn initial_state(&self, _p: &[f64], x0: &mut [f64]) {
        x0[0] = self.x0;
        x0[1] = 0.0;
    }
    fn initial_sens(&self, _p: &[f64], s0: &mut [f64]) {
        s0.fill(0.0);
    }
    fn flow(&self, _mode: usize, _t: f64, _x: &[f64], p: &[f64], dx: &mut [f64]) {
        dx[0] = -p[0];
        dx[1] = 0.0;
    }
    fn flow_sens(
        &self,
        mode: usize,
        t: f64,
        x: &[f64],
        _s: &[f64],
        p: &[f64],
        dx: &mut [f64],
        ds: &mut [f64],
    ) {
        self.flow(mode, t, x, p, dx);
        ds[0] = -1.0;
        ds[1] = 0.0;
    }
    fn guards(&self, _mode: usize, _t: f64, x: &[f64], _p: &[f64], g: &mut [f64]) {
        g[0] = x[0];
        g[1] = x[0];
    }
    fn guard_grad(
        &self,
        _event: usize,
        _t: f64,
        _x: &[f64],
        _p: &[f64],
        gx: &mut [f64],
        gp: &mut [f64],
    ) -> f64 {
        gx.copy_from_slice(&[1.0, 0.0]);
        gp.fill(0.0);
        0.0
    }
    fn condition(&self, _event: usize, _t: f64, _x: &[f64], _p: &[f64]) -> bool {
        true
    }
    fn reset(&self, event: usize, _t: f64, x: &[f64], _p: &[f64], r: &mut [f64]) {
        if event == 0 {
            r.copy_from_slice(&[0.0, x[1] + 1.0]);
        } else {
            r.copy_from_slice(&[x[0], 10.0 * x[1]]);
        }
    }
    fn reset_jac(
        &self,
        event: usize,
        _t: f64,
        _x: &[f64],
        _p: &[f64],
        rx: &mut [f64],
        rp: &mut [f64],
        rt: &mut [f64],
    ) {
        if event == 0 {
            rx.copy_from_slice(&[0.0, 0.0, 0.0, 1.0]);
        } else {
            rx.copy_from_slice(&[1.0, 0.0, 0.0, 10.0]);
        }
        rp.fill(0.0);
        rt.fill(0.0);
    }
    fn outputs(&self, _t: f64, _x: &[f64], _p: &[f64], _y: &mut [f64]) {}
    fn output_jac(&self, _t: f64, _x: &[f64], _p: &[f64], _yx: &mut [f64], _yp: &mut [f64], _yt: &mut [f64]) {
    }
}

/// Relative closeness with an absolute floor for values near zero.
pub fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * b.abs().max(1e-3)
}

/// Harmonic oscillator `der(x) = v, der(v) = -w^2 x` from `[1, 0]`, parameter `[w]`; one event
/// `zero` on the guard `x` in either direction with an identity reset. Crossings at
/// `t_k = (pi/2 + k pi) / w`.
pub struct Oscillator {
    info: SystemInfo,
}

impl Oscillator {
    pub fn new() -> Oscillator {
        Oscillator {
            info: SystemInfo {
                state_names: names(&["x", "v"]),
                output_names: names(&[]),
                param_names: names(&["w"]),
                grad_params: vec![0],
                modes: vec![ModeInfo { name: "only".into(), events: vec![0] }],
                events: vec![EventInfo {
                    name: "zero".into(),
                    direction: Direction::Either,
                    target_mode: None,
                    is_stop: false,
                    has_condition: false,
                    implicit: false,
                    kink: false,
                    guard: GuardShape::Affine,
                    contact: false,
                }],
                initial_mode: 0,
                quadrature: Vec::new(),
                knots: Vec::new(),
            },
        }
    }
}

impl Default for Oscillator {
    fn default() -> Self {
        Oscillator::new()
    }
}

impl HybridSystem for Oscillator {
    fn info(&self) -> &SystemInfo {
        &self.info
    }
    fn initial_state(&self, _p: &[f64], x0: &mut [f64]) {
        x0.copy_from_slice(&[1.0, 0.0]);
    }
    fn initial_sens(&self, _p: &[f64], s0: &mut [f64]) {
        s0.fill(0.0);
    }
    fn flow(&self, _mode: usize, _t: f64, x: &[f64], p: &[f64], dx: &mut [f64]) {
        dx[0] = x[1];
        dx[1] = -p[0] * p[0] * x[0];
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
        self.flow(mode, t, x, p, dx);
        ds[0] = s[1];
        ds[1] = -p[0] * p[0] * s[0] - 2.0 * p[0] * x[0];
    }
    fn guards(&self, _mode: usize, _t: f64, x: &[f64], _p: &[f64], g: &mut [f64]) {
        g[0] = x[0];
    }
    fn guard_grad(
        &self,
        _event: usize,
        _t: f64,
        _x: &[f64],
        _p: &[f64],
        gx: &mut [f64],
        gp: &mut [f64],
    ) -> f64 {
        gx.copy_from_slice(&[1.0, 0.0]);
        gp.fill(0.0);
        0.0
    }
    fn condition(&self, _event: usize, _t: f64, _x: &[f64], _p: &[f64]) -> bool {
        true
    }
    fn reset(&self, _event: usize, _t: f64, x: &[f64], _p: &[f64], r: &mut [f64]) {
        r.copy_from_slice(x);
    }
    fn reset_jac(
        &self,
        _event: usize,
        _t: f64,
        _x: &[f64],
        _p: &[f64],
        rx: &mut [f64],
        rp: &mut [f64],
        rt: &mut [f64],
    ) {
        rx.copy_from_slice(&[1.0, 0.0, 0.0, 1.0]);
        rp.fill(0.0);
        rt.fill(0.0);
    }
    fn outputs(&self, _t: f64, _x: &[f64], _p: &[f64], _y: &mut [f64]) {}
    fn output_jac(&self, _t: f64, _x: &[f64], _p: &[f64], _yx: &mut [f64], _yp: &mut [f64], _yt: &mut [f64]) {
    }
}
