//! Real JSON schemas for the agent's vision channels, whose messages the contract defines
//! (`agent_contract::detections`): Foxglove lists their fields for plots and filters. The test below holds each
//! schema to its type: every field the contract serialises is described.

use agent_contract::channels as ch;
use serde_json::{Value, json};

/// The schema of a channel whose message type the contract knows, or `None`.
pub fn for_channel(name: &str) -> Option<String> {
    let (title, schema) = match name {
        n if n == ch::FACES.name => ("agent.FacesMsg", faces()),
        n if n == ch::MOTION.name => ("agent.MotionMsg", motion()),
        n if n == ch::CODES.name => ("agent.CodesMsg", codes()),
        n if n == ch::DETECTIONS.name => ("agent.DetectionsMsg", detections()),
        _ => return None,
    };
    let mut schema = schema;
    schema["title"] = json!(title);
    schema["description"] = json!(format!("{name}: {} (docs/vision.md)", doc(name)));
    Some(schema.to_string())
}

fn doc(name: &str) -> &'static str {
    ch::ALL
        .iter()
        .find(|c| c.name == name)
        .map_or("", |c| c.doc)
}

fn object(properties: Value) -> Value {
    json!({"type": "object", "properties": properties})
}

fn nullable(schema: Value) -> Value {
    json!({"oneOf": [schema, {"type": "null"}]})
}

fn array(items: Value) -> Value {
    json!({"type": "array", "items": items})
}

fn integer() -> Value {
    json!({"type": "integer"})
}

fn number() -> Value {
    json!({"type": "number"})
}

fn frame() -> Value {
    object(json!({"seq": integer(), "ts_us": integer(), "width": integer(), "height": integer()}))
}

fn rect() -> Value {
    object(json!({"x": integer(), "y": integer(), "w": integer(), "h": integer()}))
}

fn point() -> Value {
    object(json!({"x": number(), "y": number()}))
}

fn faces() -> Value {
    object(json!({"frame": frame(), "faces": array(rect()), "scan_cycles": integer()}))
}

fn motion() -> Value {
    object(json!({
        "frame": frame(), "moving": {"type": "boolean"}, "centre": nullable(point()), "regions": array(rect()),
        "changed_fraction": number(), "held": {"type": "boolean"},
    }))
}

fn code() -> Value {
    object(json!({
        "kind": {"type": "string"}, "text": nullable(json!({"type": "string"})), "hex": {"type": "string"},
        "polygon": array(point()), "appearance": integer(), "new": {"type": "boolean"},
    }))
}

fn codes() -> Value {
    object(json!({"frame": frame(), "codes": array(code())}))
}

fn person() -> Value {
    let boolean = json!({"type": "boolean"});
    object(json!({
        "id": integer(), "face": rect(), "mouth_open": number(), "eyes_open": number(), "yaw_deg": number(),
        "pitch_deg": number(), "looking": boolean, "smile": number(), "smiling": boolean, "speaking": boolean,
        "name": nullable(json!({"type": "string"})),
    }))
}

