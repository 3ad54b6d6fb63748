//! The JSON test vectors in `crates/contract/vectors/`: messages built from the contract's types, which the page's
//! `node --test` suites read, so that neither side can drift. A Rust test checks each file against the types;
//! `AGENT_UPDATE_VECTORS=1 cargo test` rewrites them after an intended change.

use std::path::PathBuf;

use crate::avatar::{AvatarCommand, VISEMES, VisemeCue};
use crate::detections::{
    BoxMsg, CodeMsg, CountersMsg, DetectionsMsg, FrameRef, GazeCommand, GazeMsg, MotionMsg,
    PersonMsg, PointMsg, TimingMsg,
};

/// The folder of the vectors.
pub fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("vectors")
}

/// Compares `crates/contract/vectors/NAME.json` with `value`, or writes it when `AGENT_UPDATE_VECTORS` is set.
pub fn check_or_write(name: &str, value: &serde_json::Value) -> Result<(), String> {
    let path = dir().join(format!("{name}.json"));
    let text = serde_json::to_string_pretty(value).map_err(|e| e.to_string())? + "\n";
    if std::env::var_os("AGENT_UPDATE_VECTORS").is_some() {
        return std::fs::write(&path, text).map_err(|e| format!("{}: {e}", path.display()));
    }
    let on_disk = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let parsed: serde_json::Value =
        serde_json::from_str(&on_disk).map_err(|e| format!("{}: {e}", path.display()))?;
    if &parsed != value {
        return Err(format!(
            "{} differs from the contract's types; if the change is intended, run AGENT_UPDATE_VECTORS=1 cargo test -p agent-contract and the page's tests",
            path.display()
        ));
    }
    Ok(())
}

fn frame(seq: u64) -> FrameRef {
    FrameRef {
        seq,
        ts_us: 1_700_000_000_000_000 + seq * 66_667,
        width: 640,
        height: 360,
    }
}

/// `Agent.detections` as the vision module publishes it: two faces and the two people they are (one speaking and
/// named), motion, a QR code, gaze and figures; a frame with nothing in it; and one from another detector without
/// gaze or figures.
pub fn detections() -> serde_json::Value {
    let full = DetectionsMsg {
        frame: frame(41),
        faces: Some(vec![
            BoxMsg {
                x: 412,
                y: 96,
                w: 120,
                h: 120,
            },
            BoxMsg {
                x: 60,
                y: 140,
                w: 64,
                h: 64,
            },
        ]),
        face_scan_cycles: 12,
        people: Some(vec![
            PersonMsg {
                id: 7,
                face: BoxMsg {
                    x: 412,
                    y: 96,
                    w: 120,
                    h: 120,
                },
                mouth_open: 0.25,
                eyes_open: 0.3,
                yaw_deg: 4.5,
                pitch_deg: -2.0,
                looking: true,
                smile: 0.75,
                smiling: true,
                speaking: true,
                name: Some("Anna".into()),
            },
            PersonMsg {
                id: 9,
                face: BoxMsg {
                    x: 60,
                    y: 140,
                    w: 64,
                    h: 64,
                },
                mouth_open: 0.0,
                eyes_open: 0.28,
                yaw_deg: -40.0,
                pitch_deg: 5.0,
                looking: false,
                smile: 0.0,
                smiling: false,
                speaking: false,
                name: None,
            },
        ]),
        motion: Some(MotionMsg {
            frame: frame(41),
            moving: true,
            centre: Some(PointMsg { x: 470.5, y: 160.0 }),
            regions: vec![BoxMsg {
                x: 400,
                y: 90,
                w: 150,
                h: 140,
            }],
            changed_fraction: 0.0625,
            held: false,
        }),
        codes: Some(vec![CodeMsg {
            kind: "qr".into(),
            text: Some("https://example.org/robot".into()),
            hex: "68747470733a2f2f6578616d706c652e6f72672f726f626f74".into(),
            polygon: vec![
                PointMsg { x: 200.0, y: 200.0 },
                PointMsg { x: 280.0, y: 202.0 },
                PointMsg { x: 278.0, y: 282.0 },
                PointMsg { x: 198.0, y: 280.0 },
            ],
            appearance: 3,
            new: true,
        }]),
        gaze: Some(GazeMsg {
            x: 0.7375,
            y: 0.4333,
            source: "face".into(),
        }),
        timing: Some(TimingMsg {
            decode_ms: 2.5,
            faces_ms: Some(9.25),
            people_ms: Some(6.5),
            motion_ms: Some(1.5),
            codes_ms: None,
            total_ms: 13.5,
        }),
        counters: Some(CountersMsg {
            processed: 41,
            skipped: 2,
            bad: 0,
        }),
    };
    let empty = DetectionsMsg {
        frame: frame(42),
        faces: Some(vec![]),
        face_scan_cycles: 12,
        people: Some(vec![]),
        motion: Some(MotionMsg {
            frame: frame(42),
            moving: false,
            centre: None,
            regions: vec![],
            changed_fraction: 0.0,
            held: false,
        }),
        codes: Some(vec![]),
        gaze: Some(GazeMsg {
            x: 0.5,
            y: 0.5,
            source: "idle".into(),
        }),
        timing: None,
        counters: None,
    };
    let other_detector = serde_json::json!({
        "frame": { "seq": 7, "ts_us": 0, "width": 1280, "height": 720 },
        "faces": [{ "x": 100, "y": 50, "w": 200, "h": 220 }],
    });
    // The third message must parse as the contract type too.
    let parsed: Result<DetectionsMsg, _> = serde_json::from_value(other_detector.clone());
    debug_assert!(parsed.is_ok());
    serde_json::json!({
        "channel": crate::channels::DETECTIONS.name,
        "messages": [full, empty, other_detector],
        "gaze_command": GazeCommand { cmd: "gaze".into(), x: 0.7375, y: 0.4333, source: "face".into(), seq: 41 },
    })
}

