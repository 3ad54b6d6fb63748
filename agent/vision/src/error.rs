//! Error types of the vision library: one for a bad frame (the caller counts it and skips the frame) and one for
//! setting up or running the detectors.

use std::path::PathBuf;

/// Why one frame could not be turned into pixels. The caller logs it, counts it and moves on to the next frame.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    #[error("not a JPEG (no start-of-image marker)")]
    NotJpeg,
    #[error("truncated JPEG: {0}")]
    Truncated(&'static str),
    #[error("malformed JPEG: {0}")]
    Malformed(&'static str),
    #[error("frame of {width}x{height} exceeds the limit of {max_pixels} pixels")]
    TooLarge {
        width: u32,
        height: u32,
        max_pixels: u64,
    },
    #[error("the JPEG decoder produced no image")]
    Undecodable,
    #[error("the JPEG decoder failed: {0}")]
    Decode(String),
    #[error("OpenCV failed while decoding: {0}")]
    OpenCv(#[from] opencv::Error),
}

/// A failure to build or run a detector.
#[derive(Debug, thiserror::Error)]
pub enum VisionError {
    #[error("cascade file {} could not be loaded (is Debian's opencv-data installed?)", path.display())]
    CascadeLoad { path: PathBuf },
    #[error("faces.centerface.model: {} not found (run `make model MODEL=centerface`, or set faces.detector = \"cascades\")", path.display())]
    ModelMissing { path: PathBuf },
    #[error("face model {} could not be loaded: {reason}", path.display())]
    ModelLoad { path: PathBuf, reason: String },
    #[error("face model output: {0}")]
    ModelOutput(String),
    #[error("invalid vision setting `{key}`: {reason}")]
    InvalidSetting { key: &'static str, reason: String },
    #[error("OpenCV: {0}")]
    OpenCv(#[from] opencv::Error),
    #[error("barcode reader: {0}")]
    Barcode(String),
    #[error("people: {0}")]
    Face(#[from] agent_face::FaceError),
}

/// Why processing one frame failed: a bad frame (skip it) or a detector failure.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    #[error(transparent)]
    Frame(#[from] FrameError),
    #[error(transparent)]
    Detector(#[from] VisionError),
}
