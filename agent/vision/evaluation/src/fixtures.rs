//! Access to the shared real-data fixtures (`../shared/fixtures` beside the repository, or `$AGENT_FIXTURES`) and
//! their ground truth, plus the face-matching score used by the tests and the benchmark to choose the cascade.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use agent_vision::geometry::BoxPx;

/// The fixtures directory: `$AGENT_FIXTURES` if set, else `shared/fixtures` next to the repository root.
pub fn fixtures_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os("AGENT_FIXTURES") {
        return PathBuf::from(dir);
    }
    // This crate sits at <repo>/agent/vision/evaluation; the shared folder is a sibling of <repo>.
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let manifest = manifest
        .canonicalize()
        .unwrap_or_else(|_| manifest.to_path_buf());
    manifest.join("../../../../shared/fixtures")
}

/// Loads an image file of any format OpenCV reads (the QR fixtures are PNGs), reduces it to grey and encodes it
/// as a JPEG at quality 95: the only format the camera channel carries.
pub fn image_as_jpeg(path: &Path) -> Result<Vec<u8>, FixtureError> {
    use opencv::core::{MatTraitConst, Vector, VectorToVec};
    use opencv::imgcodecs;
    let failed = |reason: String| FixtureError::Image {
        path: path.to_path_buf(),
        reason,
    };
    let grey = imgcodecs::imread(path.as_os_str(), imgcodecs::IMREAD_GRAYSCALE)
        .map_err(|e| failed(e.to_string()))?;
    if grey.empty() {
        return Err(failed("not an image OpenCV can read".to_owned()));
    }
    let mut jpeg = Vector::<u8>::new();
    let params = Vector::<i32>::from_slice(&[imgcodecs::IMWRITE_JPEG_QUALITY, 95]);
    imgcodecs::imencode(".jpg", &grey, &mut jpeg, &params).map_err(|e| failed(e.to_string()))?;
    Ok(jpeg.to_vec())
}

/// The camera format the page sends: 640x360 JPEGs encoded by the browser at quality 0.75
/// (`web/js/media/camera.js`), which libjpeg's quality 75 reproduces.
pub const CAMERA_WIDTH: i32 = 640;
pub const CAMERA_HEIGHT: i32 = 360;
pub const CAMERA_JPEG_QUALITY: i32 = 75;

/// An annotated photo as the camera would send it, with its ground truth in the same pixels.
#[derive(Debug, Clone)]
pub struct CameraImage {
    pub jpeg: Vec<u8>,
    pub truth: FaceTruth,
}

/// Puts an annotated photo into a 640x360 camera frame: scaled to fit with its aspect ratio kept, centred, the
/// rest black (what a canvas without alpha shows where nothing is drawn), then encoded as a colour JPEG at the
/// page's quality. The ground-truth boxes are scaled and shifted the same way.
pub fn letterbox(fixtures: &Path, truth: &FaceTruth) -> Result<CameraImage, FixtureError> {
    use opencv::core::{self, Mat, MatTraitConst, Scalar, Size, Vector, VectorToVec};
    use opencv::{imgcodecs, imgproc};
    let path = fixtures.join(&truth.image);
    let failed = |reason: String| FixtureError::Image {
        path: path.clone(),
        reason,
    };
    // The annotations refer to the stored pixels, so EXIF orientation is ignored as the decoder does.
    let photo = imgcodecs::imread(
        path.as_os_str(),
        imgcodecs::IMREAD_COLOR | imgcodecs::IMREAD_IGNORE_ORIENTATION,
    )
    .map_err(|e| failed(e.to_string()))?;
    if photo.empty() {
        return Err(failed("not an image OpenCV can read".to_owned()));
    }
    let scale = (f64::from(CAMERA_WIDTH) / f64::from(photo.cols()))
        .min(f64::from(CAMERA_HEIGHT) / f64::from(photo.rows()));
    let width = ((f64::from(photo.cols()) * scale).round() as i32).clamp(1, CAMERA_WIDTH);
    let height = ((f64::from(photo.rows()) * scale).round() as i32).clamp(1, CAMERA_HEIGHT);
    let mut scaled = Mat::default();
    // Area averaging when shrinking, like a browser's high-quality downscale; bilinear when enlarging.
    let interpolation = if scale < 1.0 {
        imgproc::INTER_AREA
    } else {
        imgproc::INTER_LINEAR
    };
    imgproc::resize(
        &photo,
        &mut scaled,
        Size::new(width, height),
        0.0,
        0.0,
        interpolation,
    )
    .map_err(|e| failed(e.to_string()))?;
    let left = (CAMERA_WIDTH - width) / 2;
    let top = (CAMERA_HEIGHT - height) / 2;
    let mut framed = Mat::default();
    core::copy_make_border(
        &scaled,
        &mut framed,
        top,
        CAMERA_HEIGHT - height - top,
        left,
        CAMERA_WIDTH - width - left,
        core::BORDER_CONSTANT,
        Scalar::all(0.0),
    )
    .map_err(|e| failed(e.to_string()))?;
    let mut jpeg = Vector::<u8>::new();
    let params = Vector::<i32>::from_slice(&[imgcodecs::IMWRITE_JPEG_QUALITY, CAMERA_JPEG_QUALITY]);
    imgcodecs::imencode(".jpg", &framed, &mut jpeg, &params).map_err(|e| failed(e.to_string()))?;
    // Both axes are scaled by the same factor, so box corners map exactly like the pixels.
    let map = |v: i32, offset: i32| (f64::from(v) * scale).round() as i32 + offset;
    let boxes = truth
        .boxes
        .iter()
        .map(|b| {
            let x = map(b.x, left);
            let y = map(b.y, top);
            BoxPx {
                x,
                y,
                width: map(b.x + b.width, left) - x,
                height: map(b.y + b.height, top) - y,
            }
        })
        .collect();
    Ok(CameraImage {
        jpeg: jpeg.to_vec(),
        truth: FaceTruth {
            image: truth.image.clone(),
            face_count: truth.face_count,
            boxes,
        },
    })
}

