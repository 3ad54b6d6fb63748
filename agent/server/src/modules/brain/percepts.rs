//! The serialisation edge from hub channels to percepts: transcripts and detections become `heard(text)`,
//! `face(count, dir)`, `looking(count)`, `smiling`, `speaker(dir)`, `acquaintance(name)`, `motion(dir)` and
//! `code(text)` facts for the rule engine.

use agent_brain::Value;
use agent_contract::detections::DetectionsMsg;
use agent_contract::transcript::Heard;
use flow_telemetry::TraceContext;

/// A percept to assert: `name(args...)`, or the whole current set of a predicate.
#[derive(Debug, Clone, PartialEq)]
pub enum Percept {
    One {
        name: &'static str,
        args: Vec<Value>,
    },
    Set {
        name: &'static str,
        sets: Vec<Vec<Value>>,
    },
}

/// What an `Agent.transcript` message tells the brain (the same reading as the TTS module's, docs/voice.md).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Hearing {
    /// A final transcript: `heard(text)`.
    Said(String),
    /// The user is speaking (`{"vad": "start"}`, or a partial transcript): `listening` holds.
    Speaking,
    /// Voice activity ended (`{"vad": "end"}`): `listening` ends.
    Paused,
    /// Nothing to act on (an empty transcript).
    Nothing,
}

/// Reads an `Agent.transcript` message: JSON with `text` (partial results, marked `"final": false` or
/// `"partial": true`, only mean the user is speaking: the brain answers complete utterances), `{"vad": "start" |
/// "end"}` voice-activity events, or plain UTF-8 text (for `flowctl` users).
pub fn hearing(payload: &[u8]) -> Result<Hearing, String> {
    let text = std::str::from_utf8(payload).map_err(|e| format!("transcript is not UTF-8: {e}"))?;
    if !text.trim_start().starts_with('{') {
        let text = text.trim();
        return Ok(if text.is_empty() {
            Hearing::Nothing
        } else {
            Hearing::Said(text.to_owned())
        });
    }
    let message: Heard = serde_json::from_str(text).map_err(|e| format!("transcript JSON: {e}"))?;
    let partial = message.is_partial();
    match (message.vad.as_deref(), message.text) {
        (Some("start"), _) => Ok(Hearing::Speaking),
        (Some("end"), _) => Ok(Hearing::Paused),
        (Some(other), _) => Err(format!(
            "unknown voice activity {other:?} (expected \"start\" or \"end\")"
        )),
        // Nothing the brain acts on (a status or other satellite's note without text): ignored quietly, since
        // a warning per message would flood the log on a busy channel.
        (None, None) => Ok(Hearing::Nothing),
        (None, Some(_)) if partial => Ok(Hearing::Speaking),
        (None, Some(text)) => {
            let text = text.trim();
            Ok(if text.is_empty() {
                Hearing::Nothing
            } else {
                Hearing::Said(text.to_owned())
            })
        }
    }
}

/// When the speech of a final transcript ended (its `end_us`, on the hub's clock), as an instant of this process;
/// `None` for plain text or a message without it.
pub fn speech_end(payload: &[u8]) -> Option<tokio::time::Instant> {
    #[derive(serde::Deserialize)]
    struct Ended {
        end_us: u64,
    }
    let ended: Ended = serde_json::from_slice(payload).ok()?;
    let now_us = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .ok()?
        .as_micros() as u64;
    let ago = std::time::Duration::from_micros(now_us.saturating_sub(ended.end_us));
    tokio::time::Instant::now().checked_sub(ago)
}

/// The turn a final transcript starts, from the `traceparent` it carries (docs/telemetry.md); `None` for plain text,
/// a message without one, or one that does not parse (that turn is then not traced).
pub fn turn_trace(payload: &[u8]) -> Option<TraceContext> {
    let message: Heard = serde_json::from_slice(payload).ok()?;
    TraceContext::parse(message.trace.as_deref()?).ok()
}

