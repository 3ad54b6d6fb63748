//! One processed frame end to end: decode once, run the enabled detectors on the same grey pixels, de-duplicate
//! codes, update the gaze policy, and time every stage.

use std::time::{Duration, Instant};

use crate::appearance::{AppearanceTracker, SeenCode};
use crate::centerface::{CenterFace, CenterFaceParams};
use crate::codes::{CodeParams, CodeReader};
use crate::error::{ProcessError, VisionError};
use crate::face::{FaceParams, FaceScan, FaceScanner};
use crate::frame::{self, GreyFrame};
use crate::gaze::{GazeParams, GazePolicy, GazeTarget};
use crate::geometry::{BoxPx, FrameSize};
use crate::motion::{Motion, MotionDetector, MotionParams};
use crate::people::{People, PeopleParams, Person};

/// Which face detector runs: the CenterFace network (the default) or OpenCV's cascades with the budgeted scan.
#[derive(Debug, Clone, PartialEq)]
pub enum FaceDetection {
    CenterFace(CenterFaceParams),
    Cascades(FaceParams),
}

impl Default for FaceDetection {
    fn default() -> Self {
        FaceDetection::CenterFace(CenterFaceParams::default())
    }
}

/// A face detector with its state across frames.
#[derive(Debug)]
enum FaceDetector {
    CenterFace(Box<CenterFace>),
    Cascades(Box<FaceScanner>),
}

impl FaceDetector {
    fn new(params: FaceDetection) -> Result<Self, VisionError> {
        Ok(match params {
            FaceDetection::CenterFace(p) => FaceDetector::CenterFace(Box::new(CenterFace::new(p)?)),
            FaceDetection::Cascades(p) => FaceDetector::Cascades(Box::new(FaceScanner::new(p)?)),
        })
    }

    /// The faces of this frame. The cascades look first where something has just moved (`moving`); the network
    /// sees the whole frame each time it runs, and runs at once when motion appears.
    /// `in_motion` is the motion detector's state, held results included: held frames do not count as motion
    /// stopping, so motion "appears" once per movement and not on every duplicated camera frame.
    fn scan(
        &mut self,
        frame: &GreyFrame,
        moving: &[BoxPx],
        in_motion: bool,
    ) -> Result<FaceScan, VisionError> {
        match self {
            FaceDetector::CenterFace(net) => net.scan(frame, in_motion),
            FaceDetector::Cascades(scanner) => scanner.scan_with_motion(frame, moving),
        }
    }
}

/// Which detectors run and how they are tuned; `None` switches a detector off.
#[derive(Debug, Clone)]
pub struct PipelineParams {
    pub faces: Option<FaceDetection>,
    /// The per-face analysis of the faces found (needs `faces`).
    pub people: Option<PeopleParams>,
    pub motion: Option<MotionParams>,
    pub codes: Option<CodeParams>,
    /// A code not decoded for this long has left the view; its next sighting is a new appearance.
    pub code_forget_after_us: u64,
    pub gaze: GazeParams,
    pub max_frame_pixels: u64,
}

impl Default for PipelineParams {
    fn default() -> Self {
        Self {
            faces: Some(FaceDetection::default()),
            people: Some(PeopleParams::default()),
            motion: Some(MotionParams::default()),
            codes: Some(CodeParams::default()),
            code_forget_after_us: 1_000_000,
            gaze: GazeParams::default(),
            max_frame_pixels: frame::DEFAULT_MAX_PIXELS,
        }
    }
}

/// Wall time spent in each stage of one frame; `None` for a detector that is switched off.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StageTimings {
    pub decode: Duration,
    pub faces: Option<Duration>,
    pub people: Option<Duration>,
    pub motion: Option<Duration>,
    pub codes: Option<Duration>,
    pub total: Duration,
}

/// Everything found in one frame. Detector fields are `None` when that detector is switched off.
#[derive(Debug, Clone)]
pub struct FrameDetections {
    pub seq: u64,
    pub frame_us: u64,
    pub size: FrameSize,
    pub faces: Option<Vec<BoxPx>>,
    /// Completed full face scans: cycles of the cascades' budgeted scan (see [`FaceScanner`]) or runs of the network
    /// (see [`CenterFace`]); 0 when face detection is off.
    pub face_cycles: u64,
    /// The analysed faces; `None` when the analysis is off.
    pub people: Option<Vec<Person>>,
    pub motion: Option<Motion>,
    pub codes: Option<Vec<SeenCode>>,
    pub gaze: GazeTarget,
    pub timings: StageTimings,
}

/// The detectors of one video stream with their state.
#[derive(Debug)]
pub struct VisionPipeline {
    faces: Option<FaceDetector>,
    /// Full face scans completed up to the last frame: a frame that completes one carried the detector's cost.
    face_cycles: u64,
    people: Option<People>,
    motion: Option<MotionDetector>,
    codes: Option<CodeReader>,
    appearances: AppearanceTracker,
    gaze: GazePolicy,
    gaze_params: GazeParams,
    code_forget_after_us: u64,
    max_frame_pixels: u64,
}

