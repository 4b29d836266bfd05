//! The repository's Markdown documents point where they say: every relative link in a `.md`
//! file (README, ARCHITECTURE, PROTOCOL, `docs/`, `bench/`, the Python client) names a file
//! that exists, and every `#fragment` a heading of the file it names, by GitHub's rule for
//! heading anchors. The README's figures live in `docs/performance.md` and the sections of
//! one file are named from others, so a heading renamed or a section moved breaks a link
//! silently; this test says which, as `file: link (what is missing)`.
//!
//! Links are the inline form `[text](target)` and `![alt](target)` outside fenced code
//! blocks; a target with a scheme (`https:`, `mailto:`) is not checked.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

/// Directories that hold no document of the project's own.
const SKIP_DIRS: [&str; 2] = ["target", "node_modules"];

fn repository() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Every `.md` file under `dir`, skipping build output, dependencies and hidden folders.
fn markdown_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<_> = entries.filter_map(Result::ok).map(|e| e.path()).collect();
    entries.sort();
    for path in entries {
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default();
        if path.is_dir() {
            if !name.starts_with('.') && !SKIP_DIRS.contains(&name) {
                markdown_files(&path, out);
            }
        } else if name.ends_with(".md") {
            out.push(path);
        }
    }
}

/// The lines of `text` outside fenced code blocks.
fn prose_lines(text: &str) -> impl Iterator<Item = &str> {
    let mut fenced = false;
    text.lines().filter(move |line| {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            return false;
        }
        !fenced
    })
}

/// GitHub's anchor for a heading's text: lower case, letters, digits, `-` and `_` kept,
/// spaces made `-`, everything else dropped.
fn anchor(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, ' ' | '-' | '_'))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The anchors of a document's headings; a repeated heading gets `-1`, `-2`, … as on GitHub.
fn anchors(text: &str) -> HashSet<String> {
    let mut seen = HashSet::new();
    for line in prose_lines(text) {
        let hashes = line.chars().take_while(|&c| c == '#').count();
        if hashes == 0 || hashes > 6 || !line[hashes..].starts_with(' ') {
            continue;
        }
        let base = anchor(&line[hashes..]);
        let mut name = base.clone();
        let mut n = 0;
        while seen.contains(&name) {
            n += 1;
            name = format!("{base}-{n}");
        }
        seen.insert(name);
    }
    seen
}

/// The targets of a document's inline links, in order.
fn link_targets(text: &str) -> Vec<String> {
    let mut targets = Vec::new();
    for line in prose_lines(text) {
        let mut rest = line;
        while let Some(at) = rest.find("](") {
            rest = &rest[at + 2..];
            let end = rest.find([')', ' ']).unwrap_or(rest.len());
            targets.push(rest[..end].to_string());
            rest = &rest[end..];
        }
    }
    targets
}

/// What is wrong with each link of `doc` (whose text is `text`), as `doc: link (why)`.
fn broken_links(doc: &Path, text: &str, root: &Path) -> Vec<String> {
    let shown = doc.strip_prefix(root).unwrap_or(doc).display().to_string();
    let mut broken = Vec::new();
    // Each linked document's headings, read once however many links name it.
    let mut own: Option<HashSet<String>> = None;
    let mut linked: HashMap<PathBuf, HashSet<String>> = HashMap::new();
    for target in link_targets(text) {
        let is_url = target.split_once(':').is_some_and(|(scheme, _)| {
            !scheme.is_empty() && scheme.chars().all(|c| c.is_ascii_alphabetic())
        });
        if is_url || target.is_empty() {
            continue;
        }
        let (path, fragment) = match target.split_once('#') {
            Some((path, fragment)) => (path, Some(fragment)),
            None => (target.as_str(), None),
        };
        let file = if path.is_empty() {
            doc.to_path_buf()
        } else {
            doc.parent().unwrap_or(root).join(path)
        };
        if !file.exists() {
            broken.push(format!("{shown}: {target} (no file {path})"));
            continue;
        }
        let Some(fragment) = fragment else { continue };
        if file.extension().is_some_and(|e| e == "md") {
            let headings = if path.is_empty() {
                own.get_or_insert_with(|| anchors(text))
            } else {
                linked
                    .entry(file.clone())
                    .or_insert_with(|| anchors(&std::fs::read_to_string(&file).unwrap_or_default()))
            };
            if !headings.contains(fragment) {
                broken.push(format!("{shown}: {target} (no heading #{fragment})"));
            }
        }
    }
    broken
}

#[test]
fn every_relative_link_in_the_documents_resolves() {
    let root = repository();
    let mut docs = Vec::new();
    markdown_files(&root, &mut docs);
    let names: Vec<_> = docs
        .iter()
        .filter_map(|d| d.file_name()?.to_str())
        .collect();
    assert!(
        names.contains(&"README.md") && names.contains(&"performance.md"),
        "the walk found {names:?}"
    );
    let mut broken = Vec::new();
    let mut links = 0;
    for doc in &docs {
        let text = std::fs::read_to_string(doc).unwrap_or_default();
        links += link_targets(&text).len();
        broken.extend(broken_links(doc, &text, &root));
    }
    println!("{} documents, {links} links checked", docs.len());
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

#[test]
fn the_checker_sees_a_missing_file_and_a_missing_heading() {
    let root = repository();
    let doc = root.join("README.md");
    let text = "# Top\n\n## Where it stands (issue 14; `bench`)\n\n\
        [ok](#where-it-stands-issue-14-bench), [also ok](docs/performance.md), \
        [web](https://example.com/x), [gone](#nowhere), [lost](docs/no-such-file.md), \
        [wrong heading](docs/performance.md#no-such-heading)\n\
        ```\n[in code](not-checked.md)\n```\n";
    let broken = broken_links(&doc, text, &root);
    assert_eq!(broken.len(), 3, "{broken:?}");
    assert!(broken[0].contains("#nowhere"), "{broken:?}");
    assert!(broken[1].contains("no file"), "{broken:?}");
    assert!(
        broken[2].contains("no heading #no-such-heading"),
        "{broken:?}"
    );
    assert_eq!(anchors("# A\n# A\n").len(), 2);
    assert!(anchors("# A\n# A\n").contains("a-1"));
}
