//! A decoded grey camera frame and the one way to get it from JPEG bytes.

use opencv::core::{Mat, MatTraitConst};
use opencv::imgcodecs;

use crate::error::FrameError;
use crate::geometry::FrameSize;
use crate::jpeg;

/// Frames larger than this are refused before decoding; 4K is far above the 640x360 camera format.
pub const DEFAULT_MAX_PIXELS: u64 = 3840 * 2160;

/// A single-channel 8-bit frame. Colour JPEGs are reduced to luma while decoding, which is cheaper than decoding
/// colour and converting, and every detector here works on grey.
#[derive(Debug)]
pub struct GreyFrame {
    mat: Mat,
    size: FrameSize,
}

impl GreyFrame {
    /// Wraps an 8-bit single-channel matrix, e.g. one loaded by a test from a PNG.
    pub fn from_mat(mat: Mat) -> Result<Self, FrameError> {
        if mat.empty() || mat.typ() != opencv::core::CV_8UC1 {
            return Err(FrameError::Undecodable);
        }
        let size = FrameSize {
            width: mat.cols().unsigned_abs(),
            height: mat.rows().unsigned_abs(),
        };
        Ok(Self { mat, size })
    }

    pub fn mat(&self) -> &Mat {
        &self.mat
    }

    pub fn size(&self) -> FrameSize {
        self.size
    }
}

/// Checks the JPEG's structure and size, then decodes it to grey.
pub fn decode_jpeg(bytes: &[u8], max_pixels: u64) -> Result<GreyFrame, FrameError> {
    let header = jpeg::inspect(bytes)?;
    if u64::from(header.width) * u64::from(header.height) > max_pixels {
        return Err(FrameError::TooLarge {
            width: header.width,
            height: header.height,
            max_pixels,
        });
    }
    // EXIF orientation is ignored: camera frames carry none, and fixture annotations refer to the stored pixels.
    let mat = imgcodecs::imdecode(
        &bytes,
        imgcodecs::IMREAD_GRAYSCALE | imgcodecs::IMREAD_IGNORE_ORIENTATION,
    )?;
    GreyFrame::from_mat(mat)
}
