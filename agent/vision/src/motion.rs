//! Motion detection: frame differencing (default) or MOG2 background subtraction on a small blurred copy of the
//! frame, cleaned with morphology and a minimum region area, and a hysteresis so that single quiet frames (the
//! camera repeating a frame, a dropped frame) do not make the result flicker.

use opencv::core::{self, Mat, MatTraitConst, Point, Ptr, Scalar, Size, Vector};
use opencv::imgproc;
use opencv::prelude::BackgroundSubtractorTrait;
use opencv::video::{self, BackgroundSubtractorMOG2};

use crate::error::VisionError;
use crate::frame::GreyFrame;
use crate::geometry::{BoxPx, PointPx};

/// How moving pixels are found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MotionMethod {
    /// Absolute difference to the previous frame: cheap, no warm-up, reports only what moves right now.
    Difference,
    /// OpenCV's Gaussian-mixture background model: also reports a newcomer who stands still, until it is learned
    /// into the background.
    Mog2,
}

impl MotionMethod {
    pub fn name(self) -> &'static str {
        match self {
            MotionMethod::Difference => "difference",
            MotionMethod::Mog2 => "mog2",
        }
    }

    pub fn from_name(name: &str) -> Option<MotionMethod> {
        [MotionMethod::Difference, MotionMethod::Mog2]
            .into_iter()
            .find(|method| method.name() == name)
    }
}

/// Tuning of the motion detector.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionParams {
    pub method: MotionMethod,
    /// Width of the working copy; the height follows the frame's aspect ratio.
    pub work_width: u32,
    /// Grey-level change (0-255) above which a pixel counts as changed, for `Difference`.
    pub pixel_threshold: f64,
    /// Fraction of the frame that must change for a frame to count as moving.
    pub on_fraction: f64,
    /// Regions smaller than this fraction of the frame are dropped as noise.
    pub min_region_fraction: f64,
    /// Motion stays reported this long after the last moving frame (the hysteresis).
    pub hold_us: u64,
    /// Frames that MOG2 only learns from before it reports anything.
    pub mog2_warmup_frames: u32,
}

impl Default for MotionParams {
    fn default() -> Self {
        Self {
            method: MotionMethod::Difference,
            work_width: 320,
            pixel_threshold: 25.0,
            on_fraction: 0.005,
            min_region_fraction: 0.002,
            hold_us: 300_000,
            mog2_warmup_frames: 15,
        }
    }
}

/// One frame's motion result.
#[derive(Debug, Clone, PartialEq)]
pub enum Motion {
    /// Nothing moves (or the detector has not seen enough frames yet).
    Still,
    Moving {
        /// Bounding boxes of the moving regions, in frame pixels.
        regions: Vec<BoxPx>,
        /// Centroid of all moving pixels, in frame pixels.
        centre: PointPx,
        /// Fraction of the frame that changed.
        changed_fraction: f64,
        /// True when this frame itself showed no motion and the previous result is being held.
        held: bool,
    },
}

impl Motion {
    pub fn centre(&self) -> Option<PointPx> {
        match self {
            Motion::Still => None,
            Motion::Moving { centre, .. } => Some(*centre),
        }
    }
}

/// Stateful motion detector; one per video stream.
pub struct MotionDetector {
    params: MotionParams,
    mog2: Option<Ptr<BackgroundSubtractorMOG2>>,
    frames_seen: u32,
    previous: Mat,
    current: Mat,
    small: Mat,
    mask: Mat,
    cleaned: Mat,
    open_kernel: Mat,
    merge_kernel: Mat,
    last_moving: Option<(u64, Motion)>,
    last_frame_us: Option<u64>,
}

impl std::fmt::Debug for MotionDetector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MotionDetector")
            .field("params", &self.params)
            .field("frames_seen", &self.frames_seen)
            .finish_non_exhaustive()
    }
}

impl MotionDetector {
    pub fn new(params: MotionParams) -> Result<Self, VisionError> {
        let mog2 = match params.method {
            // Shadows are not wanted: they would need a second threshold and add cost.
            MotionMethod::Mog2 => Some(video::create_background_subtractor_mog2(500, 16.0, false)?),
            MotionMethod::Difference => None,
        };
        let open_kernel = imgproc::get_structuring_element(
            imgproc::MORPH_ELLIPSE,
            Size::new(3, 3),
            Point::new(-1, -1),
        )?;
        let merge_kernel = imgproc::get_structuring_element(
            imgproc::MORPH_ELLIPSE,
            Size::new(9, 9),
            Point::new(-1, -1),
        )?;
        Ok(Self {
            params,
            mog2,
            frames_seen: 0,
            previous: Mat::default(),
            current: Mat::default(),
            small: Mat::default(),
            mask: Mat::default(),
            cleaned: Mat::default(),
            open_kernel,
            merge_kernel,
            last_moving: None,
            last_frame_us: None,
        })
    }

    /// Forgets the stream: the next frame is treated as the first one.
    pub fn reset(&mut self) {
        self.frames_seen = 0;
        self.previous = Mat::default();
        self.last_moving = None;
        self.last_frame_us = None;
        if let Some(mog2) = self.mog2.as_mut() {
            // A fresh model is cheaper to reason about than un-learning the old one.
            if let Ok(fresh) = video::create_background_subtractor_mog2(500, 16.0, false) {
                *mog2 = fresh;
            }
        }
    }

