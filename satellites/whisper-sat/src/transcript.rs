//! The `Agent.transcript` messages a satellite publishes: the types are the contract's
//! (`agent_contract::transcript`); this is where the satellite's voice activity becomes one.

pub use agent_contract::transcript::{TranscriptMessage, TurnVerdict, VadKind, VadMessage};

use crate::activity::VoiceActivity;

/// The message for a voice-activity change seen by `satellite`.
pub fn vad_message(activity: &VoiceActivity, satellite: &str) -> VadMessage {
    let (vad, at_us, utterance) = match activity {
        VoiceActivity::Start { at_us } => (VadKind::Start, *at_us, None),
        VoiceActivity::End { at_us, utterance } => (VadKind::End, *at_us, utterance.clone()),
    };
    VadMessage {
        vad,
        at_ms: at_us / 1000,
        trace: utterance
            .as_deref()
            .map(|u| flow_telemetry::TraceContext::turn(u).traceparent()),
        utterance,
        satellite: satellite.to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn voice_activity_serialises_as_the_contract_says() -> Result<(), serde_json::Error> {
        let start = vad_message(&VoiceActivity::Start { at_us: 1_234_567 }, "sat");
        assert_eq!(
            serde_json::to_value(&start)?,
            serde_json::json!({"vad":"start","at_ms":1234,"satellite":"sat"})
        );
        let end = vad_message(
            &VoiceActivity::End {
                at_us: 2_000_999,
                utterance: Some("u1".into()),
            },
            "sat",
        );
        let v = serde_json::to_value(&end)?;
        let trace = flow_telemetry::TraceContext::turn("u1").traceparent();
        assert_eq!(
            v,
            serde_json::json!({"vad":"end","at_ms":2000,"utterance":"u1","satellite":"sat","trace":trace})
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
            turn: None,
            threads: None,
            trace: None,
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
        let judged = TranscriptMessage {
            turn: Some(TurnVerdict::Complete),
            ..retried
        };
        let v = serde_json::to_value(&judged)?;
        assert_eq!(v["turn"], "complete");
        assert_eq!(serde_json::from_value::<TranscriptMessage>(v)?, judged);
        let threaded = TranscriptMessage {
            threads: Some(1),
            ..judged
        };
        let v = serde_json::to_value(&threaded)?;
        assert_eq!(v["threads"], 1);
        assert_eq!(serde_json::from_value::<TranscriptMessage>(v)?, threaded);
        Ok(())
    }
}
