//! The Y-channel frame: a colour JPEG turned into a single-channel (greyscale) JPEG for the detectors.
//!
//! The JPEG is decoded straight to luma with zune-jpeg (the decoder the `image` crate itself uses), which skips
//! the colour conversion a decode to RGB followed by a grey conversion would pay for; the `image` crate's JPEG
//! encoder then writes the one-channel result.

use std::io::Cursor;

use image::ExtendedColorType;
use image::codecs::jpeg::JpegEncoder;
use zune_jpeg::JpegDecoder;
use zune_jpeg::zune_core::colorspace::ColorSpace;
use zune_jpeg::zune_core::options::DecoderOptions;

/// Camera frames are 640x360; anything over this is not a camera frame and is refused before decoding.
const MAX_SIDE: usize = 4096;

/// A greyscale JPEG and its size.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GreyFrame {
    pub jpeg: Vec<u8>,
    pub width: u32,
    pub height: u32,
}

#[derive(Debug, thiserror::Error)]
pub enum LumaError {
    #[error("frame is not a decodable JPEG: {0}")]
    Decode(String),
    #[error("decoded {got} luma bytes for a {width}x{height} frame")]
    Size {
        got: usize,
        width: usize,
        height: usize,
    },
    #[error("grey JPEG encoding failed: {0}")]
    Encode(#[from] image::ImageError),
}

/// Converts a colour (or grey) JPEG to a grey JPEG of the same size at `quality` (1..=100).
pub fn grey_jpeg(jpeg: &[u8], quality: u8) -> Result<GreyFrame, LumaError> {
    let options = DecoderOptions::default()
        .jpeg_set_out_colorspace(ColorSpace::Luma)
        .set_max_width(MAX_SIDE)
        .set_max_height(MAX_SIDE);
    let mut decoder = JpegDecoder::new_with_options(Cursor::new(jpeg), options);
    let pixels = decoder
        .decode()
        .map_err(|e| LumaError::Decode(format!("{e:?}")))?;
    let (width, height) = decoder
        .dimensions()
        .ok_or_else(|| LumaError::Decode("no dimensions".into()))?;
    if pixels.len() != width * height {
        return Err(LumaError::Size {
            got: pixels.len(),
            width,
            height,
        });
    }
    let (w, h) = (
        u32::try_from(width).unwrap_or(0),
        u32::try_from(height).unwrap_or(0),
    );
    let mut out = Vec::with_capacity(pixels.len() / 8);
    JpegEncoder::new_with_quality(&mut out, quality.clamp(1, 100)).encode(
        &pixels,
        w,
        h,
        ExtendedColorType::L8,
    )?;
    Ok(GreyFrame {
        jpeg: out,
        width: w,
        height: h,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn colour_jpeg() -> Vec<u8> {
        // A 64x36 frame: a red left half and a blue right half.
        let mut rgb = Vec::with_capacity(64 * 36 * 3);
        for _y in 0..36 {
            for x in 0..64 {
                rgb.extend_from_slice(if x < 32 {
                    &[220, 30, 30]
                } else {
                    &[30, 30, 220]
                });
            }
        }
        let mut out = Vec::new();
        JpegEncoder::new_with_quality(&mut out, 90)
            .encode(&rgb, 64, 36, ExtendedColorType::Rgb8)
            .expect("encode");
        out
    }

    #[test]
    fn colour_becomes_one_channel_with_bt601_luma() {
        let grey = grey_jpeg(&colour_jpeg(), 85).expect("grey");
        assert_eq!((grey.width, grey.height), (64, 36));
        let img = image::load_from_memory(&grey.jpeg).expect("decodes");
        assert_eq!(img.color(), image::ColorType::L8, "single channel");
        let l = img.to_luma8();
        // BT.601: Y = 0.299 R + 0.587 G + 0.114 B -> red ~ 87, blue ~ 56.
        let left = l.get_pixel(8, 18).0[0];
        let right = l.get_pixel(56, 18).0[0];
        assert!((80..=95).contains(&left), "red luma {left}");
        assert!((48..=64).contains(&right), "blue luma {right}");
    }

    #[test]
    fn garbage_is_an_error_not_a_panic() {
        assert!(matches!(
            grey_jpeg(&[0xFF, 0xD8, 0x00, 0x01], 80),
            Err(LumaError::Decode(_))
        ));
        assert!(grey_jpeg(b"hello", 80).is_err());
    }
}
