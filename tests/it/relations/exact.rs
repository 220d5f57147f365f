//! The exact reference of a generated model: between events every state is a polynomial of the
//! time since the last instant, with coefficients that are dual numbers (value and gradient) in
//! double-double; every guard along it is a polynomial too, whose real roots are isolated exactly
//! (the roots of its derivative, recursively, split the span into monotone pieces; each piece
//! holds at most one root, bisected to double-double precision). An event time's gradient comes
//! from one Newton step in dual arithmetic at the converged root (`tau - g(tau)/g'(tau)`, whose
//! derivative part is `-g_p / g'`), the state at the event from the polynomials at that dual
//! time, the reset in dual arithmetic: the same algebra a hand derivation would use.
//!
//! The reference implements the rules of docs/language.md ("When events fire") that the
//! generated models reach: crossings in a direction (rule 1), every sign change found (rule 2),
//! starting on a guard within round-off (rules 5 and 11), a contact's guard leaving zero after its
//! reset (rule 6), time order (rule 8), stops. Where a model would test a rule at its edge
//! within the run's accuracy rather than far from it (a touch, a crossing within a tolerance of
//! another or of `t_end`, a reset that puts another guard near zero, a cascade, a crossing too slow
//! to resolve, too many events), the reference says so ([`Outcome::Ambiguous`]) and the model is
//! drawn again: such edges have tests of their own, with their rule.

use super::dd::{Dd, Dual};
use super::model::{Coef, Dir, GenModel, Lhs, Switch};

/// The reference run of a model.
#[derive(Clone, Debug)]
pub struct Reference {
    /// (event index, time) in firing order.
    pub events: Vec<(usize, Dual)>,
    /// Whether each event's time gradient is defined (not for an event that fires at the start
    /// on its guard: its time does not move with the parameters that put it there).
    pub event_grad: Vec<bool>,
    /// The state at the end (`t_end`, or after a stop's resets at its instant), with gradients at
    /// fixed end time (the state's total derivative after a stop).
    pub final_state: Vec<Dual>,
    pub final_mode: usize,
    pub stopped: Option<usize>,
    /// A time event fired on `t_end` itself: the final values are a cusp (rule 8), their
    /// derivatives one-sided.
    pub end_cusp: bool,
}

impl Reference {
    /// Whether the run's gradients are judged: not where an event fired at the start on its
    /// guard (rule 5). There the derivatives with respect to what places the guard are a cusp:
    /// one side fires at the start, the other starts on the crossed side and never fires, and
    /// docs/language.md does not yet say what is reported (hybc gives the firing side's
    /// derivative without a word; listed for the event issue).
    pub fn gradients_judged(&self) -> bool {
        self.event_grad.iter().all(|&g| g) && !self.end_cusp
    }
}

#[derive(Clone, Debug)]
pub enum Outcome {
    Clean(Reference),
    /// A guard no polynomial describes: the model is checked by the relations alone.
    NotPolynomial,
    Ambiguous(String),
}

/// What ends a segment: an event, or a flow switch on a chain's top (not reported, but an
/// instant of the reference: the flow changes there).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Cause {
    Event(usize),
    Switch(usize),
}

/// A candidate end of a segment: its time since the segment's start, its cause, whether its time
/// has a gradient, and the sign its guard takes after it.
type Next = (Dd, Cause, bool, f64);

/// A coefficient `k p_j` (or the constant `k`) as a dual number over the parameters `p`.
fn coef(c: &Coef, p: &[Dual]) -> Dual {
    match c.p {
        None => Dual::constant(c.k, p.len()),
        Some(j) => p[j].scale(Dd::new(c.k)),
    }
}

/// A polynomial in the time since the segment's start, lowest coefficient first.
type Poly = Vec<Dual>;

fn values(p: &Poly) -> Vec<Dd> {
    p.iter().map(|c| c.v).collect()
}

fn eval(p: &[Dd], x: Dd) -> Dd {
    p.iter().rev().fold(Dd::ZERO, |acc, &c| acc * x + c)
}

