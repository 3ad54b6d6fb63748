//! The detectors on the shared real-data fixtures: face recall and false positives on the annotated photos, exact
//! QR and Code 128 payloads, one report per code appearance, motion on the 15 fps sequence, and bad frames.

use std::path::{Path, PathBuf};

use agent_vision::centerface::{CenterFace, CenterFaceParams};
use agent_vision::codes::{CodeParams, CodeReader, Symbology};
use agent_vision::face::{FaceParams, FaceScanner};
use agent_vision::frame::{DEFAULT_MAX_PIXELS, GreyFrame, decode_jpeg};
use agent_vision::gaze::GazeSource;
use agent_vision::motion::{Motion, MotionDetector, MotionParams};
use agent_vision::pipeline::FaceDetection;
use agent_vision::{FrameError, PipelineParams, ProcessError, VisionPipeline};
use vision_evaluation::evaluation::{
    Placement, StillReport, appearance_trial, appearing_face, motion_frame, read_colour,
};
use vision_evaluation::fixtures::{
    FaceTotals, GroundTruth, fixtures_dir, image_as_jpeg, letterbox, score_faces,
};

const FRAME_US: u64 = 66_667;

fn fixtures() -> PathBuf {
    let dir = fixtures_dir();
    assert!(
        dir.join("ground_truth.json").is_file(),
        "fixtures not found at {} (set AGENT_FIXTURES)",
        dir.display()
    );
    dir
}

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
}

fn as_jpeg(path: &Path) -> Vec<u8> {
    image_as_jpeg(path).expect("fixture image")
}

#[test]
fn faces_recall_and_false_positives_on_annotated_photos() {
    let dir = fixtures();
    let truth = GroundTruth::load(&dir).expect("ground truth");
    assert_eq!(
        truth.faces.len(),
        7,
        "expected the 4 dlib photos and 3 portraits"
    );
    let mut scanner = FaceScanner::new(FaceParams::default()).expect("cascade");
    let mut totals = FaceTotals::default();
    println!(
        "{:<42} {:>9} {:>5} {:>3} {:>6}",
        "image", "annotated", "found", "fp", "frames"
    );
    for image in &truth.faces {
        let frame =
            decode_jpeg(&read(&dir.join(&image.image)), DEFAULT_MAX_PIXELS).expect("decode");
        // The scan is spread over frames: feed the still image like a camera until one whole cycle has run on it.
        let start = scanner.scan(&frame).expect("scan");
        let mut frames = 1;
        let mut scan = start.clone();
        while scan.completed_cycles < start.completed_cycles + 2 {
            scan = scanner.scan(&frame).expect("scan");
            frames += 1;
        }
        let score = score_faces(image, &scan.faces, 0.3);
        println!(
            "{:<42} {:>9} {:>5} {:>3} {:>6}",
            image.image, score.annotated, score.found, score.false_positives, frames
        );
        totals.add(&score);
    }
    println!("{}", totals.summary());
    if let Err(e) = totals.check() {
        panic!("{e}");
    }
}

/// The annotated photos as the camera sends them (letterboxed into 640x360, colour JPEG at the page's quality),
/// through the pipeline the module runs, with every detector on and the default face detector (the CenterFace
/// network): the bar, recall >= 0.90 at <= 0.3 false faces per image (`FaceTotals::check`).
#[test]
fn faces_letterboxed_into_camera_frames_meet_the_bar_with_the_default_detector() {
    let report = letterboxed_report(PipelineParams::default());
    if let Err(e) = report.totals.check() {
        panic!("{e}: {}", report.totals.summary());
    }
}

/// The cascades, still selectable (`faces.detector = "cascades"`), on the same frames. They do not reach the bar
/// letterboxed (the whole `haar_default` scan misses three of the 36-43 px faces once they are shrunk by 0.96 and
/// re-encoded; docs/vision.md), so this holds the false faces to the bar and recall to the 0.87 reached, to catch
/// a regression.
#[test]
fn faces_letterboxed_through_the_cascades_keep_their_level() {
    let report = letterboxed_report(cascades());
    assert!(
        report.totals.false_positives_per_image() <= FaceTotals::MAX_FALSE_POSITIVES_PER_IMAGE,
        "{}",
        report.totals.summary()
    );
    assert!(
        report.totals.recall() >= 0.85,
        "{}",
        report.totals.summary()
    );
}

