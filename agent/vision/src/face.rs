//! Frontal face detection with OpenCV cascade classifiers from Debian's `opencv-data`.
//!
//! Cost grows with the number of pixels scanned, so the frame is first shrunk to the smallest size at which the
//! smallest face we care about (`min_face_px`) still fills the cascade's native window; the boxes are mapped back to
//! frame pixels.

use std::path::{Path, PathBuf};

use opencv::core::{Mat, MatTraitConst, Rect, Size, Vector};
use opencv::imgproc;
use opencv::objdetect::{CascadeClassifier, CascadeClassifierTrait, CascadeClassifierTraitConst};

use crate::error::VisionError;
use crate::frame::GreyFrame;
use crate::geometry::BoxPx;

/// Where Debian's `opencv-data` installs the cascades.
pub const DEBIAN_CASCADE_DIR: &str = "/usr/share/opencv4";

/// The frontal-face cascades shipped by `opencv-data`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cascade {
    HaarDefault,
    HaarAlt,
    HaarAlt2,
    Lbp,
    LbpImproved,
}

impl Cascade {
    pub const ALL: [Cascade; 5] = [
        Cascade::HaarDefault,
        Cascade::HaarAlt,
        Cascade::HaarAlt2,
        Cascade::Lbp,
        Cascade::LbpImproved,
    ];

    /// The name used in configuration files and reports.
    pub fn name(self) -> &'static str {
        match self {
            Cascade::HaarDefault => "haar_default",
            Cascade::HaarAlt => "haar_alt",
            Cascade::HaarAlt2 => "haar_alt2",
            Cascade::Lbp => "lbp",
            Cascade::LbpImproved => "lbp_improved",
        }
    }

    pub fn from_name(name: &str) -> Option<Cascade> {
        Cascade::ALL
            .into_iter()
            .find(|cascade| cascade.name() == name)
    }

    /// Path of the cascade file below the `opencv-data` directory.
    pub fn relative_path(self) -> &'static str {
        match self {
            Cascade::HaarDefault => "haarcascades/haarcascade_frontalface_default.xml",
            Cascade::HaarAlt => "haarcascades/haarcascade_frontalface_alt.xml",
            Cascade::HaarAlt2 => "haarcascades/haarcascade_frontalface_alt2.xml",
            Cascade::Lbp => "lbpcascades/lbpcascade_frontalface.xml",
            Cascade::LbpImproved => "lbpcascades/lbpcascade_frontalface_improved.xml",
        }
    }
}

/// About 10 ms of Haar cascade work per frame on the 2-core reference machine (the whole 640x360 scan, about
/// 1.3 million scanned pixels, costs about 180 ms of CPU; see `docs/bench-vision.md`).
pub const DEFAULT_SCAN_BUDGET_PX: u64 = 48_000;

/// Tuning of the face detector.
#[derive(Debug, Clone, PartialEq)]
pub struct FaceParams {
    pub cascade: Cascade,
    pub cascade_dir: PathBuf,
    /// Step between pyramid levels; larger is faster and misses more faces between levels.
    pub scale_factor: f64,
    /// Overlapping raw hits needed to keep a detection; the main lever against false positives.
    pub min_neighbors: i32,
    /// The smallest face side, in frame pixels, that must still be found.
    pub min_face_px: u32,
    /// Frames wider than this are shrunk to it before detection, whatever `min_face_px` says.
    pub max_detect_width: u32,
    /// Histogram equalisation before detection, which helps in dim or low-contrast frames.
    pub equalize: bool,
    /// Pixels the cascade may scan per frame (summed over pyramid levels) when scanning with [`FaceScanner`];
    /// `None` scans the whole pyramid on every frame.
    pub scan_budget_px: Option<u64>,
    /// A second cascade that must also find a face around each candidate before it is reported (`None`: report
    /// every candidate). Two cascades trained apart rarely share a ghost: on the annotated fixtures `haar_alt`
    /// over `haar_default`'s candidates keeps 22 of 23 faces and drops every false one (docs/vision.md).
    pub verify: Option<Cascade>,
    /// A third cascade whose confirmation also counts (`None`, the default: only `verify`'s). Tried against the
    /// small faces `haar_alt` rejects on letterboxed frames; it did not pay off as the module runs it
    /// (docs/vision.md has the figures).
    pub verify_also: Option<Cascade>,
    /// The budgeted cycle scans this many pyramids, each shifted by a fraction of `scale_factor` (1, the default:
    /// the plain pyramid): a face whose size falls between two levels of one pyramid lies on a level of another.
    /// The cost per frame stays the budget; the cycle grows by this factor. Tried, not the default: it finds more
    /// faces and more ghosts (docs/vision.md).
    pub pyramid_phases: u32,
    /// Scan where motion appears first, at every face size, before going on with the cycle (see
    /// [`FaceScanner::scan_with_motion`]): a face that comes into view moves, so its box is found within a few
    /// frames instead of within one cycle.
    pub motion_focus: bool,
    /// `min_neighbors` of the focus scans at the smallest face sizes (up to 1.25 times the cascade's window). A
    /// region's scan sees the pyramid on a grid shifted from the whole frame's, and a face barely above the
    /// cascade's window then collects fewer overlapping hits: at the cycle's 3 a 32 px face that came into view was
    /// missed until the cycle came round (1.3 s). Every candidate still needs the verifier (docs/vision.md has the
    /// figures).
    pub focus_min_neighbors: i32,
}