fn eval_dual(p: &Poly, x: &Dual) -> Dual {
    let m = x.d.len();
    p.iter().rev().fold(Dual::constant(0.0, m), |acc, c| &(&acc * x) + c)
}

fn derivative(p: &[Dd]) -> Vec<Dd> {
    p.iter().enumerate().skip(1).map(|(k, &c)| c * Dd::new(k as f64)).collect()
}

fn poly_add(a: &Poly, b: &Poly, m: usize) -> Poly {
    (0..a.len().max(b.len()))
        .map(|k| match (a.get(k), b.get(k)) {
            (Some(x), Some(y)) => x + y,
            (Some(x), None) | (None, Some(x)) => x.clone(),
            (None, None) => Dual::constant(0.0, m),
        })
        .collect()
}

fn poly_mul(a: &Poly, b: &Poly, m: usize) -> Poly {
    let mut out = vec![Dual::constant(0.0, m); a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            out[i + j] = &out[i + j] + &(x * y);
        }
    }
    out
}

fn poly_scale(a: &Poly, k: f64) -> Poly {
    a.iter().map(|c| c.scale(Dd::new(k))).collect()
}

/// The sum of the magnitudes of a polynomial's terms over `[0, span]`: the scale its values are
/// judged against.
fn magnitude(p: &[Dd], span: Dd) -> f64 {
    let s = span.f64().abs();
    p.iter().enumerate().map(|(k, c)| c.f64().abs() * s.powi(k as i32)).sum()
}

/// A root of `p` in `(lo, hi]` where `p` changes sign, for `p` monotone there: bisected until the
/// bracket is as narrow as double-double resolves.
fn bisect(p: &[Dd], mut lo: Dd, mut hi: Dd) -> Dd {
    let s_lo = eval(p, lo).signum();
    for _ in 0..4000 {
        let mid = (lo + hi) * Dd::new(0.5);
        if !(mid > lo && mid < hi) {
            break;
        }
        let s = eval(p, mid).signum();
        if s == 0.0 {
            return mid;
        }
        if s == s_lo {
            lo = mid;
        } else {
            hi = mid;
        }
        if (hi - lo).f64() <= 1e-31 * hi.f64().abs().max(lo.f64().abs()) {
            break;
        }
    }
    (lo + hi) * Dd::new(0.5)
}

/// What a polynomial does on `(0, span]`: its sign changes in order, each with the sign it takes
/// after, or `Err` where it touches zero (an extremum within `touch` of zero) or ends near zero.
/// `start_zero`: the value at 0 is taken as zero (the sign of the first piece is its end's).
fn sign_changes(p: &[Dd], span: Dd, touch: f64, start_zero: bool) -> Result<Vec<(Dd, f64)>, String> {
    // Critical points, recursively: they split (0, span] into monotone pieces.
    let mut cuts = vec![Dd::ZERO];
    let dp = derivative(p);
    if dp.len() > 1 {
        let crit = critical_points(&dp, span);
        cuts.extend(crit.into_iter().filter(|&c| c > Dd::ZERO && c < span));
    }
    cuts.push(span);
    let mut out = Vec::new();
    for w in cuts.windows(2) {
        let (a, b) = (w[0], w[1]);
        let (ga, gb) = (eval(p, a), eval(p, b));
        if a > Dd::ZERO && ga.abs().f64() <= touch {
            return Err(format!("a guard touches zero (extremum {:e}) at tau = {:e}", ga.f64(), a.f64()));
        }
        if gb.abs().f64() <= touch {
            return Err(format!("a guard is {:e} from zero at the end of a segment", gb.f64()));
        }
        if a == Dd::ZERO && start_zero {
            // Starting on zero: the first piece's sign is its end's; no change inside it.
            continue;
        }
        if ga.signum() != gb.signum() {
            out.push((bisect(p, a, b), gb.signum()));
        }
    }
    Ok(out)
}