/// Why a fixture could not be read.
#[derive(Debug, thiserror::Error)]
pub enum FixtureError {
    #[error("cannot convert {} to JPEG: {reason}", path.display())]
    Image { path: PathBuf, reason: String },
    #[error("cannot read {}: {source}", path.display())]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot parse {}: {source}", path.display())]
    Parse {
        path: PathBuf,
        source: serde_json::Error,
    },
}

#[derive(Debug, Deserialize)]
struct GroundTruthFile {
    faces: BTreeMap<String, FaceEntry>,
    qr: BTreeMap<String, QrEntry>,
}

#[derive(Debug, Deserialize)]
struct FaceEntry {
    face_count: usize,
    #[serde(default)]
    boxes_xywh: Vec<XywhBox>,
    #[serde(default)]
    boxes_trbl_dlib_hog: Vec<[i32; 4]>,
}

#[derive(Debug, Deserialize)]
struct XywhBox {
    x: i32,
    y: i32,
    w: i32,
    h: i32,
}

#[derive(Debug, Deserialize)]
struct QrEntry {
    decoded_text: Option<String>,
    #[serde(default)]
    decoded_texts: Vec<String>,
}

/// Ground truth of one face image. `boxes` is empty where the source only gives a count.
#[derive(Debug, Clone)]
pub struct FaceTruth {
    pub image: String,
    pub face_count: usize,
    pub boxes: Vec<BoxPx>,
}

/// Ground truth of one QR image: the exact texts it must decode to.
#[derive(Debug, Clone)]
pub struct QrTruth {
    pub image: String,
    pub texts: Vec<String>,
}

/// The parts of `ground_truth.json` this crate uses.
#[derive(Debug, Clone)]
pub struct GroundTruth {
    pub faces: Vec<FaceTruth>,
    pub qr: Vec<QrTruth>,
}

impl GroundTruth {
    pub fn load(fixtures: &Path) -> Result<Self, FixtureError> {
        let path = fixtures.join("ground_truth.json");
        let text = std::fs::read_to_string(&path).map_err(|source| FixtureError::Read {
            path: path.clone(),
            source,
        })?;
        let file: GroundTruthFile =
            serde_json::from_str(&text).map_err(|source| FixtureError::Parse { path, source })?;
        let faces = file
            .faces
            .into_iter()
            .map(|(image, entry)| {
                let mut boxes: Vec<BoxPx> = entry
                    .boxes_xywh
                    .iter()
                    .map(|b| BoxPx {
                        x: b.x,
                        y: b.y,
                        width: b.w,
                        height: b.h,
                    })
                    .collect();
                boxes.extend(entry.boxes_trbl_dlib_hog.iter().map(
                    |&[top, right, bottom, left]| BoxPx {
                        x: left,
                        y: top,
                        width: right - left,
                        height: bottom - top,
                    },
                ));
                FaceTruth {
                    image,
                    face_count: entry.face_count,
                    boxes,
                }
            })
            .collect();
        let qr = file
            .qr
            .into_iter()
            .map(|(image, entry)| {
                let mut texts = entry.decoded_texts;
                texts.extend(entry.decoded_text);
                QrTruth { image, texts }
            })
            .collect();
        Ok(Self { faces, qr })
    }
}