impl VisionPipeline {
    pub fn new(params: PipelineParams) -> Result<Self, VisionError> {
        Ok(Self {
            people: match (&params.faces, params.people) {
                (Some(_), Some(people)) => Some(People::new(people)?),
                _ => None,
            },
            faces: params.faces.map(FaceDetector::new).transpose()?,
            face_cycles: 0,
            motion: params.motion.map(MotionDetector::new).transpose()?,
            codes: params.codes.map(CodeReader::new).transpose()?,
            appearances: AppearanceTracker::new(params.code_forget_after_us),
            gaze: GazePolicy::new(params.gaze.clone()),
            gaze_params: params.gaze,
            code_forget_after_us: params.code_forget_after_us,
            max_frame_pixels: params.max_frame_pixels,
        })
    }

    /// Forgets everything learned from the current stream (previous frame, codes in view, gaze); called when the
    /// source channel starts over.
    pub fn reset_stream(&mut self) {
        if let Some(motion) = self.motion.as_mut() {
            motion.reset();
        }
        self.appearances = AppearanceTracker::new(self.code_forget_after_us);
        self.gaze = GazePolicy::new(self.gaze_params.clone());
        if let Some(people) = self.people.as_mut() {
            people.reset();
        }
    }

    /// The per-face analysis, when it runs (voice activity, acquaintances, the face to learn).
    pub fn people(&mut self) -> Option<&mut People> {
        self.people.as_mut()
    }

    /// Decodes and processes one JPEG frame with sequence number `seq` taken at `frame_us`.
    pub fn process_jpeg(
        &mut self,
        jpeg: &[u8],
        seq: u64,
        frame_us: u64,
    ) -> Result<FrameDetections, ProcessError> {
        let started = Instant::now();
        let frame = frame::decode_jpeg(jpeg, self.max_frame_pixels)?;
        let decode = started.elapsed();
        let mut detections = self.process(&frame, seq, frame_us)?;
        detections.timings.decode = decode;
        detections.timings.total = started.elapsed();
        Ok(detections)
    }

    /// Processes an already decoded frame.
    pub fn process(
        &mut self,
        frame: &GreyFrame,
        seq: u64,
        frame_us: u64,
    ) -> Result<FrameDetections, VisionError> {
        let started = Instant::now();
        let mut timings = StageTimings::default();
        let motion = match self.motion.as_mut() {
            Some(detector) => Some(timed(&mut timings.motion, || {
                detector.process(frame, frame_us)
            })?),
            None => None,
        };
        // Motion first: the face scanner looks first where something has just moved, since a face that comes into
        // view moves (see `FaceScanner::scan_with_motion`). Held results repeat an older frame's regions, which
        // were queued then.
        let moving: &[BoxPx] = match &motion {
            Some(Motion::Moving {
                regions,
                held: false,
                ..
            }) => regions,
            _ => &[],
        };
        let in_motion = matches!(motion, Some(Motion::Moving { .. }));
        let (faces, face_cycles) = match self.faces.as_mut() {
            Some(detector) => {
                let scan = timed(&mut timings.faces, || {
                    detector.scan(frame, moving, in_motion)
                })?;
                (Some(scan.faces), scan.completed_cycles)
            }
            None => (None, 0),
        };
        // A descriptor (about 20 ms) waits for a frame on which the face detector did not run (the network, about
        // 60 ms, runs on one frame in three), so that no frame carries both.
        let detector_ran = face_cycles != self.face_cycles;
        self.face_cycles = face_cycles;
        let people = match (self.people.as_mut(), faces.as_deref()) {
            (Some(analysis), Some(found)) => Some(timed(&mut timings.people, || {
                analysis.observe(frame, frame_us, found, !detector_ran)
            })?),
            _ => None,
        };
        let codes = match self.codes.as_mut() {
            Some(reader) => {
                let decoded = timed(&mut timings.codes, || reader.read(frame))?;
                Some(self.appearances.observe(frame_us, decoded))
            }
            None => None,
        };
        let size = frame.size();
        self.gaze.prefer(
            people
                .iter()
                .flatten()
                .find(|person| person.speaking)
                .map(|person| person.face),
        );
        let gaze = self.gaze.update(
            frame_us,
            size,
            faces.as_deref().unwrap_or_default(),
            motion.as_ref().and_then(Motion::centre),
        );
        timings.total = started.elapsed();
        Ok(FrameDetections {
            seq,
            frame_us,
            size,
            faces,
            face_cycles,
            people,
            motion,
            codes,
            gaze,
            timings,
        })
    }
}

fn timed<T>(
    slot: &mut Option<Duration>,
    work: impl FnOnce() -> Result<T, VisionError>,
) -> Result<T, VisionError> {
    let started = Instant::now();
    let result = work();
    *slot = Some(started.elapsed());
    result
}