/// The real roots of `p` in `(0, span)`, each root isolated in a monotone piece.
fn critical_points(p: &[Dd], span: Dd) -> Vec<Dd> {
    if p.len() <= 1 {
        return Vec::new();
    }
    let mut cuts = vec![Dd::ZERO];
    let dp = derivative(p);
    cuts.extend(critical_points(&dp, span).into_iter().filter(|&c| c > Dd::ZERO && c < span));
    cuts.push(span);
    let mut out = Vec::new();
    for w in cuts.windows(2) {
        let (ga, gb) = (eval(p, w[0]), eval(p, w[1]));
        if ga.signum() == 0.0 {
            out.push(w[0]);
        } else if ga.signum() != gb.signum() && gb.signum() != 0.0 {
            out.push(bisect(p, w[0], w[1]));
        }
    }
    out
}

/// The polynomials of every state from `x` at `t0` in `mode`: a chain's top gets its rate
/// integrated (`a + b t`, or a switch's `then` where `branch` says it holds), each state below it
/// the integral of the one above.
fn state_polys(g: &GenModel, p: &[Dual], x: &[Dual], t0: &Dual, mode: usize, branch: &[bool]) -> Vec<Poly> {
    let m = p.len();
    let mut out: Vec<Poly> = vec![Vec::new(); x.len()];
    for (c, chain) in g.chains.iter().enumerate() {
        let top = g.tops[mode][c];
        let mut rate: Poly = match g.switches[c] {
            Some(s) if branch[c] => vec![coef(&s.then, p)],
            // der(top) = a + b (t0 + tau).
            _ => vec![&coef(&top.a, p) + &t0.scale(Dd::new(top.b)), Dual::constant(top.b, m)],
        };
        for &i in chain.iter().rev() {
            let mut poly = vec![x[i].clone()];
            for (k, c) in rate.iter().enumerate() {
                poly.push(c.scale(Dd::new(1.0) / Dd::new((k + 1) as f64)));
            }
            out[i] = poly.clone();
            rate = poly;
        }
    }
    out
}

/// A switch's comparison `x_state - at` along the polynomials.
fn switch_poly(s: &Switch, p: &[Dual], xs: &[Poly]) -> Poly {
    let mut poly = xs[s.state].clone();
    poly[0] = &poly[0] - &coef(&s.at, p);
    poly
}

/// A state held still: constant polynomials, to read a guard at one instant.
fn held(x: &[Dual]) -> Vec<Poly> {
    x.iter().map(|xi| vec![xi.clone()]).collect()
}

/// The margin of an enabling condition or a switch on the state `x` (positive: it holds), and
/// the scale that margin is judged against.
fn level_margin(at: &Coef, above: bool, p: &[Dual], x: Dd) -> (Dd, f64) {
    let at = coef(at, p).v;
    let d = if above { x - at } else { at - x };
    (d, x.abs().f64() + at.abs().f64())
}

/// Whether event `e`'s enabling condition holds on the state `x`; `Err` where it is too close to
/// its boundary for a run's accuracy to decide.
fn condition_holds(g: &GenModel, e: usize, p: &[Dual], x: &[Dual]) -> Result<bool, String> {
    let Some(c) = g.events[e].cond else { return Ok(true) };
    let (margin, scale) = level_margin(&c.at, c.above, p, x[c.state].v);
    if margin.abs().f64() <= COND_TOUCH * scale.max(1.0) {
        return Err(format!(
            "event {}'s condition is at its boundary ({:e})",
            g.events[e].name,
            margin.f64()
        ));
    }
    Ok(margin.signum() > 0.0)
}