/// How detections on one image compare with its ground truth.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FaceScore {
    pub annotated: usize,
    pub found: usize,
    pub false_positives: usize,
}

/// Face scores summed over the annotated images, with the acceptance bar of the face tests: recall of at least
/// 90% at IoU 0.3, and no more than 0.3 false positives per image on average.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct FaceTotals {
    pub images: usize,
    pub annotated: usize,
    pub found: usize,
    pub false_positives: usize,
}

impl FaceTotals {
    pub const MIN_RECALL: f64 = 0.90;
    pub const MAX_FALSE_POSITIVES_PER_IMAGE: f64 = 0.3;

    pub fn add(&mut self, score: &FaceScore) {
        self.images += 1;
        self.annotated += score.annotated;
        self.found += score.found;
        self.false_positives += score.false_positives;
    }

    pub fn recall(&self) -> f64 {
        self.found as f64 / self.annotated.max(1) as f64
    }

    pub fn false_positives_per_image(&self) -> f64 {
        self.false_positives as f64 / self.images.max(1) as f64
    }

    /// The totals line of the per-image table.
    pub fn summary(&self) -> String {
        format!(
            "recall {}/{} = {:.2}, false positives per image {:.2}",
            self.found,
            self.annotated,
            self.recall(),
            self.false_positives_per_image()
        )
    }

    /// Whether the bar is met; the error says which part is not.
    pub fn check(&self) -> Result<(), String> {
        if self.recall() < Self::MIN_RECALL {
            return Err(format!(
                "recall {:.2} below {}",
                self.recall(),
                Self::MIN_RECALL
            ));
        }
        if self.false_positives_per_image() > Self::MAX_FALSE_POSITIVES_PER_IMAGE {
            return Err(format!(
                "{:.2} false positives per image, more than {}",
                self.false_positives_per_image(),
                Self::MAX_FALSE_POSITIVES_PER_IMAGE
            ));
        }
        Ok(())
    }
}

/// Matches detections to annotated boxes greedily by IoU (each used once) and counts hits at `min_iou` and extra
/// detections. For an image with only a face count, detections up to the count are hits and the rest are false
/// positives (the count-only images are portraits, where that is a fair reading).
pub fn score_faces(truth: &FaceTruth, detections: &[BoxPx], min_iou: f64) -> FaceScore {
    if truth.boxes.is_empty() {
        let found = detections.len().min(truth.face_count);
        return FaceScore {
            annotated: truth.face_count,
            found,
            false_positives: detections.len() - found,
        };
    }
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (t, annotated) in truth.boxes.iter().enumerate() {
        for (d, detected) in detections.iter().enumerate() {
            let iou = annotated.iou(detected);
            if iou >= min_iou {
                pairs.push((iou, t, d));
            }
        }
    }
    pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut truth_used = vec![false; truth.boxes.len()];
    let mut detection_used = vec![false; detections.len()];
    let mut found = 0;
    for (_, t, d) in pairs {
        if !truth_used[t] && !detection_used[d] {
            truth_used[t] = true;
            detection_used[d] = true;
            found += 1;
        }
    }
    FaceScore {
        annotated: truth.boxes.len(),
        found,
        false_positives: detections.len() - found,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn greedy_matching_uses_each_box_once() {
        let truth = FaceTruth {
            image: "x".into(),
            face_count: 2,
            boxes: vec![
                BoxPx {
                    x: 0,
                    y: 0,
                    width: 10,
                    height: 10,
                },
                BoxPx {
                    x: 100,
                    y: 0,
                    width: 10,
                    height: 10,
                },
            ],
        };
        let detections = [
            BoxPx {
                x: 1,
                y: 1,
                width: 10,
                height: 10,
            },
            BoxPx {
                x: 0,
                y: 0,
                width: 11,
                height: 11,
            },
            BoxPx {
                x: 300,
                y: 0,
                width: 10,
                height: 10,
            },
        ];
        let score = score_faces(&truth, &detections, 0.3);
        assert_eq!(
            score,
            FaceScore {
                annotated: 2,
                found: 1,
                false_positives: 2
            }
        );
    }

    #[test]
    fn count_only_truth() {
        let truth = FaceTruth {
            image: "x".into(),
            face_count: 2,
            boxes: vec![],
        };
        let three = [BoxPx {
            x: 0,
            y: 0,
            width: 1,
            height: 1,
        }; 3];
        assert_eq!(
            score_faces(&truth, &three, 0.3),
            FaceScore {
                annotated: 2,
                found: 2,
                false_positives: 1
            }
        );
    }
}
