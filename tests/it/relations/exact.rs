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
use super::model::{Coef, Dir, GenModel, Lhs};

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
}

impl Reference {
    /// Whether the run's gradients are judged: not where an event fired at the start on its
    /// guard (rule 5). There the derivatives with respect to what places the guard are a cusp:
    /// one side fires at the start, the other starts on the crossed side and never fires, and
    /// docs/language.md does not yet say what is reported (hybc gives the firing side's
    /// derivative without a word; listed for the event issue).
    pub fn gradients_judged(&self) -> bool {
        self.event_grad.iter().all(|&g| g)
    }
}

#[derive(Clone, Debug)]
pub enum Outcome {
    Clean(Reference),
    /// A guard no polynomial describes: the model is checked by the relations alone.
    NotPolynomial,
    Ambiguous(String),
}

/// An active event in a segment: its index, its guard's sign changes (time, sign after) and
/// whether it is armed at the segment's start.
type Candidate = (usize, Vec<(Dd, f64)>, bool);

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

/// The polynomials of every state from `x` at `t0` in `mode`: a chain's top gets `a + b t`
/// integrated, each state below it the integral of the one above.
fn state_polys(g: &GenModel, p: &[Dual], x: &[Dual], t0: &Dual, mode: usize) -> Vec<Poly> {
    let m = p.len();
    let mut out: Vec<Poly> = vec![Vec::new(); x.len()];
    for (c, chain) in g.chains.iter().enumerate() {
        let top = g.tops[mode][c];
        // der(top) = a + b (t0 + tau).
        let a = &coef(&top.a, p) + &t0.scale(Dd::new(top.b));
        let mut rate: Poly = vec![a, Dual::constant(top.b, m)];
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
        Lhs::Sin(..) => unreachable!("the reference follows polynomial guards only"),
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

fn run(g: &GenModel, t_start: f64) -> Result<Reference, String> {
    let m = g.params.len();
    let p: Vec<Dual> = g.params.iter().enumerate().map(|(j, &v)| Dual::param(v, j, m)).collect();
    let mut x: Vec<Dual> = g.init.iter().map(|c| coef(c, &p)).collect();
    let span = g.t_end;
    let t_end = Dd::new(t_start) + Dd::new(g.t_end);
    let mut t0 = Dual::constant(t_start, m);
    let mut mode = 0usize;
    let mut armed: Vec<bool> = vec![false; g.events.len()];
    // Each event's guard sign just before the last instant's resets (0: not active then).
    let mut sign_before: Vec<f64> = vec![0.0; g.events.len()];
    let mut fired_last: Option<usize> = None;
    let mut first_segment = true;
    let mut out = Reference {
        events: Vec::new(),
        event_grad: Vec::new(),
        final_state: Vec::new(),
        final_mode: 0,
        stopped: None,
    };
    loop {
        let rest = t_end - t0.v;
        let xs = state_polys(g, &p, &x, &t0, mode);
        // Per active event: its guard's sign changes on (0, rest] and whether it is armed at 0+
        // (strictly on its pre-crossing side, or a contact leaving zero that way).
        let mut cands: Vec<Candidate> = Vec::new();
        let mut earliest: Vec<(Dd, usize, bool)> = Vec::new();
        for (e, ev) in g.events.iter().enumerate() {
            if ev.mode.is_some_and(|em| em != mode) {
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
                    if fires(ev.dir, s) {
                        earliest.push((Dd::ZERO, e, false));
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
                if fired_last != Some(e) {
                    return Err(format!("an instant leaves event {} on its guard ({g0:e})", ev.name));
                }
                let s = sign_after_zero(&gv, touch);
                if s == 0.0 {
                    return Err(format!("a contact {} is left on its guard with no speed (stuck)", ev.name));
                }
                // Rule 6: a bounce re-arms; a pass-through waits for the pre-crossing side.
                (true, pre_side(ev.dir, s))
            } else {
                let before = sign_before[e];
                if before == 0.0 && !pre_side(ev.dir, g0.signum()) {
                    return Err(format!("event {} becomes active on its crossed side", ev.name));
                }
                if fired_last != Some(e) && before != 0.0 && before != g0.signum() {
                    return Err(format!("an instant moves event {} across its guard (a cascade)", ev.name));
                }
                (false, if before == 0.0 { true } else { armed[e] || pre_side(ev.dir, g0.signum()) })
            };
            let changes = sign_changes(&gv, rest, touch, start_zero)?;
            let mut is_armed = armed0;
            for &(tau, after) in &changes {
                if is_armed && fires(ev.dir, after) {
                    // The slope there: slow crossings are near grazing.
                    let speed = eval(&derivative(&gv), tau).f64().abs() * rest.f64().abs().max(1e-300);
                    if speed < SLOW * scale {
                        return Err(format!("event {} crosses slowly ({:e})", ev.name, speed / scale));
                    }
                    earliest.push((tau, e, true));
                    break;
                }
                is_armed = pre_side(ev.dir, after);
            }
            cands.push((e, changes, armed0));
        }
        earliest.sort_by(|a, b| a.0.partial_cmp(&b.0).expect("finite"));
        let sep = Dd::new(SEPARATION * span.max(1.0));
        if let Some(&(tau, e, _)) = earliest.first() {
            if (tau - rest).abs() < sep {
                return Err(format!("event {} is within {SEPARATION:e} of t_end", g.events[e].name));
            }
        }
        let Some(&(tau, e, grad)) = earliest.first().filter(|f| f.0 <= rest) else {
            // No event: the end.
            let tau = &Dual::of_dd(t_end, m) - &t0;
            out.final_state = xs.iter().map(|poly| eval_dual(poly, &tau)).collect();
            out.final_mode = mode;
            return Ok(out);
        };
        if earliest.get(1).is_some_and(|f| (f.0 - tau).abs() < sep) {
            return Err("two events within a tolerance of each other".into());
        }
        if tau > Dd::ZERO && tau < sep && !first_segment {
            return Err("an event right after an instant".into());
        }
        // Every guard's state at the instant: armed as its sign changes before it left it, and
        // its sign there (just before the resets).
        sign_before.iter_mut().for_each(|s| *s = 0.0);
        for (c, changes, armed0) in &cands {
            let mut is_armed = *armed0;
            for &(_, after) in changes.iter().filter(|(t, _)| *t < tau) {
                is_armed = pre_side(g.events[*c].dir, after);
            }
            armed[*c] = is_armed;
            let (gp, _) = guard_poly(g, *c, &p, &xs, &t0);
            sign_before[*c] = eval(&values(&gp), tau).signum();
            if sign_before[*c] == 0.0 {
                sign_before[*c] = 1.0;
            }
        }
        // The dual time of the crossing: one Newton step at the converged root.
        let (gp, _) = guard_poly(g, e, &p, &xs, &t0);
        let tau_dual = if tau == Dd::ZERO {
            Dual::constant(0.0, m)
        } else {
            let slope = eval(&derivative(&values(&gp)), tau);
            let at = eval_dual(&gp, &Dual::of_dd(tau, m));
            &Dual::of_dd(tau, m) - &at.scale(Dd::new(1.0) / slope)
        };
        let t_e = &t0 + &tau_dual;
        let x_minus: Vec<Dual> = xs.iter().map(|poly| eval_dual(poly, &tau_dual)).collect();
        out.events.push((e, t_e.clone()));
        out.event_grad.push(grad);
        if out.events.len() > MAX_EVENTS {
            return Err("too many events".into());
        }
        let ev = &g.events[e];
        let mut x_plus = x_minus.clone();
        for r in &ev.resets {
            x_plus[r.state] = &(&coef(&r.a, &p) * &x_minus[r.state]) + &coef(&r.b, &p);
        }
        if let Some(to) = ev.to {
            mode = to;
        }
        x = x_plus;
        t0 = t_e;
        armed[e] = false;
        fired_last = Some(e);
        first_segment = false;
        if ev.stop {
            out.final_state = x;
            out.final_mode = mode;
            out.stopped = Some(e);
            return Ok(out);
        }
    }
}
