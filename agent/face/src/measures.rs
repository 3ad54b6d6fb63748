//! What one face's landmarks say: how open the mouth and the eyes are, where the head is turned, and how much it
//! smiles. Pure geometry on the 68 points, in units of the distance between the outer eye corners, so a face's
//! size in the frame does not matter.
//!
//! The head pose is an estimate from the 2D points (no 3D model): the nose tip's place between the jaw's ends
//! for the yaw, and between the eyes and the chin for the pitch. It tells a face turned to the camera from one
//! turned away, which is what `looking` needs, not a measured angle.

use crate::landmarks::{Landmarks, Point, index};

/// A face turned to the camera has its nose tip this far down from the eye line to the chin (the fixtures' 21
/// annotated faces: 0.15-0.36, median 0.29).
const NEUTRAL_NOSE_DROP: f32 = 0.28;
/// How far the nose tip moves in those units for a quarter turn up or down.
const NOSE_DROP_RANGE: f32 = 0.4;
/// The smile reads the lift of the mouth's corners over the lips' middle (per eye distance: -0.06-0.10 at rest,
/// 0.07-0.18 smiling on the fixtures) and the mouth's widening past its width at rest (0.52-0.72 of the eye
/// distance at rest, up to 0.84 smiling). Those faces, labelled by eye, agree with `smiling` in 17 of 21.
const REST_CORNER_LIFT: f32 = 0.025;
const SMILE_CORNER_LIFT: f32 = 0.09;
const REST_MOUTH_WIDTH: f32 = 0.72;
const SMILE_WIDENING: f32 = 0.15;
/// A smile degree from this up is `smiling`.
pub const SMILING_FROM: f32 = 0.5;

/// Head yaw and pitch within this many degrees count as looking at the camera (the agent).
pub const LOOKING_WITHIN_DEG: f32 = 25.0;

/// One face's measures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaceMeasures {
    /// The gap between the inner lips over the eye corners' distance: about 0 closed, 0.1-0.4 talking.
    pub mouth_open: f32,
    /// The eyes' aspect ratio (height over width, both eyes' mean): about 0.25-0.35 open, under 0.15 closed.
    pub eyes_open: f32,
    /// Degrees the head is turned: positive towards the image's right, 0 facing the camera.
    pub yaw_deg: f32,
    /// Degrees the head is tilted: positive up.
    pub pitch_deg: f32,
    /// 0 (at rest) to 1 (a broad smile).
    pub smile: f32,
}

impl FaceMeasures {
    /// Whether the face is turned to the camera.
    pub fn looking(&self) -> bool {
        self.yaw_deg.abs() <= LOOKING_WITHIN_DEG && self.pitch_deg.abs() <= LOOKING_WITHIN_DEG
    }

    /// Whether the face smiles.
    pub fn smiling(&self) -> bool {
        self.smile >= SMILING_FROM
    }
}

/// The measures of one face; `None` when the points are degenerate (eyes on top of each other).
pub fn measure(face: &Landmarks) -> Option<FaceMeasures> {
    let p = |i| face.point(i);
    let eye_distance = p(index::RIGHT_EYE_OUTER).distance(p(index::LEFT_EYE_OUTER));
    if !eye_distance.is_finite() || eye_distance < 1.0 {
        return None;
    }
    let mouth_open = index::INNER_UPPER
        .iter()
        .zip(index::INNER_LOWER)
        .map(|(&upper, lower)| (p(lower).y - p(upper).y).max(0.0))
        .sum::<f32>()
        / index::INNER_UPPER.len() as f32
        / eye_distance;
    let eyes_open = (eye_aspect(face, index::RIGHT_EYE) + eye_aspect(face, index::LEFT_EYE)) / 2.0;

    let jaw_span = p(index::JAW_LEFT).x - p(index::JAW_RIGHT).x;
    let yaw_deg = if jaw_span.abs() < 1.0 {
        90.0
    } else {
        let across = (p(index::NOSE_TIP).x - p(index::JAW_RIGHT).x) / jaw_span;
        degrees_of(2.0 * across - 1.0)
    };
    let eyes = p(index::RIGHT_EYE_OUTER).midpoint(p(index::LEFT_EYE_OUTER));
    let face_height = p(index::CHIN).y - eyes.y;
    let pitch_deg = if face_height < 1.0 {
        90.0
    } else {
        let drop = (p(index::NOSE_TIP).y - eyes.y) / face_height;
        degrees_of((NEUTRAL_NOSE_DROP - drop) / NOSE_DROP_RANGE)
    };

    let width = p(index::MOUTH_RIGHT).distance(p(index::MOUTH_LEFT)) / eye_distance;
    let lips_middle = p(index::UPPER_LIP_TOP).midpoint(p(index::LOWER_LIP_BOTTOM));
    let corners = p(index::MOUTH_RIGHT).midpoint(p(index::MOUTH_LEFT));
    let lift = (lips_middle.y - corners.y) / eye_distance;
    let smile = ((lift - REST_CORNER_LIFT) / SMILE_CORNER_LIFT
        + (width - REST_MOUTH_WIDTH).max(0.0) / SMILE_WIDENING)
        .clamp(0.0, 1.0);

    Some(FaceMeasures {
        mouth_open,
        eyes_open,
        yaw_deg,
        pitch_deg,
        smile,
    })
}

