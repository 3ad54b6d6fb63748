//! A borrowed 8-bit grey frame, checked once so that the FFI calls can trust its size.

use crate::error::FaceError;

/// Rows of `stride` bytes, each with `width` pixels in front.
#[derive(Debug, Clone, Copy)]
pub struct GreyImage<'a> {
    pixels: &'a [u8],
    width: i32,
    height: i32,
    stride: i32,
}

impl<'a> GreyImage<'a> {
    /// Fails unless `pixels` holds `height` rows of `stride` bytes and `0 < width <= stride`.
    pub fn new(pixels: &'a [u8], width: u32, height: u32, stride: u32) -> Result<Self, FaceError> {
        let as_i32 = |v: u32, what: &str| {
            i32::try_from(v).map_err(|_| FaceError::Image(format!("{what} {v} is too large")))
        };
        if width == 0 || height == 0 || width > stride {
            return Err(FaceError::Image(format!(
                "{width}x{height} with a row stride of {stride} bytes"
            )));
        }
        let needed = u64::from(stride) * u64::from(height);
        if (pixels.len() as u64) < needed {
            return Err(FaceError::Image(format!(
                "{} bytes for {height} rows of {stride}",
                pixels.len()
            )));
        }
        Ok(Self {
            pixels,
            width: as_i32(width, "width")?,
            height: as_i32(height, "height")?,
            stride: as_i32(stride, "stride")?,
        })
    }

    pub fn pixels(&self) -> &'a [u8] {
        self.pixels
    }

    pub fn width(&self) -> i32 {
        self.width
    }

    pub fn height(&self) -> i32 {
        self.height
    }

    pub fn stride(&self) -> i32 {
        self.stride
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_buffer_too_short_for_its_rows_is_refused() {
        assert!(GreyImage::new(&[0; 100], 10, 10, 10).is_ok());
        assert!(GreyImage::new(&[0; 99], 10, 10, 10).is_err());
        assert!(GreyImage::new(&[0; 100], 11, 10, 10).is_err());
        assert!(GreyImage::new(&[0; 100], 0, 10, 10).is_err());
    }
}
