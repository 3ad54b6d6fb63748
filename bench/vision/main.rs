//! `vision-bench`: per-frame cost of the vision detectors at 640x360 on one thread, side by side with the same
//! work done through Python's cv2 (`bench/vision/cv2_baseline.py`) in the same run, plus the cascade comparison
//! on the annotated fixtures that picks the default face cascade. Prints `SUMMARY` lines and, with
//! `--write-doc`, writes `docs/bench-vision.md`.

mod baseline;
mod stats;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use agent_vision::centerface::{CenterFace, CenterFaceParams};
use agent_vision::codes::{CodeParams, CodeReader};
use agent_vision::face::{Cascade, DEBIAN_CASCADE_DIR, FaceDetector, FaceParams, FaceScanner};
use agent_vision::frame::{DEFAULT_MAX_PIXELS, GreyFrame, decode_jpeg};
use agent_vision::motion::{MotionDetector, MotionParams};
use agent_vision::{PipelineParams, VisionPipeline};
use anyhow::Context;
use clap::Parser;
use opencv::barcode::{BarcodeDetector, BarcodeDetectorTraitConst};
use opencv::core::{Point2f, Vector};
use serde_json::json;
use vision_evaluation::fixtures::{GroundTruth, fixtures_dir, score_faces};

use stats::Samples;

const FRAME_US: u64 = 66_667;
const TARGET_ALL_MS: f64 = 20.0;

#[derive(Debug, Parser)]
#[command(about = "Vision detector timings against the Python cv2 baseline")]
struct Args {
    /// Timed repetitions of the face full-scan cases (per cascade and for the baseline).
    #[arg(long, default_value_t = 7)]
    iterations: usize,
    /// Passes over the frame sets for decode, motion and codes.
    #[arg(long, default_value_t = 2)]
    rounds: usize,
    /// Write the report to this Markdown file (e.g. docs/bench-vision.md).
    #[arg(long)]
    write_doc: Option<PathBuf>,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    opencv::core::set_num_threads(1)?;
    // The crate (agent-bench) sits at <repo>/bench.
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let repo = manifest
        .canonicalize()
        .unwrap_or_else(|_| manifest.to_path_buf())
        .join("..");
    let fixtures = fixtures_dir();
    let truth = GroundTruth::load(&fixtures)?;
    let mut report = String::new();
    let mut summary = Vec::new();

    let motion_paths: Vec<PathBuf> = (1..=120)
        .map(|i| {
            fixtures.join(format!(
                "motion/derived/intel_one-by-one_t2-10s_640x360_15fps/frame_{i:04}.jpg"
            ))
        })
        .collect();
    let motion_jpegs: Vec<Vec<u8>> = motion_paths
        .iter()
        .map(read)
        .collect::<anyhow::Result<_>>()?;
    let faces_path = fixtures.join("faces/derived/fr_two_people_640x360.jpg");
    let faces_jpeg = read(&faces_path)?;
    let qr_paths: Vec<PathBuf> = [
        "qr/derived/zxing_qrcode-1_1_640x360.jpg",
        "qr/derived/zxing_qrcode-1_17_640x360.jpg",
    ]
    .iter()
    .map(|p| fixtures.join(p))
    .collect();
    let qr_jpegs: Vec<Vec<u8>> = qr_paths.iter().map(read).collect::<anyhow::Result<_>>()?;
    let no_code_paths: Vec<PathBuf> = motion_paths.iter().step_by(8).cloned().collect();

