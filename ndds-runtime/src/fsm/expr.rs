//! Transition conditions: boolean expressions over stimuli.
//!
//! ```text
//! expr    := or
//! or      := and { ("or" | "||") and }
//! and     := unary { ("and" | "&&") unary }
//! unary   := ("not" | "!") unary | primary
//! primary := "(" expr ")" | "*" | NAME [ ("=" | "==" | "!=") VALUE ]
//! NAME    := letter or `_`, then letters, digits, `_`, `.`, `-`
//! VALUE   := NAME-like word or a "double-quoted string"
//! ```
//!
//! Keywords are case-insensitive (`Object = Visible AND Acquire`). A bare name is true while
//! the stimulus is present: a transient one only while it is being processed, a latched one
//! until a transition consumes it, a condition while it has a value. `*` (the wildcard) is true
//! for an arriving stimulus that no other transition handles.

use std::fmt;

/// A parsed condition.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Expr {
    /// `*`: any stimulus not otherwise handled.
    Wildcard,
    /// A stimulus is present.
    Present(String),
    /// A condition has this value.
    Equals(String, String),
    /// A condition does not have this value (or has none).
    NotEquals(String, String),
    /// Negation.
    Not(Box<Expr>),
    /// Both.
    And(Box<Expr>, Box<Expr>),
    /// Either.
    Or(Box<Expr>, Box<Expr>),
}

/// What an expression is evaluated against.
pub trait Stimuli {
    /// Whether stimulus `name` is present now.
    fn present(&self, name: &str) -> bool;
    /// The value of condition `name`, if it has one.
    fn value(&self, name: &str) -> Option<&str>;
}

/// An expression that does not parse.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("`{text}`: {problem} at character {at}")]
pub struct ParseError {
    /// The expression.
    pub text: String,
    /// Where (0-based character index).
    pub at: usize,
    /// What was wrong.
    pub problem: String,
}

#[derive(Clone, Debug, PartialEq, Eq)]
enum Token {
    Word(String),
    Quoted(String),
    LParen,
    RParen,
    Star,
    Eq,
    Ne,
    And,
    Or,
    Not,
}

/// Expressions longer than this are refused (they come from files and the network).
pub const MAX_EXPR_LEN: usize = 4096;
/// Nesting deeper than this is refused.
pub const MAX_DEPTH: usize = 64;

impl Expr {
    /// Parses `text`.
    pub fn parse(text: &str) -> Result<Expr, ParseError> {
        let fail = |at: usize, problem: &str| ParseError {
            text: text.to_owned(),
            at,
            problem: problem.to_owned(),
        };
        if text.len() > MAX_EXPR_LEN {
            return Err(fail(MAX_EXPR_LEN, "expression too long"));
        }
        let tokens = tokenize(text).map_err(|(at, p)| fail(at, &p))?;
        let mut parser = Parser {
            tokens: &tokens,
            pos: 0,
            depth: 0,
            end: text.chars().count(),
        };
        let expr = parser.or().map_err(|(at, p)| fail(at, &p))?;
        if let Some((at, token)) = tokens.get(parser.pos) {
            return Err(fail(*at, &format!("unexpected {}", describe(token))));
        }
        Ok(expr)
    }

    /// Evaluates it; `unhandled` says whether a stimulus just arrived that no other transition
    /// took (what `*` matches).
    pub fn eval(&self, stimuli: &dyn Stimuli, unhandled: bool) -> bool {
        match self {
            Expr::Wildcard => unhandled,
            Expr::Present(name) => stimuli.present(name),
            Expr::Equals(name, value) => stimuli.value(name) == Some(value),
            Expr::NotEquals(name, value) => stimuli.value(name) != Some(value),
            Expr::Not(inner) => !inner.eval(stimuli, unhandled),
            Expr::And(a, b) => a.eval(stimuli, unhandled) && b.eval(stimuli, unhandled),
            Expr::Or(a, b) => a.eval(stimuli, unhandled) || b.eval(stimuli, unhandled),
        }
    }

    /// Whether it contains the wildcard.
    pub fn has_wildcard(&self) -> bool {
        match self {
            Expr::Wildcard => true,
            Expr::Present(_) | Expr::Equals(..) | Expr::NotEquals(..) => false,
            Expr::Not(inner) => inner.has_wildcard(),
            Expr::And(a, b) | Expr::Or(a, b) => a.has_wildcard() || b.has_wildcard(),
        }
    }

    /// Every stimulus name it mentions.
    pub fn names(&self) -> Vec<&str> {
        let mut out = Vec::new();
        self.collect(&mut out, true, false);
        out
    }

    /// The names it requires present (not under a `not`): the latched stimuli a firing
    /// transition consumes.
    pub fn positive_names(&self) -> Vec<&str> {
        let mut out = Vec::new();
        self.collect(&mut out, false, false);
        out
    }

