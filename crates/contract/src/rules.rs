//! The `Agent.rules` message: one per rule change of the brain, what the page's rule trace shows, with the
//! brain's full trace for tools.

use serde::{Deserialize, Serialize};

/// A rule change.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RuleChange {
    /// When it happened (ms since the Unix epoch).
    pub ts_ms: i64,
    /// The program's file name.
    pub program: String,
    /// The path of active rules, as `main.converse > answer.time`; `(none)` when no rule holds.
    pub rule: String,
    /// The source line of the innermost rule.
    pub index: u32,
    /// The actions it started, `; `-separated.
    pub action: String,
    /// The facts its guard rested on.
    pub because: Vec<String>,
    /// The brain's full trace (its own shape, for tools and tests).
    #[serde(default)]
    pub trace: serde_json::Value,
    /// Set on the entry a barge-in adds: the reply the user cut off by speaking over it (the rule that said it
    /// may have ended already; `rule` is what holds now). Absent on rule changes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interrupted: Option<String>,
    /// Set on the entries of a chat turn (the `chat(T)` action): its prompt, each sentence, a call, its end.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chat: Option<ChatStep>,
}

/// One step of a chat turn in the rule trace.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChatStep {
    /// The brain's turn number (the one `Agent.chat.reply` events carry).
    pub turn: u64,
    /// `prompt`, `sentence`, `call`, `end`, `interrupted` or `failed`.
    pub step: String,
    /// The prompt as the model saw it, the sentence, the call as JSON, why it ended, or what was heard of it.
    pub text: String,
}
