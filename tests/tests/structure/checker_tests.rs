//! The checker's own tests, on inline sources: the lexer does not see code in strings,
//! comments or lifetimes, paths resolve as rule 2 defines, and every rule fails on a source
//! that breaks it (so a clean run cannot be vacuous) while test code stays exempt.

use super::graph::{build_graphs, cycles, use_tree};
use super::lex::{lex, Kind};
use super::rules::{file_lengths, function_lengths, kind_enums, wildcard_matches};
use super::workspace::Workspace;

fn workspace(files: &[(&str, &str)]) -> Workspace {
    let sources: Vec<(String, String)> = files
        .iter()
        .map(|(p, s)| (p.to_string(), s.to_string()))
        .collect();
    Workspace::build(&sources).expect("inline sources lex")
}

/// Every file edge as `from -> to` paths.
fn edges(ws: &Workspace) -> Vec<String> {
    let mut out = Vec::new();
    for graph in build_graphs(ws) {
        for (from, targets) in &graph {
            for to in targets.keys() {
                out.push(format!(
                    "{} -> {}",
                    ws.files[*from].path, ws.files[*to].path
                ));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn lexer_keeps_strings_comments_and_lifetimes_out_of_code() {
    let src = "fn f<'a>(x: &'a str) -> char {\n    let _ = r#\"{ \"}\" crate::x }\"#;\n    /* { /* nested } */ crate::y */\n    let _ = (b\"{\", br\"}\", \"\\\"{\", 0x1e-5, 1e-5);\n    '{'\n}\n";
    let lexed = lex(src).expect("balanced");
    let texts: Vec<&str> = lexed.tokens.iter().map(|t| t.text.as_str()).collect();
    assert!(!texts.contains(&"crate"), "{texts:?}");
    assert_eq!(
        texts.iter().filter(|t| **t == "{" || **t == "}").count(),
        2,
        "{texts:?}"
    );
    let lifetimes = lexed
        .tokens
        .iter()
        .filter(|t| t.kind == Kind::Lifetime)
        .count();
    assert_eq!(lifetimes, 2);
    let last = lexed.tokens.iter().rev().nth(1).expect("tokens");
    assert_eq!(
        (last.text.as_str(), last.kind, last.line),
        ("'{'", Kind::Literal, 5)
    );
    let close = lexed.tokens.len() - 1;
    assert_eq!(lexed.partner[close].map(|j| lexed.tokens[j].line), Some(1));
    assert_eq!(
        (lexed.tokens[close].depth, last.depth),
        (0, 1),
        "brace depth"
    );
    assert!(
        lex("fn f() { \"}\" ").is_err(),
        "an unclosed brace is an error"
    );
}

#[test]
fn nested_use_trees_give_every_leaf() {
    let lexed = lex("use crate::{a::X, b::{self, c, d::Y as Z}, *};").expect("balanced");
    let mut leaves = Vec::new();
    use_tree(&lexed, 1, &[], &mut leaves);
    let leaves: Vec<String> = leaves.into_iter().map(|(p, _)| p.join("::")).collect();
    assert_eq!(
        leaves,
        [
            "crate::a::X",
            "crate::b::self",
            "crate::b::c",
            "crate::b::d::Y",
            "crate::*"
        ]
    );
}

#[test]
fn paths_resolve_to_the_deepest_module_file() {
    let ws = workspace(&[
        ("x/src/lib.rs", "pub mod a;\npub mod b;\npub use a::Item;\n"),
        ("x/src/a/mod.rs", "pub mod c;\npub struct Item;\n"),
        ("x/src/a/c.rs", "mod d;\nuse super::super::b::Thing;\npub fn f() { d::g(); let _ = crate::a::Item; }\n"),
        ("x/src/a/c/d.rs", "pub fn g() { let s = \"crate::b\"; }\n#[cfg(test)]\nmod tests { use crate::b::Thing; }\n"),
        ("x/src/b.rs", "pub struct Thing;\nmod inner { pub fn h() { self::deeper::k(); } mod deeper { pub fn k() {} } }\n"),
        ("x/src/main.rs", "use x::a::Item;\nfn main() {}\n"),
    ]);
    assert_eq!(
        edges(&ws),
        [
            "x/src/a/c.rs -> x/src/a/c/d.rs",
            "x/src/a/c.rs -> x/src/a/mod.rs",
            "x/src/a/c.rs -> x/src/b.rs",
            "x/src/lib.rs -> x/src/a/mod.rs"
        ]
    );
    assert_eq!(ws.trees.len(), 2, "lib.rs and main.rs are separate roots");
}

#[test]
fn a_two_file_cycle_is_found_and_test_code_makes_no_edge() {
    let cyclic = workspace(&[
        ("x/src/lib.rs", "mod a;\nmod b;\n"),
        ("x/src/a.rs", "use crate::b::B;\npub struct A;\n"),
        (
            "x/src/b.rs",
            "pub struct B;\npub fn f() -> crate::a::A { todo!() }\n",
        ),
    ]);
    let found: Vec<Vec<usize>> = build_graphs(&cyclic).iter().flat_map(cycles).collect();
    assert_eq!(found.len(), 1);
    let names: Vec<&str> = found[0]
        .iter()
        .map(|&f| cyclic.files[f].path.as_str())
        .collect();
    assert_eq!(names, ["x/src/a.rs", "x/src/b.rs"]);
    let through_lib = workspace(&[
        ("x/src/lib.rs", "mod a;\npub use a::f;\npub struct Root;\n"),
        ("x/src/a.rs", "pub fn f() -> crate::Root { crate::Root }\n"),
    ]);
    assert_eq!(
        build_graphs(&through_lib).iter().flat_map(cycles).count(),
        1,
        "lib.rs is a node too"
    );
    let test_only = workspace(&[
        ("x/src/lib.rs", "mod a;\nmod b;\n#[cfg(test)]\nmod t;\n"),
        ("x/src/a.rs", "use crate::b::B;\npub struct A;\n"),
        (
            "x/src/b.rs",
            "pub struct B;\n#[cfg(test)]\nmod tests { use crate::a::A; }\n",
        ),
        ("x/src/t.rs", "use crate::a::A;\n"),
    ]);
    assert_eq!(edges(&test_only), ["x/src/a.rs -> x/src/b.rs"]);
}

#[test]
fn a_wildcard_on_a_kind_fails_and_others_pass() {
    let src = "pub enum Geometry { Metaballs, Tets }\npub enum FooKind { A, B }\n\
        fn f(g: &Geometry) -> u8 { match g { Geometry::Metaballs => 1, _ => 2 } }\n\
        fn h(n: u8) -> FooKind { match n { 0 => FooKind::A, _ if n > 3 => FooKind::B, _ => FooKind::A } }\n\
        fn other(o: Option<u8>) -> u8 { match o { Some(x) => x, _ => 0 } }\n\
        impl Geometry { fn m(&self) -> u8 { match self { Self::Tets => { 1 } _ => 0 } } }\n\
        fn all(g: &Geometry) -> u8 { match g { Geometry::Metaballs | Geometry::Tets => 1 } }\n\
        #[cfg(test)]\nmod tests { fn t(g: &super::Geometry) { match g { super::Geometry::Tets => {}, _ => {} } } }\n";
    let ws = workspace(&[("render/src/lib.rs", src)]);
    let kinds = kind_enums(&ws, &["render/src/"]);
    assert!(kinds.contains(&"FooKind".to_string()), "{kinds:?}");
    let lines: Vec<String> = wildcard_matches(&ws, &["render/src/"], &kinds)
        .violations
        .iter()
        .map(|v| v.split(':').take(2).collect::<Vec<_>>().join(":"))
        .collect();
    assert_eq!(
        lines,
        [
            "render/src/lib.rs:3",
            "render/src/lib.rs:4",
            "render/src/lib.rs:4",
            "render/src/lib.rs:6"
        ]
    );
}

#[test]
fn long_files_and_functions_fail_unless_they_are_tests() {
    let body = |n: usize| "    let _ = 0;\n".repeat(n);
    let long_fn = format!(
        "fn long() {{\n{}}}\nfn ok() {{\n{}}}\n",
        body(149),
        body(148)
    );
    let long_file = "const A: u8 = 0;\n".repeat(801);
    let test_file = format!("#[test]\nfn t() {{\n{}}}\n", body(900));
    let ws = workspace(&[
        (
            "server/src/lib.rs",
            "mod long;\nmod many;\n#[cfg(test)]\nmod tested;\nmod inline_tests;\n",
        ),
        ("server/src/long.rs", &long_fn),
        ("server/src/many.rs", &long_file),
        ("server/src/tested.rs", &body(900)),
        ("server/src/inline_tests.rs", &test_file),
    ]);
    let files = file_lengths(&ws, &["server/src/"]);
    assert_eq!(
        files.violations,
        ["server/src/many.rs: 801 lines (limit 800)"]
    );
    let functions = function_lengths(&ws, &["server/src/"]);
    assert_eq!(
        functions.violations,
        ["server/src/long.rs:1: fn long spans 151 lines (limit 150)"]
    );
}
