//! The `Agent.transcript` messages: the transcript a whisper satellite publishes for each utterance, and the
//! voice-activity events (`{"vad":"start"|"end",...}`) that frame it. The brain answers final transcripts; the TTS
//! module's barge-in and the behaviour controllers follow the voice activity. `flowctl pub` users may also send
//! plain text, which consumers take as a final transcript.

use serde::{Deserialize, Serialize};

/// One transcript, serialised as JSON on `Agent.transcript`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TranscriptMessage {
    /// The utterance id every satellite derives from the audio clock.
    pub utterance: String,
    pub text: String,
    /// Start of the utterance audio and end of speech on the hub clock (µs since the Unix epoch).
    pub start_us: u64,
    pub end_us: u64,
    pub satellite: String,
    pub model: String,
    /// Inference time.
    pub processing_ms: u64,
    /// True on `Agent.transcript`; false on `Agent.transcript.pause`, where the transcript of a pause goes out
    /// before the end of the turn is decided (a preview: the final one follows unless the voice resumed).
    #[serde(rename = "final")]
    pub is_final: bool,
    /// The text was decoded during the end-of-speech hangover, from the audio the utterance had when it paused
    /// (the very audio it ended with). Only present when true.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub speculative: bool,
    /// The fitted encoder window made whisper loop, and the text comes from a second decode with the full 30 s
    /// window, which costs several times more (`processing_ms` includes both). Only present when true.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub full_window_retry: bool,
    /// How the satellite judged the transcript of the pause the utterance ended at: `complete` (the turn ended
    /// after the short confirmation silence instead of the whole hangover), `incomplete` (held open for the rest
    /// of the sentence) or `unknown` (the ordinary hangover). Absent when no pause was judged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub turn: Option<TurnVerdict>,
    /// Inference threads the decode ran on: the satellite's share of its machine's cores, which it splits with
    /// the other satellites there. Absent from satellites that do not say.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threads: Option<u32>,
    /// The turn's W3C `traceparent` (its root span, `flow_telemetry::TraceContext::turn` of the utterance), which
    /// the spans of every process that works on the turn hang under (docs/telemetry.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trace: Option<String>,
}

/// What a transcript says about the end of the user's turn (docs/asr.md, "End of turn").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TurnVerdict {
    /// The user said something whole: the turn ends after the confirmation silence.
    Complete,
    /// The user is mid-sentence: the utterance is held open longer than the hangover for the rest.
    Incomplete,
    /// No telling: the ordinary hangover ends the utterance.
    Unknown,
}

/// Which way voice activity changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum VadKind {
    Start,
    End,
}

/// A voice-activity event, serialised as JSON on `Agent.transcript` beside the transcripts (it has no `text`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct VadMessage {
    pub vad: VadKind,
    /// When the voice began or ended on the hub clock (ms since the Unix epoch), the clock of `start_us`/`end_us`.
    pub at_ms: u64,
    /// On `end`: the utterance whose transcript follows; absent when the speech was dropped as too short or noise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub utterance: Option<String>,
    /// The satellite that published the event (the transcript relay).
    pub satellite: String,
    /// On an end: the `traceparent` of the turn the utterance starts (as on its transcript).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trace: Option<String>,
}

/// What a consumer reads of any `Agent.transcript` message: a [`TranscriptMessage`], a [`VadMessage`], a partial
/// result (`"final": false` or `"partial": true`) or a note from another producer. Every field is optional, since
/// producers other than whisper-sat (flowctl, other ASR satellites) send less; `vad` stays text so that a consumer
/// can name an unknown value.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Heard {
    #[serde(default)]
    pub text: Option<String>,
    #[serde(default, rename = "final")]
    pub is_final: Option<bool>,
    #[serde(default)]
    pub partial: bool,
    #[serde(default)]
    pub vad: Option<String>,
    /// The turn's `traceparent` ([`TranscriptMessage::trace`]).
    #[serde(default)]
    pub trace: Option<String>,
}

impl Heard {
    /// Whether this is a partial result: the user is still speaking.
    pub fn is_partial(&self) -> bool {
        self.is_final == Some(false) || self.partial
    }
}
