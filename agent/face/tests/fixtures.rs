//! The real models on the real fixture photos: landmarks land on the faces, the measures read a frontal face at
//! rest as looking with its mouth closed, a dark mouth drawn open reads open, and the descriptor tells two people
//! apart and one person from a shifted crop of the same face.

use std::path::PathBuf;

use agent_face::{
    FaceAnalyzer, FaceBox, FaceError, FaceModelPaths, GreyImage, SAME_PERSON_DISTANCE, measure,
};
use zune_jpeg::JpegDecoder;
use zune_jpeg::zune_core::colorspace::ColorSpace;
use zune_jpeg::zune_core::options::DecoderOptions;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn fixtures() -> PathBuf {
    std::env::var_os("AGENT_FIXTURES")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join("../shared/fixtures"))
}

fn paths() -> FaceModelPaths {
    FaceModelPaths::default()
}

/// A fixture JPEG as grey pixels, width and height.
fn grey(relative: &str) -> (Vec<u8>, u32, u32) {
    let bytes = std::fs::read(fixtures().join(relative)).expect("fixture photo");
    let options = DecoderOptions::default().jpeg_set_out_colorspace(ColorSpace::Luma);
    let mut decoder = JpegDecoder::new_with_options(std::io::Cursor::new(bytes), options);
    let pixels = decoder.decode().expect("decodable JPEG");
    let (w, h) = decoder.dimensions().expect("dimensions");
    (pixels, w as u32, h as u32)
}

/// The two faces of the camera-format fixture (dlib's own detector's boxes for it).
const OBAMA: FaceBox = FaceBox {
    x: 141,
    y: 26,
    width: 87,
    height: 87,
};
const BIDEN: FaceBox = FaceBox {
    x: 446,
    y: 31,
    width: 104,
    height: 104,
};

#[test]
fn landmarks_land_on_each_face_and_read_a_frontal_face_at_rest() {
    let analyzer = FaceAnalyzer::load(&paths()).expect("models (make model-face)");
    let (pixels, w, h) = grey("faces/derived/fr_two_people_640x360.jpg");
    let image = GreyImage::new(&pixels, w, h, w).expect("image");
    for face in [OBAMA, BIDEN] {
        let points = analyzer.landmarks(&image, face).expect("landmarks");
        let (low, high) = points.bounds();
        let margin = face.width as f32 * 0.3;
        assert!(
            low.x > face.x as f32 - margin
                && high.x < (face.x + face.width) as f32 + margin
                && low.y > face.y as f32 - margin
                && high.y < (face.y + face.height) as f32 + margin,
            "points {low:?}-{high:?} outside {face:?}"
        );
        let m = measure(&points).expect("measures");
        assert!(m.looking(), "{face:?}: {m:?}");
        assert!(m.mouth_open < 0.06, "{face:?}: {m:?}");
        assert!(m.eyes_open > 0.15, "{face:?}: {m:?}");
    }
}

#[test]
fn a_mouth_drawn_open_reads_open() {
    let analyzer = FaceAnalyzer::load(&paths()).expect("models (make model-face)");
    let (mut pixels, w, h) = grey("faces/derived/fr_two_people_640x360.jpg");
    let points = analyzer
        .landmarks(&GreyImage::new(&pixels, w, h, w).expect("image"), OBAMA)
        .expect("landmarks");
    let eye = points.point(36).distance(points.point(45));
    let centre = points.point(62).midpoint(points.point(66));
    let half_width = points.point(60).distance(points.point(64)) / 2.0 * 0.9;
    let half_height = 0.3 * eye / 2.0;
    for y in (centre.y - half_height) as i32..=(centre.y + half_height) as i32 {
        for x in (centre.x - half_width) as i32..=(centre.x + half_width) as i32 {
            let dx = (x as f32 - centre.x) / half_width;
            let dy = (y as f32 - centre.y) / half_height;
            if dx * dx + dy * dy <= 1.0 {
                pixels[y as usize * w as usize + x as usize] = 30;
            }
        }
    }
    let opened = analyzer
        .landmarks(&GreyImage::new(&pixels, w, h, w).expect("image"), OBAMA)
        .expect("landmarks");
    let m = measure(&opened).expect("measures");
    assert!(m.mouth_open > 0.12, "{m:?}");
}

