//! Voice activity as the rest of the agent sees it: one `start` when the user is speaking and one `end` when the
//! utterance is over (after the end of turn), derived from the pipeline's events.
//!
//! The segmenter's own events say more than listeners need: an utterance cut at the maximum length ends and a new
//! one starts while the voice goes on, and speech too short to transcribe is dropped rather than ended. Listeners
//! (barge-in, the avatar's listening behaviour) only care whether the user is speaking, so a cut is no event at all.
//! `start` is reported once the voice is confirmed as speech (it has lasted `min_voiced_ms`, 200 ms by default,
//! and been tonal), stamped with the onset: a click, a cough or a knock shorter than that never starts anything, so
//! it never interrupts the agent (barge-in), and the 200 ms keep a barge-in well inside 300 ms of the onset.

use crate::stream::StreamEvent;

/// A change of the user's voice activity, located on the hub clock (µs since the Unix epoch).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum VoiceActivity {
    /// The voice began at `at_us` (the detected onset, without the pre-roll).
    Start { at_us: u64 },
    /// The voice ended at `at_us` (end of the last voiced frame); reported once the hangover has passed.
    /// `utterance` names the utterance that will be transcribed, `None` when the speech was dropped as too short
    /// or as noise.
    End {
        at_us: u64,
        utterance: Option<String>,
    },
}

/// The voice-activity change a pipeline event means, if any.
pub fn of_event(event: &StreamEvent) -> Option<VoiceActivity> {
    match event {
        StreamEvent::Confirmed { onset_us, .. } => Some(VoiceActivity::Start { at_us: *onset_us }),
        StreamEvent::Utterance(u) if !u.forced => Some(VoiceActivity::End {
            at_us: u.speech_end_us,
            utterance: Some(u.id.clone()),
        }),
        // Only what was reported as started ends.
        StreamEvent::Dropped {
            speech_end_us,
            confirmed: true,
            ..
        } => Some(VoiceActivity::End {
            at_us: *speech_end_us,
            utterance: None,
        }),
        // A pause is no end: the voice may come back before the hangover is over, and listeners hear of the end
        // only when it is certain.
        StreamEvent::Started { .. }
        | StreamEvent::Dropped { .. }
        | StreamEvent::Utterance(_)
        | StreamEvent::Paused(_)
        | StreamEvent::Resumed { .. }
        | StreamEvent::Restarted => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::segmenter::SegmenterConfig;
    use crate::stream::AudioStream;
    use crate::stream::tests::{feed, tone_pcm as pcm};

    /// Voice activity of PCM published as 20 ms real-time messages from hub time `t0`.
    fn activity(cfg: SegmenterConfig, pcm: &[u8], t0: u64) -> Vec<VoiceActivity> {
        let mut stream = AudioStream::new(cfg).expect("pipeline");
        let mut events = feed(&mut stream, pcm, 1, t0);
        stream.finish(&mut events).expect("finish");
        events.iter().filter_map(of_event).collect()
    }

    /// One start then one end, the end naming an utterance when `transcribed`.
    fn assert_one_start_and_end(got: &[VoiceActivity], transcribed: bool) {
        assert_eq!(got.len(), 2, "{got:?}");
        assert!(matches!(got[0], VoiceActivity::Start { .. }), "{got:?}");
        assert!(
            matches!(&got[1], VoiceActivity::End { utterance, .. } if utterance.is_some() == transcribed),
            "{got:?}"
        );
    }

    #[test]
    fn one_utterance_gives_one_start_at_the_onset_and_one_end_at_the_end_of_speech() {
        let t0 = 1_700_000_000_000_000;
        let audio = [pcm(1000, false), pcm(1500, true), pcm(1000, false)].concat();
        let got = activity(SegmenterConfig::default(), &audio, t0);
        let [
            VoiceActivity::Start { at_us: start },
            VoiceActivity::End {
                at_us: end,
                utterance: Some(id),
            },
        ] = got.as_slice()
        else {
            panic!("expected start then end: {got:?}");
        };
        // The voice runs from 1.0 s to 2.5 s; the detector works in 20 ms frames behind a resampler.
        assert!(start.abs_diff(t0 + 1_000_000) <= 60_000, "{}", start - t0);
        assert!(end.abs_diff(t0 + 2_500_000) <= 60_000, "{}", end - t0);
        assert!(id.starts_with('u'));
    }

    #[test]
    fn speech_cut_at_the_maximum_length_is_one_start_and_one_end() {
        let cfg = SegmenterConfig {
            max_utterance_ms: 1000,
            ..SegmenterConfig::default()
        };
        let audio = [pcm(500, false), pcm(3000, true), pcm(800, false)].concat();
        let got = activity(cfg, &audio, 0);
        assert_one_start_and_end(&got, true);
    }

    #[test]
    fn a_burst_shorter_than_speech_is_no_activity() {
        // 120 ms of voice (a cough, a knock) opens an utterance (80 of 100 ms voiced) but is under the 200 ms
        // minimum: the user never started speaking, so nothing listens up and nothing is interrupted.
        let audio = [pcm(500, false), pcm(120, true), pcm(800, false)].concat();
        let got = activity(SegmenterConfig::default(), &audio, 0);
        assert!(got.is_empty(), "{got:?}");
    }

    #[test]
    fn a_pause_inside_an_utterance_is_no_activity() {
        // 240 ms of silence: long enough to pause (150 ms post-roll), shorter than the 300 ms hangover.
        let audio = [
            pcm(500, false),
            pcm(800, true),
            pcm(240, false),
            pcm(800, true),
            pcm(800, false),
        ]
        .concat();
        let got = activity(SegmenterConfig::default(), &audio, 0);
        assert_one_start_and_end(&got, true);
    }

    #[test]
    fn silence_is_no_activity() {
        assert!(activity(SegmenterConfig::default(), &pcm(3000, false), 0).is_empty());
    }
}
