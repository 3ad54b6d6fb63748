//! The browser link's wire format (docs/browser-link.md): binary media frames and JSON control messages.
//!
//! Parsing is strict because a frame that breaks the contract means a broken or hostile page: the caller closes
//! that one socket with the error's text as the close reason.

use bytes::{BufMut, Bytes, BytesMut};
use serde::{Deserialize, Serialize};

/// Every binary frame starts with this many header bytes.
pub const HEADER_BYTES: usize = 8;
const VERSION: u8 = 1;
/// 100 ms of audio; a page sends 20 ms chunks, so anything bigger is not our page.
pub const MAX_AUDIO_BYTES: usize = 8820;
pub const MAX_VIDEO_BYTES: usize = 1 << 20;
/// The longest JSON text message the server accepts from a page.
pub const MAX_TEXT_BYTES: usize = 64 * 1024;

/// What a binary frame carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameKind {
    /// Page -> server: s16le mono 22050 Hz PCM.
    Audio = 0x01,
    /// Page -> server: one JPEG.
    Video = 0x02,
    /// Server -> page: utterance id, offset, s16le PCM.
    Speech = 0x81,
    /// Server -> page: f32le magnitudes.
    Spectrum = 0x82,
}

/// One media frame received from a page.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MediaFrame {
    pub kind: FrameKind,
    pub seq: u32,
    pub payload: Bytes,
}

/// Why a frame from a page was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    #[error("binary frame of {0} bytes is shorter than the {HEADER_BYTES}-byte header")]
    Short(usize),
    #[error("binary frame version {0} is not supported (expected {VERSION})")]
    Version(u8),
    #[error("binary frame kind 0x{0:02x} is not one a page may send")]
    Kind(u8),
    #[error(
        "audio payload of {0} bytes is not whole s16 samples within 2..={MAX_AUDIO_BYTES} bytes"
    )]
    Audio(usize),
    #[error("video payload of {0} bytes is not a JPEG within 2..={MAX_VIDEO_BYTES} bytes")]
    Video(usize),
    #[error("text message of {0} bytes is over the {MAX_TEXT_BYTES}-byte limit")]
    TextTooLong(usize),
    #[error("text message is not valid JSON: {0}")]
    Json(String),
}

/// Parses a binary frame a page sent (only audio and video are allowed in that direction).
pub fn parse_media(frame: Bytes) -> Result<MediaFrame, WireError> {
    if frame.len() < HEADER_BYTES {
        return Err(WireError::Short(frame.len()));
    }
    if frame[1] != VERSION {
        return Err(WireError::Version(frame[1]));
    }
    let seq = u32::from_le_bytes([frame[4], frame[5], frame[6], frame[7]]);
    let payload = frame.slice(HEADER_BYTES..);
    let kind = match frame[0] {
        0x01 => {
            if payload.len() < 2
                || payload.len() > MAX_AUDIO_BYTES
                || !payload.len().is_multiple_of(2)
            {
                return Err(WireError::Audio(payload.len()));
            }
            FrameKind::Audio
        }
        0x02 => {
            if payload.len() < 2 || payload.len() > MAX_VIDEO_BYTES || payload[..2] != [0xFF, 0xD8]
            {
                return Err(WireError::Video(payload.len()));
            }
            FrameKind::Video
        }
        other => return Err(WireError::Kind(other)),
    };
    Ok(MediaFrame { kind, seq, payload })
}

/// Builds a server -> page binary frame: the header, then `parts` one after the other.
pub fn encode_frame(kind: FrameKind, seq: u32, parts: &[&[u8]]) -> Bytes {
    let len = HEADER_BYTES + parts.iter().map(|p| p.len()).sum::<usize>();
    let mut out = BytesMut::with_capacity(len);
    out.put_u8(kind as u8);
    out.put_u8(VERSION);
    out.put_u16_le(0);
    out.put_u32_le(seq);
    for p in parts {
        out.put_slice(p);
    }
    out.freeze()
}

