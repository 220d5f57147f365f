//! `--of` (`SimOptions::of`, Python's `of=`): only the quantities named get gradients, in either
//! mode; the others keep their values, and the report leaves their gradients out (not "missing").
//! The gradients kept are those of a run without `--of`, to the bit under forward sensitivities
//! (the same run) and to round-off under the adjoint (fewer rows in the same backward pass).

use hybc::sim::{SimOptions, SimResult};
use hybc::{Compiled, Model, Sens, SimOverrides, Spelling};

use crate::support::cli::hybc;

fn ball() -> Compiled {
    let model = Model::from_file("models/ball.hyb").expect("ball");
    model.compile(&["g", "e", "h0"]).expect("compiles")
}

/// A run of `compiled` with `of` resolved by the door, under `sens`.
fn run_of(compiled: &Compiled, of: Option<&[&str]>, sens: Sens) -> Result<SimResult, String> {
    let overrides = SimOverrides {
        of: of.map(|names| names.iter().map(|s| s.to_string()).collect()),
        sens: Some(sens),
        sens_error_control: Some(false),
        ..SimOverrides::default()
    };
    let mut opts: SimOptions =
        overrides.apply(&compiled.model().sim_options(), Spelling::Keyword).map_err(|e| e.message)?;
    overrides.gradients_of(compiled.info(), &mut opts, Spelling::Keyword).map_err(|e| e.message)?;
    let run = compiled.simulate(&compiled.params(), &opts).map_err(|e| e.to_string())?;
    Ok(run.into_result())
}

fn row(d: &Option<Vec<f64>>, rows: usize, i: usize, m: usize) -> Vec<f64> {
    let d = d.as_ref().expect("gradients");
    (0..m).map(|j| d[j * rows + i]).collect()
}

#[test]
fn only_the_quantities_named_get_gradients_in_either_mode() {
    let c = ball();
    let (n, k, m) = (2, 1, 3);
    for sens in [Sens::Forward, Sens::Adjoint] {
        let all = run_of(&c, None, sens).unwrap();
        let some = run_of(&c, Some(&["v", "touchdown#2", "energy"]), sens).unwrap();
        assert_eq!(some.stats.sens, Some(sens), "{sens:?} ran");
        // Values are untouched, and so are the event times.
        assert_eq!(all.final_state.state, some.final_state.state);
        let times = |r: &SimResult| r.events.iter().map(|e| e.time).collect::<Vec<_>>();
        assert_eq!(times(&all), times(&some));
        assert!(all.events.len() >= 3, "the ball bounces at least 3 times by t_end");
        // The second firing's time gradient only.
        for (e, (a, s)) in all.events.iter().zip(&some.events).enumerate() {
            if e == 1 {
                let (a, s) = (a.dtime.as_ref().unwrap(), s.dtime.as_ref().expect("asked for"));
                for (x, y) in a.iter().zip(s) {
                    assert!((x - y).abs() <= 1e-13 * x.abs().max(1.0), "{sens:?} dt2: {x} vs {y}");
                }
            } else {
                assert!(s.dtime.is_none(), "{sens:?}: event {e} was not asked for");
            }
        }
        // `v` and `energy` have their gradients, `y` none (NaN, and the report leaves it out).
        let (fa, fs) = (&all.final_state, &some.final_state);
        for (x, y) in row(&fa.dstate, n, 1, m).iter().zip(row(&fs.dstate, n, 1, m)) {
            assert!((x - y).abs() <= 1e-13 * x.abs().max(1.0), "{sens:?} dv: {x} vs {y}");
        }
        for (x, y) in row(&fa.doutputs, k, 0, m).iter().zip(row(&fs.doutputs, k, 0, m)) {
            assert!((x - y).abs() <= 1e-13 * x.abs().max(1.0), "{sens:?} denergy: {x} vs {y}");
        }
        assert!(row(&fs.dstate, n, 0, m).iter().all(|d| d.is_nan()), "{sens:?}: y was not asked for");
        assert!(!some.reports_gradient(false, 0) && some.reports_gradient(false, 1));
        assert!(all.reports_gradient(false, 0), "without --of every gradient is reported");
    }
}

#[test]
fn the_gradients_kept_by_forward_mode_are_those_of_the_full_run_to_the_bit() {
    let c = ball();
    let all = run_of(&c, None, Sens::Forward).unwrap();
    let some = run_of(&c, Some(&["y", "touchdown#last"]), Sens::Forward).unwrap();
    assert_eq!(row(&all.final_state.dstate, 2, 0, 3), row(&some.final_state.dstate, 2, 0, 3));
    assert_eq!(all.events.last().unwrap().dtime, some.events.last().unwrap().dtime);
}