#[test]
fn the_descriptor_tells_two_people_apart_and_knows_a_face_again() {
    let mut analyzer = FaceAnalyzer::load(&paths()).expect("models (make model-face)");
    let (pixels, w, h) = grey("faces/derived/fr_two_people_640x360.jpg");
    let image = GreyImage::new(&pixels, w, h, w).expect("image");
    let mut describe = |face: FaceBox| {
        let points = analyzer.landmarks(&image, face).expect("landmarks");
        analyzer.descriptor(&image, &points).expect("descriptor")
    };
    let obama = describe(OBAMA);
    let biden = describe(BIDEN);
    let obama_shifted = describe(FaceBox {
        x: OBAMA.x + 6,
        y: OBAMA.y - 4,
        width: OBAMA.width + 8,
        height: OBAMA.height + 8,
    });
    assert!(
        obama.distance(&biden) > SAME_PERSON_DISTANCE,
        "{}",
        obama.distance(&biden)
    );
    assert!(
        obama.distance(&obama_shifted) < SAME_PERSON_DISTANCE / 2.0,
        "{}",
        obama.distance(&obama_shifted)
    );

    // The portrait, another photo of the same man, is within the threshold.
    let (pixels, w, h) = grey("faces/fr_obama.jpg");
    let portrait = GreyImage::new(&pixels, w, h, w).expect("image");
    let face = FaceBox {
        x: 366,
        y: 136,
        width: 259,
        height: 259,
    };
    let points = analyzer.landmarks(&portrait, face).expect("landmarks");
    let again = analyzer.descriptor(&portrait, &points).expect("descriptor");
    assert!(
        obama.distance(&again) < SAME_PERSON_DISTANCE,
        "{}",
        obama.distance(&again)
    );
    assert!(
        biden.distance(&again) > SAME_PERSON_DISTANCE,
        "{}",
        biden.distance(&again)
    );
}

#[test]
fn the_smile_agrees_with_the_labelled_fixture_faces() {
    let analyzer = FaceAnalyzer::load(&paths()).expect("models (make model-face)");
    let labels: serde_json::Value =
        serde_json::from_str(include_str!("smiles.json")).expect("labels");
    let faces = labels["faces"].as_array().expect("faces");
    let mut agree = 0;
    for face in faces {
        let photo = face["photo"].as_str().expect("photo");
        let b: Vec<i32> = face["box"]
            .as_array()
            .expect("box")
            .iter()
            .map(|v| v.as_i64().expect("number") as i32)
            .collect();
        let (pixels, w, h) = grey(photo);
        let image = GreyImage::new(&pixels, w, h, w).expect("image");
        let points = analyzer
            .landmarks(
                &image,
                FaceBox {
                    x: b[0],
                    y: b[1],
                    width: b[2],
                    height: b[3],
                },
            )
            .expect("landmarks");
        let m = measure(&points).expect("measures");
        if m.smiling() == face["smiling"].as_bool().expect("label") {
            agree += 1;
        } else {
            eprintln!(
                "{photo} {b:?}: labelled {}, smile {:.2}",
                face["smiling"], m.smile
            );
        }
    }
    eprintln!("smile agreement: {agree} of {}", faces.len());
    // 17 of 21 when the constants were set (measures.rs); a change that loses more than two fails.
    assert!(agree >= 15, "{agree} of {}", faces.len());
}

#[test]
fn a_missing_or_broken_model_fails_naming_the_file_and_the_make_target() {
    let missing = FaceModelPaths {
        landmarks: PathBuf::from("/nonexistent/shape.dat"),
        descriptor: None,
    };
    let err = FaceAnalyzer::load(&missing).expect_err("missing");
    assert!(matches!(err, FaceError::Missing { .. }));
    let text = err.to_string();
    assert!(
        text.contains("/nonexistent/shape.dat") && text.contains("make model-face"),
        "{text}"
    );

    let dir = std::env::temp_dir().join(format!("agent-face-broken-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let broken = dir.join("shape.dat");
    std::fs::write(&broken, b"not a dlib model").expect("write");
    let err = FaceAnalyzer::load(&FaceModelPaths {
        landmarks: broken.clone(),
        descriptor: None,
    })
    .expect_err("broken");
    let text = err.to_string();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(matches!(err, FaceError::Load { .. }), "{text}");
    assert!(
        text.contains(&broken.display().to_string()) && text.contains("make model-face"),
        "{text}"
    );
}