/// A JSON message from the page.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum PageMessage {
    Hello {
        #[serde(default)]
        version: u32,
        #[serde(default)]
        client: String,
        #[serde(default)]
        autostart: bool,
    },
    Claim,
    Release,
    Media {
        #[serde(default)]
        audio: bool,
        #[serde(default)]
        video: bool,
    },
    Ctrl {
        data: serde_json::Value,
    },
    Ping {
        t: f64,
    },
    /// The page began playing an utterance of speech (`agent_contract::say::PlaybackStarted`).
    Played {
        utterance: u64,
        at_ms: f64,
    },
}

/// What a text frame turned out to be: a known message, or a JSON object of a type this server does not know
/// (answered with an error, not a disconnect, so newer pages keep working).
#[derive(Debug, Clone, PartialEq)]
pub enum PageText {
    Message(PageMessage),
    Unknown(String),
}

/// Parses a text frame from the page.
pub fn parse_text(text: &str) -> Result<PageText, WireError> {
    if text.len() > MAX_TEXT_BYTES {
        return Err(WireError::TextTooLong(text.len()));
    }
    let value: serde_json::Value =
        serde_json::from_str(text).map_err(|e| WireError::Json(e.to_string()))?;
    let kind = value
        .get("type")
        .and_then(|t| t.as_str())
        .unwrap_or_default()
        .to_string();
    match serde_json::from_value::<PageMessage>(value) {
        Ok(msg) => Ok(PageText::Message(msg)),
        Err(_) if !is_known_type(&kind) => Ok(PageText::Unknown(kind)),
        Err(e) => Err(WireError::Json(format!(
            "malformed \"{kind}\" message: {e}"
        ))),
    }
}

fn is_known_type(kind: &str) -> bool {
    matches!(
        kind,
        "hello" | "claim" | "release" | "media" | "ctrl" | "ping" | "played"
    )
}

/// The role states the server reports to a page.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RoleState {
    Granted,
    Busy,
    Free,
    Released,
}

