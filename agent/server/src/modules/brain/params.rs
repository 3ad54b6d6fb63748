//! The brain module's parameters (`[modules.brain]` in the configuration), checked at start.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

use agent_brain::Language;
use serde::Deserialize;

/// `[modules.brain]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BrainParams {
    /// Read by the server to switch the module off; accepted and ignored here.
    #[serde(default, rename = "enabled")]
    _enabled: serde::de::IgnoredAny,
    /// The teleo-reactive program; a relative path is taken from the working directory. By default the
    /// program of the agent's language (`config/brain.tr`, `config/brain.it.tr`).
    #[serde(default)]
    pub program: Option<PathBuf>,
    /// The commands programs may `run`, by name: each a fixed command line (no shell).
    #[serde(default = "default_commands")]
    pub commands: BTreeMap<String, Vec<String>>,
    /// A command still running after this long is killed and reported as failed.
    #[serde(default = "default_command_timeout_ms")]
    pub command_timeout_ms: u64,
    /// How long a `call` waits for the service's answer.
    #[serde(default = "default_call_timeout_ms")]
    pub call_timeout_ms: u64,
    /// Command output and service answers are cut to this many characters before they become percepts (and
    /// are possibly spoken).
    #[serde(default = "default_answer_chars")]
    pub answer_chars: usize,
    /// Own-voice suppression: a transcript arriving up to this long after the agent finished saying something
    /// is compared with it.
    #[serde(default = "default_echo_window_ms")]
    pub echo_window_ms: u64,
    /// Own-voice suppression: the share (0 to 1) of a transcript's words, in order, that must come from one
    /// recent utterance for the transcript to be dropped as an echo.
    #[serde(default = "default_echo_threshold")]
    pub echo_threshold: f64,
    /// A `chat` reply ends after this long, whatever it has said (the language-model satellite stops generating;
    /// its own `--timeout-s` applies when lower). A satellite that has not answered 5 s later counts as failed.
    #[serde(default = "default_chat_timeout_ms")]
    pub chat_timeout_ms: u64,
    /// Sentences per `chat` reply at most (the satellite's own `--max-sentences` applies when lower).
    #[serde(default = "default_chat_max_sentences")]
    pub chat_max_sentences: u32,
    /// Turns of the conversation a chat turn carries (and the pair database keeps), each a question and its reply.
    #[serde(default = "default_chat_memory_turns")]
    pub chat_memory_turns: usize,
    /// `thinking` is asserted when a chat turn has no sentence this long after the end of the user's speech (the
    /// program may say a short acknowledgement, docs/brain.md); 0 never asserts it (tests that time the answer).
    #[serde(default = "default_chat_thinking_ms")]
    pub chat_thinking_ms: u64,
    /// Preemptive replies: the model starts on the transcript of a pause (`Agent.transcript.pause`) when the
    /// program would hand that text to `chat`, and the reply is kept when the final transcript is the same.
    #[serde(default = "default_true")]
    pub chat_preempt: bool,
    /// The conversation is forgotten after this long without a chat turn.
    #[serde(default = "default_chat_forget_after_s")]
    pub chat_forget_after_s: u64,
    /// The local time zone as minutes east of UTC, for `time.*`; by default the server's own.
    #[serde(default)]
    pub utc_offset_minutes: Option<i32>,
}

fn default_chat_thinking_ms() -> u64 {
    400
}

fn default_true() -> bool {
    true
}

fn default_commands() -> BTreeMap<String, Vec<String>> {
    BTreeMap::from([
        (
            "uptime".to_owned(),
            vec!["uptime".to_owned(), "-p".to_owned()],
        ),
        ("hostname".to_owned(), vec!["hostname".to_owned()]),
    ])
}

fn default_command_timeout_ms() -> u64 {
    5000
}

fn default_call_timeout_ms() -> u64 {
    3000
}

fn default_chat_timeout_ms() -> u64 {
    15_000
}

fn default_chat_max_sentences() -> u32 {
    3
}

fn default_chat_memory_turns() -> usize {
    6
}

fn default_chat_forget_after_s() -> u64 {
    600
}

