//! Own-voice suppression: remembers what the agent said recently and recognises a transcript that is only the
//! microphone hearing the agent itself (when the browser's echo cancellation fails).

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use crate::phrase::{common_words, normalise};

/// How long espeak-ng takes per word at its default rate (175 words per minute), to estimate when an utterance
/// ends; a transcript of its tail can arrive that long after it started, plus the ASR's own delay.
const SECONDS_PER_WORD: f64 = 60.0 / 175.0;

/// At most this many utterances are remembered; older ones are forgotten first.
const REMEMBERED: usize = 16;

/// The fewest words a transcript must share with an utterance to be taken for its echo (fewer if the utterance
/// itself is shorter): one common word, such as the user's "hello" after the agent's "Hello! How can I help
/// you?", is no evidence of an echo.
const MIN_COMMON_WORDS: usize = 3;

/// Recent utterances of the agent, each with when it may still be heard.
#[derive(Debug, Clone)]
pub struct EchoFilter {
    /// How long after an utterance ends a transcript of it may still arrive.
    window: Duration,
    /// The share of a transcript's words that must come from one utterance for it to count as an echo.
    threshold: f64,
    recent: VecDeque<(Instant, String)>,
}

impl EchoFilter {
    /// `window`: how long after the end of an utterance its echo is expected (ASR latency included);
    /// `threshold`: from 0.0 to 1.0, e.g. 0.6.
    pub fn new(window: Duration, threshold: f64) -> Self {
        EchoFilter {
            window,
            threshold: threshold.clamp(0.0, 1.0),
            recent: VecDeque::new(),
        }
    }

    /// Records that the agent started saying `text` at `at`.
    pub fn said(&mut self, at: Instant, text: &str) {
        let words = normalise(text).len() as f64;
        let until = at + Duration::from_secs_f64(words * SECONDS_PER_WORD) + self.window;
        if self.recent.len() == REMEMBERED {
            self.recent.pop_front();
        }
        self.recent.push_back((until, text.to_owned()));
    }

    /// The recent utterance a transcript heard at `at` echoes, if any: one with which the transcript shares, in
    /// order, at least `threshold` of its own words and at least three words (or all of a shorter utterance).
    pub fn echo_of(&mut self, at: Instant, transcript: &str) -> Option<&str> {
        self.recent.retain(|(until, _)| *until >= at);
        let heard = normalise(transcript);
        if heard.is_empty() {
            return None;
        }
        self.recent
            .iter()
            .rev()
            .find(|(_, said)| {
                let said_words = normalise(said);
                let common = common_words(&heard, &said_words);
                common as f64 >= self.threshold * heard.len() as f64
                    && common >= MIN_COMMON_WORDS.min(said_words.len())
            })
            .map(|(_, said)| said.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drops_what_the_agent_just_said_and_keeps_the_user() {
        let t0 = Instant::now();
        let mut filter = EchoFilter::new(Duration::from_secs(3), 0.6);
        filter.said(t0, "It is quarter past 3 in the afternoon.");
        let soon = t0 + Duration::from_secs(2);
        assert!(
            filter
                .echo_of(soon, "It's a quarter past three in the afternoon")
                .is_some()
        );
        assert!(filter.echo_of(soon, "quarter past three").is_some());
        assert!(filter.echo_of(soon, "what time is it").is_none());
        assert!(filter.echo_of(soon, "how many people do you see").is_none());
    }

    #[test]
    fn one_common_word_is_not_an_echo_unless_that_was_all_the_agent_said() {
        let t0 = Instant::now();
        let mut filter = EchoFilter::new(Duration::from_secs(3), 0.6);
        filter.said(t0, "Hello! How can I help you?");
        assert!(filter.echo_of(t0, "hello").is_none());
        assert!(filter.echo_of(t0, "help you").is_none());
        assert!(filter.echo_of(t0, "can I help you").is_some());
        filter.said(t0, "Okay.");
        assert!(filter.echo_of(t0, "okay").is_some());
    }

    #[test]
    fn forgets_after_the_window() {
        let t0 = Instant::now();
        let mut filter = EchoFilter::new(Duration::from_secs(3), 0.6);
        filter.said(t0, "Hello! How can I help you?");
        // Six words take about two seconds to say; three more seconds of window.
        assert!(
            filter
                .echo_of(t0 + Duration::from_secs(4), "how can I help you")
                .is_some()
        );
        assert!(
            filter
                .echo_of(t0 + Duration::from_secs(6), "how can I help you")
                .is_none()
        );
    }
}