/// The default detector on the photos at their stored size (up to 1126x661, resized to the network's input).
#[test]
fn centerface_meets_the_bar_on_the_photos_at_their_stored_size() {
    let dir = fixtures();
    let truth = GroundTruth::load(&dir).expect("ground truth");
    let mut net = CenterFace::new(CenterFaceParams::default())
        .expect("models/centerface.onnx (make model MODEL=centerface)");
    let mut totals = FaceTotals::default();
    for image in &truth.faces {
        let frame =
            decode_jpeg(&read(&dir.join(&image.image)), DEFAULT_MAX_PIXELS).expect("decode");
        let faces = net.detect(&frame).expect("detect");
        let score = score_faces(image, &faces, 0.3);
        println!("{:<42} {score:?}", image.image);
        totals.add(&score);
    }
    println!("{}", totals.summary());
    if let Err(e) = totals.check() {
        panic!("{e}");
    }
}

/// The pipeline with the cascades instead of the network, the rest default.
fn cascades() -> PipelineParams {
    PipelineParams {
        faces: Some(FaceDetection::Cascades(FaceParams::default())),
        ..PipelineParams::default()
    }
}

fn letterboxed_report(params: PipelineParams) -> StillReport {
    let dir = fixtures();
    let truth = GroundTruth::load(&dir).expect("ground truth");
    let images: Vec<(Vec<u8>, _)> = truth
        .faces
        .iter()
        .map(|t| {
            let camera = letterbox(&dir, t).expect("letterbox");
            (camera.jpeg, camera.truth)
        })
        .collect();
    let mut pipeline = VisionPipeline::new(params).expect("pipeline");
    let report = StillReport::run(&mut pipeline, &images).expect("run");
    print!("{}", report.table());
    report
}

/// A face that comes into an empty scene gets its box within 4 frames (267 ms at 15 fps), with either detector:
/// the network sees the whole frame every third frame, and the cascades look where the motion appeared first.
/// Counted in frames, so the test does not depend on the machine's speed.
#[test]
fn a_face_that_appears_is_boxed_within_four_frames() {
    for params in [PipelineParams::default(), cascades()] {
        face_appears_within_four_frames(params);
    }
}

fn face_appears_within_four_frames(params: PipelineParams) {
    let dir = fixtures();
    let patch = appearing_face(&dir).expect("patch");
    let backgrounds: Vec<_> = (1..=60)
        .map(|i| read_colour(&motion_frame(&dir, i)).expect("background"))
        .collect();
    for (face_px, centre_x, centre_y, lead_in) in
        // The 32 px face in the middle is the smallest the scan looks for on a grid of its own (it needs the
        // focus scans' lower neighbour count).
        [
            (48, 160, 120, 10),
            (90, 450, 200, 23),
            (140, 320, 180, 37),
            (32, 320, 200, 27),
        ]
    {
        let mut pipeline = VisionPipeline::new(params.clone()).expect("pipeline");
        let placement = Placement {
            face_px,
            centre_x,
            centre_y,
        };
        let outcome = appearance_trial(&mut pipeline, &backgrounds, &patch, placement, lead_in, 40)
            .expect("trial");
        println!("{placement:?}: boxed after {:?} frames", outcome.frames);
        assert!(
            outcome.frames.is_some_and(|f| f <= 4),
            "{placement:?}: {outcome:?}"
        );
    }
}

