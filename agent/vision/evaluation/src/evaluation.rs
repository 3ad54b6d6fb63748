//! Face recall and false positives of the vision pipeline on still camera frames, the way the module sees a
//! camera pointed at a still scene: the same JPEG fed frame after frame through [`VisionPipeline::process_jpeg`]
//! until the budgeted face scan has covered it, then the last frame's faces scored against the ground truth.

use std::path::Path;

use agent_vision::error::ProcessError;
use agent_vision::geometry::BoxPx;
use agent_vision::pipeline::VisionPipeline;

use crate::fixtures::{FaceScore, FaceTotals, FaceTruth, score_faces};

/// The camera's frame period at 15 fps, in microseconds.
pub const FRAME_US: u64 = 66_667;

/// The minimum IoU at which a detection matches an annotated face.
pub const MIN_IOU: f64 = 0.3;

/// How one still image fared.
#[derive(Debug, Clone)]
pub struct StillResult {
    pub image: String,
    /// The score of the faces reported on the last frame, once the scan has covered the image.
    pub score: FaceScore,
    /// Frames fed until then.
    pub frames: usize,
    /// False faces summed over every frame fed (boxes on screen that match no face, frame by frame).
    pub false_positive_frames: usize,
}

/// Feeds `jpeg` to `pipeline` as consecutive frames, starting at sequence number `*seq + 1`, until the face
/// scan's cycle counter has advanced twice since the first frame (so one whole cycle has run on this image
/// alone), and scores every frame's faces against `truth`.
pub fn run_still(
    pipeline: &mut VisionPipeline,
    jpeg: &[u8],
    truth: &FaceTruth,
    seq: &mut u64,
) -> Result<StillResult, ProcessError> {
    let mut start = None;
    let mut frames = 0;
    let mut false_positive_frames = 0;
    loop {
        *seq += 1;
        let detections = pipeline.process_jpeg(jpeg, *seq, *seq * FRAME_US)?;
        frames += 1;
        let faces = detections.faces.unwrap_or_default();
        let score = score_faces(truth, &faces, MIN_IOU);
        false_positive_frames += score.false_positives;
        let first = *start.get_or_insert(detections.face_cycles);
        // A pipeline without face detection never advances; one frame is all there is to see.
        if detections.face_cycles >= first + 2 || frames > 10_000 {
            return Ok(StillResult {
                image: truth.image.clone(),
                score,
                frames,
                false_positive_frames,
            });
        }
    }
}

/// The results of a set of still images run one after the other through one pipeline, with their totals.
#[derive(Debug, Clone, Default)]
pub struct StillReport {
    pub rows: Vec<StillResult>,
    pub totals: FaceTotals,
}

impl StillReport {
    /// Runs every `(jpeg, truth)` through `pipeline` in order.
    pub fn run(
        pipeline: &mut VisionPipeline,
        images: &[(Vec<u8>, FaceTruth)],
    ) -> Result<Self, ProcessError> {
        let mut report = StillReport::default();
        let mut seq = 0;
        for (jpeg, truth) in images {
            let row = run_still(pipeline, jpeg, truth, &mut seq)?;
            report.totals.add(&row.score);
            report.rows.push(row);
        }
        Ok(report)
    }

    /// False faces per frame over every frame fed, a measure of ghosts that come and go while the scan runs.
    pub fn false_positives_per_frame(&self) -> f64 {
        let frames: usize = self.rows.iter().map(|r| r.frames).sum();
        let fp: usize = self.rows.iter().map(|r| r.false_positive_frames).sum();
        fp as f64 / frames.max(1) as f64
    }

    /// The per-image table and the totals line.
    pub fn table(&self) -> String {
        let mut out = format!(
            "{:<42} {:>9} {:>5} {:>3} {:>6}\n",
            "image", "annotated", "found", "fp", "frames"
        );
        for r in &self.rows {
            out.push_str(&format!(
                "{:<42} {:>9} {:>5} {:>3} {:>6}\n",
                r.image, r.score.annotated, r.score.found, r.score.false_positives, r.frames
            ));
        }
        out.push_str(&format!(
            "{}; false positives per frame over the run {:.2}\n",
            self.totals.summary(),
            self.false_positives_per_frame()
        ));
        out
    }
}

/// How much of the head around the annotated face box is cut out with it, as a fraction of the box side on each
/// edge: hair, ears and chin, so the pasted face looks like a face in a scene and not a tile.
const HEAD_MARGIN: f64 = 0.3;

/// A face cut from an annotated photo, in colour, with the face box inside the cut-out.
#[derive(Debug)]
pub struct FacePatch {
    pixels: opencv::core::Mat,
    face: BoxPx,
}