    fn collect<'a>(&'a self, out: &mut Vec<&'a str>, all: bool, negated: bool) {
        match self {
            Expr::Wildcard => {}
            Expr::Present(name) => {
                if all || !negated {
                    out.push(name);
                }
            }
            Expr::Equals(name, _) | Expr::NotEquals(name, _) => {
                if all {
                    out.push(name);
                }
            }
            Expr::Not(inner) => inner.collect(out, all, !negated),
            Expr::And(a, b) | Expr::Or(a, b) => {
                a.collect(out, all, negated);
                b.collect(out, all, negated);
            }
        }
    }
}

impl fmt::Display for Expr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Expr::Wildcard => f.write_str("*"),
            Expr::Present(name) => f.write_str(name),
            Expr::Equals(name, value) => write!(f, "{name} = {}", quote(value)),
            Expr::NotEquals(name, value) => write!(f, "{name} != {}", quote(value)),
            Expr::Not(inner) => write!(f, "not ({inner})"),
            Expr::And(a, b) => write!(f, "({a} and {b})"),
            Expr::Or(a, b) => write!(f, "({a} or {b})"),
        }
    }
}

fn quote(value: &str) -> String {
    let keyword = matches!(value.to_ascii_lowercase().as_str(), "and" | "or" | "not");
    let plain = value.chars().all(word_char)
        && value
            .chars()
            .next()
            .is_some_and(|c| word_start(c) || c.is_ascii_digit());
    if plain && !keyword {
        return value.to_owned();
    }
    let mut out = String::with_capacity(value.len() + 2);
    out.push('"');
    for c in value.chars() {
        if matches!(c, '"' | '\\') {
            out.push('\\');
        }
        out.push(c);
    }
    out.push('"');
    out
}

fn word_start(c: char) -> bool {
    c.is_alphabetic() || c == '_'
}

fn word_char(c: char) -> bool {
    c.is_alphanumeric() || matches!(c, '_' | '.' | '-')
}

fn describe(token: &Token) -> String {
    match token {
        Token::Word(w) => format!("`{w}`"),
        Token::Quoted(q) => format!("{q:?}"),
        Token::LParen => "`(`".into(),
        Token::RParen => "`)`".into(),
        Token::Star => "`*`".into(),
        Token::Eq => "`=`".into(),
        Token::Ne => "`!=`".into(),
        Token::And => "`and`".into(),
        Token::Or => "`or`".into(),
        Token::Not => "`not`".into(),
    }
}

fn tokenize(text: &str) -> Result<Vec<(usize, Token)>, (usize, String)> {
    let chars: Vec<char> = text.chars().collect();
    let mut tokens = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        let start = i;
        let two = |second: char| chars.get(i + 1) == Some(&second);
        let token = match c {
            _ if c.is_whitespace() => {
                i += 1;
                continue;
            }
            '(' => Token::LParen,
            ')' => Token::RParen,
            '*' => Token::Star,
            '=' if two('=') => {
                i += 1;
                Token::Eq
            }
            '=' => Token::Eq,
            '!' if two('=') => {
                i += 1;
                Token::Ne
            }
            '!' => Token::Not,
            '&' if two('&') => {
                i += 1;
                Token::And
            }
            '|' if two('|') => {
                i += 1;
                Token::Or
            }
            '"' => {
                let mut value = String::new();
                i += 1;
                loop {
                    match chars.get(i) {
                        None => return Err((start, "unterminated string".into())),
                        Some('"') => break,
                        Some('\\') if matches!(chars.get(i + 1), Some('"' | '\\')) => {
                            value.push(chars[i + 1]);
                            i += 2;
                        }
                        Some(&ch) => {
                            value.push(ch);
                            i += 1;
                        }
                    }
                }
                Token::Quoted(value)
            }
            _ if word_start(c) || c.is_ascii_digit() => {
                let mut word = String::new();
                while let Some(&ch) = chars.get(i).filter(|ch| word_char(**ch)) {
                    word.push(ch);
                    i += 1;
                }
                i -= 1;
                match word.to_ascii_lowercase().as_str() {
                    "and" => Token::And,
                    "or" => Token::Or,
                    "not" => Token::Not,
                    _ => Token::Word(word),
                }
            }
            _ => return Err((start, format!("unexpected character {c:?}"))),
        };
        tokens.push((start, token));
        i += 1;
    }
    Ok(tokens)
}

struct Parser<'a> {
    tokens: &'a [(usize, Token)],
    pos: usize,
    depth: usize,
    /// Where the text ends (reported when it ends too early).
    end: usize,
}

type Parsed = Result<Expr, (usize, String)>;