/// `auto` weighs the rows asked for: a double integrator driven by 10 knots reports two states
/// and an output, 3 rows against 10 parameters (above `AUTO_ROWS_PER_PARAM`, 0.2), so `auto`
/// takes forward sensitivities; asked for one quantity (1 row: below), it takes the adjoint. The
/// ball's one row against its 3 parameters stays forward (a forward column of a 2-state model
/// costs a twentieth of a plain run, the adjoint two plain runs).
#[test]
fn auto_counts_the_rows_asked_for() {
    let src = "model drive\nparam u[10] = 0.5\nstate p = 0\nstate v = 0\n\
               der(p) = v\nder(v) = pwl(t, 0, 1, u)\noutput cost = p^2 + v^2\n";
    let drive = Model::parse(src).unwrap().compile(&["u"]).unwrap();
    assert_eq!(run_of(&drive, None, Sens::Auto).unwrap().stats.sens, Some(Sens::Forward));
    assert_eq!(run_of(&drive, Some(&["cost"]), Sens::Auto).unwrap().stats.sens, Some(Sens::Adjoint));
    assert_eq!(run_of(&ball(), Some(&["energy"]), Sens::Auto).unwrap().stats.sens, Some(Sens::Forward));
}

#[test]
fn a_sample_named_at_a_time_is_taken_and_only_its_gradient_kept() {
    let c = ball();
    let r = run_of(&c, Some(&["y@1.5"]), Sens::Forward).unwrap();
    assert_eq!(r.samples.len(), 1, "--of y@1.5 samples t = 1.5");
    let s = r.samples.get(0).unwrap();
    assert_eq!(s.time, 1.5);
    let ds = s.dstate.unwrap();
    assert!((0..3).all(|j| ds[j * 2].is_finite()), "d y(1.5) is kept");
    assert!((0..3).all(|j| ds[j * 2 + 1].is_nan()), "d v(1.5) was not asked for");
    // Against a plain `--at 1.5` run.
    let opts = SimOptions { at: vec![1.5], sens_error_control: false, ..c.model().sim_options() };
    let plain = c.simulate(&c.params(), &opts).unwrap().into_result();
    let want = plain.samples.get(0).unwrap().dstate.unwrap().to_vec();
    assert_eq!(
        (0..3).map(|j| want[j * 2]).collect::<Vec<_>>(),
        (0..3).map(|j| ds[j * 2]).collect::<Vec<_>>()
    );
}

#[test]
fn names_that_are_not_quantities_are_refused_with_the_flags_words() {
    let c = ball();
    let err = run_of(&c, Some(&["w"]), Sens::Forward).unwrap_err();
    assert!(err.starts_with("of: ") && err.contains("no output or state `w`"), "{err}");
    let err = run_of(&c, Some(&["bounce#1"]), Sens::Forward).unwrap_err();
    assert!(err.contains("no event `bounce`"), "{err}");
    let err = run_of(&c, Some(&["y@7"]), Sens::Forward).unwrap_err();
    assert!(err.starts_with("of: ") && err.contains("after t_end"), "{err}");
}

#[test]
fn the_cli_reports_only_the_gradients_asked_for() {
    let out =
        hybc(&["run", "models/ball.hyb", "--grad", "e,h0", "--of", "v,touchdown#1", "--format", "json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let fin = &json["final"];
    let dstate = fin["dstate"].as_object().unwrap();
    assert_eq!(dstate.keys().collect::<Vec<_>>(), ["v"], "only v's row");
    assert!(fin["doutputs"].as_object().unwrap().is_empty(), "no output asked for");
    let events = json["events"].as_array().unwrap();
    assert!(events[0]["dtime"]["e"].is_number(), "the first touchdown's dt/de");
    assert!(events[1].get("dtime").is_none(), "the second was not asked for");
    // The table leaves them blank, not `-` (which says a derivative does not exist).
    let table = hybc(&["run", "models/ball.hyb", "--grad", "e", "--of", "v"]);
    let text = String::from_utf8_lossy(&table.stdout);
    let y_line = text.lines().find(|l| l.trim_start().starts_with("y ")).expect("a y row");
    assert_eq!(y_line.split_whitespace().count(), 2, "y and its value only: {y_line}");
    let bad = hybc(&["run", "models/ball.hyb", "--grad", "e", "--of", "nothing"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--of: model has no output or state `nothing`"));
}
