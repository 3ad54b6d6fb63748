//! One claimed utterance from its claim to its transcript, transcribed speculatively while the hangover runs.
//!
//! The segmenter reports an utterance as paused once its trailing silence holds the post-roll, with exactly the
//! audio it will carry if it ends there, and the end only after the whole hangover. A satellite that claims the
//! utterance at the pause starts decoding at once; when the utterance then ends unchanged, the speculative result
//! is its transcript, ready up to a hangover earlier than a decode started at the end. The result is never
//! submitted before the end, because the voice may still resume: then the decode in flight is aborted (or its
//! result thrown away if it had finished), the claim is kept (its id, the start, does not change), and the next
//! pause or the end starts a decode of the longer audio.
//!
//! `Hold` is only the decision logic: it says when to decode, abort and submit, and the satellite carries that
//! out. Decodes are numbered by the version of the utterance they were started on, so a result that arrives after
//! the utterance changed is recognised and dropped. One decode runs at a time (one transcriber per satellite).

use crate::stream::ClockedUtterance;

/// What the holder must do next.
#[derive(Debug, Clone, PartialEq)]
pub enum Action<R> {
    /// Decode this utterance and report the result with `Hold::decoded`. No other decode of this hold is running.
    Decode(ClockedUtterance),
    /// Stop the decode in flight: its result will not be used (it is still reported with `decoded`).
    Abort,
    /// The utterance has ended and this is its result: submit it. The hold is finished.
    Submit {
        utterance: ClockedUtterance,
        result: R,
        /// The decode started before the utterance ended (during the hangover).
        speculative: bool,
    },
}

/// The state of one claim; `R` is the decoder's result.
#[derive(Debug)]
pub struct Hold<R> {
    /// The latest version of the utterance: the last pause, or the end.
    utterance: ClockedUtterance,
    ended: bool,
    /// The voice resumed after `utterance` paused: there is nothing worth decoding until the next pause or the end.
    stale: bool,
    /// Version of `utterance`; raised whenever what will be transcribed changes.
    generation: u64,
    /// The decode in flight: the version it works on and whether that version had ended when it started.
    decoding: Option<(u64, bool)>,
    /// An abort was already asked of the decode in flight.
    aborting: bool,
    /// The result of decoding the current version, and whether it was speculative.
    result: Option<(R, bool)>,
}

impl<R> Hold<R> {
    /// The hold of a freshly claimed utterance (paused or ended), with the decode to start.
    pub fn claimed(utterance: ClockedUtterance, ended: bool) -> (Self, Action<R>) {
        let mut hold = Self {
            utterance,
            ended,
            stale: false,
            generation: 0,
            decoding: None,
            aborting: false,
            result: None,
        };
        let first = hold.start_decode();
        (hold, first)
    }

    /// The utterance id the claim is on.
    pub fn id(&self) -> &str {
        &self.utterance.id
    }

    /// The latest version of the utterance.
    pub fn utterance(&self) -> &ClockedUtterance {
        &self.utterance
    }

    /// True once the utterance has ended (no more pauses or resumptions come).
    pub fn is_ended(&self) -> bool {
        self.ended
    }

    /// The result decoded from the pause the utterance stands at, while it waits for its end: what the end of turn
    /// is judged on.
    pub fn paused_result(&self) -> Option<&R> {
        if self.ended || self.stale {
            return None;
        }
        self.result.as_ref().map(|(result, _)| result)
    }

    /// True while a decode of this hold is in flight.
    pub fn is_decoding(&self) -> bool {
        self.decoding.is_some()
    }

    /// The utterance paused (again): `utterance` is what it will be if it ends now.
    pub fn paused(&mut self, utterance: ClockedUtterance) -> Option<Action<R>> {
        self.update(utterance, false)
    }

    /// The utterance ended.
    pub fn ended(&mut self, utterance: ClockedUtterance) -> Option<Action<R>> {
        self.update(utterance, true)
    }

    /// The voice came back after the pause: whatever was decoded so far is not the transcript.
    pub fn resumed(&mut self) -> Option<Action<R>> {
        if self.ended || self.stale {
            return None;
        }
        self.stale = true;
        self.generation += 1;
        self.result = None;
        self.abort_in_flight()
    }

    /// The decode started by the last `Action::Decode` finished (or was aborted) with `result`.
    pub fn decoded(&mut self, result: R) -> Option<Action<R>> {
        let (of, started_ended) = self.decoding.take()?;
        self.aborting = false;
        if of == self.generation {
            self.result = Some((result, !started_ended));
            return self.submit_if_ended();
        }
        // Out of date: the utterance changed while it ran.
        if self.stale {
            None
        } else {
            Some(self.start_decode())
        }
    }

    fn update(&mut self, utterance: ClockedUtterance, ended: bool) -> Option<Action<R>> {
        if !self.stale && utterance == self.utterance {
            // What was (being) decoded is the utterance: it only has to end.
            self.ended |= ended;
            return self.submit_if_ended();
        }
        self.utterance = utterance;
        self.ended = ended;
        self.stale = false;
        self.generation += 1;
        self.result = None;
        if self.decoding.is_some() {
            // The next decode starts when the one in flight comes back.
            self.abort_in_flight()
        } else {
            Some(self.start_decode())
        }
    }