impl Default for FaceParams {
    fn default() -> Self {
        Self {
            cascade: Cascade::HaarDefault,
            cascade_dir: PathBuf::from(DEBIAN_CASCADE_DIR),
            scale_factor: 1.1,
            min_neighbors: 3,
            min_face_px: 24,
            max_detect_width: 640,
            equalize: true,
            scan_budget_px: Some(DEFAULT_SCAN_BUDGET_PX),
            verify: Some(Cascade::HaarAlt),
            verify_also: None,
            pyramid_phases: 1,
            motion_focus: true,
            focus_min_neighbors: 2,
        }
    }
}

/// How far around a candidate box the verifier looks, as a fraction of its side on each edge.
const VERIFY_MARGIN: f64 = 0.25;
/// Raw hits the verifier needs: one is enough, since the candidate already has the first cascade's neighbours.
const VERIFY_MIN_NEIGHBORS: i32 = 1;
/// The verifier's pyramid step: finer than the scan's, since it searches only a small region.
const VERIFY_SCALE: f64 = 1.05;

/// The second opinion on candidate faces: a different cascade run only around each candidate, at sizes near it.
pub struct FaceVerifier {
    classifier: CascadeClassifier,
    window: Size,
    crop: Mat,
    equalized: Mat,
    found: Vector<Rect>,
}

impl std::fmt::Debug for FaceVerifier {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FaceVerifier")
            .field("window", &self.window)
            .finish_non_exhaustive()
    }
}

impl FaceVerifier {
    pub fn new(cascade: Cascade, cascade_dir: &Path) -> Result<Self, VisionError> {
        let classifier = load_cascade(&cascade_dir.join(cascade.relative_path()))?;
        let window = classifier.get_original_window_size()?;
        Ok(Self {
            classifier,
            window,
            crop: Mat::default(),
            equalized: Mat::default(),
            found: Vector::new(),
        })
    }

    /// Whether the verifier also sees a face in `candidate` (frame pixels) of `frame`.
    pub fn confirms(&mut self, frame: &GreyFrame, candidate: &BoxPx) -> Result<bool, VisionError> {
        let mat = frame.mat();
        let grow_x = (f64::from(candidate.width) * VERIFY_MARGIN) as i32;
        let grow_y = (f64::from(candidate.height) * VERIFY_MARGIN) as i32;
        let x0 = (candidate.x - grow_x).max(0);
        let y0 = (candidate.y - grow_y).max(0);
        let x1 = (candidate.x + candidate.width + grow_x).min(mat.cols());
        let y1 = (candidate.y + candidate.height + grow_y).min(mat.rows());
        if x1 - x0 < self.window.width || y1 - y0 < self.window.height {
            return Ok(false);
        }
        Mat::roi(mat, Rect::new(x0, y0, x1 - x0, y1 - y0))?.copy_to(&mut self.crop)?;
        imgproc::equalize_hist(&self.crop, &mut self.equalized)?;
        // Sizes near the candidate's only: the verifier judges this face, not others in the region.
        let side = f64::from(candidate.width.min(candidate.height));
        let smallest = ((side * 0.6) as i32).max(self.window.width);
        let largest =
            ((f64::from(candidate.width.max(candidate.height)) * 1.5) as i32).max(smallest);
        self.classifier.detect_multi_scale(
            &self.equalized,
            &mut self.found,
            VERIFY_SCALE,
            VERIFY_MIN_NEIGHBORS,
            0,
            Size::new(smallest, smallest),
            Size::new(largest, largest),
        )?;
        Ok(!self.found.is_empty())
    }

