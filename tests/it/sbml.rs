//! SBML import (`hybc::sbml`, `Model::from_sbml`): the committed cases of the SBML Test Suite
//! (`tests/data/sbml/`, chosen to cover every component and test tag hybc passes, three cases
//! each) run and compared as the suite says; refusals located at their element; names hybc
//! reserves mangled; triggers split into crossings; long expressions kept within a line;
//! hostile documents refused without a panic.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use hybc::{Model, SimOptions};
use rand_chacha::ChaCha8Rng;
use rand_core::{Rng, SeedableRng};

#[path = "../../benches/support/sbml_case.rs"]
mod sbml_case;
use sbml_case::{run_case, Outcome};

#[test]
fn the_committed_suite_cases_pass() {
    let root = Path::new("tests/data/sbml");
    let mut cases: Vec<String> = std::fs::read_dir(root)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().to_string()))
        .filter(|n| n.len() == 5 && n.chars().all(|c| c.is_ascii_digit()))
        .collect();
    cases.sort();
    assert!(cases.len() >= 45, "the committed subset holds {} cases", cases.len());
    let mut failed = Vec::new();
    for case in &cases {
        let (tags, outcome) = run_case(&root.join(case), case);
        assert!(!tags.components.is_empty(), "{case}: no component tags read");
        if outcome != Outcome::Pass {
            failed.push(format!("{case}: {outcome:?}"));
        }
    }
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}

/// A minimal Level 3 Version 2 document around `body` (the model's lists).
fn doc(body: &str) -> String {
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<sbml xmlns="http://www.sbml.org/sbml/level3/version2/core" level="3" version="2">
  <model id="m">
{body}
  </model>
</sbml>
"#
    )
}

