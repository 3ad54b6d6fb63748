//! The gaze target policy: look at the person talking, else the largest / most central face, else at the centre of
//! motion, else go idle; smoothed so the avatar's eyes glide instead of jittering with every detection.

use crate::geometry::{BoxPx, FrameSize, PointPx};

/// What the avatar is looking at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GazeSource {
    Face,
    Motion,
    Idle,
}

/// A gaze target in normalised image coordinates: x and y in [0, 1], (0, 0) the top-left corner of the camera image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GazeTarget {
    pub x: f32,
    pub y: f32,
    pub source: GazeSource,
}

/// Tuning of the policy.
#[derive(Debug, Clone, PartialEq)]
pub struct GazeParams {
    /// Time constant of the exponential smoothing; about 63% of a jump is followed within it.
    pub smoothing_us: u64,
    /// A new face must score this many times better than the one being watched before the gaze switches, so two
    /// similar faces do not make the eyes flip back and forth.
    pub switch_margin: f32,
    /// Raw target moves smaller than this (normalised units) are ignored; detection boxes wobble by a few pixels.
    pub deadband: f32,
    /// How long the last target is held after faces and motion vanish before the gaze goes idle.
    pub hold_us: u64,
}

impl Default for GazeParams {
    fn default() -> Self {
        Self {
            smoothing_us: 150_000,
            switch_margin: 1.3,
            deadband: 0.01,
            hold_us: 1_000_000,
        }
    }
}

/// Stateful gaze policy fed once per processed frame.
#[derive(Debug)]
pub struct GazePolicy {
    params: GazeParams,
    watched_face: Option<BoxPx>,
    /// The speaker's face for the next update (see [`GazePolicy::prefer`]).
    preferred: Option<BoxPx>,
    raw: Option<(f32, f32, GazeSource)>,
    smoothed: (f32, f32),
    last_evidence_us: Option<u64>,
    last_update_us: Option<u64>,
}

impl GazePolicy {
    pub fn new(params: GazeParams) -> Self {
        Self {
            params,
            watched_face: None,
            preferred: None,
            raw: None,
            smoothed: (0.5, 0.5),
            last_evidence_us: None,
            last_update_us: None,
        }
    }

    /// Looks at `face` (the person talking) in the next update, whatever the other faces score; it becomes the
    /// watched face, so the gaze stays there after the talk until another face beats it by `switch_margin`.
    pub fn prefer(&mut self, face: Option<BoxPx>) {
        self.preferred = face;
    }

    /// Updates the policy with one frame's faces and centre of motion and returns the smoothed target.
    pub fn update(
        &mut self,
        frame_us: u64,
        size: FrameSize,
        faces: &[BoxPx],
        motion: Option<PointPx>,
    ) -> GazeTarget {
        if self.last_update_us.is_some_and(|last| frame_us < last) {
            // The source restarted; do not let a negative time step confuse the smoothing.
            *self = Self::new(self.params.clone());
        }
        let wanted = match self.choose_face(size, faces) {
            Some(face) => Some((to_unit(size, face.centre()), GazeSource::Face)),
            None => motion.map(|centre| (to_unit(size, centre), GazeSource::Motion)),
        };
        match wanted {
            Some(((x, y), source)) => {
                self.last_evidence_us = Some(frame_us);
                let moved_enough = self.raw.is_none_or(|(rx, ry, rsource)| {
                    rsource != source
                        || (rx - x).abs() > self.params.deadband
                        || (ry - y).abs() > self.params.deadband
                });
                if moved_enough {
                    self.raw = Some((x, y, source));
                }
            }
            None => {
                let held = self
                    .last_evidence_us
                    .is_some_and(|last| frame_us.saturating_sub(last) <= self.params.hold_us);
                if !held {
                    self.raw = None;
                    self.watched_face = None;
                }
            }
        }
        let (goal_x, goal_y, source) = self.raw.unwrap_or((0.5, 0.5, GazeSource::Idle));
        let dt_us = self
            .last_update_us
            .map_or(u64::MAX, |last| frame_us.saturating_sub(last));
        self.last_update_us = Some(frame_us);
        let follow = if dt_us == u64::MAX || self.params.smoothing_us == 0 {
            1.0
        } else {
            1.0 - (-(dt_us as f64) / self.params.smoothing_us as f64).exp() as f32
        };
        self.smoothed.0 += (goal_x - self.smoothed.0) * follow;
        self.smoothed.1 += (goal_y - self.smoothed.1) * follow;
        GazeTarget {
            x: self.smoothed.0,
            y: self.smoothed.1,
            source,
        }
    }

