//! Where forward mode says a derivative does not exist, the adjoint says the same, entry by
//! entry and per parameter (docs/design.md, "Where a derivative does not exist, in the
//! adjoint"): a grazing crossing, an event a reset put on its guard (rule 7), a grazing flow
//! switch (and the benign one, whose derivative exists: rule 12's exception), a flow switch at
//! another event's instant. Each run is compared with the forward run without sensitivity error
//! control (the same steps): the same NaN entries, the same `None` where nothing exists, the
//! finite entries within the adjoint tests' bound (1e-11 of the quantity's largest entry), the
//! same warnings. Each test also states the pattern itself, so that both modes giving NaN
//! everywhere would fail.

use hybc::sim::adjoint::{record, ExistenceMarks};
use hybc::sim::{run, Method, Sens, SimOptions, SimResult, SimWarning};

/// The adjoint tests' bound (tests/it/adjoint.rs), relative to the largest finite entry of the
/// quantity's gradient, or to 1e-3 of the run's largest where that is smaller.
const BOUND: f64 = 1e-11;

/// Compiles `src` with every parameter differentiated, at its defaults but `set`.
fn compiled(src: &str, set: &[(&str, f64)]) -> (hybc::Compiled, Vec<f64>) {
    let model = hybc::Model::parse(src).unwrap_or_else(|e| panic!("{e}"));
    let names: Vec<String> = model.params().iter().map(|(name, _)| name.to_string()).collect();
    let compiled = model.compile(&names).expect("compiles");
    let mut params = compiled.params();
    for (name, value) in set {
        params.set(name, *value).expect("a parameter of the model");
    }
    let p = params.values().to_vec();
    (compiled, p)
}

/// One gradient array of both modes: both absent, or the same NaN entries and (`floor` finite)
/// finite entries within [`BOUND`]. Returns (entries that do not exist, entries that do).
fn same_entries(label: &str, adj: Option<&Vec<f64>>, fwd: Option<&Vec<f64>>, floor: f64) -> (usize, usize) {
    match (adj, fwd) {
        (None, None) => (0, 0),
        (Some(a), Some(f)) => {
            assert_eq!(a.len(), f.len(), "{label}");
            let scale = f.iter().filter(|v| v.is_finite()).fold(floor, |s, v| s.max(v.abs()));
            let mut counts = (0, 0);
            for (i, (a, f)) in a.iter().zip(f).enumerate() {
                assert_eq!(
                    a.is_nan(),
                    f.is_nan(),
                    "{label}[{i}]: adjoint {a}, forward {f}\n{adj:?}\n{fwd:?}"
                );
                if f.is_nan() {
                    counts.0 += 1;
                } else {
                    let gap = (a - f).abs();
                    assert!(
                        !floor.is_finite() || gap <= BOUND * scale,
                        "{label}[{i}]: adjoint {a}, forward {f}, gap {gap:e}"
                    );
                    counts.1 += 1;
                }
            }
            counts
        }
        _ => panic!("{label}: adjoint {adj:?}, forward {fwd:?}"),
    }
}

/// Forward (sensitivities out of the error test) and adjoint runs of `src` at `set`, compared
/// entry by entry, warnings included; returns the forward run and what the tape marked.
fn both(label: &str, src: &str, set: &[(&str, f64)], opts: &SimOptions) -> (SimResult, ExistenceMarks) {
    both_with(label, src, set, opts, true)
}