/// Height over width of one eye's six points (corners at 0 and 3, lids at 1-2 and 5-4).
fn eye_aspect(face: &Landmarks, eye: std::ops::Range<usize>) -> f32 {
    let e: Vec<Point> = eye.map(|i| face.point(i)).collect();
    let width = e[0].distance(e[3]);
    if width < 1e-3 {
        return 0.0;
    }
    (e[1].distance(e[5]) + e[2].distance(e[4])) / (2.0 * width)
}

/// The angle whose sine is `ratio`, clamped to a quarter turn.
fn degrees_of(ratio: f32) -> f32 {
    ratio.clamp(-1.0, 1.0).asin().to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::landmarks::LANDMARKS;

    /// A schematic frontal face: eye corners 100 px apart, the nose tip halfway across, mouth closed.
    fn frontal() -> [Point; LANDMARKS] {
        let mut points = [Point::default(); LANDMARKS];
        let mut set = |i: usize, x: f32, y: f32| points[i] = Point { x, y };
        for i in 0..17 {
            // The jaw from ear to ear through the chin.
            let t = i as f32 / 16.0;
            let angle = std::f32::consts::PI * t;
            set(i, 200.0 - 80.0 * angle.cos(), 100.0 + 110.0 * angle.sin());
        }
        set(36, 150.0, 100.0);
        set(37, 160.0, 95.0);
        set(38, 170.0, 95.0);
        set(39, 180.0, 100.0);
        set(40, 170.0, 105.0);
        set(41, 160.0, 105.0);
        set(42, 220.0, 100.0);
        set(43, 230.0, 95.0);
        set(44, 240.0, 95.0);
        set(45, 250.0, 100.0);
        set(46, 240.0, 105.0);
        set(47, 230.0, 105.0);
        set(30, 200.0, 100.0 + NEUTRAL_NOSE_DROP * 110.0);
        set(48, 163.0, 180.0);
        set(54, 237.0, 180.0);
        set(51, 200.0, 175.0);
        set(57, 200.0, 185.0);
        for (upper, lower) in [(61, 67), (62, 66), (63, 65)] {
            set(upper, 200.0, 180.0);
            set(lower, 200.0, 180.0);
        }
        points
    }

    #[test]
    fn a_frontal_face_at_rest_looks_with_a_closed_mouth_and_open_eyes() {
        let m = measure(&Landmarks::new(frontal())).expect("measures");
        assert!(m.mouth_open.abs() < 1e-6, "{m:?}");
        assert!((m.eyes_open - 1.0 / 3.0).abs() < 1e-3, "{m:?}");
        assert!(m.yaw_deg.abs() < 1.0 && m.pitch_deg.abs() < 1.0, "{m:?}");
        assert!(m.looking());
        assert!(m.smile < 0.05, "{m:?}");
    }

    #[test]
    fn an_open_mouth_is_measured_in_eye_distances() {
        let mut points = frontal();
        for lower in [65, 66, 67] {
            points[lower].y += 30.0;
        }
        let m = measure(&Landmarks::new(points)).expect("measures");
        assert!((m.mouth_open - 0.3).abs() < 1e-3, "{m:?}");
    }

    #[test]
    fn a_nose_near_one_ear_is_a_face_turned_away() {
        let mut points = frontal();
        points[30].x = 270.0;
        let m = measure(&Landmarks::new(points)).expect("measures");
        assert!(m.yaw_deg > 45.0, "{m:?}");
        assert!(!m.looking());
        points[30].x = 130.0;
        let m = measure(&Landmarks::new(points)).expect("measures");
        assert!(m.yaw_deg < -45.0, "{m:?}");
    }

    #[test]
    fn a_wide_mouth_with_raised_corners_smiles() {
        let mut points = frontal();
        points[48] = Point { x: 150.0, y: 174.0 };
        points[54] = Point { x: 250.0, y: 174.0 };
        let m = measure(&Landmarks::new(points)).expect("measures");
        assert!(m.smile > 0.9 && m.smiling(), "{m:?}");
    }

    #[test]
    fn closed_eyes_measure_low() {
        let mut points = frontal();
        for i in [37, 38, 43, 44] {
            points[i].y = 99.0;
        }
        for i in [40, 41, 46, 47] {
            points[i].y = 101.0;
        }
        let m = measure(&Landmarks::new(points)).expect("measures");
        assert!(m.eyes_open < 0.1, "{m:?}");
    }

    #[test]
    fn degenerate_points_have_no_measures() {
        assert_eq!(
            measure(&Landmarks::new([Point::default(); LANDMARKS])),
            None
        );
    }
}