    // The Python side first, so that our numbers and its numbers see the same machine state on average when the
    // run is repeated; both run single-threaded.
    let defaults = FaceParams::default();
    let face_frame = decode_jpeg(&faces_jpeg, DEFAULT_MAX_PIXELS)?;
    let full_scan_params = FaceParams {
        scan_budget_px: None,
        ..defaults.clone()
    };
    let detect_size = detect_size(&full_scan_params, &face_frame)?;
    let centerface = CenterFaceParams::default();
    let spec = json!({
        "threads": 1,
        "decode": { "images": paths(&motion_paths), "rounds": args.rounds },
        "faces": {
            "image": faces_path,
            "cascade": Path::new(DEBIAN_CASCADE_DIR).join(defaults.cascade.relative_path()),
            "iterations": args.iterations,
            "cases": [{
                "name": "full",
                "detect_size": detect_size,
                "scale_factor": defaults.scale_factor,
                "min_neighbors": defaults.min_neighbors,
                "min_size": [24, 24],
            }],
        },
        "centerface": {
            "image": faces_path,
            "model": centerface.model,
            "input": [centerface.input_width, centerface.input_height],
            "iterations": args.iterations,
        },
        "motion": {
            "frames": paths(&motion_paths),
            "rounds": args.rounds,
            "work_size": [MotionParams::default().work_width, 180],
            "pixel_threshold": MotionParams::default().pixel_threshold,
            "on_fraction": MotionParams::default().on_fraction,
        },
        "qr": { "rounds": args.rounds, "sets": { "no_code": paths(&no_code_paths), "with_qr": paths(&qr_paths) } },
        "barcode": { "rounds": args.rounds, "sets": { "no_code": paths(&no_code_paths), "with_qr": paths(&qr_paths) } },
    });
    let python = baseline::python(&repo);
    let base = baseline::run(&python, &repo.join("bench/vision/cv2_baseline.py"), &spec)?;
    let base_case = |name: &str| {
        base.cases
            .get(name)
            .cloned()
            .with_context(|| format!("baseline case {name} missing"))
    };

    // Decode.
    let mut decode = Samples::default();
    for _ in 0..args.rounds {
        for jpeg in &motion_jpegs {
            decode
                .time(|| decode_jpeg(jpeg, DEFAULT_MAX_PIXELS))
                .context("decode")?;
        }
    }
    let base_decode = base_case("decode")?;
    summary.push(line("vision decode 640x360 grey", &decode, &base_decode));

    // Faces: one full detectMultiScale per call, then the budgeted scanner per frame.
    let mut full = FaceDetector::new(full_scan_params.clone())?;
    let mut face_full = Samples::default();
    for _ in 0..args.iterations {
        face_full
            .time(|| full.detect(&face_frame))
            .context("detect")?;
    }
    let base_faces = base_case("faces:full")?;
    summary.push(line(
        "vision faces full scan per call (haar_default, min face 24)",
        &face_full,
        &base_faces,
    ));
    let mut scanner = FaceScanner::new(defaults.clone())?;
    let mut face_scan = Samples::default();
    let mut scan = scanner.scan(&face_frame)?;
    let first_cycle = scan.completed_cycles;
    while scan.completed_cycles < first_cycle + 3 {
        scan = face_scan
            .time(|| scanner.scan(&face_frame))
            .context("scan")?;
    }
    summary.push(line(
        "vision faces budgeted scan per frame",
        &face_scan,
        &base_faces,
    ));

    // The default detector: one run of the network, the same calls as the baseline's (after one run to warm up).
    let mut net = CenterFace::new(centerface.clone())?;
    net.detect(&face_frame)?;
    let mut net_runs = Samples::default();
    for _ in 0..args.iterations {
        net_runs
            .time(|| net.detect(&face_frame))
            .context("centerface")?;
    }
    summary.push(line(
        &format!(
            "vision faces CenterFace {}x{} per run (the default detector; it runs every {} frames)",
            centerface.input_width, centerface.input_height, centerface.every_frames
        ),
        &net_runs,
        &base_case("centerface")?,
    ));

    // Motion over the whole sequence.
    let motion_frames: Vec<GreyFrame> = motion_jpegs
        .iter()
        .map(|j| decode_jpeg(j, DEFAULT_MAX_PIXELS))
        .collect::<Result<_, _>>()?;
    let mut motion = Samples::default();
    for _ in 0..args.rounds {
        let mut detector = MotionDetector::new(MotionParams::default())?;
        for (i, frame) in motion_frames.iter().enumerate() {
            motion
                .time(|| detector.process(frame, i as u64 * FRAME_US))
                .context("motion")?;
        }
    }
    let base_motion = base_case("motion")?;
    summary.push(line("vision motion per frame", &motion, &base_motion));

