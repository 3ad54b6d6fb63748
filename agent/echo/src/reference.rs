//! The far end: the agent's speech placed on the hub clock where the page plays it.
//!
//! A chunk of `Agent.speech` carries its utterance and sample offset (the channel's `framing`); the page plays an
//! utterance's sample 0 a jitter buffer after its first chunk arrived and every later sample at its offset from
//! there (docs/browser-link.md). When the page says when it began to play an utterance (`Agent.playback`, on the
//! server's clock) that anchor replaces the estimate. Unframed speech (another publisher) plays back to back from
//! when it arrives. A stop (`speech_stop`) ends what was sent ahead: the page fades out over 80 ms from when it
//! hears the stop, so the reference keeps that much, faded the same way.

use std::collections::{HashMap, VecDeque};

use crate::rate::{RATE, samples_us};

/// At most this many utterances' anchors are remembered.
const ANCHORS: usize = 16;
/// The page's fade-out after a stop (`web/js/media/speech.js`).
const STOP_FADE_US: u64 = 80_000;

/// Where a chunk plays.
#[derive(Debug, Clone, Copy)]
enum Place {
    /// Sample `offset` of utterance `utterance`: its anchor plus the offset.
    Framed { utterance: u32, offset: u32 },
    /// At a fixed hub time.
    At(u64),
}

#[derive(Debug)]
struct Chunk {
    place: Place,
    samples: Vec<f32>,
}

/// The agent's speech on the hub clock.
#[derive(Debug)]
pub struct Reference {
    jitter_us: u64,
    /// Hub time at which sample 0 of each utterance plays.
    anchors: HashMap<u32, u64>,
    anchor_order: VecDeque<u32>,
    chunks: VecDeque<Chunk>,
    /// Where unframed speech plays next.
    unframed_end: u64,
}

impl Reference {
    /// A reference whose utterances play `jitter_ms` after their first chunk arrives unless the page says otherwise.
    pub fn new(jitter_ms: u32) -> Self {
        Self {
            jitter_us: u64::from(jitter_ms) * 1000,
            anchors: HashMap::new(),
            anchor_order: VecDeque::new(),
            chunks: VecDeque::new(),
            unframed_end: 0,
        }
    }

    /// A chunk of speech (s16 samples) that reached the hub at `arrival_us`, with its utterance and sample offset
    /// when the channel frames its payloads.
    pub fn speech(&mut self, arrival_us: u64, framing: Option<(u32, u32)>, samples: &[i16]) {
        let place = match framing {
            Some((utterance, offset)) => {
                if !self.anchors.contains_key(&utterance) {
                    let anchor =
                        (arrival_us + self.jitter_us).saturating_sub(samples_us(offset.into()));
                    self.anchor(utterance, anchor);
                }
                Place::Framed { utterance, offset }
            }
            None => {
                let at = self.unframed_end.max(arrival_us + self.jitter_us);
                self.unframed_end = at + samples_us(samples.len() as u64);
                Place::At(at)
            }
        };
        self.chunks.push_back(Chunk {
            place,
            samples: samples.iter().map(|&s| f32::from(s) / 32768.0).collect(),
        });
    }

    /// The page began playing `utterance` at `at_us` (hub clock): its samples move there.
    pub fn played(&mut self, utterance: u32, at_us: u64) {
        self.anchor(utterance, at_us);
    }

    /// The speech was stopped at `at_us`: `utterance` only, or everything when `None`.
    pub fn stopped(&mut self, at_us: u64, utterance: Option<u32>) {
        let end = at_us + STOP_FADE_US;
        let anchors = &self.anchors;
        for chunk in &mut self.chunks {
            if let (Some(u), Place::Framed { utterance: own, .. }) = (utterance, chunk.place)
                && u != own
            {
                continue;
            }
            let Some(start) = start_of(anchors, chunk.place) else {
                continue;
            };
            let keep = if end <= start {
                0
            } else {
                ((end - start) * u64::from(RATE) / 1_000_000) as usize
            };
            chunk.samples.truncate(keep);
            // The fade: gain 1 at `at_us`, 0 at `end`.
            for (i, s) in chunk.samples.iter_mut().enumerate() {
                let t = start + samples_us(i as u64);
                if t > at_us {
                    *s *= (end - t) as f32 / STOP_FADE_US as f32;
                }
            }
        }
        self.chunks.retain(|c| !c.samples.is_empty());
        if utterance.is_none() {
            self.unframed_end = self.unframed_end.min(end);
        }
    }

