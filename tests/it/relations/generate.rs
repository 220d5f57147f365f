//! Random hybrid models drawn from the language's forms (`model.rs`): chains of integrators
//! whose tops are `a + b t` per mode, flow switches (`if` on a state) on a top, damped tops (for
//! the relations alone; half of them damped on one side only, a kink), events with affine,
//! product and time guards in every direction, `sin` and `abs` guards (for the relations alone),
//! enabling conditions, affine resets (bounces, kicks, assignments, which also make cascades),
//! mode switches, stops, a time event near or on `t_end`, and starts on or a hair from a guard
//! (down to subnormal distances). Model `i` of seed `s` is a function of `(s, i)` alone, so a
//! violation is reproduced from the two numbers.

use rand_chacha::ChaCha8Rng;
use rand_core::{Rng, SeedableRng};

use super::model::{Coef, Cond, Dir, Event, GenModel, Lhs, Reset, Switch, Top};

struct Draw {
    rng: ChaCha8Rng,
    params: Vec<f64>,
}

impl Draw {
    fn unit(&mut self) -> f64 {
        (self.rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    fn below(&mut self, n: usize) -> usize {
        (self.rng.next_u64() % n as u64) as usize
    }

    fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }

    /// A value rounded to a few digits (readable models), of either sign.
    fn value(&mut self, lo: f64, hi: f64) -> f64 {
        let v = self.range(lo, hi);
        let v = (v * 1000.0).round() / 1000.0;
        if v == 0.0 {
            0.25
        } else {
            v
        }
    }

    /// A coefficient with value `v`: a new parameter half of the time, else the constant.
    fn coef(&mut self, v: f64) -> Coef {
        if self.chance(0.5) {
            self.params.push(v);
            Coef::p(1.0, self.params.len() - 1)
        } else {
            Coef::c(v)
        }
    }
}

/// Distances of a start from its guard, from ordinary to subnormal.
const HAIRS: [f64; 8] = [1e-3, 1e-9, 1e-30, 1e-100, 1e-150, 1e-160, 1e-200, 1e-300];

/// Rates of a damped top (`- k x`): from slow to stiff for an explicit method at the harness's
/// tolerances.
const DAMPING: [f64; 4] = [0.5, 3.0, 50.0, 1000.0];

/// Where the end is put near a time event, as a fraction of the span: on it, and before or after
/// it by more than the reference's separation.
const NEAR_END: [f64; 5] = [0.0, 1e-4, -1e-4, 1e-3, -1e-3];

/// Model `index` of the stream `seed`.
pub fn model(seed: u64, index: u64) -> GenModel {
    let mut d = Draw {
        rng: ChaCha8Rng::seed_from_u64(seed ^ index.wrapping_mul(0x9E37_79B9_7F4A_7C15)),
        params: Vec::new(),
    };
    let n_chains = 1 + d.below(2);
    let n_modes = if d.chance(0.4) { 2 } else { 1 };
    let mut chains = Vec::new();
    let mut init = Vec::new();
    for _ in 0..n_chains {
        let len = 1 + d.below(3);
        let mut chain = Vec::new();
        for _ in 0..len {
            chain.push(init.len());
            let v = d.value(-1.0, 1.0);
            init.push(d.coef(v));
        }
        chains.push(chain);
    }
    let mut tops = Vec::new();
    for _ in 0..n_modes {
        let mut row = Vec::new();
        for _ in 0..n_chains {
            let v = d.value(-3.0, 3.0);
            let a = d.coef(v);
            let b = if d.chance(0.3) { d.value(-1.0, 1.0) } else { 0.0 };
            row.push(Top { a, b });
        }
        tops.push(row);
    }
    let mut t_end = d.value(1.0, 3.0).abs().max(1.0);
    let n_states = init.len();
    let x0: Vec<f64> = init.iter().map(|c| c.value(&d.params)).collect();
    // A switch on a chain's top, on a state's level a little away from its start.
    let mut switches = Vec::new();
    let mut damping = Vec::new();
    let mut kinked = Vec::new();
    for chain in &chains {
        let damped = d.chance(0.1);
        // Half the damped chains, by the damping drawn (no draw of their own, so that the models
        // drawn after them stay the same), are damped on one side only: a kink.
        let which = if damped { Some(d.below(DAMPING.len())) } else { None };
        damping.push(which.map_or(0.0, |k| DAMPING[k]));
        kinked.push(which.is_some_and(|k| k % 2 == 1));
        // A damped chain has no exact reference to tell a sliding switch (one whose branches
        // push its own top back at the level from both sides): its switch reads another state.
        let top = *chain.last().expect("a chain has a state");
        let switch = if d.chance(0.2) && !(damped && n_states == 1) {
            let mut state = d.below(n_states);
            if damped && state == top {
                state = (state + 1) % n_states;
            }
            let at = x0[state] + d.value(-1.0, 1.0);
            let at = d.coef(at);
            let v = d.value(-3.0, 3.0);
            Some(Switch { state, at, then: d.coef(v) })
        } else {
            None
        };
        switches.push(switch);
    }
    let mut events = Vec::new();
    let n_events = 1 + d.below(3);
    for k in 0..n_events {
        let kind = d.below(20);
        let (lhs, l0) = if kind < 10 {
            let i = d.below(n_states);
            (Lhs::Lin(vec![(i, 1.0)]), x0[i])
        } else if kind < 14 {
            let (i, j) = (d.below(n_states), d.below(n_states));
            let w = d.value(-2.0, 2.0);
            if i == j {
                (Lhs::Lin(vec![(i, 1.0)]), x0[i])
            } else {
                (Lhs::Lin(vec![(i, 1.0), (j, w)]), x0[i] + w * x0[j])
            }
        } else if kind < 16 {
            let (i, j) = (d.below(n_states), d.below(n_states));
            (Lhs::Prod(i, j), x0[i] * x0[j])
        } else if kind < 18 {
            let i = d.below(n_states);
            let w = d.value(1.0, 6.0);
            // Half of these draws read `abs` instead of `sin` (the same draws, so that the rest
            // of the stream is unchanged): a guard with a kink where its argument is zero.
            if kind == 16 {
                (Lhs::Sin(i, w), (w * x0[i]).sin())
            } else {
                (Lhs::Abs(i, w), (w * x0[i]).abs())
            }
        } else {
            (Lhs::Time, 0.0)
        };
        let (rhs_value, dir) = if lhs == Lhs::Time {
            (d.value(0.05, t_end - 0.05), Dir::Rising)
        } else {
            let rhs = match lhs {
                Lhs::Sin(..) => d.value(-0.9, 0.9),
                Lhs::Abs(..) => d.value(-0.9, 0.9).abs(),
                _ => l0 + d.value(-1.0, 1.0),
            };
            let dir = if d.chance(0.25) {
                Dir::Crosses
            } else if l0 > rhs {
                Dir::Falling
            } else {
                Dir::Rising
            };
            (rhs, dir)
        };
        let rhs = d.coef(rhs_value);
        let cond = if d.chance(0.2) {
            let state = d.below(n_states);
            let at = x0[state] + d.value(-1.0, 1.0);
            Some(Cond { state, above: d.chance(0.5), at: d.coef(at) })
        } else {
            None
        };
        let mut resets = Vec::new();
        for _ in 0..d.below(3) {
            let state = d.below(n_states);
            if resets.iter().any(|r: &Reset| r.state == state) {
                continue;
            }
            let (a, b) = match d.below(4) {
                0 => {
                    let e = d.value(0.5, 0.95);
                    (d.coef(-e), Coef::c(0.0))
                }
                1 => {
                    let kick = d.value(-1.0, 1.0);
                    (Coef::c(1.0), d.coef(kick))
                }
                2 => {
                    let v = d.value(-1.0, 1.0);
                    (Coef::c(0.0), d.coef(v))
                }
                _ => {
                    let a = d.value(-1.5, 1.5);
                    let b = d.value(-0.5, 0.5);
                    (Coef::c(a), d.coef(b))
                }
            };
            resets.push(Reset { state, a, b });
        }
        let mode = if n_modes > 1 && d.chance(0.6) { Some(d.below(n_modes)) } else { None };
        let to = if n_modes > 1 && d.chance(0.6) { Some(d.below(n_modes)) } else { None };
        let stop = d.chance(0.1);
        events.push(Event { name: format!("e{k}"), mode, lhs, dir, rhs, cond, resets, to, stop });
    }
    // A start on or a hair from the first event's guard, for a single-state affine guard.
    if d.chance(0.15) {
        if let Lhs::Lin(terms) = &events[0].lhs {
            if terms.len() == 1 {
                let i = terms[0].0;
                let c = events[0].rhs.value(&d.params);
                let hair = if d.chance(0.2) { 0.0 } else { HAIRS[d.below(HAIRS.len())] };
                // Before the guard on its pre-crossing side: above it for a falling guard.
                let side = match events[0].dir {
                    Dir::Falling => 1.0,
                    Dir::Rising => -1.0,
                    Dir::Crosses => {
                        if d.chance(0.5) {
                            1.0
                        } else {
                            -1.0
                        }
                    }
                };
                // The guard at 0 is x - c = side * hair exactly when c is 0; else the start is
                // c + side * hair rounded, which the reference reads exactly as it is.
                let at_zero = d.chance(0.5);
                if at_zero {
                    events[0].rhs = Coef::c(0.0);
                }
                init[i] = Coef::c(if at_zero { side * hair } else { c + side * hair });
            }
        }
    }
    // The end near or on a time event: before it, after it, or at its very time (a cusp of the
    // final values, rule 8 of docs/language.md).
    if let Some(e) = events.iter().find(|e| e.lhs == Lhs::Time) {
        if d.chance(0.3) {
            let at = e.rhs.value(&d.params);
            t_end = at + NEAR_END[d.below(NEAR_END.len())] * t_end;
        }
    }
    GenModel { params: d.params, init, chains, tops, switches, damping, kinked, events, t_end }
}
