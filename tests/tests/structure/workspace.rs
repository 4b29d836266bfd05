//! The scanned sources and each crate's module tree, found by following `mod name;`
//! declarations from every crate root (`<crate>/src/lib.rs` and `<crate>/src/main.rs` are
//! separate roots, as in Cargo: a binary reaches its library only by the crate's name).
//!
//! A module's file is `dir/name.rs` or `dir/name/mod.rs`, where `dir` is the declaring file's
//! folder for `lib.rs`, `main.rs` and `mod.rs`, and `folder/stem` for any other file, plus the
//! names of the inline modules the declaration stands in. A file is test-only when all its
//! items are test code or it is declared under `#[cfg(test)]` (or from a test-only file).

use super::source::SourceFile;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// A module path from its crate root (`[]` is the root).
pub type ModPath = Vec<String>;

/// One crate root's module tree.
pub struct CrateTree {
    /// Index of the root file in `Workspace::files`.
    pub root: usize,
    /// Every module (file or inline) and the file it lives in.
    pub module_file: BTreeMap<ModPath, usize>,
    /// Every module's child module names.
    pub children: BTreeMap<ModPath, BTreeSet<String>>,
}

/// Where a file sits: which tree, at which module path.
#[derive(Clone)]
pub struct Place {
    pub tree: usize,
    pub module: ModPath,
}

pub struct Workspace {
    pub files: Vec<SourceFile>,
    pub trees: Vec<CrateTree>,
    /// Per file: its place in a tree, if a root reaches it.
    pub place: Vec<Option<Place>>,
    /// Per file: declared under `#[cfg(test)]`, directly or through a test-only parent.
    pub declared_test: Vec<bool>,
    /// Declarations whose file does not exist: `file:line: mod name`.
    pub missing: Vec<String>,
}

impl Workspace {
    /// Reads every `.rs` file under `<root>/<crate>/src` for each crate folder.
    pub fn load(root: &Path, crates: &[&str]) -> Result<Workspace, String> {
        let mut sources = Vec::new();
        for krate in crates {
            collect_rs(root, &root.join(krate).join("src"), &mut sources)?;
        }
        sources.sort();
        Workspace::build(&sources)
    }

    /// Builds from `(relative path, source)` pairs (the unit tests pass inline sources).
    pub fn build(sources: &[(String, String)]) -> Result<Workspace, String> {
        let files = sources
            .iter()
            .map(|(path, src)| SourceFile::parse(path, src))
            .collect::<Result<Vec<_>, _>>()?;
        let n = files.len();
        let mut ws = Workspace {
            files,
            trees: Vec::new(),
            place: vec![None; n],
            declared_test: vec![false; n],
            missing: Vec::new(),
        };
        let roots: Vec<usize> = (0..n)
            .filter(|&i| {
                let p = &ws.files[i].path;
                let parts: Vec<&str> = p.split('/').collect();
                parts.len() == 3 && parts[1] == "src" && matches!(parts[2], "lib.rs" | "main.rs")
            })
            .collect();
        for root in roots {
            ws.walk_tree(root);
        }
        Ok(ws)
    }

    /// Whether the file at `i` is exempt as test code.
    pub fn test_only(&self, i: usize) -> bool {
        self.files[i].only_tests || self.declared_test[i]
    }

    /// Indices of the files whose path starts with one of `prefixes`.
    pub fn files_under<'a>(&'a self, prefixes: &'a [&str]) -> impl Iterator<Item = usize> + 'a {
        (0..self.files.len())
            .filter(move |&i| prefixes.iter().any(|p| self.files[i].path.starts_with(p)))
    }

    fn walk_tree(&mut self, root: usize) {
        let tree_index = self.trees.len();
        let mut tree = CrateTree {
            root,
            module_file: BTreeMap::new(),
            children: BTreeMap::new(),
        };
        let mut queue = vec![(root, ModPath::new())];
        while let Some((file, module)) = queue.pop() {
            if self.place[file].is_some() {
                continue;
            }
            self.place[file] = Some(Place {
                tree: tree_index,
                module: module.clone(),
            });
            tree.module_file.insert(module.clone(), file);
            tree.children.entry(module.clone()).or_default();
            for scope in &self.files[file].scopes {
                add_module(&mut tree, &module, &scope.path, file);
            }
            let dir = child_dir(&self.files[file].path);
            let parent_test = self.test_only(file);
            for decl in &self.files[file].mods {
                let mut sub = decl.scope.clone();
                sub.push(decl.name.clone());
                let base = format!("{dir}/{}", sub.join("/"));
                let found = [format!("{base}.rs"), format!("{base}/mod.rs")]
                    .iter()
                    .find_map(|p| self.files.iter().position(|f| &f.path == p));
                let Some(child) = found else {
                    let at = format!("{}:{}: mod {}", self.files[file].path, decl.line, decl.name);
                    self.missing.push(at);
                    continue;
                };
                self.declared_test[child] |= decl.test || parent_test;
                add_module(&mut tree, &module, &sub, child);
                let mut child_module = module.clone();
                child_module.extend(sub);
                queue.push((child, child_module));
            }
        }
        self.trees.push(tree);
    }
}

/// Records module `base + sub` (and the inline modules on the way) as living in `file`.
fn add_module(tree: &mut CrateTree, base: &ModPath, sub: &[String], file: usize) {
    let mut path = base.clone();
    for name in sub {
        tree.children
            .entry(path.clone())
            .or_default()
            .insert(name.clone());
        path.push(name.clone());
    }
    tree.children.entry(path.clone()).or_default();
    tree.module_file.entry(path).or_insert(file);
}

/// The folder a file's `mod name;` declarations look in.
fn child_dir(path: &str) -> String {
    let (dir, name) = path.rsplit_once('/').unwrap_or(("", path));
    match name {
        "lib.rs" | "main.rs" | "mod.rs" => dir.to_string(),
        _ => format!("{dir}/{}", name.trim_end_matches(".rs")),
    }
}

fn collect_rs(root: &Path, dir: &Path, out: &mut Vec<(String, String)>) -> Result<(), String> {
    let entries = std::fs::read_dir(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    for entry in entries {
        let path = entry.map_err(|e| e.to_string())?.path();
        if path.is_dir() {
            collect_rs(root, &path, out)?;
        } else if path.extension().is_some_and(|e| e == "rs") {
            let src =
                std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
            let rel = path.strip_prefix(root).map_err(|e| e.to_string())?;
            let rel = rel
                .components()
                .map(|c| c.as_os_str().to_string_lossy())
                .collect::<Vec<_>>()
                .join("/");
            out.push((rel, src));
        }
    }
    Ok(())
}
