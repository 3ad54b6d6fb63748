//! The TTS module's edges: the `Agent.say` service and `Agent.ctrl` requests it accepts, the voice activity and
//! detections it follows, and the `Agent.speech` / `Agent.avatar` messages it publishes (docs/voice.md,
//! docs/browser-link.md). Everything inside the module works on the plain types defined here and on the contract's
//! `AvatarCommand`, which is rounded to the page's precision only as it goes out ([`avatar_json`]).

use agent_contract::avatar::{self, AvatarCommand};
use agent_contract::ctrl::Ctrl;
use agent_contract::detections::DetectionsMsg;
use agent_contract::say;
use agent_contract::transcript::Heard;
use agent_voice::Viseme;
use bytes::{BufMut, Bytes, BytesMut};
use flow_telemetry::TraceContext;

/// An `Agent.speech` payload: `[utterance u32 LE][offset u32 LE][s16le PCM]`, `offset` being the index of the
/// first sample inside the utterance.
pub fn speech_payload(utterance: u64, offset: u64, pcm: &[i16]) -> Bytes {
    let mut out = BytesMut::with_capacity(8 + pcm.len() * 2);
    // Utterance numbers and offsets fit u32 for 2^32 utterances and 54 hours of speech; past that they wrap,
    // which the page only uses to tell utterances apart.
    out.put_u32_le(utterance as u32);
    out.put_u32_le(offset as u32);
    for sample in pcm {
        out.put_i16_le(*sample);
    }
    out.freeze()
}

/// Voice changes a single request may ask for; unset fields keep the module's configured voice.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct VoiceChoice {
    pub voice: Option<String>,
    pub rate_wpm: Option<u32>,
    pub pitch: Option<u32>,
}

/// Which utterances a cancel request stops.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CancelTarget {
    All,
    One(u64),
}

/// A request to the TTS module.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SayRequest {
    Say {
        text: String,
        choice: VoiceChoice,
        /// The reply span this speech starts (docs/telemetry.md).
        trace: Option<TraceContext>,
    },
    Cancel(CancelTarget),
    /// Synthesise `text` in the configured voice into its cache, without playing it.
    Prepare {
        text: String,
    },
    /// Show an expression on the avatar for a few seconds (one the page knows: `MOODS`).
    Mood(&'static str),
}

/// The expressions a `{"mood": ...}` request may ask for (web/js/avatar/moods.js has each one's face).
pub const MOODS: [&str; 7] = [
    "neutral",
    "happy",
    "sad",
    "surprised",
    "angry",
    "thinking",
    "listening",
];

/// Parses an `Agent.say` call: `{"text": "...", "voice"?, "rate_wpm"?, "pitch"?}` or
/// `{"cancel": "all"}` / `{"cancel": N}`.
pub fn say_request(payload: &[u8]) -> Result<SayRequest, String> {
    let value: serde_json::Value =
        serde_json::from_slice(payload).map_err(|e| format!("not JSON: {e}"))?;
    if let Some(mood) = value.get("mood") {
        let name = mood.as_str().unwrap_or_default();
        return MOODS
            .iter()
            .find(|m| **m == name)
            .map(|m| SayRequest::Mood(m))
            .ok_or_else(|| format!("mood: {mood} is not one of {}", MOODS.join(", ")));
    }
    if let Some(cancel) = value.get("cancel") {
        return match cancel {
            serde_json::Value::String(all) if all == "all" => {
                Ok(SayRequest::Cancel(CancelTarget::All))
            }
            serde_json::Value::Number(n) => n
                .as_u64()
                .map(|n| SayRequest::Cancel(CancelTarget::One(n)))
                .ok_or_else(|| format!("cancel: {n} is not an utterance number")),
            other => Err(format!(
                "cancel: expected \"all\" or an utterance number, got {other}"
            )),
        };
    }
    let say: say::SayRequest = serde_json::from_value(value).map_err(|e| e.to_string())?;
    if say.text.trim().is_empty() {
        return Err("text is empty".into());
    }
    if say.prepare {
        if say.voice.is_some() || say.rate_wpm.is_some() || say.pitch.is_some() {
            return Err("prepare: only the configured voice keeps a cache, so voice, rate_wpm and pitch are not taken".into());
        }
        return Ok(SayRequest::Prepare { text: say.text });
    }
    let choice = VoiceChoice {
        voice: say.voice,
        rate_wpm: say.rate_wpm,
        pitch: say.pitch,
    };
    // A trace that does not parse costs the turn its synthesis span, never the speech.
    let trace = say
        .trace
        .as_deref()
        .and_then(|t| TraceContext::parse(t).ok());
    Ok(SayRequest::Say {
        text: say.text,
        choice,
        trace,
    })
}

