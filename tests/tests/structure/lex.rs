//! A small Rust lexer for the structure checks: tokens with their line numbers and brace depth,
//! and the matching partner of every `(`, `[`, `{`.
//!
//! It knows just enough Rust to never mistake text for code: line and nested block comments
//! (doc comments included) are skipped; string literals (with escapes), raw strings
//! `r#".."#`, byte and C strings, char literals and numbers are one `Literal` token each, so a
//! brace or `crate::` inside them is not seen; `'a'` is a char but `'a` a lifetime or label.
//! Punctuation is one char per token except `::`, `=>`, `->` and `..`/`..=`/`...`, which the
//! checks look for as units.

/// What a token is; `Punct` text is the operator itself.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Ident,
    Lifetime,
    Literal,
    Punct,
}

/// One token: its text, the 1-based line it starts on, and the `{}` depth it sits at (an
/// opening or closing brace has the depth outside it).
#[derive(Clone, Debug)]
pub struct Token {
    pub kind: Kind,
    pub text: String,
    pub line: usize,
    pub depth: usize,
}

/// A lexed file: its tokens, each delimiter's partner index, and its line count.
pub struct Lexed {
    pub tokens: Vec<Token>,
    pub partner: Vec<Option<usize>>,
    pub lines: usize,
}

impl Lexed {
    /// Whether token `i` is the identifier or punctuation `text`.
    pub fn is(&self, i: usize, text: &str) -> bool {
        self.tokens
            .get(i)
            .is_some_and(|t| t.text == text && t.kind != Kind::Literal)
    }

    /// The identifier at `i`, if it is one.
    pub fn ident(&self, i: usize) -> Option<&str> {
        self.tokens
            .get(i)
            .filter(|t| t.kind == Kind::Ident)
            .map(|t| t.text.as_str())
    }

    /// The line of token `i` (the last line for an index past the end).
    pub fn line(&self, i: usize) -> usize {
        self.tokens.get(i).map_or(self.lines, |t| t.line)
    }

    /// The index after the group opened at `i` (its closing delimiter + 1), or `i + 1` when
    /// `i` opens nothing.
    pub fn skip(&self, i: usize) -> usize {
        self.partner[i].filter(|&j| j > i).map_or(i + 1, |j| j + 1)
    }
}

const MULTI_PUNCT: [&str; 6] = ["..=", "...", "::", "=>", "->", ".."];

/// Lexes `src`; an unbalanced delimiter is an error naming its line.
pub fn lex(src: &str) -> Result<Lexed, String> {
    let chars: Vec<char> = src.chars().collect();
    let mut lexer = Lexer {
        chars: &chars,
        at: 0,
        line: 1,
    };
    let mut tokens = Vec::new();
    while let Some((kind, text, line)) = lexer.next_token()? {
        tokens.push(Token {
            kind,
            text,
            line,
            depth: 0,
        });
    }
    let partner = pair_delimiters(&mut tokens)?;
    let lines = src.lines().count();
    Ok(Lexed {
        tokens,
        partner,
        lines,
    })
}

struct Lexer<'a> {
    chars: &'a [char],
    at: usize,
    line: usize,
}