/// The percepts in one `Agent.detections` message (faces, motion and visible codes of a video frame).
///
/// Absence is not asserted: a frame without faces simply does not refresh `face`, which goes stale after its
/// freshness window, so that a detector missing a few frames does not end a person's visit.
pub fn detections(payload: &[u8]) -> Result<Vec<Percept>, String> {
    let message: DetectionsMsg =
        serde_json::from_slice(payload).map_err(|e| format!("detections JSON: {e}"))?;
    let width = f64::from(message.frame.width.max(1));
    let mut percepts = Vec::new();
    if let Some(faces) = message.faces.filter(|faces| !faces.is_empty()) {
        let largest = faces.iter().max_by_key(|f| i64::from(f.w) * i64::from(f.h));
        let dir = largest.map_or("centre", |face| {
            direction((f64::from(face.x) + f64::from(face.w) / 2.0) / width)
        });
        percepts.push(Percept::One {
            name: "face",
            args: vec![Value::Num(faces.len() as f64), Value::from(dir)],
        });
    }
    if let Some(people) = message.people.filter(|people| !people.is_empty()) {
        let looking = people.iter().filter(|p| p.looking).count();
        if looking > 0 {
            percepts.push(Percept::One {
                name: "looking",
                args: vec![Value::Num(looking as f64)],
            });
        }
        if people.iter().any(|p| p.smiling) {
            percepts.push(Percept::One {
                name: "smiling",
                args: vec![],
            });
        }
        if let Some(speaker) = people.iter().find(|p| p.speaking) {
            let centre = f64::from(speaker.face.x) + f64::from(speaker.face.w) / 2.0;
            percepts.push(Percept::One {
                name: "speaker",
                args: vec![Value::from(direction(centre / width))],
            });
        }
        let names: Vec<Vec<Value>> = people
            .iter()
            .filter_map(|p| p.name.clone())
            .map(|name| vec![Value::Text(name)])
            .collect();
        if !names.is_empty() {
            percepts.push(Percept::Set {
                name: "acquaintance",
                sets: names,
            });
        }
    }
    if let Some(centre) = message.motion.filter(|m| m.moving).and_then(|m| m.centre) {
        percepts.push(Percept::One {
            name: "motion",
            args: vec![Value::from(direction(f64::from(centre.x) / width))],
        });
    }
    if let Some(codes) = message.codes {
        let texts: Vec<Vec<Value>> = codes
            .into_iter()
            .filter_map(|code| code.text)
            .map(|text| vec![Value::Text(text)])
            .collect();
        if !texts.is_empty() {
            percepts.push(Percept::Set {
                name: "code",
                sets: texts,
            });
        }
    }
    Ok(percepts)
}

