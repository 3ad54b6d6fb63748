//! Who is talking: the face whose mouth moves most while a voice is heard. Pure logic over each face's recent mouth
//! openness and the voice activity, fed once per processed frame.
//!
//! A mouth that talks opens and closes several times a second, so its openness varies; a mouth at rest, or one that
//! only smiles, stays put. The movement is the spread (standard deviation) of a face's mouth openness over the last
//! `window_us`. While a voice is heard the speaker is the face that moves most, if it moves at least
//! `min_movement`; the one already speaking keeps the turn unless another moves `switch_margin` times more. When the
//! voice stops the speaker is held for `hold_us` (pauses between words), then there is none.

use std::collections::VecDeque;

/// Tuning of the choice.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeakerParams {
    pub window_us: u64,
    /// The least spread of mouth openness (in eye distances) that counts as talking.
    pub min_movement: f32,
    pub switch_margin: f32,
    pub hold_us: u64,
}

impl Default for SpeakerParams {
    fn default() -> Self {
        Self {
            window_us: 500_000,
            min_movement: 0.02,
            switch_margin: 1.3,
            hold_us: 600_000,
        }
    }
}

/// The fewest samples the movement is measured on: a module that processes few frames a second (a busy machine
/// skips frames) reaches further back than the window for them, up to [`MAX_REACH`] windows.
const MIN_SAMPLES: usize = 4;
const MAX_REACH: u64 = 3;

/// One face's mouth openness over the last window.
#[derive(Debug, Clone, Default)]
pub struct MouthHistory {
    samples: VecDeque<(u64, f32)>,
}

impl MouthHistory {
    pub fn push(&mut self, at_us: u64, mouth_open: f32, window_us: u64) {
        self.samples.push_back((at_us, mouth_open));
        while self.samples.front().is_some_and(|&(t, _)| {
            let age = at_us.saturating_sub(t);
            age > window_us * MAX_REACH || (age > window_us && self.samples.len() > MIN_SAMPLES)
        }) {
            self.samples.pop_front();
        }
    }

    /// The spread of the openness in the window; 0 with fewer than three samples.
    pub fn movement(&self) -> f32 {
        let n = self.samples.len();
        if n < 3 {
            return 0.0;
        }
        let mean = self.samples.iter().map(|&(_, m)| m).sum::<f32>() / n as f32;
        let variance = self
            .samples
            .iter()
            .map(|&(_, m)| (m - mean) * (m - mean))
            .sum::<f32>()
            / n as f32;
        variance.sqrt()
    }
}

/// The choice across frames.
#[derive(Debug, Clone)]
pub struct SpeakerChoice {
    params: SpeakerParams,
    current: Option<u64>,
    voice: bool,
    last_voice_us: Option<u64>,
}

impl SpeakerChoice {
    pub fn new(params: SpeakerParams) -> Self {
        Self {
            params,
            current: None,
            voice: false,
            last_voice_us: None,
        }
    }

    pub fn params(&self) -> &SpeakerParams {
        &self.params
    }

    /// Whether a voice is heard now (the user's voice activity: `{"vad": "start"}` to `{"vad": "end"}`).
    pub fn set_voice(&mut self, active: bool) {
        self.voice = active;
    }

