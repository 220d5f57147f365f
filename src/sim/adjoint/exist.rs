//! Stage 5 (sim): where a derivative does not exist, the adjoint says so as forward mode does,
//! per parameter (docs/design.md, "Where a derivative does not exist, in the adjoint").
//!
//! Forward mode marks an event time's derivative that does not exist (a grazing crossing, an
//! event whose guard a reset put the state on) as NaN for each parameter `j` that moves the
//! guard there (`g_x S_j + g_p_j != 0`; at a reset onto a guard also each that moves the
//! instant), and the NaN reaches exactly what depends on that time: every product skips exact
//! zeros. Transposed, a quantity (a row of the backward pass) depends on the time when its
//! cotangent of that time, `u`, is not zero; it then has no derivative by the parameters whose
//! `g_x S + g_p` is not zero, and keeps its value for the others, whose share through the time
//! is `-(u / d) (g_x S_j + g_p_j) = 0`: the backward pass drops that share (it would divide by a
//! speed near zero) and notes the row as voided there.
//!
//! `g_x S + g_p`, the guard's total derivative at the event, is itself a backward pass: an
//! auxiliary row seeded at the event's piece (`lam = g_x`, `pbar = g_p` at its state) and
//! carried back to the start with the others. An auxiliary row is voided like any row by the
//! events before it, so its entries that do not exist are NaN, which counts as "moves the
//! guard", as forward mode's NaN numerator does. At the end the rows are resolved in time order.
//!
//! A flow switch at another event's instant voids every column in forward mode: a row whose
//! cotangent there is not zero loses every parameter.

use super::backward::Switch;
use super::{Piece, Tape};
use crate::sim::system::HybridSystem;
use std::ops::Range;

/// What the tape says about a piece's derivative's existence.
#[derive(Clone, Copy, Debug)]
pub(super) enum Mark {
    /// The piece's crossing (a jump or a flow switch) grazed.
    Graze,
    /// The jump is an event whose guard a reset put the state on.
    OntoGuard,
    /// The flow switch grazed with a jump that vanishes with the crossing speed: the limit `c`
    /// of `J / d` at this offset of the tape's store.
    Benign(usize),
}

/// The marks of a tape with the auxiliary rows they need: `marks[k] = (piece, mark, range into
/// `voiders`)`, sorted by piece; `auxes[a]` the piece auxiliary row `a` is seeded at, ascending.
#[derive(Debug, Default)]
pub(super) struct Plan {
    marks: Vec<(usize, Mark, Range<usize>)>,
    voiders: Vec<usize>,
    auxes: Vec<usize>,
}

impl Plan {
    /// The plan of `tape`'s marks.
    pub(super) fn new(tape: &Tape) -> Plan {
        let pieces = &tape.pieces;
        // The pieces whose guard a row may need: a grazing piece's own, a reset onto a guard's
        // own and its instant's first event's.
        let mut needs: Vec<(usize, Mark, Vec<usize>)> = Vec::new();
        for &(piece, mark) in &tape.marks {
            let seeds = match mark {
                Mark::Graze => vec![piece],
                Mark::OntoGuard => {
                    let first = pieces[..piece]
                        .iter()
                        .rposition(|p| matches!(p, Piece::Jump { first_of_instant: true, .. }));
                    std::iter::once(piece).chain(first).collect()
                }
                Mark::Benign(_) => Vec::new(),
            };
            needs.push((piece, mark, seeds));
        }
        let mut auxes: Vec<usize> = needs.iter().flat_map(|n| n.2.iter().copied()).collect();
        auxes.sort_unstable();
        auxes.dedup();
        let mut plan = Plan { auxes, ..Plan::default() };
        for (piece, mark, seeds) in needs {
            let start = plan.voiders.len();
            for s in seeds {
                let a = plan.auxes.binary_search(&s).expect("each seed piece has its row");
                plan.voiders.push(a);
            }
            plan.marks.push((piece, mark, start..plan.voiders.len()));
        }
        plan
    }

    /// How many auxiliary rows.
    pub(super) fn auxes(&self) -> usize {
        self.auxes.len()
    }

    /// The mark of piece `index`, with the auxiliary rows whose nonzero entries void a row
    /// there.
    pub(super) fn mark(&self, index: usize) -> Option<(Mark, &[usize])> {
        let k = self.marks.binary_search_by_key(&index, |m| m.0).ok()?;
        let (_, mark, range) = &self.marks[k];
        Some((*mark, &self.voiders[range.clone()]))
    }

    /// The auxiliary rows seeded at piece `index`.
    pub(super) fn seeded_at(&self, index: usize) -> Range<usize> {
        let start = self.auxes.partition_point(|&p| p < index);
        let end = self.auxes.partition_point(|&p| p <= index);
        start..end
    }
}

