//! A generated two-person clip for the active-speaker tests and benchmark: the camera-format fixture with two
//! people, whose mouths are drawn open and closed in turn (a dark ellipse between the lips, where dlib's landmarks
//! read an open mouth), with the voice activity that goes with it.

use std::path::Path;

use agent_face::{FaceAnalyzer, FaceBox, FaceModelPaths, GreyImage};
use agent_vision::geometry::BoxPx;
use opencv::core::{
    Mat, MatTraitConst, MatTraitConstManual, Point, Scalar, Size, Vector, VectorToVec,
};
use opencv::{imgcodecs, imgproc};

use crate::evaluation::{FRAME_US, SceneError, read_colour};
use crate::fixtures::CAMERA_JPEG_QUALITY;

/// The photo: two people side by side, both turned to the camera.
pub const TWO_PEOPLE: &str = "faces/derived/fr_two_people_640x360.jpg";

/// Their faces in it (dlib's detector's boxes): the left one, then the right one.
pub const FACES: [BoxPx; 2] = [
    BoxPx {
        x: 141,
        y: 26,
        width: 87,
        height: 87,
    },
    BoxPx {
        x: 446,
        y: 31,
        width: 104,
        height: 104,
    },
];

/// Which of the two is talking.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    Left,
    Right,
}

impl Side {
    pub fn face(self) -> BoxPx {
        match self {
            Side::Left => FACES[0],
            Side::Right => FACES[1],
        }
    }
}

/// One frame of the clip.
#[derive(Debug, Clone)]
pub struct TalkingFrame {
    pub jpeg: Vec<u8>,
    pub frame_us: u64,
    /// Who talks in this frame (`None`: nobody, and no voice).
    pub speaker: Option<Side>,
}

/// A talking mouth's opening over four frames (in eye distances): about four syllables a second at 15 fps.
const SYLLABLE: [f32; 4] = [0.3, 0.15, 0.0, 0.22];

/// The clip: `turns` in order, each `turn_frames` frames long (15 fps).
pub fn talking_pair(
    fixtures: &Path,
    turns: &[Option<Side>],
    turn_frames: usize,
) -> Result<Vec<TalkingFrame>, SceneError> {
    let photo = read_colour(&fixtures.join(TWO_PEOPLE))?;
    let mouths = mouths(&photo)?;
    let mut frames = Vec::with_capacity(turns.len() * turn_frames);
    for (turn, speaker) in turns.iter().enumerate() {
        for i in 0..turn_frames {
            let index = turn * turn_frames + i;
            let mut frame = photo.try_clone()?;
            if let Some(side) = speaker {
                let mouth = &mouths[*side as usize];
                let open = SYLLABLE[i % SYLLABLE.len()] * mouth.eye_distance;
                if open > 0.5 {
                    imgproc::ellipse(
                        &mut frame,
                        Point::new(mouth.centre.0.round() as i32, mouth.centre.1.round() as i32),
                        Size::new(
                            mouth.half_width.round() as i32,
                            (open / 2.0).round().max(1.0) as i32,
                        ),
                        0.0,
                        0.0,
                        360.0,
                        Scalar::new(30.0, 25.0, 35.0, 0.0),
                        -1,
                        imgproc::LINE_AA,
                        0,
                    )?;
                }
            }
            let mut jpeg = Vector::<u8>::new();
            let params =
                Vector::<i32>::from_slice(&[imgcodecs::IMWRITE_JPEG_QUALITY, CAMERA_JPEG_QUALITY]);
            imgcodecs::imencode(".jpg", &frame, &mut jpeg, &params)?;
            frames.push(TalkingFrame {
                jpeg: jpeg.to_vec(),
                frame_us: index as u64 * FRAME_US,
                speaker: *speaker,
            });
        }
    }
    Ok(frames)
}

/// Where a mouth is drawn: between the inner lips, as wide as they are.
#[derive(Debug, Clone, Copy)]
struct Mouth {
    centre: (f32, f32),
    half_width: f32,
    eye_distance: f32,
}

/// The two mouths, from the landmarks of the faces in the photo.
fn mouths(photo: &Mat) -> Result<[Mouth; 2], SceneError> {
    let mut grey = Mat::default();
    imgproc::cvt_color_def(photo, &mut grey, imgproc::COLOR_BGR2GRAY)?;
    let (width, height) = (grey.cols().unsigned_abs(), grey.rows().unsigned_abs());
    let pixels = grey.data_bytes()?;
    let failed = |e: agent_face::FaceError| SceneError::Face(e.to_string());
    let image = GreyImage::new(pixels, width, height, width).map_err(failed)?;
    let analyzer = FaceAnalyzer::load(&FaceModelPaths {
        descriptor: None,
        ..FaceModelPaths::default()
    })
    .map_err(failed)?;
    let mouth = |face: BoxPx| -> Result<Mouth, SceneError> {
        let points = analyzer
            .landmarks(&image, FaceBox::from(face))
            .map_err(failed)?;
        let centre = points.point(62).midpoint(points.point(66));
        Ok(Mouth {
            centre: (centre.x, centre.y),
            half_width: points.point(60).distance(points.point(64)) / 2.0 * 0.9,
            eye_distance: points.point(36).distance(points.point(45)),
        })
    };
    Ok([mouth(FACES[0])?, mouth(FACES[1])?])
}