/// The answer to a `say` call.
pub fn said(utterance: u64) -> Bytes {
    // Plain data with string keys always serialises.
    Bytes::from(serde_json::to_vec(&say::SayAnswer { utterance }).unwrap_or_default())
}

/// The answer to a `prepare` call.
pub fn prepared(cached: bool) -> Bytes {
    Bytes::from(serde_json::to_vec(&say::PrepareAnswer { cached }).unwrap_or_default())
}

/// The answer to a `cancel` call: the utterances stopped.
pub fn cancelled(utterances: &[u64]) -> Bytes {
    let answer = say::CancelAnswer {
        cancelled: utterances.to_vec(),
    };
    Bytes::from(serde_json::to_vec(&answer).unwrap_or_default())
}

/// What an `Agent.ctrl` message asks of the TTS module, if anything: `{"say": "text"}` speaks, `{"speech":
/// "stop"}` (or `{"cmd": "speech_stop"}`) stops all speech. Every other control message is for someone else.
pub fn ctrl_request(payload: &[u8]) -> Option<SayRequest> {
    let ctrl: Ctrl = serde_json::from_slice(payload).ok()?;
    if let Some(text) = &ctrl.say {
        let text = text.trim();
        return (!text.is_empty()).then(|| SayRequest::Say {
            text: text.to_owned(),
            choice: VoiceChoice::default(),
            trace: None,
        });
    }
    ctrl.stops_speech()
        .then_some(SayRequest::Cancel(CancelTarget::All))
}

/// What an `Agent.transcript` message says about the user's voice.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Hearing {
    /// Voice activity began (`{"vad": "start"}`), or a partial transcript arrived: the user is speaking.
    Speaking,
    /// Voice activity ended (`{"vad": "end"}`): a pause.
    Paused,
    /// A final transcript: the user has said something the agent will now think about.
    Said,
}

/// Reads voice activity from `Agent.transcript`: `{"vad": "start" | "end"}` events, partial transcripts
/// (`"final": false` or `"partial": true`) and final ones (JSON with `text`, or plain text).
pub fn hearing(payload: &[u8]) -> Option<Hearing> {
    let text = std::str::from_utf8(payload).ok()?.trim();
    if !text.starts_with('{') {
        return (!text.is_empty()).then_some(Hearing::Said);
    }
    let heard: Heard = serde_json::from_str(text).ok()?;
    match heard.vad.as_deref() {
        Some("start") => return Some(Hearing::Speaking),
        Some("end") => return Some(Hearing::Paused),
        _ => {}
    }
    let words = heard.text.as_deref()?;
    if heard.is_partial() {
        Some(Hearing::Speaking)
    } else {
        (!words.trim().is_empty()).then_some(Hearing::Said)
    }
}

/// Where the vision modules say the avatar should look, in normalised camera coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sighting {
    pub x: f64,
    pub y: f64,
    /// `face` or `motion`.
    pub source: &'static str,
}