    /// The candidates the verifier confirms.
    pub fn filter(
        &mut self,
        frame: &GreyFrame,
        candidates: Vec<BoxPx>,
    ) -> Result<Vec<BoxPx>, VisionError> {
        let mut kept = Vec::with_capacity(candidates.len());
        for c in candidates {
            if self.confirms(frame, &c)? {
                kept.push(c);
            }
        }
        Ok(kept)
    }
}

/// A loaded cascade with reusable scratch buffers; one per worker thread.
pub struct FaceDetector {
    params: FaceParams,
    classifier: CascadeClassifier,
    window: Size,
    small: Mat,
    equalized: Mat,
    found: Vector<Rect>,
}

impl std::fmt::Debug for FaceDetector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FaceDetector")
            .field("params", &self.params)
            .field("window", &self.window)
            .finish_non_exhaustive()
    }
}

impl FaceDetector {
    pub fn new(params: FaceParams) -> Result<Self, VisionError> {
        let path = params.cascade_dir.join(params.cascade.relative_path());
        let classifier = load_cascade(&path)?;
        let window = classifier.get_original_window_size()?;
        Ok(Self {
            params,
            classifier,
            window,
            small: Mat::default(),
            equalized: Mat::default(),
            found: Vector::new(),
        })
    }

    pub fn params(&self) -> &FaceParams {
        &self.params
    }

    /// The factor by which a frame of `width` pixels is shrunk before detection (1 = not at all).
    pub fn detection_scale(&self, width: u32) -> f64 {
        let by_width = f64::from(self.params.max_detect_width) / f64::from(width.max(1));
        let by_face = f64::from(self.window.width) / f64::from(self.params.min_face_px.max(1));
        by_width.min(by_face).min(1.0)
    }

    /// Scans the whole pyramid of the frame at once and returns the faces in frame pixels.
    pub fn detect(&mut self, frame: &GreyFrame) -> Result<Vec<BoxPx>, VisionError> {
        let factor = self.prepare(frame)?;
        let whole = ScanUnit {
            min_window: self.window,
            max_window: Size::new(0, 0),
            left: 0,
            width: i32::MAX,
            first_row: 0,
            rows: i32::MAX,
            cost: 0,
            phase: 0,
            min_neighbors: self.params.min_neighbors,
        };
        self.run_unit(&whole, factor)
    }

    /// The shrink factor of pyramid `phase` (0 = the plain pyramid) for a frame `width` pixels wide.
    fn phase_factor(&self, width: u32, phase: u32) -> f64 {
        let phases = self.params.pyramid_phases.max(1);
        self.detection_scale(width)
            * self
                .params
                .scale_factor
                .powf(-f64::from(phase.min(phases - 1)) / f64::from(phases))
    }

    /// Shrinks and equalises the frame into `self.equalized` for the plain pyramid; returns the shrink factor.
    fn prepare(&mut self, frame: &GreyFrame) -> Result<f64, VisionError> {
        self.prepare_phase(frame, 0)
    }

    /// Shrinks and equalises the frame into `self.equalized` for pyramid `phase`; returns the shrink factor.
    fn prepare_phase(&mut self, frame: &GreyFrame, phase: u32) -> Result<f64, VisionError> {
        let size = frame.size();
        let factor = self.phase_factor(size.width, phase);
        let source = if factor < 1.0 {
            let target = Size::new(
                (f64::from(size.width) * factor).round().max(1.0) as i32,
                (f64::from(size.height) * factor).round().max(1.0) as i32,
            );
            imgproc::resize(
                frame.mat(),
                &mut self.small,
                target,
                0.0,
                0.0,
                imgproc::INTER_AREA,
            )?;
            &self.small
        } else {
            frame.mat()
        };
        if self.params.equalize {
            imgproc::equalize_hist(source, &mut self.equalized)?;
        } else {
            source.copy_to(&mut self.equalized)?;
        }
        Ok(factor)
    }

