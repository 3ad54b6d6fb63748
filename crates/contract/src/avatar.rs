//! The avatar commands on `Agent.avatar`, which the page obeys: `{"cmd": NAME, ...}` (docs/browser-link.md). The TTS
//! module publishes them (visemes with its speech, captions, and through its behaviour controllers blink, gaze and
//! mood); the vision module may publish gaze.

use serde::{Deserialize, Serialize};

/// One command. Times are milliseconds; `Visemes` cues are relative to sample 0 of `utterance`'s speech on
/// `Agent.speech`, so the page schedules them on its audio clock.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "cmd", rename_all = "snake_case")]
pub enum AvatarCommand {
    /// A blink in three phases at their own speeds: closing, closed, opening.
    Blink {
        close_ms: u32,
        hold_ms: u32,
        open_ms: u32,
    },
    /// Where to look, in normalised camera-image coordinates (0..1, top-left); `source` is `face`, `motion` or
    /// `idle`, `seq` the video frame it was computed from.
    Gaze {
        x: f64,
        y: f64,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        source: Option<String>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        seq: Option<u64>,
    },
    /// An expression (`neutral`, `happy`, `thinking`, `listening`...), 0..1.
    Mood {
        mood: String,
        #[serde(default = "full")]
        intensity: f64,
    },
    /// Mouth shapes (the 15 Oculus visemes) of one utterance.
    Visemes {
        utterance: u64,
        items: Vec<VisemeCue>,
    },
    /// Stop speaking: one utterance, or all when `utterance` is absent.
    SpeechStop {
        #[serde(default, skip_serializing_if = "Option::is_none")]
        utterance: Option<u64>,
        /// The user started speaking over the agent (barge-in): the page fades the speech out rather than cutting
        /// it, and the brain records the interrupted reply. Only present when true.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        barge_in: bool,
    },
    /// The caption shown while the agent speaks.
    Say { text: String },
}

/// A mouth shape due `t_ms` after sample 0 of its utterance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VisemeCue {
    pub t_ms: f64,
    /// One of [`VISEMES`].
    pub v: String,
}

/// The viseme names, in the Oculus order.
pub const VISEMES: [&str; 15] = [
    "sil", "PP", "FF", "TH", "DD", "kk", "CH", "SS", "nn", "RR", "aa", "E", "I", "O", "U",
];

fn full() -> f64 {
    1.0
}
