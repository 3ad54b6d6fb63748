//! The `Agent.latency` message: one per conversational turn, as the observer module matched it up from the
//! pipeline's own timestamps (VAD end, transcript, rule, first reply PCM); the page's status strip shows it.

use serde::{Deserialize, Serialize};

/// How long one turn took, stage by stage (ms, hub clock).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TurnLatency {
    /// Always `voice` (the kind leaves room for other figures on the channel).
    pub kind: String,
    /// When the user's voice stopped (ms since the Unix epoch).
    pub speech_end_ms: u64,
    /// End of speech -> the VAD end event (the silence hangover).
    pub vad_ms: f64,
    /// The VAD end event -> the final transcript.
    pub transcript_ms: f64,
    /// The final transcript -> the rule that fired on it.
    pub rule_ms: f64,
    /// The rule -> the first PCM of the reply.
    pub reply_ms: f64,
    /// End of speech -> the first PCM of the reply: what the user waited.
    pub total_ms: f64,
    /// The stages that are behind on this machine: their median over the last turns is over their budget (`vad`,
    /// `transcription`, `rule`, `reply`). Empty while the machine keeps up; the page shows them beside the figure.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub behind: Vec<String>,
}
