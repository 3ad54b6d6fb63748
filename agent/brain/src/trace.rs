//! The trace of rule changes: which rule became active, which facts made its guard true, with what bindings,
//! when, and what it did; the host publishes it on `Agent.rules` for the page to show.

use std::fmt;

use serde::Serialize;

use crate::action::Effect;
use crate::value::Value;

/// One rule of the active path, outermost procedure first.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct RuleRef {
    pub procedure: String,
    pub rule: String,
    /// The line of the rule in the program file.
    pub line: u32,
}

impl fmt::Display for RuleRef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}", self.procedure, self.rule)
    }
}

/// A fact that supported the new rule's guard, rendered in program syntax, and how old it was.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Evidence {
    pub fact: String,
    pub age_ms: u64,
}

/// A variable binding of the new active rule.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Binding {
    pub name: String,
    pub value: Value,
}

/// One change of the active rule path.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Trace {
    /// Wall-clock time of the change, milliseconds since the Unix epoch.
    pub unix_ms: i64,
    /// The new active path (empty when no rule's guard holds).
    pub path: Vec<RuleRef>,
    /// The path active before.
    pub previous: Vec<RuleRef>,
    /// True when the same rule was entered again because of a new event (a new `heard`).
    pub reentered: bool,
    /// The facts the new path's guards matched.
    pub because: Vec<Evidence>,
    pub bindings: Vec<Binding>,
    /// The effects of the change, in the order the host should perform them.
    pub effects: Vec<Effect>,
    /// Beliefs the rules remembered or forgot, such as `remember(greeted)`.
    pub updates: Vec<String>,
}

impl fmt::Display for Trace {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let path = |refs: &[RuleRef]| {
            if refs.is_empty() {
                "(none)".to_owned()
            } else {
                refs.iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join(" > ")
            }
        };
        write!(f, "{} -> {}", path(&self.previous), path(&self.path))?;
        if !self.because.is_empty() {
            let facts: Vec<String> = self
                .because
                .iter()
                .map(|e| format!("{} ({} ms ago)", e.fact, e.age_ms))
                .collect();
            write!(f, " because {}", facts.join(", "))?;
        }
        for effect in &self.effects {
            write!(f, "; {effect}")?;
        }
        for update in &self.updates {
            write!(f, "; {update}")?;
        }
        Ok(())
    }
}
