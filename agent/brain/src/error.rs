//! Errors: a program that does not load (with line, column and the offending line) and a percept the host got wrong.

use std::fmt;

use crate::syntax::Pos;

/// A problem found while reading or checking a program, before it is placed in the source text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Diagnostic {
    pub pos: Pos,
    pub message: String,
}

impl Diagnostic {
    pub fn new(pos: Pos, message: impl Into<String>) -> Self {
        Diagnostic {
            pos,
            message: message.into(),
        }
    }
}

/// A program that could not be loaded: where, why, and the line it happened on.
///
/// Displayed in the compiler style `config/brain.tr:12:7: expected ')'`, followed by the source line and a caret,
/// so that a reload failure logged by the host points straight at the mistake.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct LoadError {
    /// The file name (or another label) the program was loaded from.
    pub origin: String,
    pub line: u32,
    pub col: u32,
    pub message: String,
    /// The offending source line, for display.
    pub source_line: String,
}

impl LoadError {
    pub(crate) fn locate(origin: &str, source: &str, diagnostic: Diagnostic) -> Self {
        let line = diagnostic.pos.line.max(1);
        let source_line = source
            .lines()
            .nth(line as usize - 1)
            .unwrap_or_default()
            .to_owned();
        LoadError {
            origin: origin.to_owned(),
            line,
            col: diagnostic.pos.col.max(1),
            message: diagnostic.message,
            source_line,
        }
    }
}

impl fmt::Display for LoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}:{}:{}: {}",
            self.origin, self.line, self.col, self.message
        )?;
        if !self.source_line.is_empty() {
            let pad: String = self
                .source_line
                .chars()
                .take(self.col as usize - 1)
                .map(|c| if c == '\t' { '\t' } else { ' ' })
                .collect();
            write!(f, "\n  | {}\n  | {pad}^", self.source_line)?;
        }
        Ok(())
    }
}

/// A percept the host tried to assert that does not fit the program's declaration.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PerceptError {
    #[error("percept `{name}` takes {expected} argument(s), got {got}")]
    Arity {
        name: String,
        expected: usize,
        got: usize,
    },
    #[error("argument {index} of percept `{name}` must be {expected}, got {got}")]
    Type {
        name: String,
        index: usize,
        expected: &'static str,
        got: &'static str,
    },
    #[error(
        "`{name}` is declared as a belief the program keeps itself, not a percept the host can assert"
    )]
    NotPercept { name: String },
}