    /// Runs the cascade over one unit of the prepared image and maps the hits back to frame pixels.
    fn run_unit(&mut self, unit: &ScanUnit, factor: f64) -> Result<Vec<BoxPx>, VisionError> {
        let image_rows = self.equalized.rows();
        let image_cols = self.equalized.cols();
        let first_row = unit.first_row.clamp(0, image_rows);
        let rows = unit.rows.min(image_rows - first_row);
        let left = unit.left.clamp(0, image_cols);
        let cols = unit.width.min(image_cols - left);
        if rows < self.window.height || cols < self.window.width {
            return Ok(Vec::new());
        }
        let stripe = Mat::roi(&self.equalized, Rect::new(left, first_row, cols, rows))?;
        self.classifier.detect_multi_scale(
            &stripe,
            &mut self.found,
            self.params.scale_factor,
            unit.min_neighbors,
            0,
            unit.min_window,
            unit.max_window,
        )?;
        Ok(self
            .found
            .iter()
            .map(|r| {
                BoxPx {
                    x: r.x + left,
                    y: r.y + first_row,
                    width: r.width,
                    height: r.height,
                }
                .unscale(factor)
            })
            .collect())
    }
}

/// One piece of the full scan: a band of pyramid levels (window sizes) over a horizontal stripe of the prepared
/// image, or of a region of it (`left`, `width`; the whole width for the cycle's units).
#[derive(Debug, Clone, PartialEq)]
struct ScanUnit {
    min_window: Size,
    /// `Size(0, 0)` means no upper limit.
    max_window: Size,
    left: i32,
    width: i32,
    first_row: i32,
    rows: i32,
    /// Estimated pixels scanned.
    cost: u64,
    /// The pyramid it belongs to (see [`FaceParams::pyramid_phases`]).
    phase: u32,
    /// Overlapping raw hits a face needs in this unit.
    min_neighbors: i32,
}

/// Splits the scan of a `width` x `height` prepared image into units of at most about `budget` scanned pixels.
///
/// Levels are grouped into bands from the smallest window (the largest, costliest image) upwards; each band also
/// scans one level beyond each end so that faces on a band boundary keep the neighbouring hits that
/// `min_neighbors` counts. A single level costlier than the budget is cut into horizontal stripes that overlap by
/// the band's largest window, so every face lies whole inside some stripe.
fn plan_units(
    width: i32,
    height: i32,
    window: Size,
    scale_factor: f64,
    budget: u64,
    min_neighbors: i32,
) -> Vec<ScanUnit> {
    // Reproduce OpenCV's own level sequence: factor starts at 1 and is multiplied up while the window fits.
    let mut levels: Vec<(Size, u64)> = Vec::new();
    let mut factor = 1.0_f64;
    loop {
        let level_window = Size::new(
            (f64::from(window.width) * factor).round() as i32,
            (f64::from(window.height) * factor).round() as i32,
        );
        if level_window.width > width || level_window.height > height {
            break;
        }
        let cost = (f64::from(width) / factor * (f64::from(height) / factor)) as u64;
        levels.push((level_window, cost));
        factor *= scale_factor.max(1.01);
    }
    if levels.is_empty() {
        return Vec::new();
    }
    let budget = budget.max(1);
    let mut units = Vec::new();
    let mut start = 0;
    while start < levels.len() {
        let mut end = start;
        let mut cost = levels[start].1;
        while end + 1 < levels.len() && cost + levels[end + 1].1 <= budget {
            end += 1;
            cost += levels[end].1;
        }
        let min_window = levels[start.saturating_sub(1)].0;
        let max_window = if end + 2 >= levels.len() {
            Size::new(0, 0)
        } else {
            levels[end + 1].0
        };
        let stripes = cost.div_ceil(budget).max(1) as i32;
        let overlap = if max_window.height > 0 {
            max_window.height
        } else {
            height
        };
        let stripe_rows = (height + stripes - 1) / stripes;
        for stripe in 0..stripes {
            let first_row = stripe * stripe_rows;
            let rows = (stripe_rows + overlap).min(height - first_row);
            let stripe_cost = cost * rows.max(0) as u64 / height.max(1) as u64;
            units.push(ScanUnit {
                min_window,
                max_window,
                left: 0,
                width,
                first_row,
                rows,
                cost: stripe_cost,
                phase: 0,
                min_neighbors,
            });
        }
        start = end + 1;
    }
    units
}