/// The guard `lhs - rhs` of event `e` along the polynomials, and the per-component round-off
/// scale of rule 11 at the segment's start (`sum |g_x,i x_i| + |g_t t|`).
fn guard_poly(g: &GenModel, e: usize, p: &[Dual], xs: &[Poly], t0: &Dual) -> (Poly, f64) {
    let m = p.len();
    let ev = &g.events[e];
    let rhs = coef(&ev.rhs, p);
    let (lhs, round) = match &ev.lhs {
        Lhs::Lin(terms) => {
            let mut acc: Poly = vec![Dual::constant(0.0, m)];
            let mut round = 0.0;
            for &(i, w) in terms {
                acc = poly_add(&acc, &poly_scale(&xs[i], w), m);
                round += (w * xs[i][0].v.f64()).abs();
            }
            (acc, round)
        }
        Lhs::Prod(i, j) => {
            let prod = poly_mul(&xs[*i], &xs[*j], m);
            (prod, 2.0 * (xs[*i][0].v.f64() * xs[*j][0].v.f64()).abs())
        }
        Lhs::Time => (vec![t0.clone(), Dual::constant(1.0, m)], t0.v.f64().abs()),
        Lhs::Sin(..) | Lhs::Abs(..) => unreachable!("the reference follows polynomial guards only"),
    };
    let mut poly = lhs;
    poly[0] = &poly[0] - &rhs;
    (poly, round)
}

/// Whether the sign `s` (after a change) is the crossed side of `dir`, coming from the other.
fn fires(dir: Dir, s: f64) -> bool {
    match dir {
        Dir::Falling => s < 0.0,
        Dir::Rising => s > 0.0,
        Dir::Crosses => true,
    }
}

/// The pre-crossing side's sign check: `s` is strictly on it.
fn pre_side(dir: Dir, s: f64) -> bool {
    match dir {
        Dir::Falling => s > 0.0,
        Dir::Rising => s < 0.0,
        Dir::Crosses => s != 0.0,
    }
}

/// The sign `p` takes just after 0 when its value there is (within `touch`) zero: its first
/// clearly non-zero coefficient's.
fn sign_after_zero(p: &[Dd], touch_coef: f64) -> f64 {
    p.iter().skip(1).find(|c| c.abs().f64() > touch_coef).map_or(0.0, |c| c.signum())
}

/// How far apart (relative to the run's span) two instants, or an instant and `t_end`, must be
/// for their order to be decided by any run at rtol >= 1e-10.
pub const SEPARATION: f64 = 1e-5;
/// A guard extremum or end value within this fraction of the guard's magnitude is a touch.
const TOUCH: f64 = 1e-7;
/// A crossing slower than this (the guard's speed times the span, over its magnitude) is too
/// close to grazing for its gradient to be judged at the harness's tolerances.
const SLOW: f64 = 1e-4;
/// Generated models with more events are drawn again (they stay well within `--max-events`).
const MAX_EVENTS: usize = 40;
/// An enabling condition within this fraction of its sides' size from its boundary is decided by
/// the run's error, not by the model.
const COND_TOUCH: f64 = 1e-6;
/// Rounds of cascades at one instant the reference follows (rule 7).
const MAX_ROUNDS: usize = 5;

/// The reference run of `g` from `t_start`.
pub fn reference(g: &GenModel, t_start: f64) -> Outcome {
    if !g.polynomial() {
        return Outcome::NotPolynomial;
    }
    match run(g, t_start) {
        Ok(r) => Outcome::Clean(r),
        Err(why) => Outcome::Ambiguous(why),
    }
}

/// Whether `e` is active in `mode`.
fn active(g: &GenModel, e: usize, mode: usize) -> bool {
    g.events[e].mode.is_none_or(|em| em == mode)
}

/// Event `e`'s guard on the state `x` held at `t`, and the scale it is judged against.
fn guard_at(g: &GenModel, e: usize, p: &[Dual], x: &[Dual], t: &Dual) -> (Dd, f64) {
    let (gp, round) = guard_poly(g, e, p, &held(x), t);
    let rhs = coef(&g.events[e].rhs, p).v.f64().abs();
    (gp[0].v, (round + rhs).max(1e-300))
}

/// Applies event `e`'s resets and mode switch to `x`; returns whether it stops the run.
fn apply(g: &GenModel, e: usize, p: &[Dual], x: &mut [Dual], mode: &mut usize) -> bool {
    let ev = &g.events[e];
    let before = x.to_vec();
    for r in &ev.resets {
        x[r.state] = &(&coef(&r.a, p) * &before[r.state]) + &coef(&r.b, p);
    }
    if let Some(to) = ev.to {
        *mode = to;
    }
    ev.stop
}