/// Reads the gaze target from an `Agent.detections` message: its `gaze` field when the vision module filled
/// it (`source` `face`/`motion`; `idle` means nothing seen), else the largest face, else the moving centre.
/// `None` when nothing is seen (or the message is not understood).
pub fn sighting(payload: &[u8]) -> Option<Sighting> {
    let message: DetectionsMsg = serde_json::from_slice(payload).ok()?;
    let inside = |x: f64, y: f64| (0.0..=1.0).contains(&x) && (0.0..=1.0).contains(&y);
    if let Some(gaze) = message.gaze {
        let (x, y) = (f64::from(gaze.x), f64::from(gaze.y));
        let source = match gaze.source.as_str() {
            "face" => "face",
            "motion" => "motion",
            _ => return None,
        };
        return inside(x, y).then_some(Sighting { x, y, source });
    }
    let (width, height) = (
        f64::from(message.frame.width),
        f64::from(message.frame.height),
    );
    if width <= 0.0 || height <= 0.0 {
        return None;
    }
    let largest = message
        .faces
        .unwrap_or_default()
        .into_iter()
        .max_by_key(|f| i64::from(f.w) * i64::from(f.h));
    let (x, y, source) = match (largest, message.motion) {
        (Some(face), _) => (
            (f64::from(face.x) + f64::from(face.w) / 2.0) / width,
            (f64::from(face.y) + f64::from(face.h) / 2.0) / height,
            "face",
        ),
        (None, Some(motion)) if motion.moving => match motion.centre {
            Some(c) => (f64::from(c.x) / width, f64::from(c.y) / height, "motion"),
            None => return None,
        },
        _ => return None,
    };
    inside(x, y).then_some(Sighting { x, y, source })
}

/// The `visemes` avatar command: cues in ms from sample 0 of `utterance`, each with its mouth shape's name.
pub fn visemes(utterance: u64, items: &[(f64, Viseme)]) -> AvatarCommand {
    AvatarCommand::Visemes {
        utterance,
        items: items
            .iter()
            .map(|(t_ms, viseme)| avatar::VisemeCue {
                t_ms: *t_ms,
                v: viseme.name().to_owned(),
            })
            .collect(),
    }
}

/// An `Agent.avatar` payload. The controllers work at full precision; what goes out is rounded to what the page
/// can show (a thousandth of the image for gaze and of the scale for moods, a tenth of a millisecond for cues).
pub fn avatar_json(command: &AvatarCommand) -> Bytes {
    let sent = match command {
        AvatarCommand::Gaze { x, y, source, seq } => AvatarCommand::Gaze {
            x: round3(*x),
            y: round3(*y),
            source: source.clone(),
            seq: *seq,
        },
        AvatarCommand::Mood { mood, intensity } => AvatarCommand::Mood {
            mood: mood.clone(),
            intensity: round3(*intensity),
        },
        AvatarCommand::Visemes { utterance, items } => AvatarCommand::Visemes {
            utterance: *utterance,
            items: items
                .iter()
                .map(|cue| avatar::VisemeCue {
                    t_ms: (cue.t_ms * 10.0).round() / 10.0,
                    v: cue.v.clone(),
                })
                .collect(),
        },
        other => other.clone(),
    };
    // Serialising plain data with string keys cannot fail.
    Bytes::from(serde_json::to_vec(&sent).unwrap_or_default())
}

