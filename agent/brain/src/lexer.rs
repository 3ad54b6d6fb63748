//! Splits program text into tokens, each with the line and column where it starts.

use std::time::Duration;

use crate::error::Diagnostic;
use crate::syntax::Pos;

#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Tok {
    /// A lower-case name: keyword, predicate, procedure, function, symbol or rule label.
    Ident(String),
    /// A name starting with an upper-case letter or `_`.
    Var(String),
    Str(String),
    Num(f64),
    Duration(Duration),
    LParen,
    RParen,
    LBracket,
    RBracket,
    LBrace,
    RBrace,
    Comma,
    Colon,
    Dot,
    Amp,
    /// `~`
    Tilde,
    /// `~>`
    Durative,
    /// `++`
    Discrete,
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
    Eof,
}

impl Tok {
    /// How the token is named in "expected ..., found ..." messages.
    pub fn describe(&self) -> String {
        match self {
            Tok::Ident(name) => format!("`{name}`"),
            Tok::Var(name) => format!("variable `{name}`"),
            Tok::Str(_) => "a string".into(),
            Tok::Num(_) => "a number".into(),
            Tok::Duration(_) => "a duration".into(),
            Tok::Eof => "the end of the program".into(),
            other => format!("`{}`", other.symbol()),
        }
    }

