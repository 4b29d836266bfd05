//! Rules 1 and 3: file and function length, and wildcard arms on kind enums.
//!
//! A function spans from the line of its `fn` to the line of its body's closing brace (a `fn`
//! without a body, or a `fn(..)` pointer type, is not measured). A match is on a kind enum
//! when one of its arm patterns holds a path `Name::..` with `Name` a kind enum (or `Self::..`
//! inside an `impl` of one), or an arm's value starts with one (a match that maps something to
//! a kind); such a match fails when an arm's pattern is `_` or `_ if ..`.

use super::source::{body_open, SourceFile};
use super::workspace::Workspace;

pub const MAX_FILE_LINES: usize = 800;
pub const MAX_FN_LINES: usize = 150;

/// The kind and backend enums named by issue 10; any `enum ..Kind` or `enum ..Geometry` found
/// in the scanned crates joins them.
pub const KIND_ENUMS: [&str; 6] = [
    "Geometry",
    "PreparedGeometry",
    "SceneKind",
    "StepLayout",
    "KindSetup",
    "Backend",
];

/// What a check looked at and what it found.
pub struct Outcome {
    pub checked: String,
    pub violations: Vec<String>,
}

pub fn file_lengths(ws: &Workspace, prefixes: &[&str]) -> Outcome {
    let (mut files, mut exempt, mut lines) = (0, 0, 0);
    let mut violations = Vec::new();
    for i in ws.files_under(prefixes) {
        let file = &ws.files[i];
        if ws.test_only(i) {
            exempt += 1;
            continue;
        }
        files += 1;
        lines += file.lex.lines;
        if file.lex.lines > MAX_FILE_LINES {
            violations.push(format!(
                "{}: {} lines (limit {MAX_FILE_LINES})",
                file.path, file.lex.lines
            ));
        }
    }
    let checked = format!("{files} files ({lines} lines) checked, {exempt} test-only files exempt");
    Outcome {
        checked,
        violations,
    }
}

pub fn function_lengths(ws: &Workspace, prefixes: &[&str]) -> Outcome {
    let (mut functions, mut exempt) = (0, 0);
    let mut violations = Vec::new();
    for i in ws.files_under(prefixes) {
        let file = &ws.files[i];
        for (at, name, lines) in functions_of(file) {
            if ws.test_only(i) || file.test[at] {
                exempt += 1;
                continue;
            }
            functions += 1;
            if lines > MAX_FN_LINES {
                let line = file.lex.line(at);
                violations.push(format!(
                    "{}:{line}: fn {name} spans {lines} lines (limit {MAX_FN_LINES})",
                    file.path
                ));
            }
        }
    }
    let checked = format!("{functions} functions checked, {exempt} test functions exempt");
    Outcome {
        checked,
        violations,
    }
}

/// Every `fn` with a body: its token index, its name and how many lines it spans.
pub fn functions_of(file: &SourceFile) -> Vec<(usize, String, usize)> {
    let lex = &file.lex;
    let mut out = Vec::new();
    for i in 0..lex.tokens.len() {
        let (Some("fn"), Some(name)) = (lex.ident(i), lex.ident(i + 1)) else {
            continue;
        };
        if let Some(open) = body_open(lex, i + 2) {
            let close = lex.skip(open) - 1;
            out.push((i, name.to_string(), lex.line(close) - lex.line(i) + 1));
        }
    }
    out
}

/// The kind enum names: `KIND_ENUMS` and every non-test `enum ..Kind` / `enum ..Geometry` in
/// the files under `prefixes`.
pub fn kind_enums(ws: &Workspace, prefixes: &[&str]) -> Vec<String> {
    let mut names: Vec<String> = KIND_ENUMS.iter().map(|s| s.to_string()).collect();
    for i in ws.files_under(prefixes).filter(|&i| !ws.test_only(i)) {
        let file = &ws.files[i];
        for t in 0..file.lex.tokens.len() {
            if let (Some("enum"), Some(name), false) =
                (file.lex.ident(t), file.lex.ident(t + 1), file.test[t])
            {
                if (name.ends_with("Kind") || name.ends_with("Geometry"))
                    && !names.iter().any(|n| n == name)
                {
                    names.push(name.to_string());
                }
            }
        }
    }
    names
}