fn round3(value: f64) -> f64 {
    (value * 1000.0).round() / 1000.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn say_requests() {
        assert_eq!(
            say_request(br#"{"text":"Ciao","voice":"it"}"#),
            Ok(SayRequest::Say {
                text: "Ciao".into(),
                choice: VoiceChoice {
                    voice: Some("it".into()),
                    ..VoiceChoice::default()
                },
                trace: None,
            })
        );
        assert_eq!(
            say_request(br#"{"text":"Let me think.","prepare":true}"#),
            Ok(SayRequest::Prepare {
                text: "Let me think.".into()
            })
        );
        let other_voice = say_request(br#"{"text":"Ciao","voice":"it","prepare":true}"#);
        assert!(
            matches!(&other_voice, Err(reason) if reason.contains("prepare")),
            "{other_voice:?}"
        );
        let reply = TraceContext::turn("u1").child("reply");
        let traced = format!(r#"{{"text":"Hi","trace":"{}"}}"#, reply.traceparent());
        assert!(
            matches!(say_request(traced.as_bytes()), Ok(SayRequest::Say { trace: Some(t), .. }) if t == reply),
            "a reply's speech names its span"
        );
        assert!(
            matches!(
                say_request(br#"{"text":"Hi","trace":"junk"}"#),
                Ok(SayRequest::Say { trace: None, .. })
            ),
            "a malformed trace costs the span, not the speech"
        );
        assert_eq!(
            say_request(br#"{"cancel":"all"}"#),
            Ok(SayRequest::Cancel(CancelTarget::All))
        );
        assert_eq!(
            say_request(br#"{"cancel":7}"#),
            Ok(SayRequest::Cancel(CancelTarget::One(7)))
        );
        assert!(say_request(br#"{"cancel":"some"}"#).is_err());
        assert_eq!(
            say_request(br#"{"mood":"happy"}"#),
            Ok(SayRequest::Mood("happy"))
        );
        assert!(say_request(br#"{"mood":"smug"}"#).is_err());
        assert!(say_request(br#"{"mood":3}"#).is_err());
        assert!(say_request(br#"{"text":"  "}"#).is_err());
        assert!(say_request(br#"{"txt":"hi"}"#).is_err_and(|e| e.contains("txt")));
        assert!(say_request(b"hello").is_err());
    }

    #[test]
    fn ctrl_and_hearing() {
        assert!(matches!(
            ctrl_request(br#"{"say":"hi"}"#),
            Some(SayRequest::Say { .. })
        ));
        assert_eq!(
            ctrl_request(br#"{"speech":"stop"}"#),
            Some(SayRequest::Cancel(CancelTarget::All))
        );
        assert_eq!(ctrl_request(br#"{"asr":false}"#), None);
        assert_eq!(hearing(br#"{"vad":"start"}"#), Some(Hearing::Speaking));
        assert_eq!(hearing(br#"{"vad":"end"}"#), Some(Hearing::Paused));
        assert_eq!(
            hearing(br#"{"text":"what ti","final":false}"#),
            Some(Hearing::Speaking)
        );
        assert_eq!(
            hearing(br#"{"text":"what time is it","final":true}"#),
            Some(Hearing::Said)
        );
        assert_eq!(hearing(b"what time is it"), Some(Hearing::Said));
        assert_eq!(hearing(br#"{"other":1}"#), None);
    }

    #[test]
    fn sightings() {
        let vision = br#"{"frame":{"seq":1,"ts_us":0,"width":640,"height":360},"faces":[],"gaze":{"x":0.25,"y":0.5,"source":"face"}}"#;
        assert_eq!(
            sighting(vision),
            Some(Sighting {
                x: 0.25,
                y: 0.5,
                source: "face"
            })
        );
        let idle =
            br#"{"frame":{"seq":1,"ts_us":0,"width":640,"height":360},"gaze":{"x":0.5,"y":0.5,"source":"idle"}}"#;
        assert_eq!(sighting(idle), None);
        let faces = br#"{"frame":{"seq":1,"ts_us":0,"width":640,"height":360},"faces":[{"x":0,"y":0,"w":10,"h":10},{"x":300,"y":100,"w":40,"h":40}]}"#;
        assert_eq!(
            sighting(faces),
            Some(Sighting {
                x: 0.5,
                y: 120.0 / 360.0,
                source: "face"
            })
        );
        let motion = br#"{"frame":{"seq":1,"ts_us":0,"width":640,"height":360},"motion":{"frame":{"seq":1,"ts_us":0,"width":640,"height":360},"moving":true,"centre":{"x":64,"y":36}}}"#;
        assert_eq!(
            sighting(motion),
            Some(Sighting {
                x: 0.1,
                y: 0.1,
                source: "motion"
            })
        );
        assert_eq!(sighting(b"junk"), None);
    }

    #[test]
    fn wire_formats() {
        let payload = speech_payload(3, 441, &[1, -1]);
        assert_eq!(&payload[..], &[3, 0, 0, 0, 0xB9, 1, 0, 0, 1, 0, 0xFF, 0xFF]);
        let visemes = visemes(2, &[(0.0, Viseme::Sil), (62.35, Viseme::U)]);
        let sent: serde_json::Value = serde_json::from_slice(&avatar_json(&visemes)).expect("json");
        assert_eq!(
            sent,
            json!({"cmd":"visemes","items":[{"t_ms":0.0,"v":"sil"},{"t_ms":62.4,"v":"U"}],"utterance":2})
        );
        assert_eq!(
            avatar_json(&AvatarCommand::SpeechStop {
                utterance: None,
                barge_in: false
            }),
            r#"{"cmd":"speech_stop"}"#
        );
    }
}
