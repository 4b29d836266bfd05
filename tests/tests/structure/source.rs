//! One source file as the checks see it: its tokens, which of them are test code, its inline
//! `mod name { .. }` blocks, its `mod name;` declarations and its `impl` blocks.
//!
//! Test code is every item under an attribute `#[test]` or `#[cfg(..test..)]` (without `not`),
//! wherever it stands, and everything when the file opens with `#![cfg(test)]`. An item runs
//! from its attributes to its first `;` or `{..}` group at its own level; `const`, `static`,
//! `let`, `type` and `use` run to their `;` (their initializer may hold braces).

use super::lex::{lex, Kind, Lexed};

/// An inline module: its path inside the file and the indices of its braces.
pub struct Scope {
    pub path: Vec<String>,
    pub open: usize,
    pub close: usize,
}

/// A `mod name;` declaration and the inline module path it stands in.
pub struct ModDecl {
    pub name: String,
    pub line: usize,
    pub scope: Vec<String>,
    pub test: bool,
}

/// An `impl` block: the name of its self type and the indices of its braces.
pub struct ImplBlock {
    pub self_type: String,
    pub open: usize,
    pub close: usize,
}

pub struct SourceFile {
    /// Relative to the scanned root, with `/`.
    pub path: String,
    pub lex: Lexed,
    /// Per token: whether it is test code.
    pub test: Vec<bool>,
    /// Every item of the file is test code (and there is at least one).
    pub only_tests: bool,
    pub scopes: Vec<Scope>,
    pub mods: Vec<ModDecl>,
    pub impls: Vec<ImplBlock>,
}

impl SourceFile {
    pub fn parse(path: &str, src: &str) -> Result<SourceFile, String> {
        let lex = lex(src).map_err(|e| format!("{path}: {e}"))?;
        let (test, only_tests) = mark_tests(&lex);
        let mut file = SourceFile {
            path: path.to_string(),
            lex,
            test,
            only_tests,
            scopes: Vec::new(),
            mods: Vec::new(),
            impls: Vec::new(),
        };
        file.find_modules();
        file.find_impls();
        Ok(file)
    }

    /// The inline module path at token `i` (empty at file level).
    pub fn scope_at(&self, i: usize) -> &[String] {
        self.scopes
            .iter()
            .filter(|s| s.open < i && i < s.close)
            .max_by_key(|s| s.path.len())
            .map_or(&[], |s| s.path.as_slice())
    }

    /// The self type of the innermost `impl` block around token `i`.
    pub fn impl_at(&self, i: usize) -> Option<&str> {
        self.impls
            .iter()
            .filter(|b| b.open < i && i < b.close)
            .max_by_key(|b| b.open)
            .map(|b| b.self_type.as_str())
    }

    fn find_modules(&mut self) {
        let lex = &self.lex;
        for i in 0..lex.tokens.len() {
            let (true, Some(name)) = (
                lex.is(i, "mod") && lex.tokens[i].kind == Kind::Ident,
                lex.ident(i + 1),
            ) else {
                continue;
            };
            let mut path = self.scope_at(i).to_vec();
            if lex.is(i + 2, "{") {
                path.push(name.to_string());
                let close = lex.skip(i + 2) - 1;
                self.scopes.push(Scope {
                    path,
                    open: i + 2,
                    close,
                });
            } else if lex.is(i + 2, ";") {
                let (line, test) = (lex.line(i), self.test[i]);
                self.mods.push(ModDecl {
                    name: name.to_string(),
                    line,
                    scope: path,
                    test,
                });
            }
        }
    }

    fn find_impls(&mut self) {
        let lex = &self.lex;
        for i in 0..lex.tokens.len() {
            let item_start = i == 0
                || [";", "}", "{", "]", "unsafe", "default"]
                    .iter()
                    .any(|p| lex.is(i - 1, p));
            if !(lex.ident(i) == Some("impl") && item_start) {
                continue;
            }
            let Some(open) = body_open(lex, i + 1) else {
                continue;
            };
            let self_type = impl_self_type(lex, i + 1, open);
            self.impls.push(ImplBlock {
                self_type,
                open,
                close: lex.skip(open) - 1,
            });
        }
    }
}

/// The index of the first `{` at the level of `from`, skipping `(..)` and `[..]`, unless a `;`
/// or a closing delimiter comes first.
pub fn body_open(lex: &Lexed, from: usize) -> Option<usize> {
    let mut i = from;
    while i < lex.tokens.len() {
        match lex.tokens[i].text.as_str() {
            _ if lex.tokens[i].kind != Kind::Punct => i += 1,
            "{" => return Some(i),
            "(" | "[" => i = lex.skip(i),
            ";" | ")" | "]" | "}" => return None,
            _ => i += 1,
        }
    }
    None
}