/// [`both`]; the finite entries' values compared only with `values` (else the NaN pattern and
/// the warnings, the values left to `adjoint::compare`, which bounds them by the run's measured
/// round-off amplification).
fn both_with(
    label: &str,
    src: &str,
    set: &[(&str, f64)],
    opts: &SimOptions,
    values: bool,
) -> (SimResult, ExistenceMarks) {
    let (compiled, p) = compiled(src, set);
    let sys = compiled.system();
    let base = SimOptions { sens_error_control: false, ..opts.clone() };
    let fwd = run(sys, &p, &SimOptions { sens: Sens::Forward, ..base.clone() }).expect("runs");
    let adj = run(sys, &p, &SimOptions { sens: Sens::Adjoint, ..base.clone() }).expect("runs");
    assert_eq!(adj.stats.sens, Some(Sens::Adjoint), "{label}: carried by the adjoint: {:?}", adj.warnings);
    let marks = record(sys, &p, &base).expect("records").tape.existence_marks();
    let words = |r: &SimResult| r.warnings.iter().map(ToString::to_string).collect::<Vec<_>>();
    assert_eq!(words(&adj), words(&fwd), "{label}: warnings");
    assert_eq!(adj.events.len(), fwd.events.len(), "{label}");
    let largest = |v: Option<&Vec<f64>>| {
        v.map_or(0.0, |v| v.iter().filter(|x| x.is_finite()).fold(0.0f64, |a, b| a.max(b.abs())))
    };
    let (ff, af) = (&fwd.final_state, &adj.final_state);
    let floor = if values { 1e-3 } else { f64::INFINITY }
        * fwd
            .events
            .iter()
            .map(|e| largest(e.dtime.as_ref()))
            .chain([largest(ff.dstate.as_ref()), largest(ff.doutputs.as_ref())])
            .fold(0.0, f64::max);
    for (k, (a, f)) in adj.events.iter().zip(&fwd.events).enumerate() {
        same_entries(&format!("{label} dt{k}/dp ({})", f.name), a.dtime.as_ref(), f.dtime.as_ref(), floor);
    }
    same_entries(&format!("{label} dstate"), af.dstate.as_ref(), ff.dstate.as_ref(), floor);
    same_entries(&format!("{label} doutputs"), af.doutputs.as_ref(), ff.doutputs.as_ref(), floor);
    same_entries(&format!("{label} dstate_total"), af.dstate_total.as_ref(), ff.dstate_total.as_ref(), floor);
    let (a_total, f_total) = (af.doutputs_total.as_ref(), ff.doutputs_total.as_ref());
    same_entries(&format!("{label} doutputs_total"), a_total, f_total, floor);
    match (&adj.end_cusp, &fwd.end_cusp) {
        (Some(a), Some(f)) => {
            same_entries(&format!("{label} cusp dstate"), a.dstate.as_ref(), f.dstate.as_ref(), floor);
            same_entries(&format!("{label} cusp doutputs"), a.doutputs.as_ref(), f.doutputs.as_ref(), floor);
        }
        (None, None) => {}
        _ => panic!("{label}: one mode has an end cusp"),
    }
    (fwd, marks)
}

fn options(t_end: f64) -> SimOptions {
    SimOptions { t_end, rtol: 1e-10, atol: 1e-12, ..SimOptions::default() }
}

/// A throw whose apex touches the ceiling `y >= c` exactly (g = 8, v0 = 4: apex y = 1 at
/// t = 0.5, exact in binary): the touch grazes. v0 and c move it; k acts only in its reset
/// (`v := -k`); `rest` at 0.9 sets v to a constant.
const GRAZE: &str = "model graze\nparam v0 = 4\nparam c = 1\nparam k = 0.5\nstate y = 0\nstate v = v0\n\
                     der(y) = v\nder(v) = -8\nevent top when y >= c {\n    v := -k\n}\n\
                     event rest when t >= 0.9 {\n    v := 0\n}\noutput e = y + v\n";

