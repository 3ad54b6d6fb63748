//! A voice that began before the agent's cannot be its echo.
//!
//! While AEC3 has not found the echo yet the canceller holds the microphone under the agent's level
//! ([`crate::canceller`]). A user who was already talking when the agent began (the reply to their last sentence
//! starting while they go on, tests/asr.rs's recordings back to back) is not the agent's echo, however quiet: so
//! the microphone's voice is followed on its own, as a run of frames over the room's noise with gaps shorter than
//! a pause between sentences, and a run that began before the agent's speech did passes the hold, unless the agent
//! had spoken within the echo's reach before it began (the echo of one sentence runs on over the pause before the
//! next: tests/conversation.rs's Piper reply).

/// A frame this far over the room's noise is voice (dB).
const OVER_NOISE_DB: f32 = 12.0;
/// And never quieter than this (dBFS): digital silence has no noise to stand over.
const QUIETEST_VOICE_DB: f32 = -55.0;
/// The noise estimate follows quieter frames at once and louder ones this slowly (dB per 10 ms frame).
const NOISE_RISE_DB: f32 = 0.05;
/// A gap this long ends a run of voice, or a run of the agent's speech (µs).
const GAP_US: u64 = 300_000;
/// How long after the agent's speech its echo may still be heard: the longest delay and the room's tail (µs).
const ECHO_REACH_US: u64 = 700_000;

/// The microphone's current run of voice and the agent's current run of speech, on the microphone's clock.
#[derive(Debug, Default)]
pub struct Onsets {
    noise_db: Option<f32>,
    /// (first, last) frame time of the microphone's current run of voice.
    voice: Option<(u64, u64)>,
    /// Whether the current run of voice began out of reach of any earlier speech of the agent's.
    voice_clear: bool,
    /// (first, last) time of the agent's current run of speech, as the microphone would hear it earliest.
    speech: Option<(u64, u64)>,
}

impl Onsets {
    /// The frame captured at `at_us` with `mic_db`; `speaking_at_us` is when the agent's speech in this frame's
    /// reference plays, if it has any. Returns whether the microphone's voice began before the agent's speech.
    pub fn frame(&mut self, at_us: u64, mic_db: f32, speaking_at_us: Option<u64>) -> bool {
        let noise = self
            .noise_db
            .map_or(mic_db, |n| mic_db.min(n + NOISE_RISE_DB));
        self.noise_db = Some(noise);
        let voiced = mic_db > (noise + OVER_NOISE_DB).max(QUIETEST_VOICE_DB);
        let voice = extend(self.voice, voiced.then_some(at_us), at_us);
        if let Some((first, _)) = voice
            && self.voice.is_none_or(|(old, _)| old != first)
        {
            // A new run: clear if the agent's last speech is out of the echo's reach.
            self.voice_clear = self
                .speech
                .is_none_or(|(_, last)| last + ECHO_REACH_US < first);
        }
        self.voice = voice;
        self.speech = extend(self.speech, speaking_at_us, at_us);
        match (self.voice, self.speech) {
            (Some((voice, _)), Some((speech, _))) => self.voice_clear && voice < speech,
            _ => false,
        }
    }
}

/// A run continued by `event`, or ended by a gap longer than `GAP_US` before `now_us`.
fn extend(run: Option<(u64, u64)>, event: Option<u64>, now_us: u64) -> Option<(u64, u64)> {
    match (run, event) {
        (Some((first, last)), Some(at)) if at <= last + GAP_US => Some((first, at.max(last))),
        (_, Some(at)) => Some((at, at)),
        (Some((first, last)), None) if now_us <= last + GAP_US => Some((first, last)),
        (_, None) => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Onsets that have heard the first second of a quiet room (-60 dB) with the agent silent, none of it early.
    fn after_a_quiet_second() -> Onsets {
        let mut onsets = Onsets::default();
        for k in 0..100u64 {
            assert!(!onsets.frame(k * 10_000, -60.0, None));
        }
        onsets
    }

    #[test]
    fn a_voice_under_way_when_the_agent_begins_is_the_users() {
        // Room noise, then the user talks from 1 s on, with short gaps between words.
        let mut onsets = after_a_quiet_second();
        for k in 100..400u64 {
            let level = if k % 30 < 25 { -25.0 } else { -60.0 };
            // The agent starts at 2 s.
            let speaking = (k >= 200).then_some(k * 10_000);
            let earlier = onsets.frame(k * 10_000, level, speaking);
            assert_eq!(earlier, k >= 200, "at frame {k}");
        }
    }

    #[test]
    fn a_voice_that_starts_after_the_agent_may_be_its_echo() {
        let mut onsets = after_a_quiet_second();
        // The agent from 1 s on, a loud microphone 300 ms later.
        for k in 100..300u64 {
            let level = if k >= 130 { -20.0 } else { -60.0 };
            assert!(
                !onsets.frame(k * 10_000, level, Some(k * 10_000)),
                "at frame {k}"
            );
        }
    }

    #[test]
    fn the_echo_of_a_sentence_running_on_into_the_next_is_not_the_users() {
        let mut onsets = after_a_quiet_second();
        // The agent's first sentence from 1 s to 2 s, its echo from 1.1 s to 2.3 s; the next sentence at 2.4 s.
        for k in 100..400u64 {
            let speaking = ((100..200).contains(&k) || k >= 240).then_some(k * 10_000);
            let level = if (110..230).contains(&k) || k >= 250 {
                -20.0
            } else {
                -60.0
            };
            assert!(!onsets.frame(k * 10_000, level, speaking), "at frame {k}");
        }
    }

    #[test]
    fn after_a_pause_the_users_next_sentence_is_not_early_any_more() {
        let mut onsets = Onsets::default();
        for k in 0..100u64 {
            onsets.frame(k * 10_000, if k >= 50 { -25.0 } else { -60.0 }, None);
        }
        // The agent begins at 0.8 s while the user talks; the user stops at 1 s and starts again at 1.5 s.
        for k in 100..200u64 {
            let level = if k >= 150 { -25.0 } else { -60.0 };
            let earlier = onsets.frame(k * 10_000, level, Some(k * 10_000 - 200_000));
            assert_eq!(earlier, k < 130, "at frame {k}");
        }
    }
}
