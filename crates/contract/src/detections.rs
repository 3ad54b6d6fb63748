//! The vision messages: `Agent.faces`, `Agent.motion`, `Agent.codes`, `Agent.detections` and the gaze command on
//! `Agent.avatar`. Geometry is in frame pixels, (0, 0) top-left, the frame's size in [`FrameRef`]. Field names are
//! the contract with the page, the behaviour controller and the brain (docs/vision.md).

use serde::{Deserialize, Serialize};

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
    #[serde(default)]
    pub centre: Option<PointMsg>,
    #[serde(default)]
    pub regions: Vec<BoxMsg>,
    #[serde(default)]
    pub changed_fraction: f64,
    /// The frame itself was quiet and the last motion is held by the hysteresis.
    #[serde(default)]
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

/// One person in view: a face the per-face analysis followed (docs/vision.md, "People"). Landmark measures are in
/// units of the distance between the outer eye corners, so a face's size does not change them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PersonMsg {
    /// Stays the same while the face stays in view (a face lost for a second gets a new one).
    pub id: u64,
    pub face: BoxMsg,
    /// The inner lips' gap: about 0 closed, 0.1-0.4 talking.
    pub mouth_open: f32,
    /// The eyes' height over their width: about 0.25-0.35 open, under 0.15 closed.
    pub eyes_open: f32,
    /// Head turn in degrees, positive towards the image's right; an estimate from the landmarks.
    pub yaw_deg: f32,
    /// Head tilt in degrees, positive up.
    pub pitch_deg: f32,
    /// The face is turned to the camera (yaw and pitch within 25 degrees).
    pub looking: bool,
    /// 0 (at rest) to 1 (a broad smile).
    pub smile: f32,
    pub smiling: bool,
    /// This face's mouth moves while a voice is heard: the one who is talking (at most one person at a time).
    pub speaking: bool,
    /// The name the person gave, when the agent was introduced to this face (`learn_face`) and knows it again.
    #[serde(default)]
    pub name: Option<String>,
}

/// Per-stage time of a frame in milliseconds; a stage that is switched off is `null`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TimingMsg {
    pub decode_ms: f64,
    pub faces_ms: Option<f64>,
    /// The per-face analysis (landmarks, and a descriptor when one is due).
    #[serde(default)]
    pub people_ms: Option<f64>,
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

/// `Agent.detections`: one per processed frame, everything seen in it, in frame pixels. The page's overlay draws
/// its faces, motion regions and centre, and code polygons (`web/js/panels/overlay-items.js`); the behaviour
/// controller turns its gaze into the avatar's gaze; the brain turns it into percepts. A stage that is switched
/// off leaves its field `null`. Another detector may publish it without the figures (`timing`, `counters`) and
/// without a gaze target: consumers then look at the largest face or the moving centre themselves.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DetectionsMsg {
    pub frame: FrameRef,
    #[serde(default)]
    pub faces: Option<Vec<BoxMsg>>,
    #[serde(default)]
    pub face_scan_cycles: u64,
    /// The faces analysed: who looks, smiles, speaks, and known names; `null` when the analysis is off.
    #[serde(default)]
    pub people: Option<Vec<PersonMsg>>,
    #[serde(default)]
    pub motion: Option<MotionMsg>,
    /// Every code visible in this frame, new or not.
    #[serde(default)]
    pub codes: Option<Vec<CodeMsg>>,
    /// Where the avatar should look; `source` `idle` when nothing is seen.
    #[serde(default)]
    pub gaze: Option<GazeMsg>,
    #[serde(default)]
    pub timing: Option<TimingMsg>,
    #[serde(default)]
    pub counters: Option<CountersMsg>,
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
