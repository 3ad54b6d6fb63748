//! Cheap structural checks on JPEG bytes before they reach the decoder.
//!
//! libjpeg (and so `cv::imdecode`) only warns on a truncated stream and hands back an image whose missing part is
//! grey, which would look like a real frame to every detector. Checking the markers ourselves turns "not a JPEG" and
//! "truncated" into typed errors, and reading the frame header first lets us refuse absurd dimensions before any
//! pixel memory is allocated.

use crate::error::FrameError;

/// Dimensions read from a JPEG's start-of-frame header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct JpegHeader {
    pub width: u32,
    pub height: u32,
    /// 1 for a grey JPEG, 3 for colour.
    pub components: u8,
}

/// How far from the end the end-of-image marker may sit. Some encoders pad the stream after EOI; inside
/// entropy-coded data a 0xFF byte is always followed by 0x00 or a restart marker, so 0xFF 0xD9 this close to the
/// end cannot be a false match.
const EOI_SEARCH_WINDOW: usize = 32;

/// Validates the marker structure of `bytes` and returns the frame header.
pub fn inspect(bytes: &[u8]) -> Result<JpegHeader, FrameError> {
    if bytes.len() < 4 || bytes[0] != 0xFF || bytes[1] != 0xD8 || bytes[2] != 0xFF {
        return Err(FrameError::NotJpeg);
    }
    let tail_start = bytes.len().saturating_sub(EOI_SEARCH_WINDOW);
    let has_eoi = bytes[tail_start..]
        .windows(2)
        .any(|pair| pair == [0xFF, 0xD9]);
    let header = read_frame_header(bytes)?;
    if !has_eoi {
        return Err(FrameError::Truncated("no end-of-image marker"));
    }
    Ok(header)
}

/// Walks the marker segments after SOI until the first start-of-frame marker.
fn read_frame_header(bytes: &[u8]) -> Result<JpegHeader, FrameError> {
    let mut pos = 2;
    loop {
        // Markers may be preceded by any number of 0xFF fill bytes.
        while bytes.get(pos) == Some(&0xFF) && bytes.get(pos + 1) == Some(&0xFF) {
            pos += 1;
        }
        let (Some(&0xFF), Some(&marker)) = (bytes.get(pos), bytes.get(pos + 1)) else {
            return Err(FrameError::Truncated("stream ends before the frame header"));
        };
        pos += 2;
        match marker {
            // Standalone markers carry no length field.
            0x01 | 0xD0..=0xD7 => continue,
            0xD9 | 0xDA => {
                return Err(FrameError::Malformed(
                    "no frame header before the image data",
                ));
            }
            _ => {}
        }
        let Some(length) = read_u16(bytes, pos) else {
            return Err(FrameError::Truncated("segment length cut off"));
        };
        let length = usize::from(length);
        if length < 2 {
            return Err(FrameError::Malformed("segment length below 2"));
        }
        if is_start_of_frame(marker) {
            let height = read_u16(bytes, pos + 3);
            let width = read_u16(bytes, pos + 5);
            let components = bytes.get(pos + 7).copied();
            return match (width, height, components) {
                (Some(width), Some(height), Some(components)) if width > 0 && height > 0 => {
                    Ok(JpegHeader {
                        width: u32::from(width),
                        height: u32::from(height),
                        components,
                    })
                }
                (Some(_), Some(_), Some(_)) => Err(FrameError::Malformed("zero width or height")),
                _ => Err(FrameError::Truncated("frame header cut off")),
            };
        }
        pos += length;
    }
}

/// SOF0..SOF15 except DHT (C4), JPG (C8) and DAC (CC), which share the range.
fn is_start_of_frame(marker: u8) -> bool {
    matches!(marker, 0xC0..=0xCF) && !matches!(marker, 0xC4 | 0xC8 | 0xCC)
}

fn read_u16(bytes: &[u8], pos: usize) -> Option<u16> {
    let high = *bytes.get(pos)?;
    let low = *bytes.get(pos + 1)?;
    Some(u16::from_be_bytes([high, low]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The smallest baseline header we need: SOI, SOF0 for 8x4 grey, EOI.
    fn minimal() -> Vec<u8> {
        vec![
            0xFF, 0xD8, 0xFF, 0xC0, 0x00, 0x0B, 0x08, 0x00, 0x04, 0x00, 0x08, 0x01, 0x01, 0x11,
            0x00, 0xFF, 0xD9,
        ]
    }

    #[test]
    fn reads_dimensions() {
        let header = inspect(&minimal()).expect("valid header");
        assert_eq!(
            header,
            JpegHeader {
                width: 8,
                height: 4,
                components: 1
            }
        );
    }

    #[test]
    fn rejects_png_and_empty() {
        assert!(matches!(
            inspect(b"\x89PNG\r\n\x1a\n0000"),
            Err(FrameError::NotJpeg)
        ));
        assert!(matches!(inspect(b""), Err(FrameError::NotJpeg)));
    }

    #[test]
    fn rejects_missing_end_marker() {
        let mut bytes = minimal();
        bytes.truncate(bytes.len() - 2);
        bytes.extend_from_slice(&[0x12; 40]);
        assert!(matches!(inspect(&bytes), Err(FrameError::Truncated(_))));
    }

    #[test]
    fn rejects_header_cut_off() {
        let bytes = &minimal()[..8];
        assert!(matches!(inspect(bytes), Err(FrameError::Truncated(_))));
    }
}
