//! A decoded grey camera frame and the one way to get it from JPEG bytes.

use std::io::Cursor;

use opencv::core::{Mat, MatTraitConst};
use zune_jpeg::JpegDecoder;
use zune_jpeg::zune_core::colorspace::ColorSpace;
use zune_jpeg::zune_core::options::DecoderOptions;

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
    // zune-jpeg decodes straight to luma (no colour conversion), about as fast as libjpeg-turbo's grey output,
    // and keeps OpenCV's imgcodecs out of the server: on Debian that library drags in GDAL, DCMTK, Poppler and
    // some 130 other shared libraries, about 25 MB of resident pages in a process that never reads a TIFF.
    // EXIF orientation is ignored: camera frames carry none, and fixture annotations refer to the stored pixels.
    let options = DecoderOptions::default()
        .jpeg_set_out_colorspace(ColorSpace::Luma)
        .set_max_width(usize::try_from(header.width).unwrap_or(usize::MAX))
        .set_max_height(usize::try_from(header.height).unwrap_or(usize::MAX));
    let mut decoder = JpegDecoder::new_with_options(Cursor::new(bytes), options);
    let pixels = decoder
        .decode()
        .map_err(|e| FrameError::Decode(e.to_string()))?;
    let (width, height) = decoder.dimensions().ok_or(FrameError::Undecodable)?;
    if pixels.len() != width * height {
        return Err(FrameError::Undecodable);
    }
    let rows = i32::try_from(height).map_err(|_| FrameError::Undecodable)?;
    let cols = i32::try_from(width).map_err(|_| FrameError::Undecodable)?;
    // The borrowed view is cloned into a matrix that owns its pixels, so the frame outlives `pixels`.
    let mat = Mat::new_rows_cols_with_data(rows, cols, &pixels)?.try_clone()?;
    GreyFrame::from_mat(mat)
}