    /// The speaker among `faces` (each face's id and mouth movement) at `now_us`, a frame's time.
    pub fn update(&mut self, now_us: u64, faces: &[(u64, f32)]) -> Option<u64> {
        if self.voice {
            self.last_voice_us = Some(now_us);
            let best = faces
                .iter()
                .copied()
                .filter(|&(_, movement)| movement >= self.params.min_movement)
                .max_by(|a, b| a.1.total_cmp(&b.1));
            let current = self
                .current
                .and_then(|id| faces.iter().find(|&&(face, _)| face == id).copied());
            self.current = match (current, best) {
                (Some((id, kept)), Some((_, other)))
                    if kept >= self.params.min_movement
                        && kept * self.params.switch_margin >= other =>
                {
                    Some(id)
                }
                (_, Some((id, _))) => Some(id),
                // Nobody's mouth moves: the voice is someone out of view, or the mouth is hidden for a moment.
                (Some((id, _)), None) => Some(id),
                (None, None) => None,
            };
        } else {
            let held = self
                .last_voice_us
                .is_some_and(|last| now_us.saturating_sub(last) <= self.params.hold_us);
            let present = self
                .current
                .is_some_and(|id| faces.iter().any(|&(face, _)| face == id));
            if !held || !present {
                self.current = None;
            }
        }
        self.current
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FRAME: u64 = 66_667;

    /// A talking mouth: open and closed in turn.
    fn talking(i: u64) -> f32 {
        if i % 4 < 2 { 0.25 } else { 0.02 }
    }

    #[test]
    fn a_resting_mouth_does_not_move_and_a_talking_one_does() {
        let mut rest = MouthHistory::default();
        let mut talk = MouthHistory::default();
        for i in 0..15 {
            rest.push(i * FRAME, 0.03, 1_000_000);
            talk.push(i * FRAME, talking(i), 1_000_000);
        }
        assert!(rest.movement() < 1e-6);
        assert!(talk.movement() > 0.1, "{}", talk.movement());
    }

    #[test]
    fn a_slow_frame_rate_still_gives_enough_samples_but_not_old_ones() {
        let mut h = MouthHistory::default();
        // Four frames a second: the last four samples reach back 750 ms, past the 500 ms window.
        for i in 0..8 {
            h.push(i * 250_000, talking(i), 500_000);
        }
        assert_eq!(h.samples.len(), MIN_SAMPLES);
        assert!(h.movement() > 0.05, "{}", h.movement());
        // One frame in two seconds: samples older than three windows go whatever their number.
        h.push(10_000_000, 0.0, 500_000);
        assert_eq!(h.samples.len(), 1);
    }

    #[test]
    fn the_history_keeps_only_the_window() {
        let mut h = MouthHistory::default();
        for i in 0..10 {
            h.push(i * FRAME, talking(i), 1_000_000);
        }
        // Two seconds of rest push the talking out.
        for i in 10..40 {
            h.push(i * FRAME, 0.02, 1_000_000);
        }
        assert!(h.movement() < 1e-6);
    }

    #[test]
    fn the_speaker_is_the_moving_mouth_while_a_voice_is_heard_and_switches_with_the_turn() {
        let mut choice = SpeakerChoice::new(SpeakerParams::default());
        // No voice: nobody speaks, however the mouths move.
        assert_eq!(choice.update(0, &[(1, 0.1), (2, 0.0)]), None);
        choice.set_voice(true);
        assert_eq!(choice.update(FRAME, &[(1, 0.1), (2, 0.0)]), Some(1));
        // The other one moves a little more: the turn stays.
        assert_eq!(choice.update(2 * FRAME, &[(1, 0.1), (2, 0.12)]), Some(1));
        // Now clearly the other one.
        assert_eq!(choice.update(3 * FRAME, &[(1, 0.01), (2, 0.12)]), Some(2));
    }

    #[test]
    fn the_speaker_is_held_over_a_short_pause_and_dropped_after() {
        let mut choice = SpeakerChoice::new(SpeakerParams::default());
        choice.set_voice(true);
        assert_eq!(choice.update(0, &[(1, 0.1)]), Some(1));
        choice.set_voice(false);
        assert_eq!(choice.update(300_000, &[(1, 0.1)]), Some(1));
        assert_eq!(choice.update(700_000, &[(1, 0.1)]), None);
    }

    #[test]
    fn a_face_that_leaves_is_no_longer_the_speaker() {
        let mut choice = SpeakerChoice::new(SpeakerParams::default());
        choice.set_voice(true);
        assert_eq!(choice.update(0, &[(1, 0.1)]), Some(1));
        choice.set_voice(false);
        assert_eq!(choice.update(FRAME, &[(2, 0.0)]), None);
    }

    #[test]
    fn a_voice_with_no_moving_mouth_names_nobody() {
        let mut choice = SpeakerChoice::new(SpeakerParams::default());
        choice.set_voice(true);
        assert_eq!(choice.update(0, &[(1, 0.001), (2, 0.0)]), None);
    }
}