#[test]
fn a_grazing_crossing_voids_in_the_adjoint_what_it_voids_forward_per_parameter() {
    for method in [Method::Auto, Method::Dopri5, Method::Dop853, Method::Rodas5p, Method::Rodas4] {
        let label = format!("graze {method:?}");
        let (r, marks) = both(&label, GRAZE, &[], &SimOptions { method, ..options(1.0) });
        assert_eq!(marks, ExistenceMarks { grazes: 1, ..ExistenceMarks::default() }, "{label}");
        assert!(matches!(r.warnings[..], [SimWarning::Grazing { .. }]), "{label}: {:?}", r.warnings);
        // Parameters [v0, c, k]: the touch's time moves with v0 and c (no derivative), not k (0).
        let dt = r.events[0].dtime.as_ref().expect("dt/dk exists");
        assert!(dt[0].is_nan() && dt[1].is_nan() && dt[2] == 0.0, "{label}: {dt:?}");
        assert_eq!(r.events[1].dtime.as_deref(), Some(&[0.0, 0.0, 0.0][..]), "{label}");
        // y keeps the touch's time (NaN by v0, c); dy/dk = -(0.9 - 0.5); v was set to 0 at 0.9:
        // its derivatives exist (0). Column per parameter: [y, v] each.
        let ds = r.final_state.dstate.as_ref().expect("some exist");
        assert!(ds[0].is_nan() && ds[2].is_nan(), "{label}: {ds:?}");
        // -(0.9 - t_top), at the touch's located time (a graze's time is known to about
        // sqrt(atol / |g''|), 3.5e-7 here).
        let t_top = r.events[0].time;
        assert!((t_top - 0.5).abs() < 1e-6, "{label}: {t_top}");
        assert!((ds[4] + (0.9 - t_top)).abs() < 1e-12, "{label}: {ds:?}");
        assert!(ds[1] == 0.0 && ds[3] == 0.0 && ds[5] == 0.0, "{label}: {ds:?}");
    }
    // Stopped before `rest`: v too depends on the touch (NaN by v0 and c), and both states keep
    // their derivatives by k.
    let (r, _) = both("graze before rest", GRAZE, &[], &options(0.8));
    let ds = r.final_state.dstate.as_ref().expect("some exist");
    assert!(ds[..4].iter().all(|v| v.is_nan()) && ds[4..].iter().all(|v| v.is_finite()), "{ds:?}");
}

/// The graze with a cascade: `top`'s reset puts v across `mark`'s guard, which fires at the
/// instant and records its time in `w` (its `R_t`): w moves with the touch's time.
#[test]
fn a_cascade_from_a_grazing_event_carries_the_grazes_missing_time() {
    let src = GRAZE
        .replace("state v = v0\n", "state v = v0\nstate w = 0\nder(w) = 0\n")
        .replace("event rest", "event mark when v <= -0.25 {\n    w := t\n}\nevent rest");
    for method in [Method::Auto, Method::Dopri5, Method::Rodas5p] {
        let label = format!("graze cascade {method:?}");
        // To 0.92: after `rest` v falls past -0.25 again at 0.93125.
        let (r, marks) = both(&label, &src, &[], &SimOptions { method, ..options(0.92) });
        assert_eq!(marks, ExistenceMarks { grazes: 1, ..ExistenceMarks::default() }, "{label}");
        assert_eq!(r.events.iter().map(|e| &*e.name).collect::<Vec<_>>(), ["top", "mark", "rest"]);
        assert_eq!(r.events[1].time, r.events[0].time, "{label}: one instant");
        // States [y, v, w] per parameter [v0, c, k]: w = t_top, NaN by v0 and c, 0 by k.
        let ds = r.final_state.dstate.as_ref().expect("some exist");
        let w: Vec<f64> = (0..3).map(|j| ds[j * 3 + 2]).collect();
        assert!(w[0].is_nan() && w[1].is_nan() && w[2] == 0.0, "{label}: {ds:?}");
    }
}

#[test]
fn the_ceiling_just_above_the_apex_is_carried_as_before() {
    // The other side: no touch, no mark, every derivative exists and agrees.
    let (r, marks) = both("no touch", GRAZE, &[("c", 1.1)], &options(1.0));
    assert_eq!(marks, ExistenceMarks::default());
    assert_eq!(r.events.len(), 1);
    assert!(r.final_state.dstate.as_ref().expect("exist").iter().all(|v| v.is_finite()));
}

