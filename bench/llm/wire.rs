//! The line protocol between the bench and its two generators (this binary with `--serve`, and
//! llama_cpp_python_bench.py): one JSON request per line in, one JSON reply per line out, the same for both.

use serde::{Deserialize, Serialize};

/// One chat message, as OpenAI-style chat APIs (and llama-cpp-python) take it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ChatMessage {
    pub role: String,
    pub content: String,
}

impl ChatMessage {
    pub fn system(content: String) -> Self {
        Self {
            role: "system".into(),
            content,
        }
    }

    pub fn user(content: String) -> Self {
        Self {
            role: "user".into(),
            content,
        }
    }

    pub fn assistant(content: &str) -> Self {
        Self {
            role: "assistant".into(),
            content: content.into(),
        }
    }
}

/// One generation to time.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Request {
    pub messages: Vec<ChatMessage>,
    pub max_tokens: u32,
}

/// The first line a generator prints, once its model is loaded.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Ready {
    pub ready: bool,
    pub load_s: f64,
}

/// What one generation took, measured inside the generator.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Reply {
    /// From the call (chat template and tokenising included) to the first piece of text.
    pub first_token_s: Option<f64>,
    /// From the first piece of text to the last.
    pub decode_s: Option<f64>,
    pub tokens: u32,
    pub prompt_tokens: Option<u32>,
    /// Prompt tokens taken from the previous generation's cache (the Rust engine reports it).
    pub cached_tokens: Option<u32>,
    pub ended: Option<String>,
    pub text: String,
}

impl Reply {
    /// Tokens per second after the first: the pace of one decode step each.
    pub fn decode_tps(&self) -> Option<f64> {
        let seconds = self.decode_s?;
        (self.tokens > 1 && seconds > 0.0).then(|| f64::from(self.tokens - 1) / seconds)
    }
}

/// The last line a generator prints, at the end of its input.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Finished {
    pub peak_rss_kb: u64,
}
