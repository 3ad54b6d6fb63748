//! Whether the microphone hears the agent at all, decided in a fraction of a second from the levels alone.
//!
//! Until AEC3 has found an echo the canceller holds the microphone under the agent's level ([`crate::canceller`]):
//! it might be the echo. A page without loudspeakers (headphones, a microphone far away) has none, and a user
//! talking over the agent there should not wait out the hold. An echo follows the reference's rhythm: its 10 ms
//! levels (in dB) rise and fall with the reference's, some delay later, through any room. So the levels of the
//! last second of microphone frames are correlated with the reference's at every delay up to `MAX_LAG`: a high
//! correlation at some delay may be an echo, a low one at every delay (the microphone silent, or a user whose
//! speech has its own rhythm) is none.

use std::collections::VecDeque;

/// Frames (10 ms) the correlation looks back over.
const WINDOW: usize = 100;
/// Delays tried, in frames: the echo's delay behind the reference fed to AEC3 (lead included) up to 500 ms.
const MAX_LAG: usize = 50;
/// Levels are floored here (dBFS): digital silence and the quietest room noise count alike.
const FLOOR_DB: f32 = -70.0;
/// A reference frame louder than this is the agent speaking.
const SPEAKING_DB: f32 = -50.0;
/// Reference frames with speech a delay's correlation needs to count: a third of a second.
const EVIDENCE: usize = 33;
/// A correlation under this at every delay is no echo. Measured on the fixtures (10 ms levels over a second,
/// delays up to 500 ms): a reply against its echo through sox's room at 50-300 ms, -12 and 0 dB, never under 0.81;
/// the reply against four other recordings at most 0.79, under 0.6 nine times in ten.
const NO_ECHO: f64 = 0.6;

/// The levels of the last frames, and the verdict on them.
#[derive(Debug, Default)]
pub struct Presence {
    /// Reference levels, the last `WINDOW + MAX_LAG` frames, oldest first.
    reference: VecDeque<f32>,
    /// Microphone levels, the last `WINDOW` frames, oldest first.
    microphone: VecDeque<f32>,
}

impl Presence {
    /// One frame: the reference level fed with it and the microphone's level (dBFS).
    pub fn frame(&mut self, reference_db: f32, microphone_db: f32) {
        self.reference.push_back(reference_db.max(FLOOR_DB));
        if self.reference.len() > WINDOW + MAX_LAG {
            self.reference.pop_front();
        }
        self.microphone.push_back(microphone_db.max(FLOOR_DB));
        if self.microphone.len() > WINDOW {
            self.microphone.pop_front();
        }
    }

    /// Whether the last second shows no echo: a low correlation at every delay, each with enough of the agent's
    /// speech behind it (until the reference's speech is older than the longest delay, a silent microphone may only
    /// be waiting for the echo).
    pub fn no_echo(&self) -> bool {
        self.correlations()
            .all(|(correlation, speaking)| speaking >= EVIDENCE && correlation < NO_ECHO)
    }

    /// The highest correlation of the microphone's levels with the reference's over the delays tried.
    pub fn best_correlation(&self) -> f64 {
        self.correlations()
            .map(|(correlation, _)| correlation)
            .fold(0.0, f64::max)
    }

    /// For each delay tried: the correlation of the microphone's levels with the reference's that far before
    /// them, and how many of those reference frames had speech.
    fn correlations(&self) -> impl Iterator<Item = (f64, usize)> + '_ {
        let n = self.microphone.len();
        let end = self.reference.len();
        // Microphone frame i (of the last n) came with reference frame `end - n + i`; the echo of reference frame
        // j is heard `lag` frames later. Early in a stream a long delay has fewer pairs.
        (0..=MAX_LAG).map(move |lag| {
            let count = n.min(end.saturating_sub(lag));
            if count < 2 {
                return (0.0, 0);
            }
            let reference = self.reference.range(end - lag - count..end - lag);
            let speaking = reference.clone().filter(|&&db| db > SPEAKING_DB).count();
            (
                pearson(self.microphone.range(n - count..), reference),
                speaking,
            )
        })
    }
}

/// Pearson's correlation of two equally long series (0 when either is flat).
fn pearson<'a>(
    a: impl Iterator<Item = &'a f32> + Clone,
    b: impl Iterator<Item = &'a f32> + Clone,
) -> f64 {
    let (mut n, mut sa, mut sb) = (0.0, 0.0, 0.0);
    for (x, y) in a.clone().zip(b.clone()) {
        n += 1.0;
        sa += f64::from(*x);
        sb += f64::from(*y);
    }
    if n < 2.0 {
        return 0.0;
    }
    let (ma, mb) = (sa / n, sb / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.zip(b) {
        let (dx, dy) = (f64::from(*x) - ma, f64::from(*y) - mb);
        sab += dx * dy;
        saa += dx * dx;
        sbb += dy * dy;
    }
    if saa < 1e-9 || sbb < 1e-9 {
        return 0.0;
    }
    sab / (saa * sbb).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A speech-like level track: syllables of varying length and loudness with pauses, from a seed.
    fn syllables(seed: u32, frames: usize) -> Vec<f32> {
        let mut s = seed;
        let mut next = move || {
            s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (s >> 8) as f32 / (1u32 << 24) as f32
        };
        let mut out = Vec::with_capacity(frames);
        while out.len() < frames {
            let length = 8 + (next() * 20.0) as usize;
            let level = -35.0 + next() * 25.0;
            out.extend(std::iter::repeat_n(level, length));
            let pause = (next() * 12.0) as usize;
            out.extend(std::iter::repeat_n(-70.0, pause));
        }
        out.truncate(frames);
        out
    }

    #[test]
    fn the_echo_of_the_reference_is_never_taken_for_no_echo() {
        let reference = syllables(7, 300);
        let mut presence = Presence::default();
        for (i, &r) in reference.iter().enumerate() {
            // 30 frames later, 12 dB down.
            let echo = if i >= 30 {
                reference[i - 30] - 12.0
            } else {
                -70.0
            };
            presence.frame(r, echo);
            assert!(!presence.no_echo(), "at frame {i}");
        }
        assert!(presence.best_correlation() > 0.9);
    }

    #[test]
    fn a_user_with_their_own_rhythm_is_no_echo_and_silence_is_none_either() {
        let reference = syllables(7, 300);
        let user = syllables(99, 300);
        let mut talking = Presence::default();
        let mut silent = Presence::default();
        for (&r, &u) in reference.iter().zip(&user) {
            talking.frame(r, u);
            silent.frame(r, -90.0);
        }
        assert!(talking.no_echo(), "{}", talking.best_correlation());
        assert!(silent.no_echo());
    }

    #[test]
    fn without_enough_of_the_agent_speaking_there_is_no_verdict() {
        let mut presence = Presence::default();
        for _ in 0..200 {
            presence.frame(-90.0, -20.0);
        }
        assert!(!presence.no_echo());
    }
}
