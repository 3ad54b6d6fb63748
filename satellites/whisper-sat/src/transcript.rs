//! The `Agent.transcript` messages: the transcript a satellite publishes for each utterance, and the voice-activity
//! events (`{"vad":"start"|"end",...}`) that frame it.

use serde::{Deserialize, Serialize};

use crate::activity::VoiceActivity;

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
    /// Always true for now: no partial results are published.
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
}

impl VadMessage {
    /// The message for a voice-activity change seen by `satellite`.
    pub fn new(activity: &VoiceActivity, satellite: &str) -> VadMessage {
        let (vad, at_us, utterance) = match activity {
            VoiceActivity::Start { at_us } => (VadKind::Start, *at_us, None),
            VoiceActivity::End { at_us, utterance } => (VadKind::End, *at_us, utterance.clone()),
        };
        VadMessage {
            vad,
            at_ms: at_us / 1000,
            utterance,
            satellite: satellite.to_owned(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn voice_activity_serialises_as_the_contract_says() -> Result<(), serde_json::Error> {
        let start = VadMessage::new(&VoiceActivity::Start { at_us: 1_234_567 }, "sat");
        assert_eq!(
            serde_json::to_value(&start)?,
            serde_json::json!({"vad":"start","at_ms":1234,"satellite":"sat"})
        );
        let end = VadMessage::new(
            &VoiceActivity::End {
                at_us: 2_000_999,
                utterance: Some("u1".into()),
            },
            "sat",
        );
        let v = serde_json::to_value(&end)?;
        assert_eq!(
            v,
            serde_json::json!({"vad":"end","at_ms":2000,"utterance":"u1","satellite":"sat"})
        );
        // Not a transcript: satellites reading Agent.transcript skip it.
        assert!(serde_json::from_value::<TranscriptMessage>(v).is_err());
        Ok(())
    }

    #[test]
    fn serialises_with_the_contract_field_names() -> Result<(), serde_json::Error> {
        let t = TranscriptMessage {
            utterance: "u1".into(),
            text: "hello".into(),
            start_us: 1,
            end_us: 2,
            satellite: "s".into(),
            model: "tiny.en".into(),
            processing_ms: 3,
            is_final: true,
            speculative: false,
            full_window_retry: false,
        };
        let v: serde_json::Value = serde_json::to_value(&t)?;
        assert_eq!(v["final"], true);
        assert_eq!(v["utterance"], "u1");
        assert!(v.get("speculative").is_none());
        assert!(v.get("full_window_retry").is_none());
        assert_eq!(serde_json::from_value::<TranscriptMessage>(v)?, t);
        let speculative = TranscriptMessage {
            speculative: true,
            ..t
        };
        let v = serde_json::to_value(&speculative)?;
        assert_eq!(v["speculative"], true);
        assert_eq!(serde_json::from_value::<TranscriptMessage>(v)?, speculative);
        let retried = TranscriptMessage {
            full_window_retry: true,
            ..speculative
        };
        let v = serde_json::to_value(&retried)?;
        assert_eq!(v["full_window_retry"], true);
        assert_eq!(serde_json::from_value::<TranscriptMessage>(v)?, retried);
        Ok(())
    }
}
