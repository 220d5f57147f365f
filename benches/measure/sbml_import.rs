//! Import and compile time of SBML models (issue #42, "Scale"): for each file given, the time to
//! import it (`hybc::sbml::import`: XML -> .hyb text), to parse and check the text, and to compile
//! it without gradients, best of 3, with the process's peak memory; then, unless
//! `SBML_NO_CHAIN` is set, generated reaction chains of 250 to 2000 species (each `S_k -> S_k+1`
//! with mass action, plus a coupling reaction every 10 species) to show how the costs grow.
//!
//! Run: `cargo run --release --example sbml_import -- model_Chen_MSB2009.xml` (the PEtab
//! benchmark collection's file). Figures in docs/performance.md.

use std::time::Instant;

fn best<T>(n: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..n {
        let start = Instant::now();
        let v = f();
        best = best.min(start.elapsed().as_secs_f64() * 1e3);
        out = Some(v);
    }
    (best, out.expect("at least one run"))
}

#[path = "../support/memory.rs"]
mod memory;
use memory::peak_mib;

fn measure(name: &str, xml: &str) {
    let (import_ms, import) = best(3, || hybc::sbml::import(xml).expect("imports"));
    let (check_ms, model) = best(3, || hybc::Model::parse(&import.text).expect("checks"));
    let (compile_ms, _c) = best(3, || model.compile::<&str>(&[]).expect("compiles"));
    let states = model.state_names().count();
    println!(
        "{name}: {} KB SBML, {states} states, {} KB .hyb; import {import_ms:.1} ms, parse+check {check_ms:.1} ms, compile {compile_ms:.1} ms; total {:.1} ms; peak {:.0} MiB",
        xml.len() / 1024,
        import.text.len() / 1024,
        import_ms + check_ms + compile_ms,
        peak_mib()
    );
}

/// A chain of `n` species in one compartment: `S_k -> S_k+1` at rate `k * S_k`, and every tenth
/// species also feeds `S_0` back (a denser Jacobian than a pure chain).
fn chain(n: usize) -> String {
    let mut s = String::from(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<sbml xmlns="http://www.sbml.org/sbml/level3/version2/core" level="3" version="2"><model id="chain">
<listOfCompartments><compartment id="c" size="1" constant="true"/></listOfCompartments><listOfSpecies>"#,
    );
    for i in 0..=n {
        s.push_str(&format!(r#"<species id="S{i}" compartment="c" initialConcentration="{}" hasOnlySubstanceUnits="false" boundaryCondition="false" constant="false"/>"#, if i == 0 { 1 } else { 0 }));
    }
    s.push_str(r#"</listOfSpecies><listOfParameters><parameter id="k" value="1" constant="true"/></listOfParameters><listOfReactions>"#);
    let reaction = |id: String, from: usize, to: usize| {
        format!(
            r#"<reaction id="{id}" reversible="false"><listOfReactants><speciesReference species="S{from}" stoichiometry="1" constant="true"/></listOfReactants><listOfProducts><speciesReference species="S{to}" stoichiometry="1" constant="true"/></listOfProducts><kineticLaw><math xmlns="http://www.w3.org/1998/Math/MathML"><apply><times/><ci>c</ci><ci>k</ci><ci>S{from}</ci></apply></math></kineticLaw></reaction>"#
        )
    };
    for i in 0..n {
        s.push_str(&reaction(format!("r{i}"), i, i + 1));
        if i % 10 == 9 {
            s.push_str(&reaction(format!("back{i}"), i, 0));
        }
    }
    s.push_str("</listOfReactions></model></sbml>\n");
    s
}

fn main() {
    for path in std::env::args().skip(1) {
        let xml = std::fs::read_to_string(&path).expect("a readable SBML file");
        measure(&path, &xml);
    }
    if std::env::var("SBML_NO_CHAIN").is_err() {
        for n in [250, 500, 1000, 2000] {
            measure(&format!("chain of {n}"), &chain(n));
        }
    }
}