/// Result of one frame of budgeted scanning.
#[derive(Debug, Clone, PartialEq)]
pub struct FaceScan {
    /// Faces from the most recent scan of every unit, merged, in frame pixels.
    pub faces: Vec<BoxPx>,
    /// Full passes over all units completed so far; a pass that starts and ends on the same scene has seen all of
    /// it.
    pub completed_cycles: u64,
    /// Units in a full pass for the current frame size.
    pub units_per_cycle: usize,
}

/// How far a motion region is grown on each edge before it is scanned, as a fraction of its side: the moving part
/// of a head (a turn, the hair) can be smaller than the face, and the cascade needs the whole face in view.
const FOCUS_MARGIN: f64 = 0.25;
/// Regions waiting for a focus scan at most; further ones are dropped (motion that goes on comes back).
const FOCUS_MAX_JOBS: usize = 4;
/// A new motion region that lies this much inside a region waiting for its scan is not queued again.
const FOCUS_COVERED: f64 = 0.7;
/// Focus units whose smallest window is at most this many times the cascade's own take a face with
/// `focus_min_neighbors` raw hits; larger faces collect plenty of hits on any grid, and a lower count there only
/// lets more ghosts flash by (0.45 false faces per frame on the letterboxed photos instead of 0.35).
const FOCUS_LENIENT_UP_TO: f64 = 1.25;
/// Consecutive frames the focus scans may take the whole budget before one frame goes to the cycle, so that
/// motion that never stops cannot starve the faces that stand still.
const FOCUS_MAX_STREAK: u32 = 6;

/// A region where motion appeared, scanned at every face size that fits it, largest sizes first: the large
/// windows cost least (the image is shrunk most), and the face that moved in is usually the large thing in its
/// region, so it is found on the first frames.
#[derive(Debug, Clone)]
struct FocusJob {
    /// The grown region in prepared-image pixels.
    region: Rect,
    /// Units not scanned yet, largest windows first.
    pending: std::collections::VecDeque<ScanUnit>,
    /// Whether its scan has begun: a region that moves again after that is queued anew, since what came into
    /// view may be larger than the windows still to come.
    started: bool,
    /// Faces found in the region so far, in frame pixels.
    found: Vec<BoxPx>,
}

/// A face found by a focus scan, reported until the cycle has run over the whole frame after it (the cycle's own
/// result then holds the face, if it is still there).
#[derive(Debug, Clone, Copy)]
struct FocusHit {
    face: BoxPx,
    found_at_cycle: u64,
}

/// Spreads the cascade's full scan over consecutive frames so that each frame costs about `scan_budget_px`,
/// and reports the union of the latest result of every part. A face is therefore found within one cycle (about
/// 2.5 s for a 640x360 frame at the default budget and 15 fps) and its box refreshed once per cycle; with
/// `motion_focus`, regions where motion appears are scanned first (see [`FaceScanner::scan_with_motion`]).
#[derive(Debug)]
pub struct FaceScanner {
    detector: FaceDetector,
    verifier: Option<FaceVerifier>,
    verifier_also: Option<FaceVerifier>,
    plan_for: Option<(i32, i32)>,
    units: Vec<ScanUnit>,
    latest: Vec<Vec<BoxPx>>,
    next_unit: usize,
    completed_cycles: u64,
    focus_jobs: std::collections::VecDeque<FocusJob>,
    focus_hits: Vec<FocusHit>,
    /// Frames in a row on which the focus scans left nothing of the budget to the cycle.
    focus_streak: u32,
}