/// Why a scene could not be built.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{0}")]
    Fixture(#[from] crate::fixtures::FixtureError),
    #[error("OpenCV: {0}")]
    OpenCv(#[from] opencv::Error),
    #[error("{0} has no annotated face box")]
    NoBox(String),
    #[error("face analysis: {0}")]
    Face(String),
}

/// The photo whose face the appearance trials paste into the empty room.
pub const APPEARING_FACE: &str = "faces/fr_obama.jpg";

/// Frame `index` (from 1) of the fixtures' 15 fps motion sequence at 640x360; its first 60 frames show an empty room.
pub fn motion_frame(fixtures: &Path, index: usize) -> std::path::PathBuf {
    fixtures.join(format!(
        "motion/derived/intel_one-by-one_t2-10s_640x360_15fps/frame_{index:04}.jpg"
    ))
}

/// The face of [`APPEARING_FACE`], cut with a margin of head, as the appearance trials paste it.
pub fn appearing_face(fixtures: &Path) -> Result<FacePatch, SceneError> {
    let truth = crate::fixtures::GroundTruth::load(fixtures)?;
    let photo = truth
        .faces
        .iter()
        .find(|t| t.image == APPEARING_FACE)
        .ok_or_else(|| SceneError::NoBox(APPEARING_FACE.to_owned()))?;
    face_patch(fixtures, photo)
}

/// Cuts the first annotated face of `truth`'s photo, with a margin of head around it.
pub fn face_patch(fixtures: &Path, truth: &FaceTruth) -> Result<FacePatch, SceneError> {
    use opencv::core::{Mat, MatTraitConst, Rect};
    let face = *truth
        .boxes
        .first()
        .ok_or_else(|| SceneError::NoBox(truth.image.clone()))?;
    let photo = read_colour(&fixtures.join(&truth.image))?;
    let grow_x = (f64::from(face.width) * HEAD_MARGIN) as i32;
    let grow_y = (f64::from(face.height) * HEAD_MARGIN) as i32;
    let left = (face.x - grow_x).max(0);
    let top = (face.y - grow_y).max(0);
    let right = (face.x + face.width + grow_x).min(photo.cols());
    let bottom = (face.y + face.height + grow_y).min(photo.rows());
    let cut = Mat::roi(&photo, Rect::new(left, top, right - left, bottom - top))?.try_clone()?;
    Ok(FacePatch {
        pixels: cut,
        face: BoxPx {
            x: face.x - left,
            y: face.y - top,
            width: face.width,
            height: face.height,
        },
    })
}

/// Reads an image in colour, ignoring EXIF orientation (annotations refer to the stored pixels).
pub fn read_colour(path: &Path) -> Result<opencv::core::Mat, SceneError> {
    use opencv::core::MatTraitConst;
    use opencv::imgcodecs;
    let image = imgcodecs::imread(
        path.as_os_str(),
        imgcodecs::IMREAD_COLOR | imgcodecs::IMREAD_IGNORE_ORIENTATION,
    )?;
    if image.empty() {
        return Err(crate::fixtures::FixtureError::Image {
            path: path.to_path_buf(),
            reason: "not an image OpenCV can read".to_owned(),
        }
        .into());
    }
    Ok(image)
}

/// Where and how large a pasted face is: its width in frame pixels and the centre of the face box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    pub face_px: i32,
    pub centre_x: i32,
    pub centre_y: i32,
}