impl RoleState {
    /// The name the page reads.
    pub fn as_str(self) -> &'static str {
        match self {
            RoleState::Granted => "granted",
            RoleState::Busy => "busy",
            RoleState::Free => "free",
            RoleState::Released => "released",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(bytes: &[u8]) -> String {
        bytes.iter().map(|b| format!("{b:02x}")).collect()
    }

    /// The binary frame layouts as hex, for the page's `frames.js` tests (crates/contract/vectors/frames.json): what the
    /// page sends is parsed here, what the server sends is encoded here.
    #[test]
    fn frame_vectors_match_the_link_codec() {
        let pcm: Vec<u8> = [0i16, 1000, -1000, i16::MAX]
            .iter()
            .flat_map(|s| s.to_le_bytes())
            .collect();
        let audio = encode_frame(FrameKind::Audio, 5, &[&pcm]);
        let parsed = parse_media(audio.clone()).expect("an audio frame");
        assert_eq!((parsed.kind, parsed.seq), (FrameKind::Audio, 5));
        let jpeg = [0xFFu8, 0xD8, 0xFF, 0xE0, 0x00, 0x10];
        let video = encode_frame(FrameKind::Video, 70_000, &[&jpeg]);
        assert_eq!(
            parse_media(video.clone()).expect("a video frame").seq,
            70_000
        );
        let speech_head: Vec<u8> = [7u32, 441].iter().flat_map(|v| v.to_le_bytes()).collect();
        let speech = encode_frame(FrameKind::Speech, 9, &[&speech_head, &pcm]);
        let bins: Vec<u8> = [0.0f32, 0.5, 1.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let spectrum = encode_frame(FrameKind::Spectrum, 3, &[&bins]);
        let v = serde_json::json!({
            "header_bytes": HEADER_BYTES,
            "version": VERSION,
            "frames": [
                {"name": "audio", "kind": FrameKind::Audio as u8, "seq": 5, "hex": hex(&audio), "pcm": [0, 1000, -1000, 32767]},
                {"name": "video", "kind": FrameKind::Video as u8, "seq": 70000, "hex": hex(&video), "payload_hex": hex(&jpeg)},
                {"name": "speech", "kind": FrameKind::Speech as u8, "seq": 9, "hex": hex(&speech), "utterance": 7, "offset": 441, "pcm": [0, 1000, -1000, 32767]},
                {"name": "spectrum", "kind": FrameKind::Spectrum as u8, "seq": 3, "hex": hex(&spectrum), "bins": [0.0, 0.5, 1.0]},
            ],
        });
        agent_contract::vectors::check_or_write("frames", &v).expect("vectors");
    }

    fn frame(kind: u8, version: u8, payload: &[u8]) -> Bytes {
        let mut v = vec![kind, version, 0, 0, 7, 0, 0, 0];
        v.extend_from_slice(payload);
        Bytes::from(v)
    }

    #[test]
    fn audio_and_video_frames_parse() {
        let a = parse_media(frame(0x01, 1, &[0u8; 882])).expect("audio");
        assert_eq!((a.kind, a.seq, a.payload.len()), (FrameKind::Audio, 7, 882));
        let v = parse_media(frame(0x02, 1, &[0xFF, 0xD8, 0xFF, 0xE0])).expect("video");
        assert_eq!((v.kind, v.payload.len()), (FrameKind::Video, 4));
    }

    #[test]
    fn broken_frames_are_refused_with_a_reason() {
        assert_eq!(
            parse_media(Bytes::from_static(&[1, 1, 0])),
            Err(WireError::Short(3))
        );
        assert_eq!(
            parse_media(frame(0x01, 2, &[0, 0])),
            Err(WireError::Version(2))
        );
        assert_eq!(
            parse_media(frame(0x81, 1, &[0, 0])),
            Err(WireError::Kind(0x81))
        );
        assert_eq!(
            parse_media(frame(0x01, 1, &[0, 0, 0])),
            Err(WireError::Audio(3))
        );
        assert_eq!(
            parse_media(frame(0x01, 1, &vec![0; MAX_AUDIO_BYTES + 2])),
            Err(WireError::Audio(8822))
        );
        assert_eq!(
            parse_media(frame(0x02, 1, &[0x89, 0x50, 0x4E])),
            Err(WireError::Video(3))
        );
        let e = parse_media(frame(0x02, 1, &[1])).expect_err("one byte is no JPEG");
        assert!(e.to_string().contains("not a JPEG"), "{e}");
    }

    #[test]
    fn encoded_frames_carry_header_and_parts() {
        let f = encode_frame(FrameKind::Speech, 0x0102_0304, &[&[9, 9], &[1]]);
        assert_eq!(&f[..], &[0x81, 1, 0, 0, 4, 3, 2, 1, 9, 9, 1]);
    }

    #[test]
    fn text_messages_parse_and_unknown_types_are_tolerated() {
        assert_eq!(
            parse_text(r#"{"type":"claim"}"#),
            Ok(PageText::Message(PageMessage::Claim))
        );
        assert_eq!(
            parse_text(r#"{"type":"media","audio":true}"#),
            Ok(PageText::Message(PageMessage::Media {
                audio: true,
                video: false
            }))
        );
        assert_eq!(
            parse_text(r#"{"type":"dance"}"#),
            Ok(PageText::Unknown("dance".into()))
        );
        assert!(matches!(parse_text("not json"), Err(WireError::Json(_))));
        assert!(
            matches!(parse_text(r#"{"type":"played","utterance":-1,"at_ms":1}"#), Err(WireError::Json(m)) if m.contains("played")),
            "a malformed playback start is refused"
        );
        assert_eq!(
            parse_text(r#"{"type":"played","utterance":3,"at_ms":1765000000000.5}"#),
            Ok(PageText::Message(PageMessage::Played {
                utterance: 3,
                at_ms: 1_765_000_000_000.5
            }))
        );
        assert!(
            matches!(parse_text(r#"{"type":"ping","t":"x"}"#), Err(WireError::Json(m)) if m.contains("ping"))
        );
        let long = format!(
            r#"{{"type":"ctrl","data":"{}"}}"#,
            "x".repeat(MAX_TEXT_BYTES)
        );
        assert!(matches!(parse_text(&long), Err(WireError::TextTooLong(_))));
    }
}
