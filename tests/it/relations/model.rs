//! A generated hybrid model as data: chains of integrators (`der(x1) = x2`, ..., `der(xk) = A +
//! B t`, so every state is a polynomial of `t` and the flow's Jacobian is not zero), a chain's top
//! switched by an `if` on a state (a flow switch) or damped (`- k xk`: no longer polynomial),
//! events with affine, product and time guards, enabling conditions, affine resets, modes and
//! stops. One description gives both
//! the `.hyb` text (in each variant a relation needs: shifted in time, `t` read from a clock
//! state, a bystander state, events in another order, a mode split in two) and the exact
//! reference (`exact.rs`).

use std::fmt::Write as _;

/// `k * p[j]`, or the constant `k`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coef {
    pub k: f64,
    pub p: Option<usize>,
}

impl Coef {
    pub fn c(k: f64) -> Coef {
        Coef { k, p: None }
    }

    pub fn p(k: f64, j: usize) -> Coef {
        Coef { k, p: Some(j) }
    }

    pub fn value(&self, params: &[f64]) -> f64 {
        self.p.map_or(self.k, |j| self.k * params[j])
    }

    fn text(&self) -> String {
        match self.p {
            None => num(self.k),
            Some(j) if self.k == 1.0 => format!("p{j}"),
            Some(j) => format!("{} * p{j}", num(self.k)),
        }
    }
}

/// A number as a literal that reads back to the same double, parenthesised when negative.
pub fn num(x: f64) -> String {
    let s = format!("{x:?}");
    if x.is_sign_negative() {
        format!("({s})")
    } else {
        s
    }
}

/// What a guard's left side is (its right side is a [`Coef`]).
#[derive(Clone, Debug, PartialEq)]
pub enum Lhs {
    /// `sum w_i x_i`.
    Lin(Vec<(usize, f64)>),
    /// `x_i * x_j` (a square when `i == j`).
    Prod(usize, usize),
    /// `t`: a time event.
    Time,
    /// `sin(w x_i)`: a guard no polynomial describes, checked by the relations only.
    Sin(usize, f64),
    /// `abs(w x_i)`: a kink where `x_i` is zero, checked by the relations only.
    Abs(usize, f64),
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Dir {
    Falling,
    Rising,
    Crosses,
}

impl Dir {
    fn op(self) -> &'static str {
        match self {
            Dir::Falling => "<=",
            Dir::Rising => ">=",
            Dir::Crosses => "crosses",
        }
    }
}

/// `x := a * x + b`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reset {
    pub state: usize,
    pub a: Coef,
    pub b: Coef,
}

/// An enabling condition `if x_state > at` (or `<` when not `above`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cond {
    pub state: usize,
    pub above: bool,
    pub at: Coef,
}

/// A flow switch on a chain's top: `der(top) = if x_state > at then then else <the mode's top>`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Switch {
    pub state: usize,
    pub at: Coef,
    pub then: Coef,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Event {
    pub name: String,
    /// `None`: declared at model level, active in every mode.
    pub mode: Option<usize>,
    pub lhs: Lhs,
    pub dir: Dir,
    pub rhs: Coef,
    pub cond: Option<Cond>,
    pub resets: Vec<Reset>,
    pub to: Option<usize>,
    pub stop: bool,
}

/// The top of a chain in one mode: `der(top) = a + b t`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Top {
    pub a: Coef,
    pub b: f64,
}

#[derive(Clone, Debug, PartialEq)]
pub struct GenModel {
    /// Values of `p0, p1, ...`.
    pub params: Vec<f64>,
    /// Initial values of `x0, x1, ...`.
    pub init: Vec<Coef>,
    /// Each chain's states in derivative order: `der(c[i]) = c[i + 1]`.
    pub chains: Vec<Vec<usize>>,
    /// `tops[mode][chain]`.
    pub tops: Vec<Vec<Top>>,
    /// Per chain, a flow switch on its top in every mode.
    pub switches: Vec<Option<Switch>>,
    /// Per chain, `k` in `der(top) = ... - k top` (0: none); a damped chain is not polynomial.
    pub damping: Vec<f64>,
    /// Per chain, whether its damping acts on one side only, `- k max(top, 0)`: a kink of the
    /// flow (a switch where nothing jumps, docs/language.md "Expressions").
    pub kinked: Vec<bool>,
    pub events: Vec<Event>,
    pub t_end: f64,
}