/// Pastes `patch` onto a copy of `background` (a colour camera frame) so that the face is `face_px` wide and
/// centred at the placement (moved inside the frame where it would stick out), and encodes the result like the
/// page does. Returns the JPEG and the face's box in the frame.
pub fn paste_face(
    background: &opencv::core::Mat,
    patch: &FacePatch,
    placement: Placement,
) -> Result<(Vec<u8>, BoxPx), SceneError> {
    use opencv::core::{Mat, MatTraitConst, Rect, Size, Vector, VectorToVec};
    use opencv::{imgcodecs, imgproc};
    let scale = f64::from(placement.face_px) / f64::from(patch.face.width.max(1));
    let width =
        ((f64::from(patch.pixels.cols()) * scale).round() as i32).clamp(1, background.cols());
    let height =
        ((f64::from(patch.pixels.rows()) * scale).round() as i32).clamp(1, background.rows());
    let mut scaled = Mat::default();
    imgproc::resize(
        &patch.pixels,
        &mut scaled,
        Size::new(width, height),
        0.0,
        0.0,
        imgproc::INTER_AREA,
    )?;
    let face_x = (f64::from(patch.face.x) * scale).round() as i32;
    let face_y = (f64::from(patch.face.y) * scale).round() as i32;
    let face_w = (f64::from(patch.face.width) * scale).round() as i32;
    let face_h = (f64::from(patch.face.height) * scale).round() as i32;
    let left = (placement.centre_x - face_x - face_w / 2).clamp(0, background.cols() - width);
    let top = (placement.centre_y - face_y - face_h / 2).clamp(0, background.rows() - height);
    let mut frame = background.try_clone()?;
    {
        let mut target = Mat::roi_mut(&mut frame, Rect::new(left, top, width, height))?;
        scaled.copy_to(&mut target)?;
    }
    let mut jpeg = Vector::<u8>::new();
    let params = Vector::<i32>::from_slice(&[
        imgcodecs::IMWRITE_JPEG_QUALITY,
        crate::fixtures::CAMERA_JPEG_QUALITY,
    ]);
    imgcodecs::imencode(".jpg", &frame, &mut jpeg, &params)?;
    Ok((
        jpeg.to_vec(),
        BoxPx {
            x: left + face_x,
            y: top + face_y,
            width: face_w,
            height: face_h,
        },
    ))
}

/// The outcome of one appearance trial.
#[derive(Debug, Clone, PartialEq)]
pub struct Appearance {
    /// Frames from the first frame with the face to the first output with its box (0: on that very frame);
    /// `None` when it was not found within the trial.
    pub frames: Option<usize>,
    /// Wall time the pipeline took on the frame whose output first had the box, in milliseconds.
    pub last_frame_ms: f64,
    /// Wall time of the pipeline on every frame of the trial with the face in view, in milliseconds.
    pub frame_ms: Vec<f64>,
}

/// An empty scene followed by a face that appears: `lead_in` frames of `backgrounds` (the camera looking at an
/// empty room), then the same sequence with the face pasted at `placement`, until the pipeline's output has a box
/// on it (IoU >= 0.3) or `max_frames` face frames have gone by. The backgrounds are played forwards and
/// backwards in turn, so the scene never jumps.
pub fn appearance_trial(
    pipeline: &mut VisionPipeline,
    backgrounds: &[opencv::core::Mat],
    patch: &FacePatch,
    placement: Placement,
    lead_in: usize,
    max_frames: usize,
) -> Result<Appearance, SceneError> {
    use opencv::core::{Vector, VectorToVec};
    use opencv::imgcodecs;
    let period = backgrounds.len().max(1);
    let background = |i: usize| {
        let phase = i % (2 * period);
        let index = if phase < period {
            phase
        } else {
            2 * period - 1 - phase
        };
        &backgrounds[index.min(backgrounds.len().saturating_sub(1))]
    };
    let params = Vector::<i32>::from_slice(&[
        imgcodecs::IMWRITE_JPEG_QUALITY,
        crate::fixtures::CAMERA_JPEG_QUALITY,
    ]);
    let mut seq = 0_u64;
    for i in 0..lead_in {
        let mut jpeg = Vector::<u8>::new();
        imgcodecs::imencode(".jpg", background(i), &mut jpeg, &params)?;
        seq += 1;
        pipeline
            .process_jpeg(&jpeg.to_vec(), seq, seq * FRAME_US)
            .map_err(process_error)?;
    }
    let mut frame_ms = Vec::new();
    for k in 0..max_frames {
        let (jpeg, face) = paste_face(background(lead_in + k), patch, placement)?;
        seq += 1;
        let detections = pipeline
            .process_jpeg(&jpeg, seq, seq * FRAME_US)
            .map_err(process_error)?;
        let took_ms = detections.timings.total.as_secs_f64() * 1000.0;
        frame_ms.push(took_ms);
        let hit = detections
            .faces
            .as_deref()
            .unwrap_or_default()
            .iter()
            .any(|b| b.iou(&face) >= MIN_IOU);
        if hit {
            return Ok(Appearance {
                frames: Some(k),
                last_frame_ms: took_ms,
                frame_ms,
            });
        }
    }
    Ok(Appearance {
        frames: None,
        last_frame_ms: 0.0,
        frame_ms,
    })
}

/// A frame the trial built itself that the pipeline refuses is a bug in the trial, reported as OpenCV's.
fn process_error(e: ProcessError) -> SceneError {
    SceneError::OpenCv(opencv::Error::new(opencv::core::StsError, e.to_string()))
}

/// Nearest-rank percentile; NaN for no samples. Shared by the benchmarks.
pub fn percentile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}