pub fn wildcard_matches(ws: &Workspace, prefixes: &[&str], kinds: &[String]) -> Outcome {
    let (mut matches, mut on_kinds) = (0, 0);
    let mut violations = Vec::new();
    for i in ws.files_under(prefixes).filter(|&i| !ws.test_only(i)) {
        let file = &ws.files[i];
        for at in 0..file.lex.tokens.len() {
            if file.lex.ident(at) != Some("match") || file.test[at] {
                continue;
            }
            let Some(open) = body_open(&file.lex, at + 1) else {
                continue;
            };
            matches += 1;
            let arms = arms(file, open);
            let kind = arms.iter().find_map(|arm| {
                kind_named(file, arm.pattern.0, arm.pattern.1, at, kinds).or_else(|| {
                    kind_named(
                        file,
                        arm.value,
                        leading_path_end(file, arm.value),
                        at,
                        kinds,
                    )
                })
            });
            let Some(kind) = kind else {
                continue;
            };
            on_kinds += 1;
            for &Arm {
                pattern: (from, to),
                ..
            } in &arms
            {
                let wild =
                    file.lex.is(from, "_") && (from + 1 == to || file.lex.is(from + 1, "if"));
                if wild {
                    let (line, match_line) = (file.lex.line(from), file.lex.line(at));
                    violations.push(format!(
                        "{}:{line}: `_` arm in a match on {kind} (match on line {match_line})",
                        file.path
                    ));
                }
            }
        }
    }
    let kinds = kinds.join(", ");
    let checked = format!("{matches} matches checked, {on_kinds} on kind enums ({kinds})");
    Outcome {
        checked,
        violations,
    }
}

/// One match arm: its pattern `(first token, its `=>`)` and where its value starts.
struct Arm {
    pattern: (usize, usize),
    value: usize,
}

/// The arms of the match body opened at `open` (a leading `|` and attributes skipped).
fn arms(file: &SourceFile, open: usize) -> Vec<Arm> {
    let lex = &file.lex;
    let close = lex.skip(open) - 1;
    let skip_group = |i: usize| {
        if matches!(lex.tokens[i].text.as_str(), "(" | "[" | "{") {
            lex.skip(i)
        } else {
            i + 1
        }
    };
    let mut out = Vec::new();
    let mut i = open + 1;
    while i < close {
        while lex.is(i, "#") && lex.is(i + 1, "[") {
            i = lex.skip(i + 1);
        }
        if lex.is(i, "|") {
            i += 1;
        }
        let from = i;
        while i < close && !lex.is(i, "=>") {
            i = skip_group(i);
        }
        out.push(Arm {
            pattern: (from, i),
            value: i + 1,
        });
        i += 1;
        if lex.is(i, "{") {
            i = lex.skip(i);
            if lex.is(i, ",") {
                i += 1;
            }
            continue;
        }
        while i < close && !lex.is(i, ",") {
            i = skip_group(i);
        }
        i += 1;
    }
    out
}

/// The end of the path (`a::B::C`) starting at `i`, so an arm whose value is a kind variant
/// (`_ => SceneKind::Metaballs`) makes its match one on a kind.
fn leading_path_end(file: &SourceFile, mut i: usize) -> usize {
    while file.lex.ident(i).is_some() && file.lex.is(i + 1, "::") {
        i += 2;
    }
    i
}

/// The kind enum a path in `from..to` names, if any (`Self` inside the match at `at` counts
/// as the type its `impl` block is for).
fn kind_named(
    file: &SourceFile,
    from: usize,
    to: usize,
    at: usize,
    kinds: &[String],
) -> Option<String> {
    let lex = &file.lex;
    (from..to).find_map(|t| {
        let name = lex.ident(t).filter(|_| lex.is(t + 1, "::"))?;
        let name = if name == "Self" {
            file.impl_at(at)?
        } else {
            name
        };
        kinds.iter().find(|k| *k == name).cloned()
    })
}
