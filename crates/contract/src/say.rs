//! The `Agent.say` service of the TTS module: a text to speak (or a cancel), and its answers.

use serde::{Deserialize, Serialize};

/// A request to speak `text`, optionally in another espeak-ng voice, rate or pitch than the configured ones.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SayRequest {
    pub text: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub voice: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_wpm: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pitch: Option<u32>,
    /// The W3C `traceparent` of the reply this speech starts, when it answers a turn (docs/telemetry.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trace: Option<String>,
    /// Synthesise `text` in the configured voice into its cache without playing it (a program's fixed replies,
    /// made before they are first asked for); answered with [`PrepareAnswer`] once done. Speech asked for
    /// meanwhile stops it, so it never holds a reply back by more than one run of the voice.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub prepare: bool,
}

/// The answer to a request to prepare a text: whether its audio is now in the voice's cache (false for a voice
/// without one, espeak-ng, which needs none, and for a preparation that speech asked for meanwhile stopped).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct PrepareAnswer {
    pub cached: bool,
}

/// The answer to a request to speak: the utterance number its speech and visemes carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SayAnswer {
    pub utterance: u64,
}

/// The answer to `{"cancel": "all" | N}`: the utterances stopped.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CancelAnswer {
    pub cancelled: Vec<u64>,
}

/// A page began playing utterance `utterance` of `Agent.speech` (the number its chunks carry): `at_ms` is when its
/// first sample is heard, on the server's clock (ms since the Unix epoch; the page converts with its ping/pong
/// offset). Published on `Agent.playback` by the page link.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlaybackStarted {
    pub utterance: u64,
    pub at_ms: f64,
}
