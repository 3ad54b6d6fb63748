//! How a hub channel's payloads become MCAP messages and back: JSON as JSON, the agent's PCM as
//! `foxglove.RawAudio`, camera JPEGs as `foxglove.CompressedImage`, anything else as raw bytes. Every form keeps
//! what replay needs to restore the original payload byte for byte.

use agent_contract::channels as ch;
use base64::Engine;
use base64::engine::general_purpose::STANDARD as BASE64;
use serde_json::{Value, json};

use crate::error::RecordError;
use crate::schemas;

/// MCAP message encodings the recorder writes.
pub const JSON: &str = "json";
pub const OCTET_STREAM: &str = "application/octet-stream";

/// The length of `Agent.speech`'s prefix: `[utterance u32 le][offset u32 le]`.
const SPEECH_PREFIX: usize = 8;

/// What a channel's messages are recorded as.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Form {
    /// JSON payloads, written as they are (message encoding "json").
    Json,
    /// s16le PCM as `foxglove.RawAudio`; `prefixed` for `Agent.speech`'s utterance/offset framing.
    RawAudio {
        rate: u32,
        channels: u32,
        prefixed: bool,
    },
    /// Camera frames as `foxglove.CompressedImage`.
    Image,
    /// Raw bytes, schema-less.
    Binary,
    /// Not decided yet: JSON if the first message is a JSON object or array, else raw bytes.
    Sniff,
}

impl Form {
    /// The form of a channel from its name and JSON header.
    pub fn of(name: &str, header: &str) -> Form {
        let header: Value = serde_json::from_str(header).unwrap_or(Value::Null);
        let field = |key: &str| header.get(key).and_then(Value::as_str).unwrap_or("");
        let number = |key: &str, default: u32| {
            header
                .get(key)
                .and_then(Value::as_u64)
                .and_then(|n| u32::try_from(n).ok())
                .unwrap_or(default)
        };
        let pcm = name == ch::AUDIO.name || name == ch::SPEECH.name || field("format") == "s16le";
        if pcm {
            return Form::RawAudio {
                rate: number("rate", 22_050),
                channels: number("channels", 1),
                prefixed: name == ch::SPEECH.name || field("framing") == "utterance-offset",
            };
        }
        if name == ch::VIDEO.name || name == ch::VIDEO_Y.name || field("format") == "jpeg" {
            return Form::Image;
        }
        if field("format") == "json" || field("mime") == "application/json" {
            return Form::Json;
        }
        Form::Sniff
    }

    /// Settles [`Form::Sniff`] on the channel's first message.
    pub fn settle(self, first: &[u8]) -> Form {
        match self {
            Form::Sniff => match serde_json::from_slice::<Value>(first) {
                Ok(Value::Object(_) | Value::Array(_)) => Form::Json,
                _ => Form::Binary,
            },
            other => other,
        }
    }

    /// The MCAP message encoding, schema name and schema text of this form on channel `name`.
    pub fn mcap_kind(&self, name: &str) -> (&'static str, Option<(String, String)>) {
        match self {
            Form::Json => {
                let schema = crate::contract_schemas::for_channel(name)
                    .unwrap_or_else(|| schemas::permissive(name));
                (JSON, Some((name.to_string(), schema)))
            }
            Form::RawAudio { .. } => (
                JSON,
                Some((schemas::RAW_AUDIO.into(), schemas::RAW_AUDIO_SCHEMA.into())),
            ),
            Form::Image => (
                JSON,
                Some((
                    schemas::COMPRESSED_IMAGE.into(),
                    schemas::COMPRESSED_IMAGE_SCHEMA.into(),
                )),
            ),
            Form::Binary | Form::Sniff => (OCTET_STREAM, None),
        }
    }

    /// The MCAP message for `payload`, or `None` when this payload does not fit the form (it is then recorded as
    /// raw bytes on the channel's fallback).
    pub fn encode(&self, name: &str, payload: &[u8], ts_us: u64) -> Option<Vec<u8>> {
        match self {
            Form::Json => serde_json::from_slice::<serde::de::IgnoredAny>(payload)
                .ok()
                .map(|_| payload.to_vec()),
            Form::RawAudio {
                rate,
                channels,
                prefixed,
            } => {
                let (prefix, pcm) = if *prefixed {
                    if payload.len() < SPEECH_PREFIX {
                        return None;
                    }
                    payload.split_at(SPEECH_PREFIX)
                } else {
                    (&payload[..0], payload)
                };
                if pcm.len() % 2 != 0 {
                    return None;
                }
                let mut msg = json!({
                    "timestamp": timestamp(ts_us),
                    "data": BASE64.encode(pcm),
                    "format": "pcm-s16",
                    "sample_rate": rate,
                    "number_of_channels": channels,
                });
                if *prefixed {
                    // Not part of foxglove.RawAudio: extra fields a player ignores, which replay needs.
                    msg["utterance"] = json!(le_u32(&prefix[..4]));
                    msg["offset"] = json!(le_u32(&prefix[4..]));
                }
                serde_json::to_vec(&msg).ok()
            }
            Form::Image => serde_json::to_vec(&json!({
                "timestamp": timestamp(ts_us),
                "frame_id": name,
                "data": BASE64.encode(payload),
                "format": "jpeg",
            }))
            .ok(),
            Form::Binary | Form::Sniff => Some(payload.to_vec()),
        }
    }
}

