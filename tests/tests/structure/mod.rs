//! Issue 10's structure rules, checked on the source text of the workspace (no compiler
//! plugin, no `syn`: a small lexer in [`lex`] is enough to see items, paths and matches):
//!
//! 1. no file in `render/src` or `server/src` over 800 lines, no function there over 150
//!    lines (test code exempt: `#[cfg(test)]` items and test-only files);
//! 2. no module import cycle at file granularity in any crate ([`graph`] says how paths
//!    become edges);
//! 3. no `_` arm in a `match` on a kind or backend enum in `render/src` or `server/src`.
//!
//! Each test fails with every violation as `file:line: what`, and prints what it checked.
//! `ISORAY_STRUCTURE_ROOT=DIR` checks another checkout (default: this repository).
//! [`checker_tests`] shows on inline sources that the checker sees what it should.

mod checker_tests;
mod graph;
mod lex;
mod rules;
mod source;
mod workspace;

use rules::Outcome;
use std::path::PathBuf;
use std::sync::OnceLock;
use workspace::Workspace;

/// The crates whose module graphs are checked.
const CRATES: [&str; 4] = ["protocol", "render", "server", "bench"];
/// Where the length and wildcard rules apply.
const ENGINE_AND_SERVER: [&str; 2] = ["render/src/", "server/src/"];
/// Where kind enums are declared.
const KIND_CRATES: [&str; 3] = ["render/src/", "server/src/", "protocol/src/"];

fn workspace() -> &'static Workspace {
    static WORKSPACE: OnceLock<Workspace> = OnceLock::new();
    WORKSPACE.get_or_init(|| {
        let root = std::env::var_os("ISORAY_STRUCTURE_ROOT")
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/..")));
        Workspace::load(&root, &CRATES)
            .unwrap_or_else(|e| panic!("reading {}: {e}", root.display()))
    })
}

/// Prints what was checked; panics with every violation.
fn assert_clean(rule: &str, outcome: Outcome) {
    println!("{rule}: {}", outcome.checked);
    assert!(
        outcome.violations.is_empty(),
        "{rule}: {} violation(s):\n{}",
        outcome.violations.len(),
        outcome.violations.join("\n")
    );
}

#[test]
fn source_files_stay_short() {
    assert_clean(
        "file length",
        rules::file_lengths(workspace(), &ENGINE_AND_SERVER),
    );
}

#[test]
fn functions_stay_short() {
    assert_clean(
        "function length",
        rules::function_lengths(workspace(), &ENGINE_AND_SERVER),
    );
}

#[test]
fn modules_import_no_cycles() {
    assert_clean("import cycles", import_cycles(workspace()));
}

#[test]
fn kind_matches_have_no_wildcard() {
    let ws = workspace();
    let kinds = rules::kind_enums(ws, &KIND_CRATES);
    assert_clean(
        "kind wildcards",
        rules::wildcard_matches(ws, &ENGINE_AND_SERVER, &kinds),
    );
}

/// Every cycle of every crate tree, each with the path that makes each of its edges.
fn import_cycles(ws: &Workspace) -> Outcome {
    let graphs = graph::build_graphs(ws);
    let mut violations = Vec::new();
    let (mut nodes, mut edges) = (0, 0);
    for (tree, graph) in ws.trees.iter().zip(&graphs) {
        nodes += graph.len();
        edges += graph.values().map(|e| e.len()).sum::<usize>();
        for component in graph::cycles(graph) {
            let names: Vec<&str> = component
                .iter()
                .map(|&f| ws.files[f].path.as_str())
                .collect();
            let root = &ws.files[tree.root].path;
            let mut text = format!(
                "cycle in {root} ({} files): {}",
                names.len(),
                names.join(", ")
            );
            for &from in &component {
                for (to, edge) in &graph[&from] {
                    if component.contains(to) {
                        let (a, b) = (&ws.files[from].path, &ws.files[*to].path);
                        text += &format!("\n    {a}:{} -> {b} (`{}`)", edge.line, edge.path);
                    }
                }
            }
            violations.push(text);
        }
    }
    let unreached: Vec<&str> = (0..ws.files.len())
        .filter(|&i| ws.place[i].is_none())
        .map(|i| ws.files[i].path.as_str())
        .collect();
    let checked = format!(
        "{} crate roots, {nodes} files, {edges} file edges; not reached from a root: {unreached:?}; \
         declared but missing: {:?}",
        ws.trees.len(),
        ws.missing
    );
    Outcome {
        checked,
        violations,
    }
}
