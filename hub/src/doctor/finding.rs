//! One line of the doctor's report: the check, what it found, how bad it is and the fix (a leaf the checks share).

use std::fmt;

/// How bad a finding is: a problem makes the doctor exit with status 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    Ok,
    Warning,
    Problem,
}

/// One line of the doctor's report: what it checked, what it found, and what to do about it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Finding {
    pub level: Level,
    /// The check's name: `models`, `ports`, `data`, `tls`, `agent`.
    pub check: &'static str,
    pub text: String,
    /// What to do, where there is something to do.
    pub fix: Option<String>,
}

impl Finding {
    pub fn ok(check: &'static str, text: impl Into<String>) -> Finding {
        Finding {
            level: Level::Ok,
            check,
            text: text.into(),
            fix: None,
        }
    }

    pub fn warning(
        check: &'static str,
        text: impl Into<String>,
        fix: impl Into<String>,
    ) -> Finding {
        Finding {
            level: Level::Warning,
            check,
            text: text.into(),
            fix: Some(fix.into()),
        }
    }

    pub fn problem(
        check: &'static str,
        text: impl Into<String>,
        fix: impl Into<String>,
    ) -> Finding {
        Finding {
            level: Level::Problem,
            check,
            text: text.into(),
            fix: Some(fix.into()),
        }
    }
}

impl fmt::Display for Finding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let level = match self.level {
            Level::Ok => "ok     ",
            Level::Warning => "warning",
            Level::Problem => "PROBLEM",
        };
        write!(f, "{level} {}: {}", self.check, self.text)?;
        if let Some(fix) = &self.fix {
            write!(f, " (fix: {fix})")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_finding_is_one_line_with_its_fix() {
        let line = Finding::problem("models", "models/x.bin is missing", "make model").to_string();
        assert_eq!(
            line,
            "PROBLEM models: models/x.bin is missing (fix: make model)"
        );
        assert!(!line.contains('\n'));
    }
}