#[test]
fn budgeted_scan_matches_whole_scan() {
    let dir = fixtures();
    let frame = decode_jpeg(
        &read(&dir.join("faces/dlib_2007_007763.jpg")),
        DEFAULT_MAX_PIXELS,
    )
    .expect("decode");
    let mut whole = FaceScanner::new(FaceParams {
        scan_budget_px: None,
        ..FaceParams::default()
    })
    .expect("cascade");
    let whole_faces = whole.scan(&frame).expect("scan").faces;
    let mut budgeted = FaceScanner::new(FaceParams::default()).expect("cascade");
    let mut scan = budgeted.scan(&frame).expect("scan");
    assert!(
        scan.units_per_cycle > 1,
        "a 500x375 photo should take several frames"
    );
    while scan.completed_cycles < 2 {
        scan = budgeted.scan(&frame).expect("scan");
    }
    let matched = whole_faces
        .iter()
        .filter(|w| scan.faces.iter().any(|b| b.iou(w) >= 0.5))
        .count();
    assert!(
        matched + 1 >= whole_faces.len(),
        "whole {whole_faces:?} budgeted {:?}",
        scan.faces
    );
}

fn texts(reader: &mut CodeReader, frame: &GreyFrame) -> Vec<String> {
    let mut texts: Vec<String> = reader
        .read(frame)
        .expect("read")
        .into_iter()
        .map(|code| String::from_utf8(code.bytes).expect("utf-8"))
        .collect();
    texts.sort();
    texts
}

#[test]
fn qr_fixtures_decode_to_exact_text() {
    let dir = fixtures();
    let truth = GroundTruth::load(&dir).expect("ground truth");
    let mut reader = CodeReader::new(CodeParams::default()).expect("reader");
    assert_eq!(truth.qr.len(), 7);
    for image in &truth.qr {
        let frame =
            decode_jpeg(&as_jpeg(&dir.join(&image.image)), DEFAULT_MAX_PIXELS).expect("decode");
        let mut expected = image.texts.clone();
        expected.sort();
        let got = texts(&mut reader, &frame);
        println!("{}: {} of {} codes", image.image, got.len(), expected.len());
        assert_eq!(got, expected, "{}", image.image);
    }
}

#[test]
fn four_code_page_yields_four_codes_with_polygons() {
    let dir = fixtures();
    let frame = decode_jpeg(
        &as_jpeg(&dir.join("qr/zxing_multi-qrcode-1_1.png")),
        DEFAULT_MAX_PIXELS,
    )
    .expect("decode");
    let mut reader = CodeReader::new(CodeParams::default()).expect("reader");
    let codes = reader.read(&frame).expect("read");
    assert_eq!(codes.len(), 4);
    for code in &codes {
        assert_eq!(code.symbology, Symbology::Qr);
        assert_eq!(code.polygon.len(), 4);
        assert!(
            code.polygon
                .iter()
                .all(|p| p.x >= 0.0 && p.x <= 792.0 && p.y >= 0.0 && p.y <= 605.0)
        );
    }
    // The last text ends in two spaces: nothing may be trimmed.
    assert!(codes.iter().any(|c| c.bytes.ends_with(b"Way to go!  ")));
}

#[test]
fn code128_keeps_nul_byte() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let mut reader = CodeReader::new(CodeParams::default()).expect("reader");
    let frame = decode_jpeg(
        &as_jpeg(&data.join("code128_null_character.png")),
        DEFAULT_MAX_PIXELS,
    )
    .expect("decode");
    let codes = reader.read(&frame).expect("read");
    assert_eq!(codes.len(), 1);
    assert_eq!(codes[0].symbology, Symbology::Code128);
    assert_eq!(codes[0].bytes, b"Hello\0Goodbye");
    let frame =
        decode_jpeg(&as_jpeg(&data.join("code128.png")), DEFAULT_MAX_PIXELS).expect("decode");
    let got = texts(&mut reader, &frame);
    assert!(got.contains(&"Foramenifera".to_owned()), "{got:?}");
}

#[test]
fn steady_qr_is_reported_once_over_thirty_frames() {
    let dir = fixtures();
    let jpeg = read(&dir.join("qr/derived/zxing_qrcode-1_1_640x360.jpg"));
    let params = PipelineParams {
        faces: None,
        motion: None,
        ..PipelineParams::default()
    };
    let mut pipeline = VisionPipeline::new(params).expect("pipeline");
    let mut first_sightings = 0;
    let mut frames_with_code = 0;
    for seq in 0..30 {
        let detections = pipeline
            .process_jpeg(&jpeg, seq, seq * FRAME_US)
            .expect("process");
        let codes = detections.codes.expect("codes enabled");
        frames_with_code += usize::from(!codes.is_empty());
        first_sightings += codes.iter().filter(|c| c.first_sighting).count();
    }
    assert_eq!(first_sightings, 1);
    assert!(
        frames_with_code >= 25,
        "decoded on only {frames_with_code} of 30 frames"
    );
}