/// The original payload of a recorded message, from its channel's encoding and schema name.
pub fn decode(encoding: &str, schema: Option<&str>, data: &[u8]) -> Result<Vec<u8>, RecordError> {
    match (encoding, schema) {
        (JSON, Some(schemas::RAW_AUDIO)) => {
            let msg: Value = serde_json::from_slice(data)?;
            let mut out = Vec::new();
            if let (Some(u), Some(o)) = (msg["utterance"].as_u64(), msg["offset"].as_u64()) {
                let u = u32::try_from(u).map_err(|_| RecordError::Form("utterance".into()))?;
                let o = u32::try_from(o).map_err(|_| RecordError::Form("offset".into()))?;
                out.extend_from_slice(&u.to_le_bytes());
                out.extend_from_slice(&o.to_le_bytes());
            }
            out.extend(base64_field(&msg)?);
            Ok(out)
        }
        (JSON, Some(schemas::COMPRESSED_IMAGE)) => {
            let msg: Value = serde_json::from_slice(data)?;
            base64_field(&msg)
        }
        (JSON | OCTET_STREAM, _) => Ok(data.to_vec()),
        (other, _) => Err(RecordError::Form(format!(
            "message encoding {other:?} is not one this replayer writes"
        ))),
    }
}

fn base64_field(msg: &Value) -> Result<Vec<u8>, RecordError> {
    let text = msg["data"]
        .as_str()
        .ok_or_else(|| RecordError::Form("no base64 data field".into()))?;
    BASE64
        .decode(text)
        .map_err(|e| RecordError::Form(format!("bad base64 data: {e}")))
}

/// A Foxglove `time` from microseconds since the Unix epoch.
pub fn timestamp(ts_us: u64) -> Value {
    json!({"sec": ts_us / 1_000_000, "nsec": (ts_us % 1_000_000) * 1000})
}

fn le_u32(bytes: &[u8]) -> u32 {
    let mut b = [0u8; 4];
    b.copy_from_slice(bytes);
    u32::from_le_bytes(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip(form: &Form, name: &str, payload: &[u8]) -> Vec<u8> {
        let encoded = form
            .encode(name, payload, 1_700_000_000_123_456)
            .expect("fits");
        let (encoding, schema) = form.mcap_kind(name);
        decode(encoding, schema.as_ref().map(|s| s.0.as_str()), &encoded).expect("decodes")
    }

    #[test]
    fn speech_keeps_its_utterance_and_offset_prefix_through_a_round_trip() {
        let form = Form::of(ch::SPEECH.name, &ch::headers::speech(22050, 20));
        assert!(matches!(form, Form::RawAudio { prefixed: true, .. }));
        let mut payload = 7u32.to_le_bytes().to_vec();
        payload.extend(4410u32.to_le_bytes());
        payload.extend([1, 2, 3, 4]);
        assert_eq!(round_trip(&form, ch::SPEECH.name, &payload), payload);
    }

    #[test]
    fn microphone_pcm_and_jpeg_frames_come_back_byte_for_byte() {
        let audio = Form::of(ch::AUDIO.name, ch::headers::AUDIO);
        assert_eq!(
            round_trip(&audio, ch::AUDIO.name, &[9, 8, 7, 6]),
            [9, 8, 7, 6]
        );
        let video = Form::of(ch::VIDEO.name, ch::headers::VIDEO);
        assert_eq!(video, Form::Image);
        let jpeg = [0xff, 0xd8, 0xff, 0xe0, 0, 1];
        assert_eq!(round_trip(&video, ch::VIDEO.name, &jpeg), jpeg);
    }

    #[test]
    fn odd_pcm_does_not_fit_the_audio_form() {
        let audio = Form::of(ch::AUDIO.name, ch::headers::AUDIO);
        assert!(audio.encode(ch::AUDIO.name, &[1, 2, 3], 0).is_none());
    }

    #[test]
    fn an_undeclared_channel_is_json_only_if_its_first_message_is_an_object_or_array() {
        assert_eq!(Form::of("X.a", "{}").settle(br#"{"a":1}"#), Form::Json);
        assert_eq!(Form::of("X.a", "{}").settle(b"42"), Form::Binary);
        assert_eq!(Form::of("X.a", "{}").settle(&[0xff, 0]), Form::Binary);
        assert!(Form::Json.encode("X.a", b"not json", 0).is_none());
    }

    #[test]
    fn a_foxglove_timestamp_splits_microseconds_into_seconds_and_nanoseconds() {
        assert_eq!(timestamp(1_500_000), json!({"sec": 1, "nsec": 500_000_000}));
    }
}
