//! The JSON messages the vision module publishes on the hub (`Agent.faces`, `Agent.motion`, `Agent.codes`,
//! `Agent.detections`, and the gaze command on `Agent.avatar`). This is the serialisation edge: the detectors work
//! on plain domain types and are converted here. Field names are the contract with the page and the brain and are
//! documented in `docs/vision.md`.

use serde::{Deserialize, Serialize};

use crate::appearance::SeenCode;
use crate::codes::DecodedCode;
use crate::gaze::{GazeSource, GazeTarget};
use crate::geometry::{BoxPx, PointPx};
use crate::motion::Motion;
use crate::pipeline::{FrameDetections, StageTimings};

/// Which frame a message is about: the source channel's sequence number and timestamp, and its size.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameRef {
    pub seq: u64,
    pub ts_us: u64,
    pub width: u32,
    pub height: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BoxMsg {
    pub x: i32,
    pub y: i32,
    pub w: i32,
    pub h: i32,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PointMsg {
    pub x: f32,
    pub y: f32,
}

/// `Agent.faces`: one per processed frame, boxes in frame pixels.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FacesMsg {
    pub frame: FrameRef,
    pub faces: Vec<BoxMsg>,
    /// Completed full scans of the frame: the scan is spread over frames, so a consumer that needs every face of
    /// a new scene waits until this has advanced by two.
    pub scan_cycles: u64,
}

/// `Agent.motion`: one per processed frame; `moving: false` is the explicit "no motion".
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MotionMsg {
    pub frame: FrameRef,
    pub moving: bool,
    pub centre: Option<PointMsg>,
    pub regions: Vec<BoxMsg>,
    pub changed_fraction: f64,
    /// The frame itself was quiet and the last motion is held by the hysteresis.
    pub held: bool,
}

/// One code as published.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CodeMsg {
    /// `qr`, `ean8`, `ean13`, `upca`, `upce`.
    pub kind: String,
    /// The payload, exactly as decoded, when it is valid UTF-8 (nothing trimmed); `null` otherwise.
    pub text: Option<String>,
    /// The payload's bytes in lowercase hex, always present.
    pub hex: String,
    pub polygon: Vec<PointMsg>,
    /// Numbers the appearances of codes since the module started.
    pub appearance: u64,
    /// True on the first frame of the appearance.
    pub new: bool,
}

/// `Agent.codes`: published only for frames in which a code appears; lists just the new appearances.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CodesMsg {
    pub frame: FrameRef,
    pub codes: Vec<CodeMsg>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GazeMsg {
    /// Normalised image coordinates in [0, 1], (0, 0) top-left.
    pub x: f32,
    pub y: f32,
    /// `face`, `motion` or `idle`.
    pub source: String,
}

/// Per-stage time of a frame in milliseconds; a stage that is switched off is `null`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TimingMsg {
    pub decode_ms: f64,
    pub faces_ms: Option<f64>,
    pub motion_ms: Option<f64>,
    pub codes_ms: Option<f64>,
    pub total_ms: f64,
}

/// Counters of the module since it started.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct CountersMsg {
    pub processed: u64,
    /// Frames superseded by a newer one before the worker got to them.
    pub skipped: u64,
    /// Frames that were not a decodable JPEG.
    pub bad: u64,
}

/// `Agent.detections`: one per processed frame, everything the page overlay needs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DetectionsMsg {
    pub frame: FrameRef,
    pub faces: Option<Vec<BoxMsg>>,
    pub face_scan_cycles: u64,
    pub motion: Option<MotionMsg>,
    /// Every code visible in this frame, new or not.
    pub codes: Option<Vec<CodeMsg>>,
    pub gaze: GazeMsg,
    pub timing: TimingMsg,
    pub counters: CountersMsg,
}

/// The gaze command on `Agent.avatar` (`{"cmd":"gaze",...}`, see docs/browser-link.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GazeCommand {
    /// Always `gaze`.
    pub cmd: String,
    pub x: f32,
    pub y: f32,
    pub source: String,
    /// The video frame the target was computed from.
    pub seq: u64,
}

impl FrameRef {
    pub fn of(detections: &FrameDetections) -> Self {
        Self {
            seq: detections.seq,
            ts_us: detections.frame_us,
            width: detections.size.width,
            height: detections.size.height,
        }
    }
}

impl From<&BoxPx> for BoxMsg {
    fn from(b: &BoxPx) -> Self {
        Self {
            x: b.x,
            y: b.y,
            w: b.width,
            h: b.height,
        }
    }
}

impl From<PointPx> for PointMsg {
    fn from(p: PointPx) -> Self {
        Self { x: p.x, y: p.y }
    }
}