fn detections() -> Value {
    let ms = nullable(number());
    object(json!({
        "frame": frame(),
        "faces": nullable(array(rect())),
        "face_scan_cycles": integer(),
        "people": nullable(array(person())),
        "motion": nullable(motion()),
        "codes": nullable(array(code())),
        "gaze": nullable(object(json!({"x": number(), "y": number(), "source": {"type": "string"}}))),
        "timing": nullable(object(json!({
            "decode_ms": number(), "faces_ms": ms, "people_ms": ms, "motion_ms": ms, "codes_ms": ms, "total_ms": number(),
        }))),
        "counters": nullable(object(json!({"processed": integer(), "skipped": integer(), "bad": integer()}))),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use agent_contract::detections::*;

    /// Every key of `value` is described by `schema`, all the way down.
    fn described(value: &Value, schema: &Value, path: &str) {
        if let Some(options) = schema["oneOf"].as_array() {
            let fits = options.iter().any(|o| match value {
                Value::Null => o["type"] == "null",
                _ => o["type"] != "null",
            });
            assert!(fits, "{path}: {value} fits no option");
            if let Some(o) = options.iter().find(|o| o["type"] != "null")
                && !value.is_null()
            {
                described(value, o, path);
            }
            return;
        }
        match value {
            Value::Object(map) => {
                for (key, v) in map {
                    let sub = &schema["properties"][key];
                    assert!(!sub.is_null(), "{path}.{key} is not in the schema");
                    described(v, sub, &format!("{path}.{key}"));
                }
            }
            Value::Array(items) => {
                for (i, v) in items.iter().enumerate() {
                    described(v, &schema["items"], &format!("{path}[{i}]"));
                }
            }
            _ => {}
        }
    }

    fn sample() -> (FrameRef, BoxMsg, PointMsg, MotionMsg, CodeMsg) {
        let frame = FrameRef {
            seq: 1,
            ts_us: 2,
            width: 640,
            height: 360,
        };
        let rect = BoxMsg {
            x: 1,
            y: 2,
            w: 3,
            h: 4,
        };
        let point = PointMsg { x: 0.5, y: 0.5 };
        let motion = MotionMsg {
            frame: frame.clone(),
            moving: true,
            centre: Some(point),
            regions: vec![rect],
            changed_fraction: 0.1,
            held: false,
        };
        let code = CodeMsg {
            kind: "qr".into(),
            text: Some("hi".into()),
            hex: "6869".into(),
            polygon: vec![point],
            appearance: 1,
            new: true,
        };
        (frame, rect, point, motion, code)
    }

    fn schema(name: &str) -> Value {
        serde_json::from_str(&for_channel(name).expect("a schema")).expect("JSON")
    }

    #[test]
    fn every_field_of_the_vision_messages_is_in_their_schemas() {
        let (frame, rect, point, motion, code) = sample();
        let faces = FacesMsg {
            frame: frame.clone(),
            faces: vec![rect],
            scan_cycles: 3,
        };
        let codes = CodesMsg {
            frame: frame.clone(),
            codes: vec![code.clone()],
        };
        let full = DetectionsMsg {
            frame: frame.clone(),
            faces: Some(vec![rect]),
            face_scan_cycles: 2,
            people: Some(vec![PersonMsg {
                id: 1,
                face: rect,
                mouth_open: 0.2,
                eyes_open: 0.3,
                yaw_deg: 5.0,
                pitch_deg: -3.0,
                looking: true,
                smile: 0.6,
                smiling: true,
                speaking: true,
                name: Some("Anna".into()),
            }]),
            motion: Some(motion.clone()),
            codes: Some(vec![code]),
            gaze: Some(GazeMsg {
                x: point.x,
                y: point.y,
                source: "face".into(),
            }),
            timing: Some(TimingMsg {
                decode_ms: 1.0,
                faces_ms: Some(2.0),
                people_ms: Some(4.0),
                motion_ms: None,
                codes_ms: Some(3.0),
                total_ms: 6.0,
            }),
            counters: Some(CountersMsg::default()),
        };
        let bare = DetectionsMsg {
            frame,
            faces: None,
            face_scan_cycles: 0,
            people: None,
            motion: None,
            codes: None,
            gaze: None,
            timing: None,
            counters: None,
        };
        described(&value(&faces), &schema(ch::FACES.name), "faces");
        described(&value(&motion), &schema(ch::MOTION.name), "motion");
        described(&value(&codes), &schema(ch::CODES.name), "codes");
        described(&value(&full), &schema(ch::DETECTIONS.name), "detections");
        described(&value(&bare), &schema(ch::DETECTIONS.name), "detections");
        assert_eq!(schema(ch::DETECTIONS.name)["title"], "agent.DetectionsMsg");
        assert!(for_channel(ch::RULES.name).is_none());
    }

    fn value<T: serde::Serialize>(message: &T) -> Value {
        serde_json::to_value(message).expect("serialises")
    }
}