/// Rule 7's reset onto a guard: at t = 1 `jump` puts x on `shift`'s guard `x >= b` at b = 1.
const ONTO: &str = "model onto\nparam b = 1\nparam c = 1\nstate x = -5\nstate y = 0\nstate k = c\n\
                    der(x) = 1\nder(y) = k\nder(k) = 0\n\
                    event jump when t >= 1 {\n    x := 1\n}\nevent shift when x >= b {\n    k := 2 * k\n}\n";

#[test]
fn a_reset_onto_a_guard_voids_in_the_adjoint_what_it_voids_forward() {
    for method in [Method::Auto, Method::Dopri5, Method::Rodas5p] {
        let label = format!("onto {method:?}");
        let (r, marks) = both(&label, ONTO, &[], &SimOptions { method, ..options(2.0) });
        assert_eq!(marks, ExistenceMarks { onto_guard: 1, ..ExistenceMarks::default() }, "{label}");
        assert!(matches!(r.warnings[..], [SimWarning::ResetOntoGuard { .. }]), "{:?}", r.warnings);
        // [b, c]: shift's time has no derivative by b, 0 by c.
        let dt = r.events[1].dtime.as_ref().expect("dt/dc exists");
        assert!(dt[0].is_nan() && dt[1] == 0.0, "{label}: {dt:?}");
        // States [x, y, k] per parameter: only y reads shift's time (its rate doubles there).
        let ds = r.final_state.dstate.as_ref().expect("some exist");
        let nan: Vec<bool> = ds.iter().map(|v| v.is_nan()).collect();
        assert_eq!(nan, [false, true, false, false, false, false], "{label}: {ds:?}");
        assert!((ds[4] - 3.0).abs() < 1e-12 && (ds[5] - 2.0).abs() < 1e-12, "{label}: {ds:?}");
    }
    // A reset clearly across the guard: no mark, no warning, every derivative.
    let across = ONTO.replace("x := 1\n", "x := 1.5\n");
    let (r, marks) = both("across", &across, &[], &options(2.0));
    assert_eq!(marks, ExistenceMarks::default());
    assert!(r.warnings.is_empty() && r.final_state.dstate.as_ref().unwrap().iter().all(|v| v.is_finite()));
}

// The dip of tests/it/flow_switches.rs: a parabola that dips `c` (1e-11 against atol 1e-12: a
// graze) below a floor whose damper `if y < 0 then k v` vanishes with the speed (benign), and
// `PUSH`, a force `k` switched on instead (a graze with no derivative by a and c).
use crate::flow_switches::{DIP, PUSH};

#[test]
fn grazing_flow_switches_are_transposed_benign_or_not() {
    for method in [Method::Rodas5p, Method::Rodas4, Method::Dopri5, Method::Dop853] {
        let label = format!("dip {method:?}");
        let (r, marks) = both(&label, DIP, &[], &SimOptions { method, ..options(2.0) });
        assert!(marks.benign >= 1 && marks.grazes == 0, "{label}: {marks:?}");
        assert!(r.final_state.dstate.as_ref().expect("exist").iter().all(|v| v.is_finite()), "{label}");
    }
    // As tests/it/flow_switches.rs, under the methods that resolve the graze as one.
    for method in [Method::Rodas5p, Method::Dopri5, Method::Dop853] {
        let label = format!("push {method:?}");
        let (r, marks) = both(&label, PUSH, &[], &SimOptions { method, ..options(2.0) });
        assert!(marks.grazes >= 1 && marks.benign == 0, "{label}: {marks:?}");
        let ds = r.final_state.dstate.as_ref().expect("dy/dk exists");
        assert!(ds[0].is_nan() && ds[2].is_nan() && ds[4].is_finite(), "{label}: {ds:?}");
    }
}