/// Each switch's branch on the state `x`; `Err` where a state is at a switch's level.
fn branches(g: &GenModel, p: &[Dual], x: &[Dual]) -> Result<Vec<bool>, String> {
    g.switches
        .iter()
        .map(|s| match s {
            None => Ok(false),
            Some(s) => {
                let (margin, scale) = level_margin(&s.at, true, p, x[s.state].v);
                if margin.abs().f64() <= COND_TOUCH * scale.max(1.0) {
                    return Err(format!("a state is at a flow switch's level ({:e})", margin.f64()));
                }
                Ok(margin.signum() > 0.0)
            }
        })
        .collect()
}

fn run(g: &GenModel, t_start: f64) -> Result<Reference, String> {
    let m = g.params.len();
    let p: Vec<Dual> = g.params.iter().enumerate().map(|(j, &v)| Dual::param(v, j, m)).collect();
    let mut x: Vec<Dual> = g.init.iter().map(|c| coef(c, &p)).collect();
    let span = g.t_end;
    let t_end = Dd::new(t_start) + Dd::new(g.t_end);
    // Rule 8: an event on `t_end` to 16 spacings of `t` fires there.
    let end_f = t_end.f64();
    let on_end = Dd::new(16.0 * (end_f.next_up() - end_f));
    let sep = Dd::new(SEPARATION * span.max(1.0));
    let mut t0 = Dual::constant(t_start, m);
    let mut mode = 0usize;
    let mut branch = branches(g, &p, &x)?;
    // The events fired at the last instant, the switch crossed there (with its sign after), and
    // which events were active in the segment before it.
    let mut fired_now: Vec<usize> = Vec::new();
    let mut switched: Option<(usize, f64)> = None;
    let mut was_active: Vec<bool> = (0..g.events.len()).map(|e| active(g, e, mode)).collect();
    let mut first_segment = true;
    let mut out = Reference {
        events: Vec::new(),
        event_grad: Vec::new(),
        final_state: Vec::new(),
        final_mode: 0,
        stopped: None,
        end_cusp: false,
    };
    loop {
        let rest = t_end - t0.v;
        let xs = state_polys(g, &p, &x, &t0, mode, &branch);
        let mut next: Vec<Next> = Vec::new();
        for (c, s) in g.switches.iter().enumerate() {
            let Some(s) = s else { continue };
            let gv = values(&switch_poly(s, &p, &xs));
            let scale = magnitude(&gv, rest).max(1e-300);
            let touch = TOUCH * scale;
            let start_zero = match switched {
                Some((sc, after)) if sc == c => {
                    // Just crossed: the new branch must carry the state on, not back (sliding).
                    if sign_after_zero(&gv, touch) != after {
                        return Err("a flow switch's new branch turns the state back (sliding)".into());
                    }
                    true
                }
                _ => false,
            };
            let changes = sign_changes(&gv, rest, touch, start_zero)?;
            if let Some(&(tau, after)) = changes.first() {
                let speed = eval(&derivative(&gv), tau).f64().abs() * rest.f64().abs().max(1e-300);
                if speed < SLOW * scale {
                    return Err(format!("a flow switch is crossed slowly ({:e})", speed / scale));
                }
                next.push((tau, Cause::Switch(c), true, after));
            }
        }
        for (e, ev) in g.events.iter().enumerate() {
            if !active(g, e, mode) {
                continue;
            }
            let (gp, round) = guard_poly(g, e, &p, &xs, &t0);
            let gv = values(&gp);
            let scale = magnitude(&gv, rest).max(1e-300);
            let touch = TOUCH * scale;
            let g0 = gv[0].f64();
            // Rule 11: the guard's round-off at the start.
            let round_off = 16.0 * f64::EPSILON * round;
            let (start_zero, armed0) = if first_segment {
                if g0.abs() <= round_off {
                    // Rule 5: on the guard at the start; fires now if the flow moves it across.
                    let s = sign_after_zero(&gv, 0.0);
                    if s == 0.0 {
                        return Err("a guard starts on zero with no speed".into());
                    }
                    if fires(ev.dir, s) && condition_holds(g, e, &p, &x)? {
                        next.push((Dd::ZERO, Cause::Event(e), false, s));
                    }
                    (true, pre_side(ev.dir, s))
                } else if g0.abs() <= 1e3 * round_off {
                    return Err(format!("a guard starts within 1e3 round-offs of zero ({g0:e})"));
                } else if !pre_side(ev.dir, g0.signum()) {
                    return Err(
                        "a run starts on a directional guard's crossed side (rule 5's warning)".into()
                    );
                } else {
                    (false, true)
                }
            } else if g0.abs() <= touch {
                if !fired_now.contains(&e) {
                    return Err(format!("an instant leaves event {} on its guard ({g0:e})", ev.name));
                }
                let s = sign_after_zero(&gv, touch);
                if s == 0.0 {
                    return Err(format!("a contact {} is left on its guard with no speed (stuck)", ev.name));
                }
                // Rule 6: a bounce re-arms; a pass-through waits for the pre-crossing side.
                (true, pre_side(ev.dir, s))
            } else if !was_active[e] && !pre_side(ev.dir, g0.signum()) {
                return Err(format!("event {} becomes active on its crossed side", ev.name));
            } else {
                (false, pre_side(ev.dir, g0.signum()))
            };
            let changes = if ev.lhs == Lhs::Time {
                // `t - at`, of slope 1: its root exactly, so that one on `t_end` is seen there.
                let root = -gv[0];
                if start_zero || root <= Dd::ZERO || root > rest + sep {
                    Vec::new()
                } else {
                    vec![(root, 1.0)]
                }
            } else {
                sign_changes(&gv, rest, touch, start_zero)?
            };
            let mut is_armed = armed0;
            for &(tau, after) in &changes {
                if is_armed && fires(ev.dir, after) {
                    // The slope there: slow crossings are near grazing.
                    let speed = eval(&derivative(&gv), tau).f64().abs() * rest.f64().abs().max(1e-300);
                    if speed < SLOW * scale {
                        return Err(format!("event {} crosses slowly ({:e})", ev.name, speed / scale));
                    }
                    // The enabling condition, on the state at the crossing.
                    let at: Vec<Dual> = xs.iter().map(|poly| eval_dual(poly, &Dual::of_dd(tau, m))).collect();
                    if condition_holds(g, e, &p, &at)? {
                        next.push((tau, Cause::Event(e), true, after));
                        break;
                    }
                }
                is_armed = pre_side(ev.dir, after);
            }
        }
        next.sort_by(|a, b| a.0.partial_cmp(&b.0).expect("finite"));
        let is_time_event = |c: Cause| matches!(c, Cause::Event(e) if g.events[e].lhs == Lhs::Time);
        let at_end = next.first().is_some_and(|f| (f.0 - rest).abs() <= on_end);
        if let Some(&(tau, cause, _, _)) = next.first() {
            if at_end && !is_time_event(cause) {
                return Err("a state event or a switch on t_end".into());
            }
            if !at_end && (tau - rest).abs() < sep {
                return Err(format!("an instant within {SEPARATION:e} of t_end ({:?})", cause));
            }
        }
        let Some(&(tau, cause, grad, after)) = next.first().filter(|f| f.0 <= rest || at_end) else {
            // No event: the end.
            let tau = &Dual::of_dd(t_end, m) - &t0;
            out.final_state = xs.iter().map(|poly| eval_dual(poly, &tau)).collect();
            out.final_mode = mode;
            return Ok(out);
        };
        if next.get(1).is_some_and(|f| (f.0 - tau).abs() < sep) {
            return Err("two instants within a tolerance of each other".into());
        }
        if tau > Dd::ZERO && tau < sep && !first_segment {
            return Err("an instant right after an instant".into());
        }
        // The dual time of the crossing: one Newton step at the converged root.
        let gp = match cause {
            Cause::Event(e) => guard_poly(g, e, &p, &xs, &t0).0,
            Cause::Switch(c) => switch_poly(g.switches[c].as_ref().expect("a switch"), &p, &xs),
        };
        let tau_dual = if tau == Dd::ZERO {
            Dual::constant(0.0, m)
        } else {
            let slope = eval(&derivative(&values(&gp)), tau);
            let at = eval_dual(&gp, &Dual::of_dd(tau, m));
            &Dual::of_dd(tau, m) - &at.scale(Dd::new(1.0) / slope)
        };
        let t_e = &t0 + &tau_dual;
        let x_minus: Vec<Dual> = xs.iter().map(|poly| eval_dual(poly, &tau_dual)).collect();
        first_segment = false;
        was_active = (0..g.events.len()).map(|e| active(g, e, mode)).collect();
        let e = match cause {
            Cause::Switch(c) => {
                // The state flows on; only the chain's top changes its rate.
                branch[c] = after > 0.0;
                switched = Some((c, after));
                fired_now.clear();
                x = x_minus;
                t0 = t_e;
                continue;
            }
            Cause::Event(e) => e,
        };
        // The instant: the event, then the cascades its resets set off (rule 7), a round at a
        // time, each event judged on the state the round before it left.
        let mut x_now = x_minus.clone();
        let mut fired = vec![e];
        out.events.push((e, t_e.clone()));
        out.event_grad.push(grad);
        let mut stopped = apply(g, e, &p, &mut x_now, &mut mode).then_some(e);
        let mut before_round = x_minus;
        let mut active_before = was_active.clone();
        for round in 0.. {
            if stopped.is_some() {
                break;
            }
            let mut cascading = Vec::new();
            // The event of the round before was at its crossing (rule 6 judges its own guard);
            // an event of an earlier round may cascade again (rule 7's ping-pong).
            for c in (0..g.events.len()).filter(|&c| active(g, c, mode) && fired.last() != Some(&c)) {
                let (ga, scale) = guard_at(g, c, &p, &x_now, &t_e);
                if ga.abs().f64() <= TOUCH * scale {
                    return Err(format!("an instant puts event {}'s guard on zero", g.events[c].name));
                }
                if !active_before[c] {
                    // Newly active: the next segment's start judges it.
                    continue;
                }
                let (gb, _) = guard_at(g, c, &p, &before_round, &t_e);
                if gb.abs().f64() <= TOUCH * scale {
                    return Err(format!("event {}'s guard is on zero at an instant", g.events[c].name));
                }
                let dir = g.events[c].dir;
                let across = gb.signum() != ga.signum();
                if across
                    && pre_side(dir, gb.signum())
                    && fires(dir, ga.signum())
                    && condition_holds(g, c, &p, &x_now)?
                {
                    cascading.push(c);
                }
            }
            let Some(&c) = cascading.first() else { break };
            if cascading.len() > 1 {
                return Err("several events cascade in one round".into());
            }
            if round >= MAX_ROUNDS {
                return Err("a long cascade".into());
            }
            out.events.push((c, t_e.clone()));
            out.event_grad.push(grad);
            before_round = x_now.clone();
            active_before = (0..g.events.len()).map(|e| active(g, e, mode)).collect();
            stopped = apply(g, c, &p, &mut x_now, &mut mode).then_some(c);
            fired.push(c);
        }
        if out.events.len() > MAX_EVENTS {
            return Err("too many events".into());
        }
        if stopped.is_some() || at_end {
            out.final_state = x_now;
            out.final_mode = mode;
            out.stopped = stopped;
            out.end_cusp = at_end;
            return Ok(out);
        }
        branch = branches(g, &p, &x_now)?;
        x = x_now;
        t0 = t_e;
        fired_now = fired;
        switched = None;
    }
}
