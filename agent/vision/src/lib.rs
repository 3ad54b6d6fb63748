//! Vision detectors (faces, motion, QR and barcodes) on camera frames, built on OpenCV.
//!
//! Everything here is plain library code over JPEG bytes or decoded grey frames; the hub plumbing lives in the
//! server's vision module. [`VisionPipeline`] runs the enabled detectors on one frame and returns a
//! [`FrameDetections`]; [`wire`] turns that into the JSON messages published on the hub.

pub mod appearance;
pub mod centerface;
pub mod codes;
pub mod error;
pub mod face;
pub mod frame;
pub mod gaze;
pub mod geometry;
pub mod jpeg;
pub mod motion;
pub mod people;
pub mod people_settings;
pub mod pipeline;
mod setting_check;
pub mod settings;
pub mod speaker;
pub mod wire;

pub use error::{FrameError, ProcessError, VisionError};
pub use pipeline::{FrameDetections, PipelineParams, StageTimings, VisionPipeline};

/// Sets how many threads OpenCV may use inside one call, process-wide. The vision module keeps it at one so that
/// its cost stays on one core, next to the hub and the other modules on a small machine.
pub fn set_opencv_threads(threads: u32) -> Result<(), VisionError> {
    opencv::core::set_num_threads(i32::try_from(threads).unwrap_or(i32::MAX))?;
    Ok(())
}
