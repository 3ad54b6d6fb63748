//! What produces a reply: a chat in, text pieces out as they are generated, stopped by a flag, a deadline or a
//! token limit. The local llama.cpp engine (`engine.rs`) and an OpenAI-compatible endpoint (`endpoint.rs`) both
//! implement it.

use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// Who speaks a message of the chat given to the model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Speaker {
    System,
    User,
    Assistant,
}

impl Speaker {
    /// The role name chat templates and OpenAI-compatible servers use.
    pub fn role(self) -> &'static str {
        match self {
            Speaker::System => "system",
            Speaker::User => "user",
            Speaker::Assistant => "assistant",
        }
    }
}

/// One message of the chat given to the model.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Message {
    pub speaker: Speaker,
    pub content: String,
}

/// A constraint on what the model may write: the same language in the two forms generators take.
#[derive(Debug, Clone, PartialEq)]
pub struct Constraint {
    /// llama.cpp's GBNF grammar, its root rule named `root`.
    pub gbnf: String,
    /// The JSON schema an OpenAI-compatible server takes as `response_format`.
    pub schema: serde_json::Value,
}

/// The limits of one generation.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    pub max_tokens: u32,
    pub deadline: Instant,
}

/// What the caller says after each piece.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flow {
    Continue,
    Stop,
}

/// Why a generation ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ended {
    /// The model ended its reply.
    EndOfText,
    /// `Limits::max_tokens`.
    MaxTokens,
    /// `Limits::deadline`.
    Deadline,
    /// The cancel flag was raised.
    Cancelled,
    /// The piece callback said stop.
    Stopped,
}

/// What one generation did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Generated {
    pub ended: Ended,
    pub prompt_tokens: u32,
    /// Prompt tokens whose keys and values were reused from the previous generation.
    pub cached_tokens: u32,
    pub tokens: u32,
    /// From the call to the first generated piece.
    pub first_token: Option<Duration>,
}

/// Why a generation failed.
#[derive(Debug, thiserror::Error)]
pub enum GenerateError {
    #[error("the prompt does not fit: {tokens} tokens, the context holds {context}")]
    PromptTooLong { tokens: usize, context: u32 },
    #[error("the model failed: {0}")]
    Model(String),
    #[error("the endpoint failed: {0}")]
    Endpoint(String),
}

/// A model that writes replies.
pub trait Generator: Send {
    /// The model's name as transcripts and traces show it.
    fn model(&self) -> &str;

    /// The chat as the model sees it (its chat template applied), for the rule trace.
    fn render(&self, chat: &[Message]) -> Result<String, GenerateError>;

    /// Generates the reply to `chat`, handing each piece of text to `on_piece` as it comes. Stops within one token
    /// of `cancel` being raised.
    fn generate(
        &mut self,
        chat: &[Message],
        constraint: Option<&Constraint>,
        limits: Limits,
        cancel: &AtomicBool,
        on_piece: &mut dyn FnMut(&str) -> Flow,
    ) -> Result<Generated, GenerateError>;
}