/// `Agent.avatar`: one command of each kind, as the TTS module and the behaviour controllers send them.
pub fn avatar() -> serde_json::Value {
    let cue = |t_ms: f64, v: &str| VisemeCue {
        t_ms,
        v: v.to_owned(),
    };
    let commands = vec![
        AvatarCommand::Blink {
            close_ms: 70,
            hold_ms: 40,
            open_ms: 150,
        },
        AvatarCommand::Gaze {
            x: 0.9,
            y: 0.3,
            source: Some("face".into()),
            seq: None,
        },
        AvatarCommand::Mood {
            mood: "happy".into(),
            intensity: 0.8,
        },
        AvatarCommand::Visemes {
            utterance: 7,
            items: vec![
                cue(0.0, "sil"),
                cue(62.5, "PP"),
                cue(180.0, "aa"),
                cue(420.0, "O"),
                cue(610.0, "FF"),
                cue(800.0, "sil"),
            ],
        },
        AvatarCommand::SpeechStop {
            utterance: Some(7),
            barge_in: false,
        },
        AvatarCommand::SpeechStop {
            utterance: None,
            barge_in: false,
        },
        AvatarCommand::SpeechStop {
            utterance: None,
            barge_in: true,
        },
        AvatarCommand::Say {
            text: "Hello! Nice to see you.".into(),
        },
    ];
    serde_json::json!({
        "channel": crate::channels::AVATAR.name,
        "commands": commands,
        "visemes": VISEMES,
    })
}

/// `Agent.rules`: a rule change as the brain publishes it.
pub fn rules() -> serde_json::Value {
    let change = crate::rules::RuleChange {
        ts_ms: 1_700_000_000_000,
        program: "brain.tr".into(),
        rule: "main.converse > answer.time".into(),
        index: 48,
        action: "say(\"It is ten past nine.\")".into(),
        because: vec!["heard(\"what time is it\")".into()],
        trace: serde_json::json!({}),
        interrupted: None,
        chat: None,
    };
    let barge_in = crate::rules::RuleChange {
        ts_ms: 1_700_000_001_500,
        rule: "main.idle".into(),
        index: 44,
        action: "interrupted say(\"It is ten past nine.\")".into(),
        because: vec!["the user spoke over it".into()],
        interrupted: Some("It is ten past nine.".into()),
        ..change.clone()
    };
    let chat = crate::rules::RuleChange {
        ts_ms: 1_700_000_002_000,
        rule: "main.converse > answer.confused".into(),
        index: 0,
        action: "chat 4 sentence: Rainbows form when sunlight bends in raindrops.".into(),
        because: Vec::new(),
        trace: serde_json::Value::Null,
        chat: Some(crate::rules::ChatStep {
            turn: 4,
            step: "sentence".into(),
            text: "Rainbows form when sunlight bends in raindrops.".into(),
        }),
        ..change.clone()
    };
    serde_json::json!({ "channel": crate::channels::RULES.name, "messages": [change, barge_in, chat] })
}

