//! `Agent.detections` as `foxglove.ImageAnnotations`, written on an extra topic so that Foxglove's image panel
//! draws the face boxes, motion regions and code outlines over the camera frames.

use agent_contract::detections::{BoxMsg, DetectionsMsg, PointMsg};
use serde_json::{Value, json};

use crate::encoding::timestamp;

/// The suffix of the annotation topic of a detections channel.
pub const SUFFIX: &str = "/annotations";

/// Foxglove's `PointsAnnotationType.LINE_LOOP`: a closed polygon.
const LINE_LOOP: u8 = 2;

/// The annotations of one detections message, or `None` if it is not one.
pub fn from_detections(payload: &[u8]) -> Option<Vec<u8>> {
    let msg: DetectionsMsg = serde_json::from_slice(payload).ok()?;
    // The frame's own hub time, which is its CompressedImage's timestamp too: Foxglove pairs an image with the
    // annotations of the same timestamp.
    let at = timestamp(msg.frame.ts_us);
    let mut points = Vec::new();
    let mut texts = Vec::new();
    for face in msg.faces.iter().flatten() {
        points.push(polygon(&at, &corners(face), [0.2, 0.9, 0.3]));
    }
    if let Some(motion) = &msg.motion {
        for region in &motion.regions {
            points.push(polygon(&at, &corners(region), [1.0, 0.6, 0.1]));
        }
    }
    for code in msg.codes.iter().flatten() {
        let outline: Vec<(f32, f32)> = code.polygon.iter().map(|p: &PointMsg| (p.x, p.y)).collect();
        points.push(polygon(&at, &outline, [0.2, 0.5, 1.0]));
        if let (Some(text), Some(first)) = (&code.text, code.polygon.first()) {
            texts.push(json!({
                "timestamp": at, "position": {"x": first.x, "y": first.y}, "text": text, "font_size": 14.0,
                "text_color": colour([1.0, 1.0, 1.0]), "background_color": colour([0.2, 0.5, 1.0]),
            }));
        }
    }
    serde_json::to_vec(&json!({"circles": [], "points": points, "texts": texts})).ok()
}

fn corners(b: &BoxMsg) -> [(f32, f32); 4] {
    let (x, y, w, h) = (b.x as f32, b.y as f32, b.w as f32, b.h as f32);
    [(x, y), (x + w, y), (x + w, y + h), (x, y + h)]
}

fn polygon(at: &Value, pts: &[(f32, f32)], rgb: [f32; 3]) -> Value {
    json!({
        "timestamp": at,
        "type": LINE_LOOP,
        "points": pts.iter().map(|(x, y)| json!({"x": x, "y": y})).collect::<Vec<_>>(),
        "outline_color": colour(rgb),
        "outline_colors": [],
        "fill_color": {"r": 0.0, "g": 0.0, "b": 0.0, "a": 0.0},
        "thickness": 2.0,
    })
}

fn colour([r, g, b]: [f32; 3]) -> Value {
    json!({"r": r, "g": g, "b": b, "a": 1.0})
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_face_becomes_a_closed_four_point_polygon() {
        let det = json!({
            "frame": {"seq": 3, "ts_us": 5_000_000, "width": 640, "height": 360},
            "faces": [{"x": 10, "y": 20, "w": 30, "h": 40}],
        });
        let out = from_detections(det.to_string().as_bytes()).expect("annotations");
        let v: Value = serde_json::from_slice(&out).expect("json");
        let face = &v["points"][0];
        assert_eq!(face["type"], 2);
        assert_eq!(face["points"].as_array().map(Vec::len), Some(4));
        assert_eq!(face["points"][2], json!({"x": 40.0, "y": 60.0}));
        assert_eq!(face["timestamp"], json!({"sec": 5, "nsec": 0}));
    }

    #[test]
    fn a_message_that_is_not_detections_has_no_annotations() {
        assert!(from_detections(b"[1,2]").is_none());
    }
}