impl FaceScanner {
    pub fn new(params: FaceParams) -> Result<Self, VisionError> {
        let verifier = params
            .verify
            .map(|c| FaceVerifier::new(c, &params.cascade_dir))
            .transpose()?;
        let verifier_also = params
            .verify_also
            .map(|c| FaceVerifier::new(c, &params.cascade_dir))
            .transpose()?;
        Ok(Self {
            detector: FaceDetector::new(params)?,
            verifier,
            verifier_also,
            plan_for: None,
            units: Vec::new(),
            latest: Vec::new(),
            next_unit: 0,
            completed_cycles: 0,
            focus_jobs: std::collections::VecDeque::new(),
            focus_hits: Vec::new(),
            focus_streak: 0,
        })
    }

    pub fn detector(&self) -> &FaceDetector {
        &self.detector
    }

    /// `candidates` as the verifier judges them, or all of them without one.
    fn verified(
        &mut self,
        frame: &GreyFrame,
        candidates: Vec<BoxPx>,
    ) -> Result<Vec<BoxPx>, VisionError> {
        let Some(first) = self.verifier.as_mut() else {
            return Ok(candidates);
        };
        let mut kept = Vec::with_capacity(candidates.len());
        for c in candidates {
            let confirmed = first.confirms(frame, &c)?
                || match self.verifier_also.as_mut() {
                    Some(also) => also.confirms(frame, &c)?,
                    None => false,
                };
            if confirmed {
                kept.push(c);
            }
        }
        Ok(kept)
    }

    /// Scans the next units of the frame within the budget.
    pub fn scan(&mut self, frame: &GreyFrame) -> Result<FaceScan, VisionError> {
        self.scan_with_motion(frame, &[])
    }

    /// Scans the next units of the frame within the budget, regions where motion appeared on this frame first
    /// (`moving`, in frame pixels: the motion detector's regions of this frame, not held ones).
    ///
    /// Each new motion region, grown by a quarter on every side, becomes a focus job: a scan of that region at
    /// every face size, cut into units like the cycle and run largest windows first, ahead of the cycle and within
    /// the same per-frame budget. Faces it finds are reported at once. When a job has scanned its whole region,
    /// boxes from earlier scans that lie inside it and that it did not find again are dropped: the face has left
    /// (or was never there), so it does not stay on screen until the cycle comes round. Ignored unless
    /// `motion_focus` is set and the scan is budgeted.
    pub fn scan_with_motion(
        &mut self,
        frame: &GreyFrame,
        moving: &[BoxPx],
    ) -> Result<FaceScan, VisionError> {
        let Some(budget) = self.detector.params.scan_budget_px else {
            let candidates = self.detector.detect(frame)?;
            let faces = self.verified(frame, candidates)?;
            self.completed_cycles += 1;
            return Ok(FaceScan {
                faces,
                completed_cycles: self.completed_cycles,
                units_per_cycle: 1,
            });
        };
        let factor = self.detector.prepare(frame)?;
        let prepared = (
            self.detector.equalized.cols(),
            self.detector.equalized.rows(),
        );
        if self.plan_for != Some(prepared) {
            // A new frame size invalidates every stored result. The cycle runs the plain pyramid's units, then
            // each shifted pyramid's.
            let params = &self.detector.params;
            let size = frame.size();
            self.units = Vec::new();
            for phase in 0..params.pyramid_phases.max(1) {
                let f = self.detector.phase_factor(size.width, phase);
                let width = (f64::from(size.width) * f).round().max(1.0) as i32;
                let height = (f64::from(size.height) * f).round().max(1.0) as i32;
                let mut units = plan_units(
                    width,
                    height,
                    self.detector.window,
                    params.scale_factor,
                    budget,
                    params.min_neighbors,
                );
                for unit in &mut units {
                    unit.phase = phase;
                }
                self.units.extend(units);
            }
            self.latest = vec![Vec::new(); self.units.len()];
            self.next_unit = 0;
            self.plan_for = Some(prepared);
            self.focus_jobs.clear();
            self.focus_hits.clear();
        }
        if self.detector.params.motion_focus {
            self.queue_focus(moving, factor, prepared, budget);
        }
        let mut spent = 0_u64;
        if self.focus_streak < FOCUS_MAX_STREAK {
            spent = self.run_focus(factor, budget)?;
        }
        let mut ran = 0;
        let (mut prepared_phase, mut phase_factor) = (0, factor);
        while ran < self.units.len() {
            let unit = &self.units[self.next_unit];
            if spent > 0 && spent + unit.cost > budget {
                break;
            }
            spent += unit.cost;
            let unit = unit.clone();
            if unit.phase != prepared_phase {
                phase_factor = self.detector.prepare_phase(frame, unit.phase)?;
                prepared_phase = unit.phase;
            }
            self.latest[self.next_unit] = self.detector.run_unit(&unit, phase_factor)?;
            ran += 1;
            self.next_unit += 1;
            if self.next_unit == self.units.len() {
                self.next_unit = 0;
                self.completed_cycles += 1;
            }
        }
        self.focus_streak = if ran == 0 { self.focus_streak + 1 } else { 0 };
        // A focus hit has served its purpose once the cycle has covered the whole frame after it.
        let cycles = self.completed_cycles;
        self.focus_hits.retain(|h| cycles < h.found_at_cycle + 2);
        let candidates = merge_overlapping(
            self.latest
                .iter()
                .flatten()
                .copied()
                .chain(self.focus_hits.iter().map(|h| h.face)),
        );
        let faces = self.verified(frame, candidates)?;
        Ok(FaceScan {
            faces,
            completed_cycles: self.completed_cycles,
            units_per_cycle: self.units.len(),
        })
    }

