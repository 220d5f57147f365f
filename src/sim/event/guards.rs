//! Stage 5 (sim): the guards of one mode at one parameter point, the context every detection
//! call reads. The integrator builds one per step (and per event of a group, whose resets may
//! switch the mode) instead of handing the system, its description, the mode and the parameters
//! to each call: the detector's methods then take what varies (a position, a time, a state, the
//! interpolant) and nothing else.

use crate::sim::system::{HybridSystem, SystemInfo};

/// The system's guards in `mode` at the parameters `p`. Copied freely: references and two counts.
pub(crate) struct Guards<'a, S: HybridSystem + ?Sized> {
    pub sys: &'a S,
    pub info: &'a SystemInfo,
    pub p: &'a [f64],
    pub mode: usize,
    /// The number of states (the leading part of `z = [x, S]` a guard reads).
    pub n: usize,
}

// By hand: a derive would ask `S: Clone`, and only the reference is copied.
impl<S: HybridSystem + ?Sized> Clone for Guards<'_, S> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<S: HybridSystem + ?Sized> Copy for Guards<'_, S> {}

impl<'a, S: HybridSystem + ?Sized> Guards<'a, S> {
    pub fn new(sys: &'a S, info: &'a SystemInfo, p: &'a [f64], mode: usize) -> Self {
        Guards { sys, info, p, mode, n: info.n_states() }
    }

    /// The mode's events, in declaration order: a guard's position is its index here.
    #[inline]
    pub fn events(&self) -> &'a [usize] {
        &self.info.modes[self.mode].events
    }

    /// Every guard of the mode at `(t, x)`, into `g[..ne]`.
    #[inline]
    pub fn eval(&self, t: f64, x: &[f64], g: &mut [f64]) {
        let ne = self.events().len();
        self.sys.guards(self.mode, t, x, self.p, &mut g[..ne]);
    }

    /// The gradient of event `ev`'s guard at `(t, x)`: `g_x` into `gx`, `g_p` into `gp`; returns
    /// `g_t`.
    #[inline]
    pub fn grad(&self, ev: usize, t: f64, x: &[f64], gx: &mut [f64], gp: &mut [f64]) -> f64 {
        self.sys.guard_grad(ev, t, x, self.p, gx, gp)
    }
}
