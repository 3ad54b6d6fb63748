//! De-duplication of decoded codes: a code held in front of the camera is decoded on many consecutive frames, but
//! it is one *appearance* and must be reported once. A code counts as gone after it has not been decoded for
//! `forget_after_us`; the next sighting starts a new appearance.

use std::collections::HashMap;

use crate::codes::{DecodedCode, Symbology};

/// A decoded code together with whether this frame is the first of its appearance.
#[derive(Debug, Clone, PartialEq)]
pub struct SeenCode {
    pub code: DecodedCode,
    /// True only on the first frame of an appearance; later frames of the same appearance carry false.
    pub first_sighting: bool,
    /// Counts appearances over the tracker's lifetime, so consumers can tell two appearances apart.
    pub appearance: u64,
}

#[derive(Debug)]
struct Presence {
    last_seen_us: u64,
    appearance: u64,
}

/// Remembers which codes are currently in view.
#[derive(Debug)]
pub struct AppearanceTracker {
    forget_after_us: u64,
    present: HashMap<(Symbology, Vec<u8>), Presence>,
    last_frame_us: Option<u64>,
    appearances: u64,
}

impl AppearanceTracker {
    /// `forget_after_us` bridges frames where a steady code fails to decode (blur, glare) without starting a new
    /// appearance; it should span a few frames at the camera's rate.
    pub fn new(forget_after_us: u64) -> Self {
        Self {
            forget_after_us,
            present: HashMap::new(),
            last_frame_us: None,
            appearances: 0,
        }
    }

    /// Records the codes decoded in the frame taken at `frame_us` and marks the new appearances.
    pub fn observe(&mut self, frame_us: u64, codes: Vec<DecodedCode>) -> Vec<SeenCode> {
        // A clock that runs backwards means the source restarted; old presences say nothing about the new stream.
        if self.last_frame_us.is_some_and(|last| frame_us < last) {
            self.present.clear();
        }
        self.last_frame_us = Some(frame_us);
        let forget_after_us = self.forget_after_us;
        self.present.retain(|_, presence| {
            frame_us.saturating_sub(presence.last_seen_us) <= forget_after_us
        });

        let mut seen = Vec::with_capacity(codes.len());
        for code in codes {
            let key = (code.symbology, code.bytes.clone());
            // A code already in view, or a second copy of a code on the same frame, continues its appearance.
            if let Some(presence) = self.present.get_mut(&key) {
                presence.last_seen_us = frame_us;
                seen.push(SeenCode {
                    code,
                    first_sighting: false,
                    appearance: presence.appearance,
                });
                continue;
            }
            self.appearances += 1;
            self.present.insert(
                key,
                Presence {
                    last_seen_us: frame_us,
                    appearance: self.appearances,
                },
            );
            seen.push(SeenCode {
                code,
                first_sighting: true,
                appearance: self.appearances,
            });
        }
        seen
    }

    /// Number of codes currently considered in view.
    pub fn in_view(&self) -> usize {
        self.present.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::PointPx;

    fn qr(text: &str) -> DecodedCode {
        DecodedCode {
            symbology: Symbology::Qr,
            bytes: text.as_bytes().to_vec(),
            polygon: vec![PointPx { x: 0.0, y: 0.0 }],
        }
    }

    const FRAME_US: u64 = 66_667;

    #[test]
    fn steady_code_is_new_once() {
        let mut tracker = AppearanceTracker::new(1_000_000);
        let firsts: usize = (0..30)
            .map(|i| {
                tracker
                    .observe(i * FRAME_US, vec![qr("a")])
                    .iter()
                    .filter(|s| s.first_sighting)
                    .count()
            })
            .sum();
        assert_eq!(firsts, 1);
    }

    #[test]
    fn short_dropout_is_bridged_long_absence_is_not() {
        let mut tracker = AppearanceTracker::new(500_000);
        assert!(tracker.observe(0, vec![qr("a")])[0].first_sighting);
        assert!(tracker.observe(FRAME_US, vec![]).is_empty());
        assert!(!tracker.observe(2 * FRAME_US, vec![qr("a")])[0].first_sighting);
        assert!(tracker.observe(2 * FRAME_US + 600_000, vec![]).is_empty());
        let again = tracker.observe(2 * FRAME_US + 700_000, vec![qr("a")]);
        assert!(again[0].first_sighting);
        assert_eq!(again[0].appearance, 2);
    }

    #[test]
    fn two_codes_and_duplicates_in_one_frame() {
        let mut tracker = AppearanceTracker::new(500_000);
        let seen = tracker.observe(0, vec![qr("a"), qr("b"), qr("a")]);
        let firsts: Vec<bool> = seen.iter().map(|s| s.first_sighting).collect();
        assert_eq!(firsts, vec![true, true, false]);
        assert_eq!(tracker.in_view(), 2);
    }

    #[test]
    fn clock_going_back_starts_over() {
        let mut tracker = AppearanceTracker::new(500_000);
        tracker.observe(10_000_000, vec![qr("a")]);
        assert!(tracker.observe(0, vec![qr("a")])[0].first_sighting);
    }
}