impl From<&GazeTarget> for GazeMsg {
    fn from(g: &GazeTarget) -> Self {
        Self {
            x: g.x,
            y: g.y,
            source: gaze_source_name(g.source).to_owned(),
        }
    }
}

impl From<&StageTimings> for TimingMsg {
    fn from(t: &StageTimings) -> Self {
        let ms = |d: std::time::Duration| d.as_secs_f64() * 1000.0;
        Self {
            decode_ms: ms(t.decode),
            faces_ms: t.faces.map(ms),
            motion_ms: t.motion.map(ms),
            codes_ms: t.codes.map(ms),
            total_ms: ms(t.total),
        }
    }
}

pub fn gaze_source_name(source: GazeSource) -> &'static str {
    match source {
        GazeSource::Face => "face",
        GazeSource::Motion => "motion",
        GazeSource::Idle => "idle",
    }
}

/// Lowercase hex of the payload.
pub fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write;
    bytes
        .iter()
        .fold(String::with_capacity(bytes.len() * 2), |mut out, byte| {
            // Writing to a String cannot fail.
            let _ = write!(out, "{byte:02x}");
            out
        })
}

fn code_msg(code: &DecodedCode, appearance: u64, new: bool) -> CodeMsg {
    CodeMsg {
        kind: code.symbology.name().to_owned(),
        text: String::from_utf8(code.bytes.clone()).ok(),
        hex: hex(&code.bytes),
        polygon: code.polygon.iter().copied().map(PointMsg::from).collect(),
        appearance,
        new,
    }
}

fn seen_msg(seen: &SeenCode) -> CodeMsg {
    code_msg(&seen.code, seen.appearance, seen.first_sighting)
}

/// `Agent.faces` for a frame, or None when face detection is off.
pub fn faces_msg(d: &FrameDetections) -> Option<FacesMsg> {
    let faces = d.faces.as_ref()?;
    Some(FacesMsg {
        frame: FrameRef::of(d),
        faces: faces.iter().map(BoxMsg::from).collect(),
        scan_cycles: d.face_cycles,
    })
}

/// `Agent.motion` for a frame, or None when motion detection is off.
pub fn motion_msg(d: &FrameDetections) -> Option<MotionMsg> {
    let frame = FrameRef::of(d);
    Some(match d.motion.as_ref()? {
        Motion::Still => MotionMsg {
            frame,
            moving: false,
            centre: None,
            regions: Vec::new(),
            changed_fraction: 0.0,
            held: false,
        },
        Motion::Moving {
            regions,
            centre,
            changed_fraction,
            held,
        } => MotionMsg {
            frame,
            moving: true,
            centre: Some((*centre).into()),
            regions: regions.iter().map(BoxMsg::from).collect(),
            changed_fraction: *changed_fraction,
            held: *held,
        },
    })
}

/// `Agent.codes` for a frame: only when at least one code appears for the first time.
pub fn codes_msg(d: &FrameDetections) -> Option<CodesMsg> {
    let codes: Vec<CodeMsg> = d
        .codes
        .as_ref()?
        .iter()
        .filter(|s| s.first_sighting)
        .map(seen_msg)
        .collect();
    (!codes.is_empty()).then(|| CodesMsg {
        frame: FrameRef::of(d),
        codes,
    })
}

/// `Agent.detections` for a frame.
pub fn detections_msg(d: &FrameDetections, counters: CountersMsg) -> DetectionsMsg {
    DetectionsMsg {
        frame: FrameRef::of(d),
        faces: faces_msg(d).map(|m| m.faces),
        face_scan_cycles: d.face_cycles,
        motion: motion_msg(d),
        codes: d
            .codes
            .as_ref()
            .map(|seen| seen.iter().map(seen_msg).collect()),
        gaze: GazeMsg::from(&d.gaze),
        timing: TimingMsg::from(&d.timings),
        counters,
    }
}

/// The gaze command for `Agent.avatar`.
pub fn gaze_command(d: &FrameDetections) -> GazeCommand {
    GazeCommand {
        cmd: "gaze".to_owned(),
        x: d.gaze.x,
        y: d.gaze.y,
        source: gaze_source_name(d.gaze.source).to_owned(),
        seq: d.seq,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_is_lowercase_and_complete() {
        assert_eq!(hex(b"A\r\n\x00\xff"), "410d0a00ff");
    }

    #[test]
    fn non_utf8_payload_keeps_bytes() {
        let code = DecodedCode {
            symbology: crate::codes::Symbology::Qr,
            bytes: vec![0xff, b' '],
            polygon: vec![],
        };
        let msg = code_msg(&code, 1, true);
        assert_eq!(msg.text, None);
        assert_eq!(msg.hex, "ff20");
    }
}