    /// Picks the face to watch: the preferred one (the speaker) when there is one, else the best score (area weighted by closeness to the centre), but the face already
    /// being watched keeps the gaze unless another beats it by `switch_margin`.
    fn choose_face(&mut self, size: FrameSize, faces: &[BoxPx]) -> Option<BoxPx> {
        if let Some(speaker) = self.preferred.take() {
            self.watched_face = Some(speaker);
            return Some(speaker);
        }
        let score = |face: &BoxPx| {
            let (nx, ny) = size.normalise(face.centre());
            let distance = (nx * nx + ny * ny).sqrt() / std::f32::consts::SQRT_2;
            face.area() as f32 * (1.0 - 0.5 * distance)
        };
        let best = faces
            .iter()
            .copied()
            .max_by(|a, b| score(a).total_cmp(&score(b)))?;
        let previous = self.watched_face.and_then(|watched| {
            faces
                .iter()
                .copied()
                .filter(|face| face.iou(&watched) > 0.2)
                .max_by(|a, b| a.iou(&watched).total_cmp(&b.iou(&watched)))
        });
        let chosen = match previous {
            Some(previous) if score(&best) < score(&previous) * self.params.switch_margin => {
                previous
            }
            _ => best,
        };
        self.watched_face = Some(chosen);
        Some(chosen)
    }
}

fn to_unit(size: FrameSize, point: PointPx) -> (f32, f32) {
    let (nx, ny) = size.normalise(point);
    ((nx + 1.0) / 2.0, (ny + 1.0) / 2.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIZE: FrameSize = FrameSize {
        width: 640,
        height: 360,
    };
    const FRAME_US: u64 = 66_667;

    fn face(x: i32, y: i32, side: i32) -> BoxPx {
        BoxPx {
            x,
            y,
            width: side,
            height: side,
        }
    }

    #[test]
    fn prefers_large_central_face_over_motion() {
        let mut policy = GazePolicy::new(GazeParams {
            smoothing_us: 0,
            ..GazeParams::default()
        });
        let faces = [face(0, 0, 40), face(280, 140, 80)];
        let target = policy.update(0, SIZE, &faces, Some(PointPx { x: 600.0, y: 300.0 }));
        assert_eq!(target.source, GazeSource::Face);
        assert!(
            (target.x - 0.5).abs() < 0.01 && (target.y - 0.5).abs() < 0.01,
            "{target:?}"
        );
    }

    #[test]
    fn falls_back_to_motion_then_idle_after_hold() {
        let mut policy = GazePolicy::new(GazeParams {
            smoothing_us: 0,
            hold_us: 200_000,
            ..GazeParams::default()
        });
        let target = policy.update(0, SIZE, &[], Some(PointPx { x: 640.0, y: 0.0 }));
        assert_eq!(
            (target.x, target.y, target.source),
            (1.0, 0.0, GazeSource::Motion)
        );
        let held = policy.update(FRAME_US, SIZE, &[], None);
        assert_eq!(held.source, GazeSource::Motion);
        let idle = policy.update(300_000, SIZE, &[], None);
        assert_eq!((idle.x, idle.y, idle.source), (0.5, 0.5, GazeSource::Idle));
    }

    #[test]
    fn smoothing_glides_and_deadband_ignores_wobble() {
        let mut policy = GazePolicy::new(GazeParams::default());
        policy.update(0, SIZE, &[], None);
        let first = policy.update(FRAME_US, SIZE, &[face(560, 150, 60)], None);
        assert!(
            first.x > 0.5 && first.x < 0.85,
            "one frame moves part of the way: {first:?}"
        );
        let mut last = first;
        for i in 2..40 {
            // The detected box wobbles by two pixels; the target must converge regardless.
            last = policy.update(
                i * FRAME_US,
                SIZE,
                &[face(560 + (i as i32 % 2) * 2, 150, 60)],
                None,
            );
        }
        assert!((last.x - 590.0 / 640.0).abs() < 0.01, "{last:?}");
    }

    #[test]
    fn keeps_watched_face_unless_clearly_beaten() {
        let mut policy = GazePolicy::new(GazeParams {
            smoothing_us: 0,
            ..GazeParams::default()
        });
        let left = face(100, 150, 60);
        let right = face(480, 150, 60);
        let first = policy.update(0, SIZE, &[left], None);
        assert!(first.x < 0.5);
        // A similar face appears: stay on the first one.
        let second = policy.update(FRAME_US, SIZE, &[left, face(480, 150, 64)], None);
        assert!(second.x < 0.5, "{second:?}");
        // A much larger face wins.
        let third = policy.update(
            2 * FRAME_US,
            SIZE,
            &[
                left,
                BoxPx {
                    width: 120,
                    height: 120,
                    ..right
                },
            ],
            None,
        );
        assert!(third.x > 0.5, "{third:?}");
    }

    #[test]
    fn the_speaker_takes_the_gaze_from_a_larger_face() {
        let mut policy = GazePolicy::new(GazeParams {
            smoothing_us: 0,
            ..GazeParams::default()
        });
        let large = face(60, 100, 140);
        let small = face(500, 150, 50);
        let first = policy.update(0, SIZE, &[large, small], None);
        assert!(first.x < 0.5, "{first:?}");
        policy.prefer(Some(small));
        let speaking = policy.update(FRAME_US, SIZE, &[large, small], None);
        assert!(speaking.x > 0.75, "{speaking:?}");
    }
}