impl Lexer<'_> {
    fn peek(&self, ahead: usize) -> Option<char> {
        self.chars.get(self.at + ahead).copied()
    }

    fn bump(&mut self) -> Option<char> {
        let c = self.peek(0)?;
        self.at += 1;
        if c == '\n' {
            self.line += 1;
        }
        Some(c)
    }

    fn next_token(&mut self) -> Result<Option<(Kind, String, usize)>, String> {
        self.skip_trivia()?;
        let Some(c) = self.peek(0) else {
            return Ok(None);
        };
        let (line, start) = (self.line, self.at);
        let kind = if let Some(hashes) = self.raw_string_start() {
            self.raw_string(hashes)?;
            Kind::Literal
        } else if c == '"' || (matches!(c, 'b' | 'c') && self.peek(1) == Some('"')) {
            self.at += usize::from(c != '"');
            self.quoted('"')?;
            Kind::Literal
        } else if c == 'b' && self.peek(1) == Some('\'') {
            self.at += 1;
            self.quoted('\'')?;
            Kind::Literal
        } else if c == '\'' {
            self.char_or_lifetime()?
        } else if c == 'r' && self.peek(1) == Some('#') && self.peek(2).is_some_and(is_ident_start)
        {
            self.at += 2;
            self.ident();
            Kind::Ident
        } else if is_ident_start(c) {
            self.ident();
            Kind::Ident
        } else if c.is_ascii_digit() {
            self.number();
            Kind::Literal
        } else {
            let rest: String = self.chars[self.at..(self.at + 3).min(self.chars.len())]
                .iter()
                .collect();
            let len = MULTI_PUNCT
                .iter()
                .find(|p| rest.starts_with(*p))
                .map_or(1, |p| p.len());
            self.at += len;
            Kind::Punct
        };
        let mut text: String = self.chars[start..self.at].iter().collect();
        if kind == Kind::Ident && text.starts_with("r#") {
            text.drain(..2);
        }
        Ok(Some((kind, text, line)))
    }

    fn skip_trivia(&mut self) -> Result<(), String> {
        loop {
            match (self.peek(0), self.peek(1)) {
                (Some(c), _) if c.is_whitespace() => {
                    self.bump();
                }
                (Some('/'), Some('/')) => {
                    while self.peek(0).is_some_and(|c| c != '\n') {
                        self.bump();
                    }
                }
                (Some('/'), Some('*')) => self.block_comment()?,
                _ => return Ok(()),
            }
        }
    }

    fn block_comment(&mut self) -> Result<(), String> {
        let line = self.line;
        let mut depth = 0usize;
        loop {
            match (self.peek(0), self.peek(1)) {
                (Some('/'), Some('*')) => {
                    depth += 1;
                    self.at += 2;
                }
                (Some('*'), Some('/')) => {
                    depth -= 1;
                    self.at += 2;
                    if depth == 0 {
                        return Ok(());
                    }
                }
                (Some(_), _) => {
                    self.bump();
                }
                (None, _) => return Err(format!("unclosed block comment from line {line}")),
            }
        }
    }

    /// The number of `#` of a raw string (`r"`, `r#"`, `br"`, `cr#"`) starting here, if one does.
    fn raw_string_start(&self) -> Option<usize> {
        let prefix = match (self.peek(0), self.peek(1)) {
            (Some('r'), _) => 1,
            (Some('b' | 'c'), Some('r')) => 2,
            _ => return None,
        };
        let hashes = (prefix..)
            .take_while(|&k| self.peek(k) == Some('#'))
            .count();
        (self.peek(prefix + hashes) == Some('"')).then_some(hashes)
    }

    fn raw_string(&mut self, hashes: usize) -> Result<(), String> {
        let line = self.line;
        while self.bump().is_some_and(|c| c != '"') {}
        loop {
            match self.bump() {
                Some('"') if (0..hashes).all(|k| self.peek(k) == Some('#')) => {
                    self.at += hashes;
                    return Ok(());
                }
                Some(_) => {}
                None => return Err(format!("unclosed raw string from line {line}")),
            }
        }
    }

    /// A `"`- or `'`-quoted literal with backslash escapes, starting at the opening quote.
    fn quoted(&mut self, quote: char) -> Result<(), String> {
        let line = self.line;
        self.bump();
        loop {
            match self.bump() {
                Some('\\') => {
                    self.bump();
                }
                Some(c) if c == quote => return Ok(()),
                Some(_) => {}
                None => return Err(format!("unclosed literal from line {line}")),
            }
        }
    }

    /// `'x'` and `'\n'` are chars; `'a` (no closing quote after one char) a lifetime or label.
    fn char_or_lifetime(&mut self) -> Result<Kind, String> {
        if self.peek(1) == Some('\\') || self.peek(2) == Some('\'') {
            self.quoted('\'')?;
            return Ok(Kind::Literal);
        }
        self.at += 1;
        self.ident();
        Ok(Kind::Lifetime)
    }

    fn ident(&mut self) {
        while self.peek(0).is_some_and(is_ident_continue) {
            self.at += 1;
        }
    }

    /// Digits, letters and `_` (suffixes, hex), a `.` only before a digit (so `0..n` stays a
    /// range), and a sign after an exponent `e`.
    fn number(&mut self) {
        let hex = self.peek(0) == Some('0') && matches!(self.peek(1), Some('x' | 'X'));
        loop {
            match self.peek(0) {
                Some(c) if is_ident_continue(c) => self.at += 1,
                Some('.') if self.peek(1).is_some_and(|c| c.is_ascii_digit()) => self.at += 1,
                Some('+' | '-')
                    if matches!(self.chars[self.at - 1], 'e' | 'E')
                        && self.peek(1).is_some_and(|c| c.is_ascii_digit())
                        && !hex =>
                {
                    self.at += 1;
                }
                _ => return,
            }
        }
    }
}

fn is_ident_start(c: char) -> bool {
    c == '_' || c.is_alphabetic()
}

fn is_ident_continue(c: char) -> bool {
    c == '_' || c.is_alphanumeric()
}

/// Sets each token's brace depth and returns every delimiter's partner.
fn pair_delimiters(tokens: &mut [Token]) -> Result<Vec<Option<usize>>, String> {
    let mut partner = vec![None; tokens.len()];
    let mut open: Vec<usize> = Vec::new();
    let mut depth = 0;
    for i in 0..tokens.len() {
        let (text, line) = (tokens[i].text.clone(), tokens[i].line);
        let punct = tokens[i].kind == Kind::Punct;
        tokens[i].depth = depth;
        match text.as_str() {
            "(" | "[" | "{" if punct => {
                open.push(i);
                depth += usize::from(text == "{");
            }
            close @ (")" | "]" | "}") if punct => {
                let want = match close {
                    ")" => "(",
                    "]" => "[",
                    _ => "{",
                };
                let j = open
                    .pop()
                    .filter(|&j| tokens[j].text == want)
                    .ok_or_else(|| format!("unbalanced `{close}` on line {line}"))?;
                depth -= usize::from(close == "}");
                tokens[i].depth = depth;
                partner[i] = Some(j);
                partner[j] = Some(i);
            }
            _ => {}
        }
    }
    match open.pop() {
        Some(j) => Err(format!(
            "unclosed `{}` from line {}",
            tokens[j].text, tokens[j].line
        )),
        None => Ok(partner),
    }
}