impl Parser<'_> {
    fn peek(&self) -> Option<&Token> {
        self.tokens.get(self.pos).map(|(_, t)| t)
    }

    fn at(&self) -> usize {
        self.tokens.get(self.pos).map_or(self.end, |(at, _)| *at)
    }

    fn or(&mut self) -> Parsed {
        let mut left = self.and()?;
        while self.peek() == Some(&Token::Or) {
            self.pos += 1;
            left = Expr::Or(Box::new(left), Box::new(self.and()?));
        }
        Ok(left)
    }

    fn and(&mut self) -> Parsed {
        let mut left = self.unary()?;
        while self.peek() == Some(&Token::And) {
            self.pos += 1;
            left = Expr::And(Box::new(left), Box::new(self.unary()?));
        }
        Ok(left)
    }

    fn unary(&mut self) -> Parsed {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err((self.at(), format!("nested more than {MAX_DEPTH} deep")));
        }
        let result = if self.peek() == Some(&Token::Not) {
            self.pos += 1;
            self.unary().map(|e| Expr::Not(Box::new(e)))
        } else {
            self.primary()
        };
        self.depth -= 1;
        result
    }

    fn primary(&mut self) -> Parsed {
        let at = self.at();
        match self.tokens.get(self.pos).map(|(_, t)| t.clone()) {
            None => Err((
                at,
                "expected a stimulus, `*`, `not` or `(`; the expression ended".into(),
            )),
            Some(Token::LParen) => {
                self.pos += 1;
                let inner = self.or()?;
                if self.peek() != Some(&Token::RParen) {
                    return Err((self.at(), "expected `)`".into()));
                }
                self.pos += 1;
                Ok(inner)
            }
            Some(Token::Star) => {
                self.pos += 1;
                Ok(Expr::Wildcard)
            }
            Some(Token::Word(name)) => {
                self.pos += 1;
                let negate = match self.peek() {
                    Some(Token::Eq) => false,
                    Some(Token::Ne) => true,
                    _ => return Ok(Expr::Present(name)),
                };
                self.pos += 1;
                let value = match self.tokens.get(self.pos).map(|(_, t)| t.clone()) {
                    Some(Token::Word(v) | Token::Quoted(v)) => v,
                    _ => return Err((self.at(), format!("expected a value after `{name} =`"))),
                };
                self.pos += 1;
                Ok(if negate {
                    Expr::NotEquals(name, value)
                } else {
                    Expr::Equals(name, value)
                })
            }
            Some(other) => Err((at, format!("unexpected {}", describe(&other)))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::{BTreeMap, BTreeSet};

    struct Memory {
        present: BTreeSet<&'static str>,
        values: BTreeMap<&'static str, &'static str>,
    }

    impl Stimuli for Memory {
        fn present(&self, name: &str) -> bool {
            self.present.contains(name) || self.values.contains_key(name)
        }
        fn value(&self, name: &str) -> Option<&str> {
            self.values.get(name).copied()
        }
    }

    fn memory(present: &[&'static str], values: &[(&'static str, &'static str)]) -> Memory {
        Memory {
            present: present.iter().copied().collect(),
            values: values.iter().copied().collect(),
        }
    }

    #[test]
    fn the_papers_condition() {
        let e = Expr::parse("Object = Visible AND Acquire").unwrap();
        assert!(e.eval(&memory(&["Acquire"], &[("Object", "Visible")]), false));
        assert!(!e.eval(&memory(&["Acquire"], &[("Object", "Hidden")]), false));
        assert!(!e.eval(&memory(&[], &[("Object", "Visible")]), false));
        assert_eq!(e.positive_names(), ["Acquire"]);
        assert_eq!(e.names(), ["Object", "Acquire"]);
    }

    #[test]
    fn precedence_parentheses_and_negation() {
        let e = Expr::parse("a or b and not c").unwrap();
        assert_eq!(e.to_string(), "(a or (b and not (c)))");
        let e = Expr::parse("(a || b) && !c").unwrap();
        assert!(e.eval(&memory(&["b"], &[]), false));
        assert!(!e.eval(&memory(&["b", "c"], &[]), false));
        assert_eq!(e.positive_names(), ["a", "b"]);
        let e = Expr::parse(r#"Mode != "free run" and *"#).unwrap();
        assert!(e.eval(&memory(&[], &[("Mode", "hold")]), true));
        assert!(!e.eval(&memory(&[], &[("Mode", "free run")]), true));
        assert!(!e.eval(&memory(&[], &[]), false));
        assert!(e.has_wildcard());
    }

    #[test]
    fn display_parses_back_to_the_same_expression() {
        for text in [
            "a",
            "a = b",
            r#"x != "two words""#,
            "not (a and b) or *",
            "a.b-c = 3",
            r#"a = "and""#,
            r#"a = "quote \" and \\ tab	""#,
            "a = 3x",
        ] {
            let e = Expr::parse(text).unwrap();
            assert_eq!(Expr::parse(&e.to_string()).unwrap(), e, "{text}");
        }
    }

    #[test]
    fn bad_expressions_say_where() {
        for (text, at) in [
            ("", 0),
            ("a and", 5),
            ("(a or b", 7),
            ("a = ", 4),
            ("a b", 2),
            ("a $ b", 2),
            ("\"open", 0),
            (")", 0),
        ] {
            let err = Expr::parse(text).unwrap_err();
            assert_eq!(err.at, at, "{text:?}: {err}");
        }
        let deep = format!("{}a{}", "(".repeat(100), ")".repeat(100));
        assert!(Expr::parse(&deep).is_err());
        assert!(Expr::parse(&"not ".repeat(100)).is_err());
        assert!(Expr::parse(&"a or ".repeat(2000)).is_err());
    }

    proptest::proptest! {
        #[test]
        fn arbitrary_text_never_panics(text in "\\PC{0,80}") {
            let _ = Expr::parse(&text);
        }
    }
}