/// `impl<T> Trait for a::Type<T> where ..` -> `Type`; `impl Type` -> `Type`.
fn impl_self_type(lex: &Lexed, from: usize, open: usize) -> String {
    let mut i = from;
    if lex.is(i, "<") {
        i = skip_angles(lex, i);
    }
    let mut start = i;
    let mut angle = 0i32;
    while i < open {
        match lex.tokens[i].text.as_str() {
            "<" => angle += 1,
            ">" => angle -= 1,
            "for" if angle == 0 => start = i + 1,
            "where" if angle == 0 => break,
            _ => {}
        }
        i += 1;
    }
    let mut name = String::new();
    let mut j = start;
    while j < open {
        match lex.ident(j) {
            Some("dyn" | "mut") => {}
            Some("where") => break,
            Some(ident) => name = ident.to_string(),
            None if lex.is(j, "::") || lex.is(j, "&") => {}
            None => break,
        }
        j += 1;
    }
    name
}

/// The index after the `<..>` opened at `i`.
fn skip_angles(lex: &Lexed, mut i: usize) -> usize {
    let mut angle = 0i32;
    while i < lex.tokens.len() {
        angle += i32::from(lex.is(i, "<")) - i32::from(lex.is(i, ">"));
        i += 1;
        if angle == 0 {
            break;
        }
    }
    i
}

/// Marks the tokens of every test item; says whether the file holds only tests.
fn mark_tests(lex: &Lexed) -> (Vec<bool>, bool) {
    let n = lex.tokens.len();
    let mut test = vec![false; n];
    let mut i = 0;
    while i < n {
        if lex.is(i, "#") && lex.is(i + 1, "!") && lex.is(i + 2, "[") && is_test_attr(lex, i + 2) {
            return (vec![true; n], true);
        }
        if lex.is(i, "#") && lex.is(i + 1, "[") && is_test_attr(lex, i + 1) {
            let end = item_end(lex, i);
            test[i..=end].iter_mut().for_each(|t| *t = true);
            i = end + 1;
        } else {
            i += 1;
        }
    }
    let only_tests = top_items_all_test(lex, &test);
    (test, only_tests)
}

fn top_items_all_test(lex: &Lexed, test: &[bool]) -> bool {
    let mut i = 0;
    let mut items = 0;
    while i < lex.tokens.len() {
        if lex.is(i, "#") && lex.is(i + 1, "!") && lex.is(i + 2, "[") {
            i = lex.skip(i + 2);
            continue;
        }
        if !test[i] {
            return false;
        }
        items += 1;
        i = item_end(lex, i) + 1;
    }
    items > 0
}

/// `#[test]`, or `#[cfg(..)]` naming `test` and not `not`, with its `[` at `open`.
fn is_test_attr(lex: &Lexed, open: usize) -> bool {
    let close = lex.skip(open) - 1;
    let idents: Vec<&str> = (open + 1..close).filter_map(|i| lex.ident(i)).collect();
    match idents.first() {
        Some(&"test") => idents.len() == 1,
        Some(&"cfg") => idents.contains(&"test") && !idents.contains(&"not"),
        _ => false,
    }
}

/// The index of the last token of the item (or statement) starting at `start`, attributes
/// included.
pub fn item_end(lex: &Lexed, start: usize) -> usize {
    let n = lex.tokens.len();
    let mut i = start;
    while lex.is(i, "#") && lex.is(i + 1, "[") {
        i = lex.skip(i + 1);
    }
    let to_semicolon = matches!(
        item_keyword(lex, i),
        Some("const" | "static" | "let" | "type" | "use")
    );
    while i < n {
        match lex.tokens[i].text.as_str() {
            _ if lex.tokens[i].kind != Kind::Punct => i += 1,
            ";" => return i,
            "{" if !to_semicolon => return lex.skip(i) - 1,
            "(" | "[" | "{" => i = lex.skip(i),
            "}" | ")" | "]" => return i.saturating_sub(1).max(start),
            _ => i += 1,
        }
    }
    n.saturating_sub(1)
}

/// The keyword that says what the item at `i` is, past visibility and qualifiers.
fn item_keyword(lex: &Lexed, mut i: usize) -> Option<&str> {
    if lex.is(i, "pub") {
        i += 1;
        if lex.is(i, "(") {
            i = lex.skip(i);
        }
    }
    loop {
        match lex.ident(i) {
            Some("async" | "unsafe" | "extern" | "default") => i += 1,
            Some("const")
                if matches!(lex.ident(i + 1), Some("fn" | "unsafe" | "async" | "extern")) =>
            {
                i += 1
            }
            None if lex.tokens.get(i).is_some_and(|t| t.kind == Kind::Literal) => i += 1,
            other => return other,
        }
    }
}
