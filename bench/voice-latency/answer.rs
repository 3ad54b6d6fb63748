//! How one question of the knowledge phase was answered, as the hub showed it: what `Watcher::follow_answer`
//! collects and the knowledge phase scores.

/// How one question was answered, as the hub showed it.
#[derive(Debug, Default)]
pub struct Answer {
    /// The action of the rule that heard the question (`recall(...)`, `chat(...)`, `say(...)`).
    pub action: String,
    /// The `passage` steps of the trace: `file (heading): text` for a recall, `file: text` in a chat turn's facts.
    pub passages: Vec<String>,
    /// What the agent said: the recalled passage, the model's sentences, or the rule's own `say`.
    pub spoken: String,
}

impl Answer {
    /// The rule's actions (`a; b; c`) handed the question to the model.
    pub fn by_model(&self) -> bool {
        self.action.contains("chat(")
    }
    /// A rule said the knowledge folder's passage.
    pub fn recalled(&self) -> bool {
        self.action.contains("recall(")
    }
}
