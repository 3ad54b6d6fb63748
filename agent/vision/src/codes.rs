//! QR codes and 1D barcodes (EAN-8/13, UPC-A/E, Code 128) with `rxing`, the Rust port of ZXing.
//!
//! Why not OpenCV here: Debian's OpenCV 4.6 is built without quirc, so `QRCodeDetector` finds QR codes but
//! decodes none ("Library QUIRC is not linked"), and its contrib `barcode` module reads only EAN/UPC (no Code 128)
//! at about 6 ms per 640x360 frame against well under 1 ms for rxing's row scan. `docs/vision.md` has the figures.
//!
//! The payload text is kept exactly as decoded: QR payloads may contain `\r\n`, trailing spaces or NUL bytes, and
//! nothing is trimmed.

use std::collections::HashSet;

use opencv::core::{MatTraitConst, MatTraitConstManual};
use rxing::common::HybridBinarizer;
use rxing::multi::{GenericMultipleBarcodeReader, MultipleBarcodeReader};
use rxing::{
    BarcodeFormat, BinaryBitmap, DecodeHintValue, DecodeHints, Luma8LuminanceSource,
    MultiUseMultiFormatReader,
};

use crate::error::VisionError;
use crate::frame::GreyFrame;
use crate::geometry::PointPx;

/// The kind of code that was read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Symbology {
    Qr,
    Ean8,
    Ean13,
    UpcA,
    UpcE,
    Code128,
}

impl Symbology {
    pub fn name(self) -> &'static str {
        match self {
            Symbology::Qr => "qr",
            Symbology::Ean8 => "ean8",
            Symbology::Ean13 => "ean13",
            Symbology::UpcA => "upca",
            Symbology::UpcE => "upce",
            Symbology::Code128 => "code128",
        }
    }

    fn from_format(format: BarcodeFormat) -> Option<Self> {
        Some(match format {
            BarcodeFormat::QR_CODE => Symbology::Qr,
            BarcodeFormat::EAN_8 => Symbology::Ean8,
            BarcodeFormat::EAN_13 => Symbology::Ean13,
            BarcodeFormat::UPC_A => Symbology::UpcA,
            BarcodeFormat::UPC_E => Symbology::UpcE,
            BarcodeFormat::CODE_128 => Symbology::Code128,
            _ => return None,
        })
    }
}

/// One decoded code: its exact payload and where it is.
#[derive(Debug, Clone, PartialEq)]
pub struct DecodedCode {
    pub symbology: Symbology,
    /// The payload as decoded (UTF-8 of the decoder's text; for QR byte segments ZXing's charset rules apply).
    pub bytes: Vec<u8>,
    /// For QR a quadrilateral through the centres of the finder patterns (the code's outer corners lie a few
    /// modules further out); for a 1D code the two ends of the decoded scan line. Frame pixels.
    pub polygon: Vec<PointPx>,
}

/// Which code families to look for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CodeParams {
    pub qr: bool,
    pub barcodes: bool,
}

impl Default for CodeParams {
    fn default() -> Self {
        Self {
            qr: true,
            barcodes: true,
        }
    }
}

/// Reads every QR code and barcode in a grey frame.
pub struct CodeReader {
    params: CodeParams,
    hints: DecodeHints,
}

impl std::fmt::Debug for CodeReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CodeReader")
            .field("params", &self.params)
            .finish_non_exhaustive()
    }
}

impl CodeReader {
    pub fn new(params: CodeParams) -> Result<Self, VisionError> {
        let mut formats = HashSet::new();
        if params.qr {
            formats.insert(BarcodeFormat::QR_CODE);
        }
        if params.barcodes {
            formats.extend([
                BarcodeFormat::EAN_8,
                BarcodeFormat::EAN_13,
                BarcodeFormat::UPC_A,
                BarcodeFormat::UPC_E,
                BarcodeFormat::CODE_128,
            ]);
        }
        if formats.is_empty() {
            return Err(VisionError::InvalidSetting {
                key: "codes",
                reason: "enabled with neither qr nor barcodes".to_owned(),
            });
        }
        // "Try harder" rotates and rescans the image; at camera rate the next frame is the better retry.
        let hints = DecodeHints::default()
            .with(DecodeHintValue::PossibleFormats(formats))
            .with(DecodeHintValue::TryHarder(false));
        Ok(Self { params, hints })
    }

    /// Finds and decodes every code in the frame. Nothing found is an empty list, not an error.
    pub fn read(&mut self, frame: &GreyFrame) -> Result<Vec<DecodedCode>, VisionError> {
        let mat = frame.mat();
        let luma = if mat.is_continuous() {
            mat.data_bytes()?.to_vec()
        } else {
            mat.try_clone()?.data_bytes()?.to_vec()
        };
        let size = frame.size();
        let mut bitmap = BinaryBitmap::new(HybridBinarizer::new(Luma8LuminanceSource::new(
            luma,
            size.width,
            size.height,
        )));
        let mut scanner = GenericMultipleBarcodeReader::new(MultiUseMultiFormatReader::default());
        // rxing reports "nothing found" and "found but unreadable" as errors; for a camera frame both mean no code.
        let results = scanner
            .decode_multiple_with_hints(&mut bitmap, &self.hints)
            .unwrap_or_default();
        Ok(results
            .into_iter()
            .filter_map(|result| {
                let symbology = Symbology::from_format(*result.getBarcodeFormat())?;
                let points: Vec<PointPx> = result
                    .getPoints()
                    .iter()
                    .map(|p| PointPx { x: p.x, y: p.y })
                    .collect();
                let polygon = if symbology == Symbology::Qr {
                    qr_quad(&points)
                } else {
                    points
                };
                Some(DecodedCode {
                    symbology,
                    bytes: result.getText().as_bytes().to_vec(),
                    polygon,
                })
            })
            .collect())
    }
}

/// ZXing reports a QR code's finder patterns as bottom-left, top-left, top-right (an alignment pattern may
/// follow); the fourth corner completes the parallelogram.
fn qr_quad(points: &[PointPx]) -> Vec<PointPx> {
    match points {
        [bottom_left, top_left, top_right, ..] => {
            let bottom_right = PointPx {
                x: top_right.x + bottom_left.x - top_left.x,
                y: top_right.y + bottom_left.y - top_left.y,
            };
            vec![*top_left, *top_right, bottom_right, *bottom_left]
        }
        _ => points.to_vec(),
    }
}