    /// Processes the frame taken at `frame_us` (microseconds, monotonic per stream).
    pub fn process(&mut self, frame: &GreyFrame, frame_us: u64) -> Result<Motion, VisionError> {
        if self.last_frame_us.is_some_and(|last| frame_us < last) {
            self.reset();
        }
        self.last_frame_us = Some(frame_us);
        let size = frame.size();
        let work_width = self.params.work_width.clamp(16, size.width.max(16));
        let factor = f64::from(work_width) / f64::from(size.width.max(1));
        let work_size = Size::new(
            work_width as i32,
            ((f64::from(size.height) * factor).round() as i32).max(1),
        );
        if !self.previous.empty() && self.previous.size()? != work_size {
            // The stream changed resolution; differences across sizes mean nothing.
            self.reset();
        }
        imgproc::resize(
            frame.mat(),
            &mut self.small,
            work_size,
            0.0,
            0.0,
            imgproc::INTER_AREA,
        )?;
        // Blur before comparing so that sensor noise and JPEG block edges do not count as motion.
        imgproc::gaussian_blur(
            &self.small,
            &mut self.current,
            Size::new(5, 5),
            0.0,
            0.0,
            core::BORDER_DEFAULT,
        )?;
        self.frames_seen = self.frames_seen.saturating_add(1);

        let ready = self.foreground_mask()?;
        std::mem::swap(&mut self.previous, &mut self.current);
        let fresh = if ready { self.measure(factor)? } else { None };
        Ok(self.apply_hysteresis(frame_us, fresh))
    }

    /// Fills `self.mask` with the changed pixels; false while there is nothing to compare against yet.
    fn foreground_mask(&mut self) -> Result<bool, VisionError> {
        match self.mog2.as_mut() {
            Some(mog2) => {
                mog2.apply(&self.current, &mut self.mask, -1.0)?;
                Ok(self.frames_seen > self.params.mog2_warmup_frames)
            }
            None => {
                if self.previous.empty() {
                    return Ok(false);
                }
                let mut difference = Mat::default();
                core::absdiff(&self.previous, &self.current, &mut difference)?;
                imgproc::threshold(
                    &difference,
                    &mut self.mask,
                    self.params.pixel_threshold,
                    255.0,
                    imgproc::THRESH_BINARY,
                )?;
                Ok(true)
            }
        }
    }

    /// Turns the mask into regions and a centre; None when too little changed.
    fn measure(&mut self, factor: f64) -> Result<Option<Motion>, VisionError> {
        // Opening removes isolated speckles before anything is counted.
        imgproc::morphology_ex(
            &self.mask,
            &mut self.cleaned,
            imgproc::MORPH_OPEN,
            &self.open_kernel,
            Point::new(-1, -1),
            1,
            core::BORDER_CONSTANT,
            imgproc::morphology_default_border_value()?,
        )?;
        let total = f64::from(self.cleaned.rows() * self.cleaned.cols()).max(1.0);
        let changed = f64::from(core::count_non_zero(&self.cleaned)?);
        let changed_fraction = changed / total;
        if changed_fraction < self.params.on_fraction {
            return Ok(None);
        }
        let moments = imgproc::moments(&self.cleaned, true)?;
        let centre = PointPx {
            x: (moments.m10 / moments.m00 / factor) as f32,
            y: (moments.m01 / moments.m00 / factor) as f32,
        };

        // Dilating merges the pieces of one moving body (limbs, edges of a shirt) into one region.
        let mut merged = Mat::default();
        imgproc::dilate(
            &self.cleaned,
            &mut merged,
            &self.merge_kernel,
            Point::new(-1, -1),
            2,
            core::BORDER_CONSTANT,
            Scalar::all(0.0),
        )?;
        let mut contours = Vector::<Vector<Point>>::new();
        imgproc::find_contours(
            &merged,
            &mut contours,
            imgproc::RETR_EXTERNAL,
            imgproc::CHAIN_APPROX_SIMPLE,
            Point::new(0, 0),
        )?;
        let min_area = self.params.min_region_fraction * total;
        let mut regions = Vec::new();
        for contour in contours.iter() {
            let rect = imgproc::bounding_rect(&contour)?;
            if f64::from(rect.width * rect.height) < min_area {
                continue;
            }
            regions.push(
                BoxPx {
                    x: rect.x,
                    y: rect.y,
                    width: rect.width,
                    height: rect.height,
                }
                .unscale(factor),
            );
        }
        if regions.is_empty() {
            return Ok(None);
        }
        regions.sort_by_key(|region| std::cmp::Reverse(region.area()));
        Ok(Some(Motion::Moving {
            regions,
            centre,
            changed_fraction,
            held: false,
        }))
    }

    fn apply_hysteresis(&mut self, frame_us: u64, fresh: Option<Motion>) -> Motion {
        if let Some(motion) = fresh {
            self.last_moving = Some((frame_us, motion.clone()));
            return motion;
        }
        match &self.last_moving {
            Some((
                since,
                Motion::Moving {
                    regions,
                    centre,
                    changed_fraction,
                    ..
                },
            )) if frame_us.saturating_sub(*since) <= self.params.hold_us => Motion::Moving {
                regions: regions.clone(),
                centre: *centre,
                changed_fraction: *changed_fraction,
                held: true,
            },
            _ => {
                self.last_moving = None;
                Motion::Still
            }
        }
    }
}