/// How the text of a model is varied for a relation. The default is the model itself.
#[derive(Clone, Debug, Default)]
pub struct Variant {
    /// Every time in the model moved later by this much (`t` read as `t - shift`, time events and
    /// the end moved): run from `t_start = shift`.
    pub shift: f64,
    /// `t` read from a state `clock` with `der(clock) = 1` (time events become state events).
    pub clock: bool,
    /// An unrelated state `by` of this size decaying at rate 1.
    pub bystander: Option<f64>,
    /// Events declared in this order (a permutation of their indices).
    pub order: Option<Vec<usize>>,
    /// The initial mode split in two identical modes joined at this (unshifted) time by an event
    /// `split` that changes nothing.
    pub split: Option<f64>,
}

impl GenModel {
    pub fn state_name(i: usize) -> String {
        format!("x{i}")
    }

    /// Whether the exact reference can follow every guard (all polynomial along the flow).
    pub fn polynomial(&self) -> bool {
        !self.events.iter().any(|e| matches!(e.lhs, Lhs::Sin(..) | Lhs::Abs(..)))
            && self.damping.iter().all(|&k| k == 0.0)
    }

    pub fn uses_time(&self) -> bool {
        self.tops.iter().flatten().any(|t| t.b != 0.0) || self.events.iter().any(|e| e.lhs == Lhs::Time)
    }

    fn time_text(&self, v: &Variant) -> String {
        let t = if v.clock { "clock" } else { "t" };
        if v.shift == 0.0 {
            t.to_string()
        } else {
            format!("({t} - {})", num(v.shift))
        }
    }

    fn lhs_text(&self, lhs: &Lhs, v: &Variant) -> String {
        match lhs {
            Lhs::Lin(terms) => {
                let parts: Vec<String> = terms
                    .iter()
                    .map(|&(i, w)| {
                        if w == 1.0 {
                            Self::state_name(i)
                        } else {
                            format!("{} * {}", num(w), Self::state_name(i))
                        }
                    })
                    .collect();
                parts.join(" + ")
            }
            Lhs::Prod(i, j) => format!("{} * {}", Self::state_name(*i), Self::state_name(*j)),
            Lhs::Time => self.time_text(v),
            Lhs::Sin(i, w) => format!("sin({} * {})", num(*w), Self::state_name(*i)),
            Lhs::Abs(i, w) => format!("abs({} * {})", num(*w), Self::state_name(*i)),
        }
    }

    fn event_text(&self, e: &Event, v: &Variant, modes: &[String], indent: &str, out: &mut String) {
        let _ = write!(
            out,
            "{indent}event {} when {} {} {}",
            e.name,
            self.lhs_text(&e.lhs, v),
            e.dir.op(),
            e.rhs.text()
        );
        if let Some(c) = e.cond {
            let _ = write!(
                out,
                " if {} {} {}",
                Self::state_name(c.state),
                if c.above { ">" } else { "<" },
                c.at.text()
            );
        }
        if let Some(to) = e.to {
            let _ = write!(out, " -> {}", modes[to]);
        }
        out.push_str(" {\n");
        for r in &e.resets {
            let x = Self::state_name(r.state);
            let _ = writeln!(out, "{indent}    {x} := {} * {x} + {}", r.a.text(), r.b.text());
        }
        if e.stop {
            let _ = writeln!(out, "{indent}    stop");
        }
        let _ = writeln!(out, "{indent}}}");
    }

