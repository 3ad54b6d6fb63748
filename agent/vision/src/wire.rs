//! The vision module's messages (`Agent.faces`, `Agent.motion`, `Agent.codes`, `Agent.detections`, and the gaze
//! command on `Agent.avatar`): the types are the contract crate's (`agent_contract::detections`); this is where the
//! detectors' plain domain types are converted into them.

pub use agent_contract::detections::{
    BoxMsg, CodeMsg, CodesMsg, CountersMsg, DetectionsMsg, FacesMsg, FrameRef, GazeCommand,
    GazeMsg, MotionMsg, PersonMsg, PointMsg, TimingMsg,
};

use crate::appearance::SeenCode;
use crate::codes::DecodedCode;
use crate::gaze::{GazeSource, GazeTarget};
use crate::geometry::{BoxPx, PointPx};
use crate::motion::Motion;
use crate::people::Person;
use crate::pipeline::{FrameDetections, StageTimings};

/// Which frame `detections` are about.
pub fn frame_ref(detections: &FrameDetections) -> FrameRef {
    FrameRef {
        seq: detections.seq,
        ts_us: detections.frame_us,
        width: detections.size.width,
        height: detections.size.height,
    }
}

impl From<&BoxPx> for BoxMsg {
    fn from(b: &BoxPx) -> Self {
        BoxMsg {
            x: b.x,
            y: b.y,
            w: b.width,
            h: b.height,
        }
    }
}

impl From<PointPx> for PointMsg {
    fn from(p: PointPx) -> Self {
        PointMsg { x: p.x, y: p.y }
    }
}

impl From<&Person> for PersonMsg {
    fn from(p: &Person) -> Self {
        // Two decimals say all the measures can tell, and keep the message short.
        let round = |v: f32| (v * 100.0).round() / 100.0;
        PersonMsg {
            id: p.id,
            face: BoxMsg::from(&p.face),
            mouth_open: round(p.measures.mouth_open),
            eyes_open: round(p.measures.eyes_open),
            yaw_deg: p.measures.yaw_deg.round(),
            pitch_deg: p.measures.pitch_deg.round(),
            looking: p.measures.looking(),
            smile: round(p.measures.smile),
            smiling: p.measures.smiling(),
            speaking: p.speaking,
            name: p.name.clone(),
        }
    }
}

impl From<&GazeTarget> for GazeMsg {
    fn from(g: &GazeTarget) -> Self {
        GazeMsg {
            x: g.x,
            y: g.y,
            source: gaze_source_name(g.source).to_owned(),
        }
    }
}

impl From<&StageTimings> for TimingMsg {
    fn from(t: &StageTimings) -> Self {
        let ms = |d: std::time::Duration| d.as_secs_f64() * 1000.0;
        TimingMsg {
            decode_ms: ms(t.decode),
            faces_ms: t.faces.map(ms),
            people_ms: t.people.map(ms),
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
        frame: frame_ref(d),
        faces: faces.iter().map(BoxMsg::from).collect(),
        scan_cycles: d.face_cycles,
    })
}

/// `Agent.motion` for a frame, or None when motion detection is off.
pub fn motion_msg(d: &FrameDetections) -> Option<MotionMsg> {
    let frame = frame_ref(d);
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
        frame: frame_ref(d),
        codes,
    })
}

/// `Agent.detections` for a frame.
pub fn detections_msg(d: &FrameDetections, counters: CountersMsg) -> DetectionsMsg {
    DetectionsMsg {
        frame: frame_ref(d),
        faces: faces_msg(d).map(|m| m.faces),
        face_scan_cycles: d.face_cycles,
        people: d
            .people
            .as_ref()
            .map(|people| people.iter().map(PersonMsg::from).collect()),
        motion: motion_msg(d),
        codes: d
            .codes
            .as_ref()
            .map(|seen| seen.iter().map(seen_msg).collect()),
        gaze: Some(GazeMsg::from(&d.gaze)),
        timing: Some(TimingMsg::from(&d.timings)),
        counters: Some(counters),
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