/// Per row (the seeds', then the auxiliary ones): the auxiliary rows that void it, and whether
/// a flow switch at another event's instant voided all of it.
#[derive(Debug)]
pub(super) struct Voids {
    by: Vec<Vec<usize>>,
    all: Vec<bool>,
}

impl Voids {
    pub(super) fn new(rows: usize) -> Voids {
        Voids { by: vec![Vec::new(); rows], all: vec![false; rows] }
    }

    /// Row `r` depends on a time whose derivative does not exist where `voiders` (auxiliary
    /// rows) are not zero.
    pub(super) fn add(&mut self, r: usize, voiders: &[usize]) {
        for &a in voiders {
            if !self.by[r].contains(&a) {
                self.by[r].push(a);
            }
        }
    }

    /// Row `r` loses every parameter.
    pub(super) fn void_all(&mut self, r: usize) {
        self.all[r] = true;
    }

    /// Writes NaN where a row's derivative does not exist: `pbars` holds `rows` seed rows and
    /// then the auxiliary rows, `m` each. The auxiliary rows first, in time order (one can be
    /// voided only by the events before its own).
    pub(super) fn resolve(&self, rows: usize, m: usize, pbars: &mut [f64]) {
        let total = self.all.len();
        let mut voided = vec![false; m];
        for r in (rows..total).chain(0..rows) {
            if self.all[r] {
                pbars[r * m..(r + 1) * m].fill(f64::NAN);
                continue;
            }
            voided.fill(false);
            for &a in &self.by[r] {
                let moves = &pbars[(rows + a) * m..(rows + a + 1) * m];
                // NaN counts as moving the guard (`!(x == 0)`), as forward mode's NaN numerator.
                for (v, g) in voided.iter_mut().zip(moves) {
                    *v |= *g != 0.0;
                }
            }
            for (pb, v) in pbars[r * m..(r + 1) * m].iter_mut().zip(&voided) {
                if *v {
                    *pb = f64::NAN;
                }
            }
        }
    }
}

/// An auxiliary row's seed at its piece: `lam = g_x`, `pbar = g_p` of event `event`'s guard at
/// `(t, x)` (both zero before: nothing after the piece reaches an auxiliary row).
pub(super) fn seed_guard<S: HybridSystem + ?Sized>(
    sys: &S,
    p: &[f64],
    event: usize,
    t: f64,
    x: &[f64],
    lam: &mut [f64],
    pbar: &mut [f64],
) {
    lam.fill(0.0);
    pbar.fill(0.0);
    sys.guard_grad(event, t, x, p, lam, pbar);
}

/// The flows on the two sides of a flow switch.
fn switch_flows<S: HybridSystem + ?Sized>(sys: &S, p: &[f64], switch: &Switch<'_>) -> (Vec<f64>, Vec<f64>) {
    let n = switch.x.len();
    let (mut f_minus, mut f_plus) = (vec![0.0; n], vec![0.0; n]);
    sys.flow(switch.mode, switch.pre.0, switch.pre.1, p, &mut f_minus);
    sys.flow(switch.mode, switch.post.0, switch.post.1, p, &mut f_plus);
    (f_minus, f_plus)
}

/// A grazing flow switch's time cotangent `u = (f- - f+) . lam` (its jump `(f- - f+) dt/dp`
/// not carried: `lam` and the parameters pass unchanged).
pub(super) fn switch_time_bar<S: HybridSystem + ?Sized>(
    sys: &S,
    p: &[f64],
    switch: &Switch<'_>,
    lam: &[f64],
) -> f64 {
    let (f_minus, f_plus) = switch_flows(sys, p, switch);
    (0..lam.len()).map(|i| (f_minus[i] - f_plus[i]) * lam[i]).sum()
}

/// A flow switch that grazed with a jump vanishing with its speed, `S+ = S - c (g_x S + g_p)`
/// (`Jump::apply_switch`), transposed: `w = c . lam`, `lam -= g_x w`, `pbar -= g_p w`.
pub(super) fn benign_backward<S: HybridSystem + ?Sized>(
    sys: &S,
    p: &[f64],
    switch: &Switch<'_>,
    c: &[f64],
    lam: &mut [f64],
    pbar: &mut [f64],
) {
    let w: f64 = c.iter().zip(lam.iter()).filter(|(c, _)| **c != 0.0).map(|(c, l)| c * l).sum();
    if w == 0.0 {
        return;
    }
    let (mut gx, mut gp) = (vec![0.0; lam.len()], vec![0.0; pbar.len()]);
    sys.guard_grad(switch.event, switch.t, switch.x, p, &mut gx, &mut gp);
    for (l, g) in lam.iter_mut().zip(&gx) {
        *l -= g * w;
    }
    for (pb, g) in pbar.iter_mut().zip(&gp) {
        *pb -= g * w;
    }
}