/// `models/soft_ball.hyb` at `wc = 1e5`: its micro-bounces graze the damper's switch, whose jump
/// vanishes with the speed (three such grazes by t = 1 under every method), and the gradients
/// exist. The values are compared by `adjoint::compare` (1e-11, or the run's measured round-off
/// amplification); DOP853's bound is 1e-10: at rest on the spring its steps are held by stability
/// and the velocity's derivatives are the remnant of O(1) values (8.5e-6 and below), so the two
/// modes' summation orders part by more. That is the pair's, not the grazes': the same run at
/// `wc = 3e4`, which does not graze, parts by 3.3e-10 at t = 2, the grazing one at 1e5 by
/// 5.7e-11 (measured with this test's comparison; `auto`, which takes DOP853 before the rest,
/// parts by 2.7e-11 at t = 1, as DOP853 does there, and by 7.3e-12 at t = 2, Rodas5P's steps
/// at rest).
#[test]
fn the_soft_ball_through_its_benign_grazes_agrees_under_auto_and_each_method() {
    let src = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/models/soft_ball.hyb")).unwrap();
    for method in [Method::Auto, Method::Rodas5p, Method::Rodas4, Method::Dopri5, Method::Dop853] {
        let label = format!("soft ball {method:?}");
        let opts = SimOptions { method, rtol: 1e-8, atol: 1e-10, ..options(T_SOFT) };
        let (r, marks) = both_with(&label, &src, &[("wc", 1e5)], &opts, false);
        let (compiled, p) = compiled(&src, &[("wc", 1e5)]);
        let bound = if method == Method::Dop853 { 1e-10 } else { 1e-11 };
        let (gap, what) = crate::adjoint::compare_within(&label, compiled.system(), &p, &opts, bound)
            .expect("carried by the adjoint");
        eprintln!(
            "{label}: {marks:?}, {} switches, {} steps, worst gap {gap:.1e} ({what})",
            r.stats.switches, r.stats.steps
        );
        assert!(marks.benign >= 1 && marks.grazes == 0, "{label}: {marks:?}");
        assert!(r.final_state.dstate.as_ref().expect("exist").iter().all(|v| v.is_finite()), "{label}");
    }
}

/// Long enough for the soft ball's micro-bounces at `wc = 1e5`.
const T_SOFT: f64 = 2.0;

/// A flow switch at the instant of an event that moved the state (tests/it/flow_switches.rs):
/// forward mode voids every column there. `fix` later sets x to `q`: x's derivatives exist again,
/// z's (which nothing resets) do not.
const KICK: &str = "model s\nparam p = 1\nparam q = 3\nstate x = p\nstate z = 0\n\
                    der(x) = if t < 1 then 1 else 2\nder(z) = p\n\
                    event kick when t >= 1 {\n    x := x + 1\n}\n";

#[test]
fn a_flow_switch_at_an_events_instant_voids_in_the_adjoint_what_it_voids_forward() {
    for method in [Method::Auto, Method::Dopri5, Method::Rodas5p] {
        let label = format!("kick {method:?}");
        let (r, marks) = both(&label, KICK, &[], &SimOptions { method, ..options(2.0) });
        assert_eq!(marks, ExistenceMarks { voids: 1, ..ExistenceMarks::default() }, "{label}");
        assert!(matches!(r.warnings[..], [SimWarning::SwitchAtEvent { .. }]), "{:?}", r.warnings);
        assert!(r.final_state.dstate.is_none(), "{label}");
        let fixed = KICK.replace("x + 1\n}\n", "x + 1\n}\nevent fix when t >= 1.5 {\n    x := q\n}\n");
        let (r, _) = both(&format!("{label} fixed"), &fixed, &[], &SimOptions { method, ..options(2.0) });
        // [x, z] per parameter [p, q]: x = q + 2 (2 - 1.5).
        let ds = r.final_state.dstate.as_ref().expect("x's exist");
        assert!(ds[0] == 0.0 && ds[1].is_nan() && ds[2] == 1.0 && ds[3].is_nan(), "{label}: {ds:?}");
    }
}