    // Codes: rxing against cv2's QR detector plus its barcode detector, on frames without and with a QR code.
    let mut reader = CodeReader::new(CodeParams::default())?;
    let mut opencv_barcode = BarcodeDetector::new("", "")?;
    let mut code_rows = String::new();
    let mut codes_all = Samples::default();
    let mut base_codes_all = Samples::default();
    for (set, set_paths) in [("no_code", &no_code_paths), ("with_qr", &qr_paths)] {
        let frames: Vec<GreyFrame> = set_paths
            .iter()
            .map(|p| read(p).and_then(|j| Ok(decode_jpeg(&j, DEFAULT_MAX_PIXELS)?)))
            .collect::<Result<_, _>>()?;
        let mut ours = Samples::default();
        let mut debian_barcode = Samples::default();
        let mut decoded = 0;
        for _ in 0..args.rounds {
            for frame in &frames {
                decoded += ours.time(|| reader.read(frame)).context("codes")?.len();
                debian_barcode
                    .time(|| debian_barcode_call(&mut opencv_barcode, frame))
                    .context("barcode")?;
            }
        }
        let base_qr = base_case(&format!("qr:{set}"))?;
        let base_bar = base_case(&format!("barcode:{set}"))?;
        let base_sum = sum_pairwise(&base_qr, &base_bar);
        writeln!(
            code_rows,
            "| {set} | {:.2} / {:.2} | {:.2} / {:.2} | {:.2} / {:.2} | {:.2} | {:.2} | {:.2} |",
            ours.cpu_median(),
            ours.p95(),
            base_qr.cpu_median(),
            base_qr.p95(),
            base_bar.cpu_median(),
            base_bar.p95(),
            ours.cpu_median() / base_sum.cpu_median(),
            debian_barcode.cpu_median(),
            decoded as f64 / (args.rounds * frames.len()).max(1) as f64,
        )?;
        codes_all.extend(&ours);
        base_codes_all.extend(&base_sum);
    }
    summary.push(line(
        "vision codes per frame (rxing QR+1D vs cv2 QR+barcode)",
        &codes_all,
        &base_codes_all,
    ));

    // Everything together through the pipeline on a mixed camera stream.
    let mut pipeline = VisionPipeline::new(PipelineParams::default())?;
    let mut all = Samples::default();
    let stream: Vec<&Vec<u8>> = motion_jpegs
        .iter()
        .chain(std::iter::repeat_n(&faces_jpeg, 45))
        .chain(qr_jpegs.iter().cycle().take(30))
        .collect();
    for _ in 0..args.rounds {
        for (seq, jpeg) in stream.iter().enumerate() {
            all.time(|| pipeline.process_jpeg(jpeg, seq as u64, seq as u64 * FRAME_US))
                .context("pipeline")?;
        }
    }
    let base_all_cpu = base_decode.cpu_median()
        + base_faces.cpu_median()
        + base_motion.cpu_median()
        + base_codes_all.cpu_median();
    summary.push(format!(
        "SUMMARY vision all modules per frame: {:.2} ms cpu median, target <= {TARGET_ALL_MS} ms (wall median {:.2} ms, p95 {:.2} ms, cpu mean {:.2} ms) (baseline cv2 decode + whole face scan + motion + QR + barcode {:.2} ms cpu, ratio {:.2})",
        all.cpu_median(),
        all.median(),
        all.p95(),
        all.cpu_mean(),
        base_all_cpu,
        all.cpu_median() / base_all_cpu
    ));

    // Cascade comparison on the annotated fixtures.
    let cascade_table = compare_cascades(&truth, &fixtures, &face_frame, args.iterations.min(3))?;

