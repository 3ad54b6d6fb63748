//! The `Agent.transcript` message: what a satellite publishes for each utterance.

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
    /// Always true for now: no partial results are published.
    #[serde(rename = "final")]
    pub is_final: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

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
        };
        let v: serde_json::Value = serde_json::to_value(&t)?;
        assert_eq!(v["final"], true);
        assert_eq!(v["utterance"], "u1");
        assert_eq!(serde_json::from_value::<TranscriptMessage>(v)?, t);
        Ok(())
    }
}