    /// Writes the speech that plays from `from_us` on into `out` (sample `i` at `from_us + i / RATE`); returns
    /// whether any speech falls in that stretch.
    pub fn render(&self, from_us: u64, out: &mut [f32]) -> bool {
        out.fill(0.0);
        let mut any = false;
        for chunk in &self.chunks {
            let Some(start) = start_of(&self.anchors, chunk.place) else {
                continue;
            };
            // Index into the chunk of `out[0]`, rounded to the nearest sample.
            let shift = ((i128::from(from_us) - i128::from(start)) * i128::from(RATE) + 500_000)
                .div_euclid(1_000_000);
            let len = chunk.samples.len() as i128;
            let lo = (-shift).clamp(0, out.len() as i128) as usize;
            let hi = (len - shift).clamp(0, out.len() as i128) as usize;
            for (i, o) in out.iter_mut().enumerate().take(hi).skip(lo) {
                *o += chunk.samples[(shift + i as i128) as usize];
                any = true;
            }
        }
        any
    }

    /// Forgets speech that finished playing before `us`: the microphone's time only moves forward.
    pub fn forget_before(&mut self, us: u64) {
        let anchors = &self.anchors;
        self.chunks.retain(|c| {
            start_of(anchors, c.place)
                .is_some_and(|start| start + samples_us(c.samples.len() as u64) >= us)
        });
    }

    fn anchor(&mut self, utterance: u32, at_us: u64) {
        if self.anchors.insert(utterance, at_us).is_none() {
            self.anchor_order.push_back(utterance);
        }
        while self.anchor_order.len() > ANCHORS {
            if let Some(old) = self.anchor_order.pop_front() {
                self.anchors.remove(&old);
                self.chunks.retain(
                    |c| !matches!(c.place, Place::Framed { utterance, .. } if utterance == old),
                );
            }
        }
    }
}

/// Hub time of a chunk's first sample.
fn start_of(anchors: &HashMap<u32, u64>, place: Place) -> Option<u64> {
    match place {
        Place::Framed { utterance, offset } => anchors
            .get(&utterance)
            .map(|anchor| anchor + samples_us(offset.into())),
        Place::At(at) => Some(at),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(n: usize, from: i16) -> Vec<i16> {
        (0..n).map(|i| from + i as i16).collect()
    }

    #[test]
    fn speech_plays_a_jitter_buffer_after_its_first_chunk_at_its_offsets() {
        let mut r = Reference::new(60);
        let t0 = 10_000_000;
        // Two 20 ms chunks of utterance 7 arrive at once (sent ahead).
        r.speech(t0, Some((7, 0)), &ramp(441, 1));
        r.speech(t0, Some((7, 441)), &ramp(441, 442));
        let mut out = vec![0.0; 441];
        // Before the jitter buffer: nothing.
        assert!(!r.render(t0, &mut out));
        // From 60 ms on: sample 0 of the utterance, then the rest in order across the chunks' boundary.
        assert!(r.render(t0 + 60_000 + samples_us(400), &mut out));
        let got: Vec<i16> = out.iter().map(|s| (s * 32768.0).round() as i16).collect();
        assert_eq!(got[0], 401);
        assert_eq!(got[100], 501);
        assert_eq!(got[440], 841);
    }

    #[test]
    fn the_pages_playback_moves_the_utterance_and_a_stop_ends_it_with_a_fade() {
        let mut r = Reference::new(60);
        let t0 = 20_000_000;
        for k in 0..50u32 {
            r.speech(t0, Some((3, k * 441)), &[16_384; 441]);
        }
        r.played(3, t0 + 150_000);
        let mut out = vec![0.0; 441];
        assert!(!r.render(t0 + 100_000, &mut out[..100]));
        assert!(r.render(t0 + 150_000, &mut out));
        assert!((out[0] - 0.5).abs() < 1e-6);
        // Stopped 200 ms into the reply: 40 ms later it is half faded, 80 ms later it is gone.
        r.stopped(t0 + 350_000, None);
        r.render(t0 + 390_000, &mut out[..1]);
        assert!((out[0] - 0.25).abs() < 0.01, "{}", out[0]);
        assert!(!r.render(t0 + 431_000, &mut out));
    }

    #[test]
    fn unframed_speech_plays_back_to_back_and_old_speech_is_forgotten() {
        let mut r = Reference::new(0);
        let t0 = 1_000_000;
        r.speech(t0, None, &[100; 441]);
        r.speech(t0, None, &[200; 441]);
        let mut out = vec![0.0; 1];
        r.render(t0 + 30_000, &mut out);
        assert!((out[0] * 32768.0 - 200.0).abs() < 0.5);
        r.forget_before(t0 + 40_001);
        assert!(!r.render(t0 + 30_000, &mut out));
    }
}
