//! The questions about the example knowledge folder (`bench/knowledge/questions.toml`), read by knowledge-bench
//! (the search) and voice-latency's knowledge phase (the spoken answers).

use std::path::{Path, PathBuf};

use anyhow::Context;

/// `questions.toml`.
#[derive(Debug, serde::Deserialize)]
pub struct Sets {
    pub on_topic: Vec<OnTopic>,
    pub off_topic: Vec<String>,
}

/// A question the folder answers.
#[derive(Debug, serde::Deserialize)]
pub struct OnTopic {
    pub question: String,
    /// The file whose passage answers it.
    pub file: String,
    /// Text the answering passage contains (compared without case).
    pub fact: String,
}

/// The sets in the source tree, found whatever the working directory.
pub fn default_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("knowledge/questions.toml")
}

pub fn load(path: &Path) -> anyhow::Result<Sets> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))
}

/// `text` holds `fact`, compared without case.
pub fn has_fact(text: &str, fact: &str) -> bool {
    text.to_lowercase().contains(&fact.to_lowercase())
}