fn default_answer_chars() -> usize {
    300
}

fn default_echo_window_ms() -> u64 {
    2500
}

fn default_echo_threshold() -> f64 {
    0.6
}

impl BrainParams {
    /// Reads and checks the parameters; errors name the key and the reason.
    pub fn from_json(params: &serde_json::Value) -> anyhow::Result<BrainParams> {
        let params: BrainParams = serde_path_to_error::deserialize(params)
            .map_err(|e| anyhow::anyhow!("[modules.brain] {}: {}", e.path(), e.inner()))?;
        params
            .validate()
            .map_err(|(key, reason)| anyhow::anyhow!("[modules.brain] {key}: {reason}"))?;
        Ok(params)
    }

    fn validate(&self) -> Result<(), (&'static str, String)> {
        for (name, argv) in &self.commands {
            if name.is_empty() {
                return Err(("commands", "a command name is empty".into()));
            }
            if argv.first().is_none_or(|program| program.is_empty()) {
                return Err((
                    "commands",
                    format!("command `{name}` has no program to run"),
                ));
            }
        }
        if !(0.0..=1.0).contains(&self.echo_threshold) {
            return Err((
                "echo_threshold",
                format!("{} is outside 0..=1", self.echo_threshold),
            ));
        }
        for (key, value) in [
            ("command_timeout_ms", self.command_timeout_ms),
            ("call_timeout_ms", self.call_timeout_ms),
            ("chat_timeout_ms", self.chat_timeout_ms),
            ("chat_forget_after_s", self.chat_forget_after_s),
        ] {
            if value == 0 {
                return Err((key, "must be at least 1".into()));
            }
        }
        if self.chat_max_sentences == 0 {
            return Err(("chat_max_sentences", "must be at least 1".into()));
        }
        if self.answer_chars == 0 {
            return Err(("answer_chars", "must be at least 1".into()));
        }
        if let Some(minutes) = self.utc_offset_minutes
            && minutes.abs() > 14 * 60
        {
            return Err((
                "utc_offset_minutes",
                format!("{minutes} is not a UTC offset (at most 14 hours)"),
            ));
        }
        Ok(())
    }

    /// The program to run: the configured one, or the default of `language`.
    pub fn program(&self, language: Language) -> PathBuf {
        self.program.clone().unwrap_or_else(|| {
            PathBuf::from(match language {
                Language::En => "config/brain.tr",
                Language::It => "config/brain.it.tr",
            })
        })
    }

    pub fn command_timeout(&self) -> Duration {
        Duration::from_millis(self.command_timeout_ms)
    }

    pub fn call_timeout(&self) -> Duration {
        Duration::from_millis(self.call_timeout_ms)
    }

    pub fn chat_timeout(&self) -> Duration {
        Duration::from_millis(self.chat_timeout_ms)
    }

    pub fn chat_forget_after(&self) -> Duration {
        Duration::from_secs(self.chat_forget_after_s)
    }

    pub fn echo_window(&self) -> Duration {
        Duration::from_millis(self.echo_window_ms)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn defaults_apply_to_an_absent_section() -> anyhow::Result<()> {
        let params = BrainParams::from_json(&json!({}))?;
        assert_eq!(
            params.program(Language::En),
            PathBuf::from("config/brain.tr")
        );
        assert_eq!(
            params.program(Language::It),
            PathBuf::from("config/brain.it.tr")
        );
        assert!(params.commands.contains_key("uptime"));
        Ok(())
    }

    #[test]
    fn errors_name_the_key() {
        let error = |value| {
            BrainParams::from_json(&value)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default()
        };
        assert!(error(json!({"progam": "x"})).contains("unknown field `progam`"));
        assert!(
            error(json!({"echo_threshold": 2.0})).starts_with("[modules.brain] echo_threshold:")
        );
        assert!(error(json!({"commands": {"x": []}})).contains("command `x` has no program"));
        assert!(
            error(json!({"call_timeout_ms": "soon"}))
                .starts_with("[modules.brain] call_timeout_ms:")
        );
    }
}