    /// Turns this frame's motion regions into focus jobs, skipping those that lie in a region still waiting for
    /// its scan.
    fn queue_focus(&mut self, moving: &[BoxPx], factor: f64, prepared: (i32, i32), budget: u64) {
        let window = self.detector.window;
        for region in moving {
            let grow_x = f64::from(region.width) * FOCUS_MARGIN;
            let grow_y = f64::from(region.height) * FOCUS_MARGIN;
            let left = ((f64::from(region.x) - grow_x) * factor).floor().max(0.0) as i32;
            let top = ((f64::from(region.y) - grow_y) * factor).floor().max(0.0) as i32;
            let right = ((f64::from(region.x + region.width) + grow_x) * factor)
                .ceil()
                .min(f64::from(prepared.0)) as i32;
            let bottom = ((f64::from(region.y + region.height) + grow_y) * factor)
                .ceil()
                .min(f64::from(prepared.1)) as i32;
            let grown = Rect::new(left, top, right - left, bottom - top);
            if grown.width < window.width || grown.height < window.height {
                continue;
            }
            let area = f64::from(grown.width) * f64::from(grown.height);
            let covered = self
                .focus_jobs
                .iter()
                .filter(|j| !j.started)
                .any(|j| f64::from((j.region & grown).area()) >= FOCUS_COVERED * area);
            if covered || self.focus_jobs.len() >= FOCUS_MAX_JOBS {
                continue;
            }
            // Finer units than the cycle's, so that the focus scans fill the frame's budget closely.
            let mut units = plan_units(
                grown.width,
                grown.height,
                window,
                self.detector.params.scale_factor,
                (budget / 2).max(1),
                self.detector.params.focus_min_neighbors,
            );
            let lenient_up_to = f64::from(window.width) * FOCUS_LENIENT_UP_TO;
            for unit in &mut units {
                unit.left += grown.x;
                unit.first_row += grown.y;
                if f64::from(unit.min_window.width) > lenient_up_to {
                    unit.min_neighbors = self.detector.params.min_neighbors;
                }
            }
            units.reverse();
            self.focus_jobs.push_back(FocusJob {
                region: grown,
                pending: units.into(),
                started: false,
                found: Vec::new(),
            });
        }
    }