    fn start_decode(&mut self) -> Action<R> {
        self.decoding = Some((self.generation, self.ended));
        self.aborting = false;
        Action::Decode(self.utterance.clone())
    }

    fn abort_in_flight(&mut self) -> Option<Action<R>> {
        if self.decoding.is_some() && !self.aborting {
            self.aborting = true;
            Some(Action::Abort)
        } else {
            None
        }
    }

    fn submit_if_ended(&mut self) -> Option<Action<R>> {
        if !self.ended {
            return None;
        }
        let (result, speculative) = self.result.take()?;
        Some(Action::Submit {
            utterance: self.utterance.clone(),
            result,
            speculative,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn utt(end_ms: u64) -> ClockedUtterance {
        ClockedUtterance {
            id: "u1000".into(),
            start_us: 1_000_000,
            speech_end_us: end_ms * 1000,
            audio: vec![0.1; (end_ms as usize - 1000) * 16 + 2400],
            forced: false,
            closed_us: end_ms * 1000 + 300_000,
        }
    }

    fn decode_of<R>(action: Option<Action<R>>) -> ClockedUtterance {
        match action {
            Some(Action::Decode(utterance)) => utterance,
            _ => panic!("expected a decode"),
        }
    }

    #[test]
    fn a_pause_that_ends_unchanged_submits_the_speculative_result_only_at_the_end() {
        let (mut hold, first) = Hold::claimed(utt(2000), false);
        let audio = decode_of(Some(first));
        assert_eq!(audio, utt(2000));
        // Finished during the hangover: kept, not submitted, since the voice might still resume.
        assert_eq!(hold.decoded("text"), None);
        assert!(!hold.is_decoding());
        // It ends where the segmenter closed it, later than it paused: the same speech all the same.
        let ended = ClockedUtterance {
            closed_us: 2_450_000,
            ..utt(2000)
        };
        assert_eq!(
            hold.ended(ended),
            Some(Action::Submit {
                utterance: utt(2000),
                result: "text",
                speculative: true
            })
        );
    }

    #[test]
    fn an_end_before_the_speculative_decode_finishes_waits_for_it() {
        let (mut hold, first) = Hold::claimed(utt(2000), false);
        decode_of(Some(first));
        assert_eq!(hold.ended(utt(2000)), None);
        assert!(hold.is_decoding());
        assert_eq!(
            hold.decoded("text"),
            Some(Action::Submit {
                utterance: utt(2000),
                result: "text",
                speculative: true
            })
        );
    }

    #[test]
    fn resumed_voice_aborts_the_decode_keeps_the_claim_and_decodes_the_longer_utterance() {
        let (mut hold, first) = Hold::claimed(utt(2000), false);
        decode_of(Some(first));
        assert_eq!(hold.resumed(), Some(Action::Abort));
        // Asked once: a second resume or a pause while the abort is under way asks nothing more.
        assert_eq!(hold.resumed(), None);
        assert_eq!(hold.paused(utt(3000)), None);
        // The aborted decode comes back: its result is dropped and the new pause is decoded.
        let audio = decode_of(hold.decoded("partial"));
        assert_eq!(audio, utt(3000));
        assert_eq!(hold.id(), "u1000");
        assert_eq!(hold.decoded("whole"), None);
        assert_eq!(
            hold.ended(utt(3000)),
            Some(Action::Submit {
                utterance: utt(3000),
                result: "whole",
                speculative: true
            })
        );
    }

    #[test]
    fn a_result_finished_before_the_voice_resumed_is_thrown_away() {
        let (mut hold, first) = Hold::claimed(utt(2000), false);
        decode_of(Some(first));
        assert_eq!(hold.decoded("partial"), None);
        // Nothing in flight to abort; nothing to decode until the voice pauses or ends again.
        assert_eq!(hold.resumed(), None);
        assert!(!hold.is_decoding());
        // It ends without another pause (say the stream stopped): decoded after the end, not speculative.
        let audio = decode_of(hold.ended(utt(2600)));
        assert_eq!(audio, utt(2600));
        assert_eq!(
            hold.decoded("whole"),
            Some(Action::Submit {
                utterance: utt(2600),
                result: "whole",
                speculative: false
            })
        );
    }

    #[test]
    fn an_end_that_differs_from_the_pause_supersedes_it() {
        // A cut at the maximum length during the hangover ends the utterance with other audio.
        let (mut hold, first) = Hold::claimed(utt(2000), false);
        decode_of(Some(first));
        let mut cut = utt(2000);
        cut.audio.extend([0.0; 640]);
        cut.speech_end_us += 40_000;
        cut.forced = true;
        assert_eq!(hold.ended(cut.clone()), Some(Action::Abort));
        let audio = decode_of(hold.decoded("stale"));
        assert_eq!(audio, cut);
        assert!(matches!(
            hold.decoded("cut"),
            Some(Action::Submit {
                result: "cut",
                speculative: false,
                ..
            })
        ));
    }

    #[test]
    fn a_claim_on_an_ended_utterance_decodes_and_submits_at_once() {
        let (mut hold, first) = Hold::claimed(utt(2000), true);
        decode_of(Some(first));
        assert_eq!(
            hold.decoded("text"),
            Some(Action::Submit {
                utterance: utt(2000),
                result: "text",
                speculative: false
            })
        );
        // A repeated report of the same pause or end changes nothing.
        assert_eq!(hold.paused(utt(2000)), None);
    }
}
