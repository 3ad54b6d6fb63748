//! What the engine asks the host to do: plain action values, and the effects that start, stop or fire them.

use std::fmt;

use serde::Serialize;

use crate::value::{Quoted, Value};

/// An instantiated action; the engine performs no I/O, the host executes these.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "action", rename_all = "lowercase")]
pub enum Action {
    /// Speak the text (through the TTS module).
    Say { text: String },
    /// Publish a JSON payload on a stream channel.
    Publish { channel: String, payload: Value },
    /// Call a service channel; the host asserts `reply(service, text)` or `failed(service, reason)` when it ends.
    Call { service: String, payload: Value },
    /// Run a whitelisted command by name; the host asserts `output(command, text)` or `failed(command, reason)`.
    Run { command: String },
    /// Set a pair-database value.
    Set { key: String, value: Value },
    /// Stop what the agent is saying (and any speech queued).
    Cancel,
    /// Hand the turn to the language model with what the user said. Without a tool the model answers in words;
    /// with one (a service declared with `tool`), it must answer with a call of that service. The host asserts
    /// `failed("chat", reason)` when no model serves or it fails mid-reply.
    Chat { text: String, tool: Option<String> },
    /// Forget the language model's memory of the conversation.
    #[serde(rename = "forget_conversation")]
    ForgetConversation,
    /// Answer `text` from the knowledge folder: the host says its best passage (docs/knowledge.md), or asserts
    /// `failed("recall", reason)` when the folder holds nothing confident about it.
    Recall { text: String },
    /// Remember the face of the person talking (or the only one in view) under `name`, in the pair database; the
    /// host asserts `failed("learn_face", reason)` when there is no such face (docs/vision.md, "Acquaintance").
    #[serde(rename = "learn_face")]
    LearnFace { name: String },
    /// Erase what was stored of the face of the person talking (or the only one in view).
    #[serde(rename = "forget_face")]
    ForgetFace,
    /// Show an expression on the avatar for a few seconds (`happy`, `surprised`, `sad`...; docs/browser-link.md).
    Mood { mood: String },
}

impl fmt::Display for Action {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Action::Say { text } => write!(f, "say({text:?})"),
            Action::Publish { channel, payload } => {
                write!(f, "publish({channel:?}, {})", Quoted(payload))
            }
            Action::Call { service, payload } => {
                write!(f, "call({service:?}, {})", Quoted(payload))
            }
            Action::Run { command } => write!(f, "run({command:?})"),
            Action::Set { key, value } => write!(f, "set({key:?}, {})", Quoted(value)),
            Action::Cancel => f.write_str("cancel"),
            Action::Chat { text, tool: None } => write!(f, "chat({text:?})"),
            Action::Chat {
                text,
                tool: Some(tool),
            } => write!(f, "chat({text:?}, {tool:?})"),
            Action::ForgetConversation => f.write_str("forget_conversation"),
            Action::Recall { text } => write!(f, "recall({text:?})"),
            Action::LearnFace { name } => write!(f, "learn_face({name:?})"),
            Action::ForgetFace => f.write_str("forget_face"),
            Action::Mood { mood } => write!(f, "mood({mood:?})"),
        }
    }
}

/// A change the host must make: start a durative action when its rule becomes active, stop it when the rule
/// stops being active, or fire a discrete action once on entry.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "effect", content = "do", rename_all = "lowercase")]
pub enum Effect {
    Start(Action),
    Stop(Action),
    Fire(Action),
}

impl Effect {
    pub fn action(&self) -> &Action {
        match self {
            Effect::Start(action) | Effect::Stop(action) | Effect::Fire(action) => action,
        }
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Effect::Start(action) => write!(f, "start {action}"),
            Effect::Stop(action) => write!(f, "stop {action}"),
            Effect::Fire(action) => write!(f, "fire {action}"),
        }
    }
}