/// Where a horizontal position (0 to 1 across the camera image) is, from the agent's point of view: the camera
/// image is not mirrored, so its left is the agent's left.
fn direction(x: f64) -> &'static str {
    if x < 1.0 / 3.0 {
        "left"
    } else if x > 2.0 / 3.0 {
        "right"
    } else {
        "centre"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transcripts_in_json_or_plain_text() {
        let said = |text: &str| Ok(Hearing::Said(text.into()));
        assert_eq!(
            hearing(br#"{"text":" What time is it? ","final":true}"#),
            said("What time is it?")
        );
        assert_eq!(
            hearing(br#"{"text":"what ti","final":false}"#),
            Ok(Hearing::Speaking)
        );
        assert_eq!(
            hearing(br#"{"text":"what ti","partial":true}"#),
            Ok(Hearing::Speaking)
        );
        assert_eq!(hearing(br#"{"vad":"start"}"#), Ok(Hearing::Speaking));
        assert_eq!(
            hearing(br#"{"vad":"end","at_ms":1200}"#),
            Ok(Hearing::Paused)
        );
        assert_eq!(hearing(b"hello there"), said("hello there"));
        assert_eq!(hearing(b"   "), Ok(Hearing::Nothing));
        assert_eq!(hearing(br#"{"text":"  "}"#), Ok(Hearing::Nothing));
        assert_eq!(hearing(br#"{"txt":"x"}"#), Ok(Hearing::Nothing));
        assert_eq!(
            hearing(br#"{"vad":"start","at_ms":5,"satellite":"whisper-1"}"#),
            Ok(Hearing::Speaking)
        );
        assert_eq!(
            hearing(br#"{"vad":"end","at_ms":9,"utterance":"u5","satellite":"whisper-1"}"#),
            Ok(Hearing::Paused)
        );
        assert_eq!(
            hearing(br#"{"utterance":"u5","final":true}"#),
            Ok(Hearing::Nothing)
        );
        assert!(hearing(br#"{"text":5}"#).is_err());
        assert!(hearing(br#"{"vad":"maybe"}"#).is_err());
        assert!(hearing(&[0xff, 0xfe]).is_err());
    }

    #[test]
    fn detections_become_percepts() {
        let message = br#"{"frame":{"seq":1,"ts_us":0,"width":640,"height":360},
            "faces":[{"x":10,"y":10,"w":40,"h":40},{"x":500,"y":100,"w":100,"h":100}],
            "motion":{"frame":{"seq":1,"ts_us":0,"width":640,"height":360},"moving":true,"centre":{"x":320,"y":100},"regions":[],"changed_fraction":0.1,"held":false},
            "codes":[{"kind":"qr","text":"HELLO","hex":"","polygon":[],"appearance":1,"new":true},
                     {"kind":"ean13","text":null,"hex":"ff","polygon":[],"appearance":2,"new":false}]}"#;
        let percepts = detections(message);
        assert_eq!(
            percepts,
            Ok(vec![
                Percept::One {
                    name: "face",
                    args: vec![Value::Num(2.0), Value::from("right")]
                },
                Percept::One {
                    name: "motion",
                    args: vec![Value::from("centre")]
                },
                Percept::Set {
                    name: "code",
                    sets: vec![vec![Value::from("HELLO")]]
                },
            ])
        );
    }

    #[test]
    fn people_become_looking_smiling_speaker_and_acquaintance() {
        let person = |x: i32, looking: bool, smiling: bool, speaking: bool, name: &str| {
            serde_json::json!({"id": x, "face": {"x": x, "y": 50, "w": 80, "h": 80}, "mouth_open": 0.1,
                "eyes_open": 0.3, "yaw_deg": 0.0, "pitch_deg": 0.0, "looking": looking, "smile": 0.0,
                "smiling": smiling, "speaking": speaking, "name": (!name.is_empty()).then_some(name)})
        };
        let message = serde_json::json!({"frame": {"seq": 1, "ts_us": 0, "width": 640, "height": 360},
            "faces": [{"x": 20, "y": 50, "w": 80, "h": 80}, {"x": 520, "y": 50, "w": 80, "h": 80}],
            "people": [person(20, true, false, false, ""), person(520, true, true, true, "Anna")]});
        let percepts = detections(message.to_string().as_bytes()).expect("percepts");
        assert_eq!(
            percepts[1..],
            [
                Percept::One {
                    name: "looking",
                    args: vec![Value::Num(2.0)]
                },
                Percept::One {
                    name: "smiling",
                    args: vec![]
                },
                Percept::One {
                    name: "speaker",
                    args: vec![Value::from("right")]
                },
                Percept::Set {
                    name: "acquaintance",
                    sets: vec![vec![Value::from("Anna")]]
                },
            ]
        );
        // Faces turned away, nobody smiling or talking, no names: only the faces.
        let away = serde_json::json!({"frame": {"seq": 1, "ts_us": 0, "width": 640, "height": 360},
            "faces": [{"x": 20, "y": 50, "w": 80, "h": 80}], "people": [person(20, false, false, false, "")]});
        assert_eq!(
            detections(away.to_string().as_bytes()).map(|p| p.len()),
            Ok(1)
        );
    }

    #[test]
    fn absence_asserts_nothing() {
        let message = br#"{"frame":{"seq":1,"ts_us":0,"width":640,"height":360},"faces":[],"motion":{"frame":{"seq":1,"ts_us":0,"width":640,"height":360},"moving":false,"centre":null},"codes":[]}"#;
        assert_eq!(detections(message), Ok(vec![]));
        assert!(detections(b"{\"faces\":[]}").is_err());
    }
}