    /// Runs focus units within the budget; returns the pixels spent.
    fn run_focus(&mut self, factor: f64, budget: u64) -> Result<u64, VisionError> {
        let mut spent = 0_u64;
        while let Some(job) = self.focus_jobs.front_mut() {
            let Some(unit) = job.pending.front() else {
                self.finish_focus(factor);
                continue;
            };
            if spent > 0 && spent + unit.cost > budget {
                break;
            }
            spent += unit.cost;
            let unit = unit.clone();
            let found = self.detector.run_unit(&unit, factor)?;
            let cycle = self.completed_cycles;
            self.focus_hits.extend(found.iter().map(|&face| FocusHit {
                face,
                found_at_cycle: cycle,
            }));
            job.found.extend(found);
            job.started = true;
            job.pending.pop_front();
            if job.pending.is_empty() {
                self.finish_focus(factor);
            }
        }
        Ok(spent)
    }

    /// Ends the first focus job: earlier boxes wholly inside its region that it did not find again are dropped.
    fn finish_focus(&mut self, factor: f64) {
        let Some(job) = self.focus_jobs.pop_front() else {
            return;
        };
        let region = BoxPx {
            x: job.region.x,
            y: job.region.y,
            width: job.region.width,
            height: job.region.height,
        }
        .unscale(factor);
        let stale = |b: &BoxPx| {
            b.intersection_area(&region) == b.area() && !job.found.iter().any(|f| f.iou(b) > 0.3)
        };
        for boxes in &mut self.latest {
            boxes.retain(|b| !stale(b));
        }
        self.focus_hits.retain(|h| !stale(&h.face));
    }
}

/// Units overlap in levels and rows, so one face can be reported by two of them; keep the larger box of any pair
/// that overlaps by IoU > 0.3 or where one box lies mostly inside the other.
fn merge_overlapping(boxes: impl Iterator<Item = BoxPx>) -> Vec<BoxPx> {
    let mut all: Vec<BoxPx> = boxes.collect();
    all.sort_by_key(|b| std::cmp::Reverse(b.area()));
    let mut kept: Vec<BoxPx> = Vec::with_capacity(all.len());
    for candidate in all {
        let duplicate = kept.iter().any(|k| {
            let inside = k.intersection_area(&candidate) as f64 / candidate.area().max(1) as f64;
            k.iou(&candidate) > 0.3 || inside > 0.7
        });
        if !duplicate {
            kept.push(candidate);
        }
    }
    kept
}

fn load_cascade(path: &Path) -> Result<CascadeClassifier, VisionError> {
    let not_loaded = || VisionError::CascadeLoad {
        path: path.to_path_buf(),
    };
    if !path.is_file() {
        return Err(not_loaded());
    }
    let classifier = CascadeClassifier::new(path.as_os_str()).map_err(|_| not_loaded())?;
    if classifier.empty()? {
        return Err(not_loaded());
    }
    Ok(classifier)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plan_covers_every_level_and_row() {
        let window = Size::new(24, 24);
        let units = plan_units(640, 360, window, 1.1, 64_000, 3);
        assert!(units.len() > 10, "{}", units.len());
        // Every stripe of a band reaches the bottom, and the band after the last one has no upper limit.
        assert_eq!(units.first().map(|u| u.min_window), Some(window));
        assert_eq!(units.last().map(|u| u.max_window), Some(Size::new(0, 0)));
        for unit in &units {
            assert!(unit.first_row + unit.rows <= 360);
        }
        let whole: u64 = plan_units(640, 360, window, 1.1, u64::MAX, 3)
            .iter()
            .map(|u| u.cost)
            .sum();
        assert_eq!(plan_units(640, 360, window, 1.1, u64::MAX, 3).len(), 1);
        assert!(whole > 1_000_000 && whole < 1_500_000, "{whole}");
    }

    #[test]
    fn merge_drops_nested_and_overlapping_boxes() {
        let big = BoxPx {
            x: 0,
            y: 0,
            width: 40,
            height: 40,
        };
        let inner = BoxPx {
            x: 5,
            y: 5,
            width: 20,
            height: 20,
        };
        let shifted = BoxPx {
            x: 4,
            y: 2,
            width: 40,
            height: 40,
        };
        let apart = BoxPx {
            x: 100,
            y: 0,
            width: 30,
            height: 30,
        };
        assert_eq!(
            merge_overlapping([inner, big, shifted, apart].into_iter()),
            vec![big, apart]
        );
    }
}