    fn flows_text(&self, mode: usize, v: &Variant, indent: &str, out: &mut String) {
        for (c, chain) in self.chains.iter().enumerate() {
            for w in chain.windows(2) {
                let _ = writeln!(out, "{indent}der({}) = {}", Self::state_name(w[0]), Self::state_name(w[1]));
            }
            let top = self.tops[mode][c];
            let x = Self::state_name(*chain.last().expect("a chain has a state"));
            let mut rate = if top.b == 0.0 {
                top.a.text()
            } else {
                format!("{} + {} * {}", top.a.text(), num(top.b), self.time_text(v))
            };
            if let Some(s) = self.switches[c] {
                rate = format!(
                    "(if {} > {} then {} else ({rate}))",
                    Self::state_name(s.state),
                    s.at.text(),
                    s.then.text()
                );
            }
            if self.damping[c] != 0.0 && self.kinked[c] {
                rate = format!("{rate} - {} * max({x}, 0)", num(self.damping[c]));
            } else if self.damping[c] != 0.0 {
                rate = format!("{rate} - {} * {x}", num(self.damping[c]));
            }
            let _ = writeln!(out, "{indent}der({x}) = {rate}");
        }
        if v.clock {
            let _ = writeln!(out, "{indent}der(clock) = 1");
        }
        if v.bystander.is_some() {
            let _ = writeln!(out, "{indent}der(by) = -by");
        }
    }

    /// The `.hyb` text of the variant `v`.
    pub fn text(&self, v: &Variant) -> String {
        let mut out = String::from("model generated\n");
        for (j, p) in self.params.iter().enumerate() {
            let _ = writeln!(out, "param p{j} = {p:?}");
        }
        for (i, x0) in self.init.iter().enumerate() {
            let _ = writeln!(out, "state {} = {}", Self::state_name(i), x0.text());
        }
        if v.clock {
            let _ = writeln!(out, "state clock = {}", num(v.shift));
        }
        if let Some(size) = v.bystander {
            let _ = writeln!(out, "state by = {}", num(size));
        }
        // Modes: the model's own, with the first one doubled by a split.
        let n_modes = self.tops.len();
        let split = v.split.is_some();
        let mut names: Vec<String> = (0..n_modes).map(|m| format!("m{m}")).collect();
        if split {
            names[0] = "m0a".to_string();
        }
        let order: Vec<usize> = v.order.clone().unwrap_or_else(|| (0..self.events.len()).collect());
        for &k in &order {
            let e = &self.events[k];
            if e.mode.is_none() {
                self.event_text(e, v, &names, "", &mut out);
            }
        }
        let single = n_modes == 1 && !split;
        if single {
            self.flows_text(0, v, "", &mut out);
            for &k in &order {
                if self.events[k].mode == Some(0) {
                    self.event_text(&self.events[k], v, &names, "", &mut out);
                }
            }
        } else {
            let emit_mode = |name: &str, m: usize, initial: bool, extra: Option<f64>, out: &mut String| {
                let _ = writeln!(out, "{}mode {name} {{", if initial { "initial " } else { "" });
                self.flows_text(m, v, "    ", out);
                for &k in &order {
                    if self.events[k].mode == Some(m) {
                        self.event_text(&self.events[k], v, &names, "    ", out);
                    }
                }
                if let Some(at) = extra {
                    let _ = writeln!(out, "    event split when {} >= {} -> m0b", self.time_text(v), num(at));
                }
                let _ = writeln!(out, "}}");
            };
            emit_mode(&names[0], 0, true, v.split, &mut out);
            if split {
                // m0b: m0's flows and events; events that return to m0 go to m0a, identical.
                emit_mode("m0b", 0, false, None, &mut out);
            }
            for (m, name) in names.iter().enumerate().skip(1) {
                emit_mode(name, m, false, None, &mut out);
            }
        }
        let _ = writeln!(out, "simulate t_end = {}", num(self.t_end + v.shift));
        out
    }
}