    fn symbol(&self) -> &'static str {
        match self {
            Tok::LParen => "(",
            Tok::RParen => ")",
            Tok::LBracket => "[",
            Tok::RBracket => "]",
            Tok::LBrace => "{",
            Tok::RBrace => "}",
            Tok::Comma => ",",
            Tok::Colon => ":",
            Tok::Dot => ".",
            Tok::Amp => "&",
            Tok::Tilde => "~",
            Tok::Durative => "~>",
            Tok::Discrete => "++",
            Tok::Eq => "=",
            Tok::Ne => "!=",
            Tok::Lt => "<",
            Tok::Le => "<=",
            Tok::Gt => ">",
            Tok::Ge => ">=",
            _ => "?",
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Token {
    pub tok: Tok,
    pub pos: Pos,
}

/// Tokenises `source`; `origin` is where the text starts (templates are tokenised from inside a string).
pub(crate) fn tokenize(source: &str, origin: Pos) -> Result<Vec<Token>, Diagnostic> {
    let mut lexer = Lexer {
        chars: source.chars().collect(),
        at: 0,
        pos: origin,
    };
    let mut tokens = Vec::new();
    loop {
        let token = lexer.next_token()?;
        let end = token.tok == Tok::Eof;
        tokens.push(token);
        if end {
            return Ok(tokens);
        }
    }
}

struct Lexer {
    chars: Vec<char>,
    at: usize,
    pos: Pos,
}

impl Lexer {
    fn peek(&self) -> Option<char> {
        self.chars.get(self.at).copied()
    }

    fn peek_second(&self) -> Option<char> {
        self.chars.get(self.at + 1).copied()
    }

    fn bump(&mut self) -> Option<char> {
        let c = self.peek()?;
        self.at += 1;
        if c == '\n' {
            self.pos.line += 1;
            self.pos.col = 1;
        } else {
            self.pos.col += 1;
        }
        Some(c)
    }

    fn skip_blanks_and_comments(&mut self) {
        while let Some(c) = self.peek() {
            if c == '#' {
                while self.peek().is_some_and(|c| c != '\n') {
                    self.bump();
                }
            } else if c.is_whitespace() {
                self.bump();
            } else {
                break;
            }
        }
    }

    fn next_token(&mut self) -> Result<Token, Diagnostic> {
        self.skip_blanks_and_comments();
        let pos = self.pos;
        let Some(c) = self.peek() else {
            return Ok(Token { tok: Tok::Eof, pos });
        };
        let tok = match c {
            '"' => self.string(pos)?,
            c if c.is_ascii_digit() => self.number(pos)?,
            '-' if self.peek_second().is_some_and(|c| c.is_ascii_digit()) => {
                self.bump();
                match self.number(pos)? {
                    Tok::Num(n) => Tok::Num(-n),
                    _ => return Err(Diagnostic::new(pos, "a duration cannot be negative")),
                }
            }
            c if c.is_alphabetic() || c == '_' => self.word(),
            _ => self.punctuation(pos)?,
        };
        Ok(Token { tok, pos })
    }

    fn word(&mut self) -> Tok {
        let mut word = String::new();
        while let Some(c) = self.peek().filter(|c| c.is_alphanumeric() || *c == '_') {
            word.push(c);
            self.bump();
        }
        if word.starts_with(|c: char| c.is_uppercase() || c == '_') {
            Tok::Var(word)
        } else {
            Tok::Ident(word)
        }
    }

    fn number(&mut self, pos: Pos) -> Result<Tok, Diagnostic> {
        let mut digits = String::new();
        while let Some(c) = self.peek().filter(|c| c.is_ascii_digit()) {
            digits.push(c);
            self.bump();
        }
        if self.peek() == Some('.') && self.peek_second().is_some_and(|c| c.is_ascii_digit()) {
            digits.push('.');
            self.bump();
            while let Some(c) = self.peek().filter(|c| c.is_ascii_digit()) {
                digits.push(c);
                self.bump();
            }
        }
        let value: f64 = digits
            .parse()
            .map_err(|_| Diagnostic::new(pos, format!("`{digits}` is not a number")))?;
        // A unit glued to the number makes it a duration: `4s`, `500ms`, `2m`, `1h`.
        let mut unit = String::new();
        while let Some(c) = self.peek().filter(|c| c.is_ascii_alphabetic()) {
            unit.push(c);
            self.bump();
        }
        let seconds = match unit.as_str() {
            "" => return Ok(Tok::Num(value)),
            "ms" => value / 1000.0,
            "s" => value,
            "m" | "min" => value * 60.0,
            "h" => value * 3600.0,
            other => {
                return Err(Diagnostic::new(
                    pos,
                    format!("unknown duration unit `{other}` (use ms, s, m or h)"),
                ));
            }
        };
        Ok(Tok::Duration(Duration::from_secs_f64(seconds)))
    }

    fn string(&mut self, pos: Pos) -> Result<Tok, Diagnostic> {
        self.bump();
        let mut text = String::new();
        loop {
            match self.bump() {
                None | Some('\n') => {
                    return Err(Diagnostic::new(
                        pos,
                        "this string is not closed on its line",
                    ));
                }
                Some('"') => return Ok(Tok::Str(text)),
                Some('\\') => {
                    let escape_pos = self.pos;
                    match self.bump() {
                        Some('n') => text.push('\n'),
                        Some('t') => text.push('\t'),
                        Some('"') => text.push('"'),
                        Some('\\') => text.push('\\'),
                        other => {
                            let shown = other.map(String::from).unwrap_or_default();
                            return Err(Diagnostic::new(
                                escape_pos,
                                format!("unknown escape `\\{shown}` (use \\\", \\\\, \\n or \\t)"),
                            ));
                        }
                    }
                }
                Some(c) => text.push(c),
            }
        }
    }

    fn punctuation(&mut self, pos: Pos) -> Result<Tok, Diagnostic> {
        let Some(c) = self.bump() else {
            return Ok(Tok::Eof);
        };
        let next = self.peek();
        let (tok, two) = match (c, next) {
            ('~', Some('>')) => (Tok::Durative, true),
            ('+', Some('+')) => (Tok::Discrete, true),
            ('!', Some('=')) => (Tok::Ne, true),
            ('<', Some('=')) => (Tok::Le, true),
            ('>', Some('=')) => (Tok::Ge, true),
            ('~', _) => (Tok::Tilde, false),
            ('<', _) => (Tok::Lt, false),
            ('>', _) => (Tok::Gt, false),
            ('=', _) => (Tok::Eq, false),
            ('(', _) => (Tok::LParen, false),
            (')', _) => (Tok::RParen, false),
            ('[', _) => (Tok::LBracket, false),
            (']', _) => (Tok::RBracket, false),
            ('{', _) => (Tok::LBrace, false),
            ('}', _) => (Tok::RBrace, false),
            (',', _) => (Tok::Comma, false),
            (':', _) => (Tok::Colon, false),
            ('.', _) => (Tok::Dot, false),
            ('&', _) => (Tok::Amp, false),
            (other, _) => {
                return Err(Diagnostic::new(
                    pos,
                    format!("unexpected character `{other}`"),
                ));
            }
        };
        if two {
            self.bump();
        }
        Ok(tok)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn toks(source: &str) -> Vec<Tok> {
        match tokenize(source, Pos { line: 1, col: 1 }) {
            Ok(tokens) => tokens.into_iter().map(|t| t.tok).collect(),
            Err(e) => panic!("unexpected lexer error {e:?}"),
        }
    }

    #[test]
    fn durations_and_operators() {
        assert_eq!(
            toks("4s 500ms ~> ++ ~ != <= X _ x"),
            vec![
                Tok::Duration(Duration::from_secs(4)),
                Tok::Duration(Duration::from_millis(500)),
                Tok::Durative,
                Tok::Discrete,
                Tok::Tilde,
                Tok::Ne,
                Tok::Le,
                Tok::Var("X".into()),
                Tok::Var("_".into()),
                Tok::Ident("x".into()),
                Tok::Eof
            ]
        );
    }

    #[test]
    fn positions_count_lines_and_columns() -> Result<(), Diagnostic> {
        let tokens = tokenize("# comment\n  say(\"hi\")", Pos { line: 1, col: 1 })?;
        assert_eq!(tokens[0].pos, Pos { line: 2, col: 3 });
        assert_eq!(tokens[2].pos, Pos { line: 2, col: 7 });
        Ok(())
    }

    #[test]
    fn unclosed_string_is_reported_where_it_starts() {
        let error = tokenize("say(\"hi)\n", Pos { line: 1, col: 1 }).err();
        assert_eq!(error.map(|e| e.pos), Some(Pos { line: 1, col: 5 }));
    }
}
