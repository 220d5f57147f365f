//! The import graph of `src/` held to ARCHITECTURE.md's floors: every module (a top-level file or
//! folder of `src/`) imports only modules below it in [`FLOORS`] (read by the `crate::` paths
//! each of its files names, the crate root's re-exports resolved to the module that defines
//! them), so the graph has no circle and no arrow running back up; and `sim/`'s wings import one
//! way (`method/` never `event/`, `linalg/` nothing else of `sim`).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The modules from the bottom floor up (ARCHITECTURE.md, "Bird's-eye view", each row read right
/// to left): a module may import only those before it.
#[rustfmt::skip]
const FLOORS: [&str; 24] = [
    "interval", "sim", "expr", "number", "limits", "stack", // leaves
    "status", "report", // results
    "syntax", "diag", "expand", "sema", "lower", "codegen", "sbml", // stages
    "sweep", "fit", "gradcheck", "periodic", "optimize", "sobol", "plot", // analyses
    "api",  // the door
    "cli",  // the command line
];

fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).expect("a source folder") {
        let path = entry.expect("an entry").path();
        if path.is_dir() {
            out.extend(rust_files(&path));
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
    out.sort();
    out
}

/// The text without comments (doc comments name modules in prose).
fn code(text: &str) -> String {
    text.lines().map(|l| l.find("//").map_or(l, |i| &l[..i])).collect::<Vec<_>>().join("\n")
}

/// Every first segment named after `crate::`, with `crate::{a, b::c}` groups opened.
fn crate_paths(code: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = code;
    while let Some(i) = rest.find("crate::") {
        rest = &rest[i + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            // One level of nesting is enough for `use` groups.
            let mut depth = 1;
            let end = group
                .char_indices()
                .find(|&(_, c)| {
                    depth += match c {
                        '{' => 1,
                        '}' => -1,
                        _ => 0,
                    };
                    depth == 0
                })
                .map_or(group.len(), |(k, _)| k);
            let mut level = 0;
            let mut item = String::new();
            for c in group[..end].chars().chain([',']) {
                match c {
                    '{' => level += 1,
                    '}' => level -= 1,
                    ',' if level == 0 => {
                        let name: String =
                            item.trim().chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
                        if !name.is_empty() {
                            out.push(name);
                        }
                        item.clear();
                        continue;
                    }
                    _ => {}
                }
                if level == 0 {
                    item.push(c);
                }
            }
        } else {
            let name: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
            out.push(name);
        }
    }
    out
}

/// Names the crate root re-exports, mapped to the module they come from (`pub use api::{..}`).
fn root_exports(lib: &str) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for (k, _) in lib.match_indices("pub use ") {
        let rest = &lib[k + "pub use ".len()..];
        let module: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
        let stmt = &rest[..rest.find(';').expect("a use statement ends")];
        let names = stmt.split_once('{').map_or(stmt.rsplit("::").next().unwrap_or(""), |(_, g)| g);
        for name in names.trim_end_matches('}').split(',') {
            let name = name.trim();
            if !name.is_empty() {
                out.insert(name.to_string(), module.clone());
            }
        }
    }
    out
}

/// `module -> {modules it imports}`, with one file that names each import.
fn graph() -> BTreeMap<String, BTreeMap<String, PathBuf>> {
    let src = Path::new("src");
    let exports = root_exports(&std::fs::read_to_string(src.join("lib.rs")).expect("lib.rs"));
    let mut graph: BTreeMap<String, BTreeMap<String, PathBuf>> = BTreeMap::new();
    for file in rust_files(src) {
        let rel = file.strip_prefix(src).expect("under src");
        let first = rel.components().next().expect("a path").as_os_str().to_string_lossy().to_string();
        let module = first.trim_end_matches(".rs").to_string();
        if module == "lib" || module == "main" {
            continue;
        }
        let text = std::fs::read_to_string(&file).expect("a source file");
        let imports = graph.entry(module.clone()).or_default();
        for name in crate_paths(&code(&text)) {
            let target = exports.get(&name).cloned().unwrap_or(name);
            if target != module {
                imports.entry(target).or_insert_with(|| file.clone());
            }
        }
    }
    graph
}

#[test]
fn every_module_imports_only_the_floors_below_it() {
    let rank = |m: &str| FLOORS.iter().position(|f| *f == m);
    let graph = graph();
    let mut wrong = Vec::new();
    for (module, imports) in &graph {
        let Some(own) = rank(module) else {
            wrong.push(format!("`{module}` has no floor: place it in FLOORS and ARCHITECTURE.md"));
            continue;
        };
        for (target, file) in imports {
            match rank(target) {
                Some(r) if r < own => {}
                Some(_) => wrong.push(format!("{module} -> {target} runs up ({})", file.display())),
                None => wrong.push(format!("{module} -> `{target}`, no module ({})", file.display())),
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    // The check sees the graph: the door imports the stages and the analyses, the CLI the door.
    assert!(graph["api"].contains_key("codegen") && graph["api"].contains_key("sobol"), "{:?}", graph["api"]);
    assert!(graph["cli"].contains_key("api"));
    let modules: BTreeSet<&str> = graph.keys().map(String::as_str).collect();
    assert_eq!(modules, FLOORS.into_iter().collect(), "a module in FLOORS is not in src/, or the reverse");
}

#[test]
fn the_wings_of_sim_import_one_way() {
    let mut wrong = Vec::new();
    for (wing, refused) in [("method", &["event"][..]), ("linalg", &["event", "method", "system", "run"][..])]
    {
        for file in rust_files(&Path::new("src/sim").join(wing)) {
            let text = code(&std::fs::read_to_string(&file).expect("a source file"));
            for other in refused {
                for path in [format!("crate::sim::{other}"), format!("super::super::{other}")] {
                    if text.contains(&path) {
                        wrong.push(format!("{} names {path}", file.display()));
                    }
                }
            }
            if wing == "linalg" && text.contains("crate::sim::") && !text.contains("crate::sim::linalg") {
                wrong.push(format!("{} imports sim outside linalg", file.display()));
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn the_path_reader_opens_use_groups_and_skips_comments() {
    let text = "use crate::{fit::Bounds, sim::{self, HybridSystem}, Model};\n// crate::cli in prose\nlet x = crate::limits::count;";
    assert_eq!(crate_paths(&code(text)), ["fit", "sim", "Model", "limits"]);
    let exports = root_exports("pub use api::{Compiled, Model};\npub use sim::{Method, SimOptions};");
    assert_eq!(exports["Model"], "api");
    assert_eq!(exports["SimOptions"], "sim");
}
