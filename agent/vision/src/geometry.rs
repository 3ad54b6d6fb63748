//! Plain geometry in frame pixels shared by every detector: boxes, points and the overlap measure used to score
//! face detections.

/// An axis-aligned box in frame pixels, origin top-left.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BoxPx {
    pub x: i32,
    pub y: i32,
    pub width: i32,
    pub height: i32,
}

/// The face analyser takes its boxes in the same frame pixels.
impl From<BoxPx> for agent_face::FaceBox {
    fn from(b: BoxPx) -> Self {
        Self {
            x: b.x,
            y: b.y,
            width: b.width,
            height: b.height,
        }
    }
}

impl BoxPx {
    pub fn area(&self) -> i64 {
        i64::from(self.width.max(0)) * i64::from(self.height.max(0))
    }

    pub fn centre(&self) -> PointPx {
        PointPx {
            x: self.x as f32 + self.width as f32 / 2.0,
            y: self.y as f32 + self.height as f32 / 2.0,
        }
    }

    /// Area shared with `other`.
    pub fn intersection_area(&self, other: &BoxPx) -> i64 {
        let left = self.x.max(other.x);
        let top = self.y.max(other.y);
        let right = (self.x + self.width).min(other.x + other.width);
        let bottom = (self.y + self.height).min(other.y + other.height);
        i64::from((right - left).max(0)) * i64::from((bottom - top).max(0))
    }

    /// Intersection over union; 0 when either box is empty.
    pub fn iou(&self, other: &BoxPx) -> f64 {
        let intersection = self.intersection_area(other);
        let union = self.area() + other.area() - intersection;
        if union <= 0 {
            0.0
        } else {
            intersection as f64 / union as f64
        }
    }

    /// Maps a box found on a resized image back to the original frame (`factor` = detection size / frame size).
    pub fn unscale(&self, factor: f64) -> BoxPx {
        let back = |v: i32| (f64::from(v) / factor).round() as i32;
        BoxPx {
            x: back(self.x),
            y: back(self.y),
            width: back(self.width),
            height: back(self.height),
        }
    }
}

/// A point in frame pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointPx {
    pub x: f32,
    pub y: f32,
}

/// Frame dimensions in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameSize {
    pub width: u32,
    pub height: u32,
}

impl FrameSize {
    /// Maps a pixel position to [-1, 1] on both axes, (0, 0) being the frame centre and +y pointing down.
    pub fn normalise(&self, point: PointPx) -> (f32, f32) {
        let half_w = self.width as f32 / 2.0;
        let half_h = self.height as f32 / 2.0;
        (
            ((point.x - half_w) / half_w).clamp(-1.0, 1.0),
            ((point.y - half_h) / half_h).clamp(-1.0, 1.0),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iou_of_identical_and_disjoint_boxes() {
        let a = BoxPx {
            x: 10,
            y: 10,
            width: 20,
            height: 20,
        };
        let b = BoxPx {
            x: 40,
            y: 40,
            width: 5,
            height: 5,
        };
        assert!((a.iou(&a) - 1.0).abs() < 1e-9);
        assert_eq!(a.iou(&b), 0.0);
    }

    #[test]
    fn iou_of_half_overlap() {
        let a = BoxPx {
            x: 0,
            y: 0,
            width: 10,
            height: 10,
        };
        let b = BoxPx {
            x: 5,
            y: 0,
            width: 10,
            height: 10,
        };
        assert!((a.iou(&b) - 50.0 / 150.0).abs() < 1e-9);
    }

    #[test]
    fn normalise_maps_corners_and_centre() {
        let size = FrameSize {
            width: 640,
            height: 360,
        };
        assert_eq!(size.normalise(PointPx { x: 320.0, y: 180.0 }), (0.0, 0.0));
        assert_eq!(size.normalise(PointPx { x: 0.0, y: 360.0 }), (-1.0, 1.0));
    }
}