#[test]
fn motion_sequence_still_then_person_without_flicker() {
    let dir = fixtures();
    let mut detector = MotionDetector::new(MotionParams::default()).expect("motion");
    let mut states = String::new();
    for index in 1..=120 {
        let frame =
            decode_jpeg(&read(&motion_frame(&dir, index)), DEFAULT_MAX_PIXELS).expect("decode");
        let motion = detector
            .process(&frame, index as u64 * FRAME_US)
            .expect("process");
        states.push(match motion {
            Motion::Still => '.',
            Motion::Moving { held: true, .. } => 'h',
            Motion::Moving { .. } => 'M',
        });
    }
    println!("frames 1-120: {states}");
    let (empty, rest) = states.split_at(60);
    assert!(
        empty.chars().all(|c| c == '.'),
        "motion reported in the empty scene: {empty}"
    );
    // The person enters at frame 61 (detected on 61 or 62) and walks until about frame 95 (source time 8.4 s).
    let walking = &rest[1..35];
    assert!(
        walking.chars().all(|c| c != '.'),
        "motion flickered off while the person walks: {walking}"
    );
    assert!(rest.starts_with('M') || rest[1..].starts_with('M'));
}

#[test]
fn bad_frames_are_typed_errors_and_the_pipeline_keeps_going() {
    let dir = fixtures();
    let good = read(&motion_frame(&dir, 1));
    let mut pipeline = VisionPipeline::new(PipelineParams::default()).expect("pipeline");
    let not_jpeg = pipeline.process_jpeg(b"definitely not a jpeg", 0, 0);
    assert!(
        matches!(not_jpeg, Err(ProcessError::Frame(FrameError::NotJpeg))),
        "{not_jpeg:?}"
    );
    let truncated = pipeline.process_jpeg(&good[..good.len() / 2], 1, FRAME_US);
    assert!(
        matches!(
            truncated,
            Err(ProcessError::Frame(FrameError::Truncated(_)))
        ),
        "{truncated:?}"
    );
    let png = std::fs::read(dir.join("qr/zxing_qrcode-1_1.png")).expect("png");
    assert!(matches!(
        pipeline.process_jpeg(&png, 2, 2 * FRAME_US),
        Err(ProcessError::Frame(FrameError::NotJpeg))
    ));
    let detections = pipeline
        .process_jpeg(&good, 3, 3 * FRAME_US)
        .expect("a good frame after bad ones");
    assert_eq!((detections.size.width, detections.size.height), (640, 360));
}

#[test]
fn gaze_looks_at_a_face_in_the_two_people_frame() {
    let dir = fixtures();
    let jpeg = read(&dir.join("faces/derived/fr_two_people_640x360.jpg"));
    let mut pipeline = VisionPipeline::new(PipelineParams::default()).expect("pipeline");
    let mut last = None;
    let mut settle = 10;
    for seq in 0..150 {
        let detections = pipeline
            .process_jpeg(&jpeg, seq, seq * FRAME_US)
            .expect("process");
        // After a complete scan, let the smoothing settle for a few more frames.
        if detections.face_cycles >= 2 {
            settle -= 1;
            if settle == 0 {
                last = Some(detections);
                break;
            }
        }
    }
    let detections = last.expect("a full face scan within 150 frames");
    let faces = detections.faces.expect("faces enabled");
    assert!(faces.len() >= 2, "{faces:?}");
    assert_eq!(detections.gaze.source, GazeSource::Face);
    let (gx, gy) = (detections.gaze.x * 640.0, detections.gaze.y * 360.0);
    assert!(
        faces
            .iter()
            .any(|f| (gx - f.centre().x).abs() < 80.0 && (gy - f.centre().y).abs() < 80.0),
        "{gx},{gy} {faces:?}"
    );
}