    println!("{cascade_table}");
    println!(
        "| codes set | ours rxing cpu median / wall p95 ms | cv2 QR cpu median / wall p95 | cv2 barcode cpu median / wall p95 | cpu ratio to cv2 QR+barcode | Debian OpenCV barcode (EAN/UPC only) cpu median ms | codes decoded per frame |"
    );
    println!("|---|---|---|---|---|---|---|");
    print!("{code_rows}");
    for s in &summary {
        println!("{s}");
    }
    writeln!(
        report,
        "{}",
        doc_text(
            &base.cv2_version,
            &cascade_table,
            &code_rows,
            &summary,
            &scan
        )
    )?;
    if let Some(path) = args.write_doc {
        std::fs::write(&path, report).with_context(|| format!("writing {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn read(path: &PathBuf) -> anyhow::Result<Vec<u8>> {
    std::fs::read(path).with_context(|| format!("reading {}", path.display()))
}

fn paths(list: &[PathBuf]) -> Vec<String> {
    list.iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect()
}

/// The size the detector shrinks this frame to, for the baseline to do the same.
fn detect_size(params: &FaceParams, frame: &GreyFrame) -> anyhow::Result<[u32; 2]> {
    let detector = FaceDetector::new(params.clone())?;
    let factor = detector.detection_scale(frame.size().width);
    let size = frame.size();
    Ok([
        (f64::from(size.width) * factor).round() as u32,
        (f64::from(size.height) * factor).round() as u32,
    ])
}

fn debian_barcode_call(detector: &mut BarcodeDetector, frame: &GreyFrame) -> opencv::Result<bool> {
    let mut texts = Vector::<String>::new();
    let mut kinds = Vector::<opencv::barcode::BarcodeType>::new();
    let mut corners = Vector::<Point2f>::new();
    detector.detect_and_decode(frame.mat(), &mut texts, &mut kinds, &mut corners)
}

fn sum_pairwise(a: &Samples, b: &Samples) -> Samples {
    Samples {
        wall_ms: a
            .wall_ms
            .iter()
            .zip(&b.wall_ms)
            .map(|(x, y)| x + y)
            .collect(),
        cpu_ms: a.cpu_ms.iter().zip(&b.cpu_ms).map(|(x, y)| x + y).collect(),
    }
}

/// One summary line. The ratio compares thread CPU time, which other processes on a busy machine disturb far
/// less than wall time (both sides are single-threaded, so CPU time is the work done).
fn line(name: &str, ours: &Samples, base: &Samples) -> String {
    format!(
        "SUMMARY {name}: {:.2} ms cpu median (wall median {:.2} ms, p95 {:.2} ms) (baseline cv2 {:.2} ms cpu median, wall {:.2} ms, ratio {:.2})",
        ours.cpu_median(),
        ours.median(),
        ours.p95(),
        base.cpu_median(),
        base.median(),
        ours.cpu_median() / base.cpu_median()
    )
}

/// Recall, false positives and full-scan time of every cascade on the annotated fixtures.
fn compare_cascades(
    truth: &GroundTruth,
    fixtures: &Path,
    camera: &GreyFrame,
    iterations: usize,
) -> anyhow::Result<String> {
    let photos: Vec<(usize, GreyFrame)> = truth
        .faces
        .iter()
        .enumerate()
        .map(|(i, t)| {
            Ok((
                i,
                decode_jpeg(&read(&fixtures.join(&t.image))?, DEFAULT_MAX_PIXELS)?,
            ))
        })
        .collect::<anyhow::Result<_>>()?;
    let mut table = String::from(
        "| cascade | min neighbours | recall (IoU >= 0.3) | false positives / image | full scan 640x360 cpu median ms |\n|---|---|---|---|---|\n",
    );
    // The rows of single cascades first (no verifier), then the default: haar_default's candidates confirmed by
    // haar_alt around each one.
    for cascade in Cascade::ALL {
        for min_neighbors in [3, 4] {
            let params = FaceParams {
                cascade,
                min_neighbors,
                scan_budget_px: None,
                verify: None,
                ..FaceParams::default()
            };
            let mut detector = FaceDetector::new(params)?;
            let (mut annotated, mut found, mut false_positives) = (0, 0, 0);
            for (i, frame) in &photos {
                let score = score_faces(&truth.faces[*i], &detector.detect(frame)?, 0.3);
                annotated += score.annotated;
                found += score.found;
                false_positives += score.false_positives;
            }
            let mut time = Samples::default();
            for _ in 0..iterations {
                time.time(|| detector.detect(camera))?;
            }
            writeln!(
                table,
                "| {} | {min_neighbors} | {found}/{annotated} = {:.2} | {:.2} | {:.1} |",
                cascade.name(),
                found as f64 / annotated as f64,
                false_positives as f64 / photos.len() as f64,
                time.cpu_median()
            )?;
        }
    }
    let verified = FaceParams {
        scan_budget_px: None,
        ..FaceParams::default()
    };
    let verifier = verified.verify.map_or("none", Cascade::name);
    let mut scanner = agent_vision::face::FaceScanner::new(verified.clone())?;
    let (mut annotated, mut found, mut false_positives) = (0, 0, 0);
    for (i, frame) in &photos {
        let score = score_faces(&truth.faces[*i], &scanner.scan(frame)?.faces, 0.3);
        annotated += score.annotated;
        found += score.found;
        false_positives += score.false_positives;
    }
    let mut time = Samples::default();
    for _ in 0..iterations {
        time.time(|| scanner.scan(camera))?;
    }
    writeln!(
        table,
        "| {} confirmed by {verifier} (default) | {} | {found}/{annotated} = {:.2} | {:.2} | {:.1} |",
        verified.cascade.name(),
        verified.min_neighbors,
        found as f64 / annotated as f64,
        false_positives as f64 / photos.len() as f64,
        time.cpu_median()
    )?;
    Ok(table)
}

fn doc_text(
    cv2_version: &str,
    cascades: &str,
    code_rows: &str,
    summary: &[String],
    scan: &agent_vision::face::FaceScan,
) -> String {
    format!(
        "# Vision benchmark\n\n\
Written by `vision-bench --write-doc docs/bench-vision.md` (`make bench`); figures from the last run on the 2-core \
reference machine. One OpenCV thread everywhere. Ours: Debian's OpenCV 4.6 through the `opencv` crate, rxing for \
codes. Baseline: Python cv2 {cv2_version} (`opencv-python-headless<5`) making the same OpenCV calls with the same \
parameters on the same frames, in the same run (`bench/vision/cv2_baseline.py`). Times are wall-clock per call \
(median and p95); `cpu` is the thread's CPU time, less disturbed by other processes: when the machine is busy \
(parallel builds), wall times stretch and the CPU column is the one to read.\n\n\
## Summary\n\n```\n{}\n```\n\n\
## Face cascades on the annotated fixtures\n\n\
All cascades from Debian's `opencv-data`, scale factor 1.1, min face 24 px, frames up to 640 px wide, whole-pyramid \
scan. Recall over the 23 annotated faces of the 4 dlib photos and 3 portraits.\n\n{cascades}\n\
The default is `haar_default` with 3 neighbours, the only cascade above 85% recall (the others miss the small \
(~37 px) faces of the group photos), with each candidate confirmed by `haar_alt` around it (the last row), which \
drops the false faces. Its whole scan is too slow for 15 fps on this machine, so the module spreads \
the scan over frames (`FaceScanner`, {} units per cycle for a 640x360 frame) within a budget of \
{} scanned pixels per frame.\n\n\
## Codes\n\n\
| set | ours rxing cpu median / wall p95 ms | cv2 QR cpu median / wall p95 | cv2 barcode cpu median / wall p95 | cpu ratio to cv2 QR+barcode | Debian OpenCV barcode (EAN/UPC only) cpu median ms | codes decoded per frame (ours) |\n\
|---|---|---|---|---|---|---|\n{code_rows}\n\
Debian's OpenCV 4.6 has no quirc, so its `QRCodeDetector` cannot decode at all; its contrib barcode module reads \
EAN/UPC only. rxing reads QR, EAN-8/13, UPC-A/E and Code 128.\n",
        summary.join("\n"),
        scan.units_per_cycle,
        FaceParams::default().scan_budget_px.unwrap_or(0),
    )
}
