//! The 68 face landmarks in the iBUG 300-W order that dlib's shape predictor gives: jaw 0-16, brows 17-26, nose
//! 27-35, the eyes 36-41 (the person's right, on the image's left) and 42-47, the lips' outline 48-59 and their
//! inner edge 60-67.

/// How many points a face has.
pub const LANDMARKS: usize = 68;

/// A point in frame pixels.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Point {
    pub x: f32,
    pub y: f32,
}

impl Point {
    pub fn distance(self, other: Point) -> f32 {
        (self.x - other.x).hypot(self.y - other.y)
    }

    pub fn midpoint(self, other: Point) -> Point {
        Point {
            x: (self.x + other.x) / 2.0,
            y: (self.y + other.y) / 2.0,
        }
    }
}

/// Indices of the points the measures use.
pub mod index {
    pub const JAW_RIGHT: usize = 0;
    pub const CHIN: usize = 8;
    pub const JAW_LEFT: usize = 16;
    pub const NOSE_TIP: usize = 30;
    pub const RIGHT_EYE: std::ops::Range<usize> = 36..42;
    pub const LEFT_EYE: std::ops::Range<usize> = 42..48;
    pub const RIGHT_EYE_OUTER: usize = 36;
    pub const LEFT_EYE_OUTER: usize = 45;
    pub const MOUTH_RIGHT: usize = 48;
    pub const UPPER_LIP_TOP: usize = 51;
    pub const MOUTH_LEFT: usize = 54;
    pub const LOWER_LIP_BOTTOM: usize = 57;
    pub const INNER_UPPER: [usize; 3] = [61, 62, 63];
    pub const INNER_LOWER: [usize; 3] = [67, 66, 65];
}

/// One face's 68 points.
#[derive(Debug, Clone, PartialEq)]
pub struct Landmarks {
    points: [Point; LANDMARKS],
}

impl Landmarks {
    pub fn new(points: [Point; LANDMARKS]) -> Self {
        Self { points }
    }

    /// From x0, y0, x1, y1, ...
    pub(crate) fn from_xy(xy: &[f32; 2 * LANDMARKS]) -> Self {
        let mut points = [Point::default(); LANDMARKS];
        for (point, pair) in points.iter_mut().zip(xy.chunks_exact(2)) {
            *point = Point {
                x: pair[0],
                y: pair[1],
            };
        }
        Self { points }
    }

    pub(crate) fn to_xy(&self) -> [f32; 2 * LANDMARKS] {
        let mut xy = [0f32; 2 * LANDMARKS];
        for (pair, point) in xy.chunks_exact_mut(2).zip(&self.points) {
            pair[0] = point.x;
            pair[1] = point.y;
        }
        xy
    }

    pub fn point(&self, i: usize) -> Point {
        self.points[i % LANDMARKS]
    }

    pub fn points(&self) -> &[Point; LANDMARKS] {
        &self.points
    }

    /// The box around every point.
    pub fn bounds(&self) -> (Point, Point) {
        self.points.iter().fold(
            (
                Point {
                    x: f32::MAX,
                    y: f32::MAX,
                },
                Point {
                    x: f32::MIN,
                    y: f32::MIN,
                },
            ),
            |(low, high), p| {
                (
                    Point {
                        x: low.x.min(p.x),
                        y: low.y.min(p.y),
                    },
                    Point {
                        x: high.x.max(p.x),
                        y: high.y.max(p.y),
                    },
                )
            },
        )
    }
}