fn math(inner: &str) -> String {
    format!(r#"<math xmlns="http://www.w3.org/1998/Math/MathML">{inner}</math>"#)
}

fn final_value(xml: &str, t_end: f64, expr_of: &str) -> f64 {
    let import = hybc::sbml::import(xml).unwrap_or_else(|e| panic!("{}", e.render("test.xml")));
    let text = format!("{}\noutput probe = {}\n", import.text, import.value_of(expr_of).expect("the id"));
    let model = Model::parse(&text).unwrap_or_else(|e| panic!("{e}\n{text}"));
    let compiled = model.compile::<&str>(&[]).unwrap();
    let opts = SimOptions { t_end, rtol: 1e-11, atol: 1e-13, ..SimOptions::default() };
    let run = compiled.simulate(&model.params(), &opts).unwrap();
    assert!(run.is_complete(), "{:?}", run.stopped_by());
    run.output("probe").unwrap()
}

#[test]
fn refusals_name_the_element_its_line_and_the_reason() {
    let xml = doc(&format!(
        r#"    <listOfParameters>
      <parameter id="x" value="1" constant="false"/>
    </listOfParameters>
    <listOfRules>
      <algebraicRule>{}</algebraicRule>
    </listOfRules>"#,
        math("<apply><minus/><ci>x</ci><cn>1</cn></apply>")
    ));
    let err = hybc::sbml::import(&xml).unwrap_err();
    assert_eq!(err.refusals.len(), 1);
    let r = &err.refusals[0];
    assert_eq!((r.line, r.column), (8, 7), "{r:?}");
    assert_eq!(r.element, "<algebraicRule>");
    assert!(r.reason.contains("algebraic rule"), "{}", r.reason);
    let rendered = err.render("m.xml");
    assert!(rendered.contains("--> m.xml:8:7"), "{rendered}");
    // Through the door the same refusal is an `Error::Import`, rendered with the file name.
    match Model::from_sbml(&xml, "m.xml") {
        Err(hybc::Error::Import(e)) => assert!(e.rendered.contains("m.xml:8:7")),
        other => panic!("{other:?}"),
    }
}

#[test]
fn every_refusal_in_a_document_is_reported() {
    let xml = doc(&format!(
        r#"    <listOfCompartments><compartment id="c" size="1" constant="true"/></listOfCompartments>
    <listOfSpecies><species id="s" compartment="c" initialAmount="1" hasOnlySubstanceUnits="true" boundaryCondition="false" constant="false"/></listOfSpecies>
    <listOfReactions>
      <reaction id="r" reversible="false" fast="true">
        <listOfReactants><speciesReference species="s" stoichiometry="1" constant="true"/></listOfReactants>
        <kineticLaw>{}</kineticLaw>
      </reaction>
    </listOfReactions>
    <listOfRules><rateRule variable="c">{}</rateRule></listOfRules>"#,
        math("<ci>s</ci>"),
        math(
            r#"<apply><csymbol definitionURL="http://www.sbml.org/sbml/symbols/delay">delay</csymbol><ci>s</ci><cn>1</cn></apply>"#
        )
    ));
    let err = hybc::sbml::import(&xml).unwrap_err();
    let reasons: Vec<&str> = err.refusals.iter().map(|r| r.reason.as_str()).collect();
    assert_eq!(reasons.len(), 2, "{reasons:?}");
    assert!(reasons[0].contains("fast reaction"));
    assert!(reasons[1].contains("delay"));
    assert!(err.refusals[0].line < err.refusals[1].line);
}

#[test]
fn documents_that_are_not_sbml_core_are_refused() {
    let bad = [
        ("<sbml level=\"3\" version=\"2\"><model", "not well-formed"),
        ("<notsbml/>", "not SBML"),
        ("<sbml level=\"1\" version=\"2\"><model/></sbml>", "Level 1"),
        (
            r#"<sbml xmlns="http://www.sbml.org/sbml/level3/version1/core" xmlns:comp="http://www.sbml.org/sbml/level3/version1/comp/version1" level="3" version="1" comp:required="true"><model/></sbml>"#,
            "package `comp`",
        ),
    ];
    for (xml, reason) in bad {
        let err = hybc::sbml::import(xml).unwrap_err();
        assert!(err.refusals[0].reason.contains(reason), "{xml}: {:?}", err.refusals);
    }
}

#[test]
fn ids_that_hybc_reserves_are_renamed_predictably() {
    // A parameter `t` is not the time: x' = t (= 2) gives x(1) = 2, where the time would give
    // 1/2. `t_` is another id, so `t` becomes `t__`.
    let xml = doc(&format!(
        r#"    <listOfParameters>
      <parameter id="t" value="2" constant="true"/>
      <parameter id="t_" value="3" constant="true"/>
      <parameter id="in" value="1" constant="true"/>
      <parameter id="exp" value="1" constant="true"/>
      <parameter id="x" value="0" constant="false"/>
    </listOfParameters>
    <listOfRules><rateRule variable="x">{}</rateRule></listOfRules>"#,
        math("<apply><times/><ci>t</ci><ci>in</ci><ci>exp</ci></apply>")
    ));
    let import = hybc::sbml::import(&xml).unwrap();
    let renamed: Vec<(&str, &str)> = import.renamed.iter().map(|(a, b)| (a.as_str(), b.as_str())).collect();
    assert_eq!(renamed, [("exp", "exp_"), ("in", "in_"), ("t", "t__")]);
    assert!(import
        .text
        .contains("# SBML ids renamed (hybc reserves them): exp -> exp_, in -> in_, t -> t__"));
    assert!((final_value(&xml, 1.0, "x") - 2.0).abs() < 1e-9);
    // Ordinary ids are kept as they are.
    assert_eq!(import.value_of("t_"), Some("t_"));
    assert_eq!(import.value_of("x"), Some("x"));
}

fn event_doc(trigger: &str, initial_value: bool) -> String {
    doc(&format!(
        r#"    <listOfParameters>
      <parameter id="x" value="0" constant="false"/>
      <parameter id="n" value="0" constant="false"/>
    </listOfParameters>
    <listOfRules><rateRule variable="x">{}</rateRule></listOfRules>
    <listOfEvents>
      <event id="e" useValuesFromTriggerTime="true">
        <trigger initialValue="{initial_value}" persistent="true">{}</trigger>
        <listOfEventAssignments><eventAssignment variable="n">{}</eventAssignment></listOfEventAssignments>
      </event>
    </listOfEvents>"#,
        math("<cn>1</cn>"),
        math(trigger),
        math("<apply><plus/><ci>n</ci><cn>1</cn></apply>")
    ))
}

#[test]
fn a_trigger_fires_when_it_turns_true_and_only_then() {
    let time = r#"<csymbol definitionURL="http://www.sbml.org/sbml/symbols/time">t</csymbol>"#;
    let gt = |a: &str, b: &str| format!("<apply><gt/>{a}{b}</apply>");
    let lt = |a: &str, b: &str| format!("<apply><lt/>{a}{b}</apply>");
    let geq = |a: &str, b: &str| format!("<apply><geq/>{a}{b}</apply>");
    let x = "<ci>x</ci>";
    let c = |v: f64| format!("<cn>{v}</cn>");
    // x = t. `x > 1 and t < 3`: true from 1 to 3, once. `x > 1 or x > 2`: turns true once
    // (at 1; at 2 it already holds). `x > 1 xor x > 2`: true on (1, 2), and again... never
    // (after 2 both hold): once. `not(x < 1)` (a falling atom): once, at 1.
    let cases = [
        (format!("<apply><and/>{}{}</apply>", gt(x, &c(1.0)), lt(time, &c(3.0))), 1.0),
        (format!("<apply><or/>{}{}</apply>", gt(x, &c(1.0)), gt(x, &c(2.0))), 1.0),
        (format!("<apply><xor/>{}{}</apply>", gt(x, &c(1.0)), gt(x, &c(2.0))), 1.0),
        (format!("<apply><not/>{}</apply>", lt(x, &c(1.0))), 1.0),
        // `x > 1 and x < 0.5` never holds.
        (format!("<apply><and/>{}{}</apply>", gt(x, &c(1.0)), lt(x, &c(0.5))), 0.0),
        // At the start with initialValue="true": `t >= 0` already holds, no firing.
        (geq(time, &c(0.0)), 0.0),
    ];
    for (trigger, fired) in &cases {
        let n = final_value(&event_doc(trigger, true), 4.0, "n");
        assert_eq!(n, *fired, "{trigger}");
    }
    // With initialValue="false" a trigger that holds at the start fires there, once; one that
    // does not hold there fires when it turns true.
    assert_eq!(final_value(&event_doc(&geq(time, &c(0.0)), false), 4.0, "n"), 1.0);
    assert_eq!(final_value(&event_doc(&gt(x, &c(-1.0)), false), 4.0, "n"), 1.0);
    assert_eq!(final_value(&event_doc(&gt(x, &c(2.0)), false), 4.0, "n"), 1.0);
    // Equalities are refused: they hold at isolated instants.
    let err =
        hybc::sbml::import(&event_doc(&format!("<apply><eq/>{x}{}</apply>", c(1.0)), true)).unwrap_err();
    assert!(err.refusals[0].reason.contains("equality"), "{:?}", err.refusals);
}

#[test]
fn species_in_a_growing_compartment_keep_their_amount() {
    // V' = 1 from V = 1, no reaction: the amount stays 2, the concentration is 2 / (1 + t).
    let xml = doc(&format!(
        r#"    <listOfCompartments><compartment id="V" size="1" constant="false"/></listOfCompartments>
    <listOfSpecies><species id="s" compartment="V" initialAmount="2" hasOnlySubstanceUnits="false" boundaryCondition="false" constant="false"/>
      <species id="u" compartment="V" initialConcentration="1" hasOnlySubstanceUnits="false" boundaryCondition="false" constant="false"/></listOfSpecies>
    <listOfRules><rateRule variable="V">{}</rateRule><rateRule variable="u">{}</rateRule></listOfRules>
    <listOfEvents><event id="e" useValuesFromTriggerTime="true"><trigger initialValue="true" persistent="true">{}</trigger>
      <listOfEventAssignments><eventAssignment variable="s">{}</eventAssignment></listOfEventAssignments></event></listOfEvents>"#,
        math("<cn>1</cn>"),
        math("<cn>1</cn>"),
        math(
            r#"<apply><geq/><csymbol definitionURL="http://www.sbml.org/sbml/symbols/time">t</csymbol><cn>2</cn></apply>"#
        ),
        math("<cn>5</cn>")
    ));
    // Before the event at t = 2: [s] = 2 / (1 + t).
    assert!((final_value(&xml, 1.0, "s") - 1.0).abs() < 1e-9);
    // The event sets the concentration 5 at V = 3: amount 15, then [s] = 15 / (1 + t).
    assert!((final_value(&xml, 4.0, "s") - 3.0).abs() < 1e-9);
    // A rate rule on a concentration in a changing compartment: d[u]/dt = 1, so [u] = 1 + t.
    assert!((final_value(&xml, 4.0, "u") - 5.0).abs() < 1e-9);
    let import = hybc::sbml::import(&xml).unwrap();
    assert_eq!(import.amount_of("s"), Some("s_amount"));
    assert_eq!(import.concentration_of("s"), Some("s"));
}

#[test]
fn long_expressions_are_cut_into_lets_within_a_line() {
    // A kinetic law summing 3000 rate constants of 1e-3: s' = -3 s, s(1) = e^-3.
    let n = 3000;
    let params: String =
        (0..n).map(|i| format!(r#"<parameter id="k{i}" value="0.001" constant="true"/>"#)).collect();
    let terms: String = (0..n).map(|i| format!("<ci>k{i}</ci>")).collect();
    let xml = doc(&format!(
        r#"    <listOfCompartments><compartment id="c" size="1" constant="true"/></listOfCompartments>
    <listOfSpecies><species id="s" compartment="c" initialAmount="1" hasOnlySubstanceUnits="true" boundaryCondition="false" constant="false"/></listOfSpecies>
    <listOfParameters>{params}</listOfParameters>
    <listOfReactions><reaction id="r" reversible="false">
      <listOfReactants><speciesReference species="s" stoichiometry="1" constant="true"/></listOfReactants>
      <kineticLaw>{}</kineticLaw></reaction></listOfReactions>"#,
        math(&format!("<apply><times/><apply><plus/>{terms}</apply><ci>s</ci></apply>"))
    ));
    let import = hybc::sbml::import(&xml).unwrap();
    let longest = import.text.lines().map(str::len).max().unwrap();
    assert!(longest <= 4096, "a line of {longest} characters");
    assert!(import.text.contains("let aux"), "the sum was not cut");
    assert!((final_value(&xml, 1.0, "s") - (-3.0f64).exp()).abs() < 1e-9);
}

#[test]
fn an_ordinary_model_is_imported_as_written() {
    // The other side of the rules above: plain names, no `aux`, no `_init`, no `t > 0`, no
    // renamed list; the suite's first case reads as its description.
    let xml = std::fs::read_to_string("tests/data/sbml/00001/00001-sbml-l3v2.xml").unwrap();
    let text = hybc::sbml::import(&xml).unwrap().text;
    for line in [
        "param k1 = 1",
        "state S1 = 0.00015 / compartment",
        "let reaction1 = compartment * k1 * S1",
        "der(S1) = -reaction1 / compartment",
        "der(S2) = reaction1 / compartment",
    ] {
        assert!(text.lines().any(|l| l.starts_with(line)), "{line} not in\n{text}");
    }
    for absent in ["aux", "_init", "renamed", "t > 0"] {
        assert!(!text.contains(absent), "{absent} in\n{text}");
    }
}

#[test]
fn hostile_documents_are_refused_without_a_panic() {
    let mut rng = ChaCha8Rng::seed_from_u64(4242);
    let seeds: Vec<String> = ["00001", "00957", "00900", "01121"]
        .iter()
        .filter_map(|c| {
            let dir = Path::new("tests/data/sbml").join(c);
            let file = std::fs::read_dir(&dir)
                .ok()?
                .filter_map(|e| e.ok())
                .find(|e| e.file_name().to_string_lossy().ends_with(".xml"))?;
            std::fs::read_to_string(file.path()).ok()
        })
        .collect();
    assert_eq!(seeds.len(), 4);
    let mut imported = 0;
    for k in 0..400 {
        let mut bytes = seeds[k % seeds.len()].clone().into_bytes();
        for _ in 0..1 + rng.next_u64() % 4 {
            let i = (rng.next_u64() % bytes.len() as u64) as usize;
            match rng.next_u64() % 3 {
                0 => bytes[i] = b"<>/=\"01e-x "[(rng.next_u64() % 11) as usize],
                1 => {
                    bytes.remove(i);
                }
                _ => bytes.insert(i, b"<>\"9"[(rng.next_u64() % 4) as usize]),
            }
        }
        let text = String::from_utf8_lossy(&bytes).into_owned();
        let outcome = catch_unwind(AssertUnwindSafe(|| Model::from_sbml(&text, "fuzz.xml").map(|_| ())));
        match outcome {
            Ok(Ok(())) => imported += 1,
            Ok(Err(hybc::Error::Import(e))) => {
                assert!(e.rendered.contains("--> fuzz.xml:"), "{}", e.rendered)
            }
            Ok(Err(e)) => panic!("case {k}: an import that does not check: {e}\n{text}"),
            Err(_) => panic!("case {k}: a panic on\n{text}"),
        }
    }
    // Some mutations leave a valid document (in a comment, a name): both sides are exercised.
    assert!(imported > 0);
}

/// Two events on `x >= 1` (x = t), with priorities `p1`, `p2`, assigning `a1 := v1`, `a2 := v2`.
fn two_events(p1: f64, a1: &str, v1: &str, p2: f64, a2: &str, v2: &str) -> String {
    let event = |id: &str, p: f64, a: &str, v: &str| {
        format!(
            r#"      <event id="{id}" useValuesFromTriggerTime="true">
        <trigger initialValue="true" persistent="true">{}</trigger>
        <priority>{}</priority>
        <listOfEventAssignments><eventAssignment variable="{a}">{}</eventAssignment></listOfEventAssignments>
      </event>"#,
            math("<apply><geq/><ci>x</ci><cn>1</cn></apply>"),
            math(&format!("<cn>{p}</cn>")),
            math(v)
        )
    };
    doc(&format!(
        r#"    <listOfParameters>
      <parameter id="x" value="0" constant="false"/>
      <parameter id="a" value="0" constant="false"/>
      <parameter id="b" value="0" constant="false"/>
      <parameter id="s" constant="false"/>
    </listOfParameters>
    <listOfRules>
      <rateRule variable="x">{}</rateRule>
      <assignmentRule variable="s">{}</assignmentRule>
    </listOfRules>
    <listOfEvents>
{}
{}
    </listOfEvents>"#,
        math("<cn>1</cn>"),
        math("<apply><plus/><ci>a</ci><cn>10</cn></apply>"),
        event("e1", p1, a1, v1),
        event("e2", p2, a2, v2)
    ))
}

#[test]
fn events_whose_order_is_random_in_sbml_are_refused() {
    let num = |v: f64| format!("<cn>{v}</cn>");
    // Equal priorities, and the second reads (through the rule `s = a + 10`) what the first
    // assigns: SBML's order is random, and so is b. Refused at the second event's priority.
    let xml = two_events(1.0, "a", &num(5.0), 1.0, "b", "<ci>s</ci>");
    let err = hybc::sbml::import(&xml).unwrap_err();
    // (e2's value from the trigger time is refused too: the test below.)
    let r = err.refusals.iter().find(|r| r.element == "<priority>").expect("a refusal at <priority>");
    assert!(r.reason.contains("`e1` and `e2` have the same priority (1)"), "{}", r.reason);
    assert!(r.reason.contains("random order"), "{}", r.reason);
    assert_eq!(&xml[r.offset..r.offset + 10], "<priority>");
    // Equal priorities assigning one symbol: the last one's value would win at random.
    let err = hybc::sbml::import(&two_events(2.0, "a", &num(5.0), 2.0, "a", &num(6.0))).unwrap_err();
    assert!(err.refusals[0].reason.contains("random order"), "{:?}", err.refusals);
    // The other side. Equal priorities, independent assignments: any order gives a = 5, b = 7.
    let xml = two_events(1.0, "a", &num(5.0), 1.0, "b", &num(7.0));
    assert_eq!(final_value(&xml, 2.0, "a"), 5.0);
    assert_eq!(final_value(&xml, 2.0, "b"), 7.0);
    // Different priorities that interact: SBML's order is fixed, the higher first, so e2 (2)
    // reads a = 0 before e1 (1) sets it: b = s = 10.
    assert_eq!(final_value(&two_events(1.0, "a", &num(5.0), 2.0, "b", "<ci>s</ci>"), 2.0, "b"), 10.0);
}

#[test]
fn simultaneous_events_judged_at_the_trigger_are_refused_where_hybc_would_not() {
    let num = |v: f64| format!("<cn>{v}</cn>");
    // e1 (priority 2) sets a before e2 executes; e2's value, from the trigger time, is s = 0 + 10
    // in SBML, 15 on the state e1 left: refused at e2's trigger.
    let xml = two_events(2.0, "a", &num(5.0), 1.0, "b", "<ci>s</ci>");
    let err = hybc::sbml::import(&xml).unwrap_err();
    assert_eq!(err.refusals.len(), 1, "{:?}", err.refusals);
    let r = &err.refusals[0];
    assert!(r.reason.starts_with("`e2` fires with `e1` and executes after it"), "{}", r.reason);
    assert_eq!(r.element, "<trigger>");
    // e1 turns e2's persistent trigger `x >= 1` false (x := 0): SBML still executes e2, hybc
    // would not. Refused.
    let err = hybc::sbml::import(&two_events(2.0, "x", &num(0.0), 1.0, "b", &num(7.0))).unwrap_err();
    assert!(err.refusals[0].reason.contains("persistent"), "{:?}", err.refusals);
    // The other side: e1 leaves e2's trigger true (x := 3): both execute, b = 7, x = 3 then
    // grows again (x = t - 1 + 3 at t = 2: 4).
    let xml = two_events(2.0, "x", &num(3.0), 1.0, "b", &num(7.0));
    assert_eq!(final_value(&xml, 2.0, "b"), 7.0);
    assert!((final_value(&xml, 2.0, "x") - 4.0).abs() < 1e-9);
}

/// Events `(id, trigger, variable, value)`, with x' = 1 from 0 and an assignment rule
/// `s = RULE`, no priorities, persistent, initialValue true.
fn events_doc(rule: &str, events: &[(&str, String, &str, String)]) -> String {
    let list: Vec<String> = events
        .iter()
        .map(|(id, trigger, var, value)| {
            format!(
                r#"      <event id="{id}" useValuesFromTriggerTime="true">
        <trigger initialValue="true" persistent="true">{}</trigger>
        <listOfEventAssignments><eventAssignment variable="{var}">{}</eventAssignment></listOfEventAssignments>
      </event>"#,
                math(trigger),
                math(value)
            )
        })
        .collect();
    doc(&format!(
        r#"    <listOfParameters>
      <parameter id="x" value="0" constant="false"/>
      <parameter id="m" value="0" constant="false"/>
      <parameter id="n" value="0" constant="false"/>
      <parameter id="s" constant="false"/>
    </listOfParameters>
    <listOfRules>
      <rateRule variable="x">{}</rateRule>
      <assignmentRule variable="s">{}</assignmentRule>
    </listOfRules>
    <listOfEvents>
{}
    </listOfEvents>"#,
        math("<cn>1</cn>"),
        math(rule),
        list.join("\n")
    ))
}

#[test]
fn a_trigger_that_can_fire_twice_at_one_instant_is_refused() {
    let at_x1 = "<apply><geq/><ci>x</ci><cn>1</cn></apply>".to_string();
    let m_gt_1 = "<apply><gt/><ci>m</ci><cn>1</cn></apply>".to_string();
    let n_plus_1 = "<apply><plus/><ci>n</ci><cn>1</cn></apply>".to_string();
    let rule = "<ci>x</ci>";
    // `on` and `off` both set m at x = 1: SBML judges `m > 1` after each (and would fire `count`
    // once per turn to true); hybc once. Refused at `count`'s trigger.
    let xml = events_doc(
        rule,
        &[
            ("on", at_x1.clone(), "m", "<cn>2</cn>".into()),
            ("off", at_x1.clone(), "m", "<cn>0</cn>".into()),
            ("count", m_gt_1.clone(), "n", n_plus_1.clone()),
        ],
    );
    let err = hybc::sbml::import(&xml).unwrap_err();
    assert_eq!(err.refusals.len(), 1, "{:?}", err.refusals);
    assert!(err.refusals[0].reason.contains("`on` and `off` both assign"), "{:?}", err.refusals);
    assert_eq!(err.refusals[0].element, "<trigger>");
    // The other side: one event sets m, `count` fires once, in SBML as in hybc.
    let xml = events_doc(rule, &[("on", at_x1, "m", "<cn>2</cn>".into()), ("count", m_gt_1, "n", n_plus_1)]);
    assert_eq!(final_value(&xml, 2.0, "n"), 1.0);
}

#[test]
fn a_trigger_reading_a_rule_that_jumps_is_refused_at_import() {
    let s_lt_0 = "<apply><lt/><ci>s</ci><cn>0</cn></apply>".to_string();
    let s_gt_1 = "<apply><gt/><ci>s</ci><cn>1</cn></apply>".to_string();
    let n_plus_1 = "<apply><plus/><ci>n</ci><cn>1</cn></apply>".to_string();
    // s = piecewise(x - 0.5, x < 2, 1): the suite's 00936. Refused at import, not at the check.
    let jump = "<piecewise><piece><apply><minus/><ci>x</ci><cn>0.5</cn></apply><apply><lt/><ci>x</ci><cn>2</cn></apply></piece><otherwise><cn>1</cn></otherwise></piecewise>";
    let err = hybc::sbml::import(&events_doc(jump, &[("e", s_lt_0, "n", n_plus_1.clone())])).unwrap_err();
    assert_eq!(err.refusals.len(), 1, "{:?}", err.refusals);
    assert!(
        err.refusals[0].reason.contains("compares `s`, whose assignment rule jumps"),
        "{:?}",
        err.refusals
    );
    // The other side: a continuous rule s = 2 x, crossing 1 at x = 0.5, once.
    let xml = events_doc("<apply><times/><cn>2</cn><ci>x</ci></apply>", &[("e", s_gt_1, "n", n_plus_1)]);
    assert_eq!(final_value(&xml, 2.0, "n"), 1.0);
}
