//! Rule 2: the module graph at file granularity and its cycles.
//!
//! Every non-test file a crate root reaches is a node. Every path in it is read: the leaves
//! of `use` trees (`use crate::{a::X, b::{c, d::Y}}` gives `crate::a::X`, `crate::b::c`,
//! `crate::b::d::Y`; `pub use` alike) and paths in code that start with `crate::`, `super::`,
//! `self::` or the name of a child module of the module in scope. A path resolves to the
//! deepest module it names (`crate::a::b::Item` -> module `a::b`, `crate::Item` -> the root,
//! `super::super::X` -> the grandparent), and that module's file is the edge's target; an inline
//! module is part of its file. Test code, `mod x;` declarations and paths into other crates
//! make no edges. Cycles are the strongly connected components (Tarjan) of more than one file.

use super::lex::Lexed;
use super::source::{item_end, SourceFile};
use super::workspace::{CrateTree, ModPath, Workspace};
use std::collections::BTreeMap;

/// A path as written (segments) and the line it is on.
pub type Path = (Vec<String>, usize);

/// One edge `from -> to` and the first path that makes it.
pub struct Edge {
    pub line: usize,
    pub path: String,
}

/// Edges between file indices, per crate tree.
pub type Graph = BTreeMap<usize, BTreeMap<usize, Edge>>;

/// The leaves of the use tree starting at `i` (after `use`), appended to `out` behind
/// `prefix`; returns the index after the tree.
pub fn use_tree(lex: &Lexed, mut i: usize, prefix: &[String], out: &mut Vec<Path>) -> usize {
    let mut path = prefix.to_vec();
    if lex.is(i, "::") {
        if path.is_empty() {
            path.push("::".to_string());
        }
        i += 1;
    }
    loop {
        if lex.is(i, "{") {
            let close = lex.skip(i) - 1;
            let mut j = i + 1;
            while j < close {
                j = use_tree(lex, j, &path, out);
                if lex.is(j, ",") {
                    j += 1;
                } else {
                    break;
                }
            }
            return close + 1;
        }
        if lex.is(i, "*") {
            path.push("*".to_string());
            out.push((path, lex.line(i)));
            return i + 1;
        }
        let Some(name) = lex.ident(i) else {
            return i;
        };
        path.push(name.to_string());
        let line = lex.line(i);
        i += 1;
        if lex.is(i, "::") {
            i += 1;
            continue;
        }
        if lex.is(i, "as") {
            i += 2;
        }
        out.push((path, line));
        return i;
    }
}

/// Resolves `segments`, written in module `current`, to the deepest module of `tree` it
/// names; `None` for a path into another crate or to a name that is not a module.
pub fn resolve(tree: &CrateTree, current: &[String], segments: &[String]) -> Option<ModPath> {
    let first = segments.first()?;
    let mut base: ModPath = match first.as_str() {
        "crate" => Vec::new(),
        "self" | "super" => current.to_vec(),
        name if tree.children.get(current).is_some_and(|c| c.contains(name)) => current.to_vec(),
        _ => return None,
    };
    let mut rest = match first.as_str() {
        "crate" | "self" => &segments[1..],
        _ => segments,
    };
    while rest.first().is_some_and(|s| s == "super") {
        base.pop()?;
        rest = &rest[1..];
    }
    for segment in rest {
        match tree.children.get(&base) {
            Some(children) if children.contains(segment) => base.push(segment.clone()),
            _ if segment == "self" => {}
            _ => break,
        }
    }
    Some(base)
}

/// Every path a non-test part of `file` uses, with the module it is written in.
pub fn paths_of(file: &SourceFile, tree: &CrateTree, module: &[String]) -> Vec<(ModPath, Path)> {
    let lex = &file.lex;
    let mut out = Vec::new();
    let mut i = 0;
    while i < lex.tokens.len() {
        if file.test[i] {
            i += 1;
            continue;
        }
        let mut scope = module.to_vec();
        scope.extend(file.scope_at(i).iter().cloned());
        if lex.ident(i) == Some("use") && !lex.is(i + 1, "<") {
            let mut leaves = Vec::new();
            use_tree(lex, i + 1, &[], &mut leaves);
            out.extend(leaves.into_iter().map(|p| (scope.clone(), p)));
            i = item_end(lex, i) + 1;
            continue;
        }
        let starts_path = i == 0 || !lex.is(i - 1, "::");
        let local = match lex.ident(i) {
            Some("crate" | "super" | "self") => true,
            Some(name) => tree.children.get(&scope).is_some_and(|c| c.contains(name)),
            None => false,
        };
        if !(starts_path && local && lex.is(i + 1, "::")) {
            i += 1;
            continue;
        }
        let line = lex.line(i);
        let mut segments = Vec::new();
        while let Some(name) = lex.ident(i) {
            segments.push(name.to_string());
            if !lex.is(i + 1, "::") {
                break;
            }
            i += 2;
        }
        out.push((scope, (segments, line)));
        i += 1;
    }
    out
}

/// The file graph of every crate tree (one `Graph` per tree, same order).
pub fn build_graphs(ws: &Workspace) -> Vec<Graph> {
    let mut graphs: Vec<Graph> = ws.trees.iter().map(|_| Graph::new()).collect();
    for (from, file) in ws.files.iter().enumerate() {
        let Some(place) = ws.place[from].as_ref().filter(|_| !ws.test_only(from)) else {
            continue;
        };
        let tree = &ws.trees[place.tree];
        let edges = graphs[place.tree].entry(from).or_default();
        for (scope, (segments, line)) in paths_of(file, tree, &place.module) {
            let Some(target) = resolve(tree, &scope, &segments) else {
                continue;
            };
            let Some(&to) = tree.module_file.get(&target) else {
                continue;
            };
            if to != from && !ws.test_only(to) {
                let path = segments.join("::").trim_end_matches("::self").to_string();
                edges.entry(to).or_insert(Edge { line, path });
            }
        }
    }
    graphs
}

/// The strongly connected components of `graph` with more than one node (Tarjan).
pub fn cycles(graph: &Graph) -> Vec<Vec<usize>> {
    let mut tarjan = Tarjan {
        graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        found: Vec::new(),
    };
    for &node in graph.keys() {
        if !tarjan.index.contains_key(&node) {
            tarjan.visit(node);
        }
    }
    tarjan.found.into_iter().filter(|c| c.len() > 1).collect()
}

struct Tarjan<'a> {
    graph: &'a Graph,
    index: BTreeMap<usize, usize>,
    low: BTreeMap<usize, usize>,
    stack: Vec<usize>,
    found: Vec<Vec<usize>>,
}

impl Tarjan<'_> {
    fn visit(&mut self, node: usize) {
        let index = self.index.len();
        self.index.insert(node, index);
        self.low.insert(node, index);
        self.stack.push(node);
        let targets: Vec<usize> = self
            .graph
            .get(&node)
            .map(|e| e.keys().copied().collect())
            .unwrap_or_default();
        for next in targets {
            if !self.index.contains_key(&next) {
                self.visit(next);
                let low = self.low[&node].min(self.low[&next]);
                self.low.insert(node, low);
            } else if self.stack.contains(&next) {
                let low = self.low[&node].min(self.index[&next]);
                self.low.insert(node, low);
            }
        }
        if self.low[&node] == index {
            let mut component = Vec::new();
            while let Some(top) = self.stack.pop() {
                component.push(top);
                if top == node {
                    break;
                }
            }
            component.sort_unstable();
            self.found.push(component);
        }
    }
}