/// The page link's `welcome` and `status` messages, as the server sends them.
pub fn link() -> serde_json::Value {
    use crate::link::*;
    let welcome = Welcome {
        kind: "welcome".into(),
        version: 1,
        session: 3,
        server: "robot-agent 0.1.0".into(),
        audio: AudioFormat {
            rate: 22050,
            channels: 1,
            format: "s16le".into(),
            chunk_ms: 20,
        },
        video: VideoFormat {
            width: 640,
            height: 360,
            fps: 15,
            format: "jpeg".into(),
        },
        fft: FftFormat {
            size: 1024,
            bins: 512,
            rate: 22050,
            window: "hann".into(),
            hop: 1024,
            scale: "linear, full-scale sine = 1.0".into(),
        },
        role: RoleInfo {
            state: "free".into(),
        },
        language: "it".into(),
        voice: "espeak".into(),
    };
    let status = Status {
        kind: "status".into(),
        role: "holder".into(),
        incoming: Incoming {
            audio_fps: 50,
            video_fps: 15,
            audio_level_dbfs: Some(-32.5),
        },
        sending: Sending {
            audio: true,
            video: true,
        },
        dropped: Dropped::default(),
        audio_dropped: 0,
        advice: Advice { video_fps: 15 },
    };
    let pong = Pong {
        kind: "pong".into(),
        t: 1234.5,
        server_ms: 1_700_000_000_123.25,
    };
    serde_json::json!({ "welcome": welcome, "status": status, "pong": pong })
}

/// `Agent.recording`: recording, then stopped.
pub fn recording() -> serde_json::Value {
    let state = |recording: bool, messages: u64| crate::recording::RecordingState {
        recording,
        file: Some("data/recordings/session-20261202-013000.mcap".into()),
        started_ms: Some(1_700_000_000_000),
        messages,
        error: None,
    };
    serde_json::json!({
        "channel": crate::channels::RECORDING.name,
        "messages": [state(true, 120), state(false, 450)],
    })
}

/// `Agent.latency`: two turns as the observer publishes them.
pub fn latency() -> serde_json::Value {
    let turn = |speech_end_ms: u64,
                vad_ms: f64,
                transcript_ms: f64,
                rule_ms: f64,
                reply_ms: f64,
                behind: &[&str]| {
        crate::latency::TurnLatency {
            kind: "voice".into(),
            speech_end_ms,
            vad_ms,
            transcript_ms,
            rule_ms,
            reply_ms,
            total_ms: vad_ms + transcript_ms + rule_ms + reply_ms,
            behind: behind.iter().map(|s| (*s).to_owned()).collect(),
        }
    };
    serde_json::json!({
        "channel": crate::channels::LATENCY.name,
        "messages": [
            turn(1_700_000_000_000, 300.0, 12.5, 2.0, 48.5, &[]),
            turn(1_700_000_009_000, 310.0, 0.0, 1.5, 40.0, &[]),
            turn(1_700_000_020_000, 320.0, 2400.0, 1.5, 45.0, &["transcription"]),
        ],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detection_vectors_match_the_types() {
        let v = detections();
        for m in v["messages"].as_array().expect("messages") {
            let parsed: DetectionsMsg =
                serde_json::from_value(m.clone()).expect("a contract message");
            assert!(parsed.frame.width > 0);
        }
        check_or_write("detections", &v).expect("vectors");
    }

    #[test]
    fn avatar_vectors_match_the_types() {
        let v = avatar();
        for c in v["commands"].as_array().expect("commands") {
            let parsed: AvatarCommand =
                serde_json::from_value(c.clone()).expect("a contract command");
            assert_eq!(
                &serde_json::to_value(&parsed).expect("json"),
                c,
                "round trip"
            );
        }
        check_or_write("avatar", &v).expect("vectors");
    }

    #[test]
    fn rule_vectors_match_the_types() {
        let v = rules();
        for m in v["messages"].as_array().expect("messages") {
            let _: crate::rules::RuleChange =
                serde_json::from_value(m.clone()).expect("a rule change");
        }
        check_or_write("rules", &v).expect("vectors");
    }

    #[test]
    fn link_vectors_match_the_types() {
        let v = link();
        let _: crate::link::Welcome =
            serde_json::from_value(v["welcome"].clone()).expect("welcome");
        let _: crate::link::Status = serde_json::from_value(v["status"].clone()).expect("status");
        let _: crate::link::Pong = serde_json::from_value(v["pong"].clone()).expect("pong");
        check_or_write("link", &v).expect("vectors");
    }

    #[test]
    fn recording_vectors_match_the_types() {
        let v = recording();
        for m in v["messages"].as_array().expect("messages") {
            let _: crate::recording::RecordingState =
                serde_json::from_value(m.clone()).expect("a recording state");
        }
        check_or_write("recording", &v).expect("vectors");
    }

    #[test]
    fn latency_vectors_match_the_types() {
        let v = latency();
        for m in v["messages"].as_array().expect("messages") {
            let t: crate::latency::TurnLatency = serde_json::from_value(m.clone()).expect("a turn");
            assert!(t.total_ms > 0.0);
        }
        check_or_write("latency", &v).expect("vectors");
    }
}
