//! The hub audio stream turned into clocked utterances: s16le 22050 Hz messages in, utterances with start and end
//! on the hub's clock out.
//!
//! Every satellite runs this same deterministic pipeline on the same messages, so they find the same utterances
//! with the same ids: an utterance's id is its start time on the hub clock, derived from the per-message hub
//! timestamps (identical for every subscriber) plus the sample offset within the stream. The pipeline restarts when
//! the stream does (the channel's sequence goes backwards), when it has a hole (the sequence skips: messages lost
//! before this subscriber), or when the hub clock runs past the audio by more than a starved publisher could be
//! late, so satellites that saw the stream start stay in step; see docs/asr.md for what a satellite that joins
//! mid-stream does.
//!
//! Late is not lost: a page whose main thread is starved sends a second of chunks at once, stamped late and close
//! together. The samples are still one stream, so lateness alone never restarts it (a restart there cut the
//! user's first words off the question they began).

use std::collections::VecDeque;

use crate::echo::{EchoConfig, EchoGate};
use crate::resample::{ResampleError, StreamResampler, pcm_s16le_to_f32};
use crate::segmenter::{
    DecidedEnd, FRAME, RATE, SegmentEvent, Segmenter, SegmenterConfig, SegmenterError, Utterance,
};
use crate::turn::Turn;

/// The hub's audio rate (`Agent.audio`).
pub const HUB_RATE: u32 = 22_050;

/// Messages later than the least late one by more than this are a pause in publishing, not a late delivery: the
/// pipeline restarts. A starved page delivers seconds late; a publisher that stopped and went on is a new stream.
pub const MAX_LATENESS_US: u64 = 4_000_000;
/// The hub clock and a sound card's sample clock drift apart by up to a few hundred parts per million: the
/// baseline lateness follows a drift of up to this many µs per second of audio, so hours of audio never add up to
/// a restart.
const DRIFT_US_PER_S: u64 = 1_000;

/// One message of `Agent.audio` as the SDK delivers it.
#[derive(Debug, Clone, Copy)]
pub struct AudioMessage<'a> {
    pub seq: u64,
    pub ts_us: u64,
    pub pcm: &'a [u8],
}

/// An utterance located on the hub clock.
///
/// Equal when the speech is (id, start, end of speech, audio, cut), wherever each was closed: a paused utterance
/// equals the one it ends as (`Utterance`'s equality), which is how a speculative decode is known to hold.
#[derive(Debug, Clone)]
pub struct ClockedUtterance {
    /// Stable id shared by every satellite: `u<start in ms on the hub clock>`.
    pub id: String,
    /// Start of the audio (pre-roll included) on the hub clock, µs since the Unix epoch.
    pub start_us: u64,
    /// End of speech on the hub clock.
    pub speech_end_us: u64,
    /// 16 kHz audio to transcribe.
    pub audio: Vec<f32>,
    /// Cut at the maximum length while the voice went on (the speech continues in the next utterance).
    pub forced: bool,
    /// Hub time at which the segmenter closed it (`Utterance::closed_at`).
    pub closed_us: u64,
}

impl PartialEq for ClockedUtterance {
    fn eq(&self, other: &Self) -> bool {
        (&self.id, self.start_us, self.speech_end_us, self.forced)
            == (&other.id, other.start_us, other.speech_end_us, other.forced)
            && self.audio == other.audio
    }
}

/// What the pipeline reports.
#[derive(Debug, Clone, PartialEq)]
pub enum StreamEvent {
    /// Speech began: its audio starts at `start_us` (pre-roll included), the voice at `onset_us`. `continued`
    /// marks the start of the next piece of speech cut at the maximum length.
    Started {
        start_us: u64,
        onset_us: u64,
        continued: bool,
    },
    /// The voice of the utterance that starts at `start_us` is speech, not a click (`SegmentEvent::Confirmed`); it
    /// began at `onset_us`.
    Confirmed {
        start_us: u64,
        onset_us: u64,
    },
    /// The open utterance paused for its post-roll: if the voice does not resume before the hangover is over, the
    /// `Utterance` that follows is exactly this one (see `SegmentEvent::Paused`).
    Paused(ClockedUtterance),
    /// The voice of the paused utterance `id` came back: the pause will not be its end.
    Resumed {
        id: String,
        start_us: u64,
    },
    Utterance(ClockedUtterance),
    /// Speech that started was too short or too noisy to transcribe; its voice ended at `speech_end_us`.
    /// `confirmed` when it had been reported as `Confirmed`.
    Dropped {
        start_us: u64,
        speech_end_us: u64,
        confirmed: bool,
    },
    /// The stream restarted or jumped; anything open was closed first.
    Restarted,
}

/// Errors of the pipeline.
#[derive(Debug, thiserror::Error)]
pub enum StreamError {
    #[error(transparent)]
    Resample(#[from] ResampleError),
    #[error(transparent)]
    Segmenter(#[from] SegmenterError),
}

/// The stateful pipeline: resampler, segmenter and the clock mapping.
#[derive(Debug)]
pub struct AudioStream {
    cfg: SegmenterConfig,
    resampler: StreamResampler,
    segmenter: Segmenter,
    /// Hub time the stream's first sample had on the least late message so far (the baseline: each message's
    /// lateness is its stamp less this plus the audio before it), and samples (22050 Hz) received since.
    origin_us: Option<u64>,
    received: u64,
    last_seq: Option<u64>,
    /// (16 kHz sample index, hub µs) marks of the last messages, to locate samples on the hub clock.
    marks: VecDeque<(u64, u64)>,
    scratch: Vec<f32>,
    resampled: Vec<f32>,
    events: Vec<SegmentEvent>,
    /// The agent's own speech as it plays, for own-voice suppression.
    echo: EchoGate,
    /// The last pause reported, as the satellite names it (id, end of speech on the hub clock) and as the
    /// segmenter knows it (start and end of speech in samples), for verdicts on it.
    last_pause: Option<(String, u64, u64, u64)>,
    /// An end another satellite's segmenter gave the open utterance, waiting for the stream to reach it:
    /// (id, end of speech, where it closed), on the hub clock.
    decided_end: Option<(String, u64, u64)>,
}

impl AudioStream {
    /// A pipeline waiting for its first message.
    pub fn new(cfg: SegmenterConfig) -> Result<Self, StreamError> {
        Ok(Self {
            resampler: StreamResampler::new(HUB_RATE, RATE)?,
            segmenter: Segmenter::new(cfg.clone())?,
            cfg,
            origin_us: None,
            received: 0,
            last_seq: None,
            marks: VecDeque::new(),
            scratch: Vec::new(),
            resampled: Vec::new(),
            events: Vec::new(),
            echo: EchoGate::new(EchoConfig::default()),
            last_pause: None,
            decided_end: None,
        })
    }

    /// Feeds one hub message.
    pub fn push(
        &mut self,
        msg: AudioMessage<'_>,
        out: &mut Vec<StreamEvent>,
    ) -> Result<(), StreamError> {
        let restart = match (self.last_seq, self.origin_us) {
            (Some(last), Some(origin)) => {
                let before_us = self.received * 1_000_000 / u64::from(HUB_RATE);
                let lateness = msg.ts_us.saturating_sub(origin + before_us);
                msg.seq <= last || msg.seq > last + 1 || lateness > MAX_LATENESS_US
            }
            _ => false,
        };
        if restart {
            self.finish(out)?;
            out.push(StreamEvent::Restarted);
        }
        self.follow_lateness(msg);
        self.last_seq = Some(msg.seq);
        // The hub stamps a message when it is published; its first sample is that far into the stream.
        let first16 = self.received * u64::from(RATE) / u64::from(HUB_RATE);
        self.marks.push_back((first16, msg.ts_us));
        while self.marks.len() > 4096 {
            self.marks.pop_front();
        }
        self.scratch.clear();
        pcm_s16le_to_f32(msg.pcm, &mut self.scratch);
        self.received += self.scratch.len() as u64;
        self.resampled.clear();
        self.resampler.push(&self.scratch, &mut self.resampled)?;
        // The message was captured just before the hub stamped it: frames of it the agent's echo could be in are
        // held to the own-voice floor of that moment.
        let floor = self.echo.heard(msg.ts_us, crate::echo::level_dbfs(msg.pcm));
        self.segmenter.set_echo_floor(floor);
        self.segmenter.push(&self.resampled, &mut self.events);
        self.emit(out);
        if self.decided_end.is_some() {
            self.apply_decided_end(out);
        }
        Ok(())
    }

    /// Moves the baseline: down to a message less late than it (the first messages may have been the late ones),
    /// up by at most the clocks' drift over this message's audio when the message is later.
    fn follow_lateness(&mut self, msg: AudioMessage<'_>) {
        let before_us = self.received * 1_000_000 / u64::from(HUB_RATE);
        let on_time = msg.ts_us.saturating_sub(before_us);
        let origin = match self.origin_us {
            None => on_time,
            Some(origin) if on_time <= origin => on_time,
            Some(origin) => {
                let samples = (msg.pcm.len() / 2) as u64;
                let drift = samples * DRIFT_US_PER_S / u64::from(HUB_RATE);
                origin + (on_time - origin).min(drift)
            }
        };
        self.origin_us = Some(origin);
    }

    /// One chunk of the agent's own speech (`Agent.speech`, s16le 22050 Hz) that reached the hub at `ts_us`, with
    /// its utterance and offset when framed: what the microphone may hear back while it plays.
    pub fn reference(&mut self, ts_us: u64, framing: Option<(u32, u32)>, pcm: &[u8]) {
        self.echo.reference(ts_us, framing, pcm);
    }

    /// The agent's speech was stopped at `ts_us` (`speech_stop` on `Agent.avatar`).
    pub fn reference_stopped(&mut self, ts_us: u64) {
        self.echo.stopped(ts_us);
    }

    /// Ends the stream: flushes the resampler and closes an open utterance.
    pub fn finish(&mut self, out: &mut Vec<StreamEvent>) -> Result<(), StreamError> {
        if self.origin_us.is_some() {
            self.resampled.clear();
            self.resampler.flush(&mut self.resampled)?;
            self.segmenter.push(&self.resampled, &mut self.events);
            self.segmenter.finish(&mut self.events);
            self.emit(out);
        }
        self.resampler = StreamResampler::new(HUB_RATE, RATE)?;
        self.segmenter = Segmenter::new(self.cfg.clone())?;
        self.origin_us = None;
        self.received = 0;
        self.last_seq = None;
        self.marks.clear();
        self.last_pause = None;
        self.decided_end = None;
        Ok(())
    }

    /// The satellite decoding utterance `id` ended it at the pause after `speech_end_us`, its segmenter closing
    /// it at `closed_us` (hub clock): this pipeline ends it there too, at once or when the stream gets there
    /// (`Segmenter::end_as_decided`).
    pub fn ended_elsewhere(
        &mut self,
        id: &str,
        speech_end_us: u64,
        closed_us: u64,
        out: &mut Vec<StreamEvent>,
    ) {
        self.decided_end = Some((id.to_owned(), speech_end_us, closed_us));
        self.apply_decided_end(out);
    }

    fn apply_decided_end(&mut self, out: &mut Vec<StreamEvent>) {
        let Some((id, speech_end_us, closed_us)) = self.decided_end.clone() else {
            return;
        };
        let Some((start, opened)) = self.segmenter.open_utterance() else {
            self.decided_end = None;
            return;
        };
        if utterance_id(self.clock_of(start)) != id {
            self.decided_end = None;
            return;
        }
        if self.clock_of(self.segmenter.position()) < closed_us {
            return;
        }
        let (Some(speech_end), Some(closed_at)) = (
            self.frame_boundary_at(opened, speech_end_us),
            self.frame_boundary_at(opened, closed_us),
        ) else {
            tracing::debug!(%id, speech_end_us, closed_us, "an end decided elsewhere is not on this stream's frames");
            self.decided_end = None;
            return;
        };
        match self
            .segmenter
            .end_as_decided(start, speech_end, closed_at, &mut self.events)
        {
            DecidedEnd::Later => return,
            DecidedEnd::Applied => {
                tracing::debug!(%id, speech_end_us, "ended where its decoder ended it")
            }
            DecidedEnd::Ignored => {
                tracing::debug!(%id, speech_end_us, "an end decided elsewhere does not fit this stream")
            }
        }
        self.decided_end = None;
        self.emit(out);
    }

    /// The frame boundary (a whole number of frames from `grid`) that lies at `at_us` on the hub clock.
    fn frame_boundary_at(&self, grid: u64, at_us: u64) -> Option<u64> {
        let (idx, ts) = self
            .marks
            .iter()
            .rev()
            .find(|(_, ts)| *ts <= at_us)
            .copied()?;
        let estimate = idx + (at_us - ts) * u64::from(RATE) / 1_000_000;
        let frame = FRAME as u64;
        let near =
            grid as i64 + (estimate as i64 - grid as i64).div_euclid(frame as i64) * frame as i64;
        (-1..=2)
            .map(|k| near + k * frame as i64)
            .filter_map(|p| u64::try_from(p).ok())
            .find(|&p| self.clock_of(p) == at_us)
    }

    /// A transcript of the pause of utterance `id` that ended speech at `speech_end_us` is being decoded (`None`)
    /// or was judged (`Some`); see `Segmenter::turn`. A verdict on any other pause is ignored.
    pub fn turn(
        &mut self,
        id: &str,
        speech_end_us: u64,
        verdict: Option<Turn>,
        out: &mut Vec<StreamEvent>,
    ) {
        let Some((_, _, start, speech_end)) = self
            .last_pause
            .as_ref()
            .filter(|(pid, end_us, ..)| pid == id && *end_us == speech_end_us)
        else {
            return;
        };
        let (start, speech_end) = (*start, *speech_end);
        self.segmenter
            .turn(start, speech_end, verdict, &mut self.events);
        self.emit(out);
    }

    /// Hub time of a 16 kHz sample index: the last message mark at or before it plus the offset.
    pub fn clock_of(&self, sample: u64) -> u64 {
        let (idx, ts) = self
            .marks
            .iter()
            .rev()
            .find(|(i, _)| *i <= sample)
            .or_else(|| self.marks.front())
            .copied()
            .unwrap_or((0, self.origin_us.unwrap_or(0)));
        let offset = (sample as i64 - idx as i64) * 1_000_000 / i64::from(RATE);
        (ts as i64 + offset).max(0) as u64
    }

    fn emit(&mut self, out: &mut Vec<StreamEvent>) {
        for ev in std::mem::take(&mut self.events) {
            match ev {
                SegmentEvent::Started {
                    start,
                    onset,
                    continued,
                } => out.push(StreamEvent::Started {
                    start_us: self.clock_of(start),
                    onset_us: self.clock_of(onset),
                    continued,
                }),
                SegmentEvent::Paused(u) => {
                    let (start, speech_end) = (u.start, u.speech_end);
                    let located = self.locate(u);
                    self.last_pause =
                        Some((located.id.clone(), located.speech_end_us, start, speech_end));
                    out.push(StreamEvent::Paused(located));
                }
                SegmentEvent::Resumed { start } => {
                    let start_us = self.clock_of(start);
                    out.push(StreamEvent::Resumed {
                        id: utterance_id(start_us),
                        start_us,
                    });
                }
                SegmentEvent::Ended(u) => out.push(StreamEvent::Utterance(self.locate(u))),
                SegmentEvent::Confirmed { start, onset } => out.push(StreamEvent::Confirmed {
                    start_us: self.clock_of(start),
                    onset_us: self.clock_of(onset),
                }),
                SegmentEvent::Dropped {
                    start,
                    speech_end,
                    confirmed,
                } => out.push(StreamEvent::Dropped {
                    start_us: self.clock_of(start),
                    speech_end_us: self.clock_of(speech_end),
                    confirmed,
                }),
            }
        }
    }

    fn locate(&self, u: Utterance) -> ClockedUtterance {
        let start_us = self.clock_of(u.start);
        ClockedUtterance {
            id: utterance_id(start_us),
            start_us,
            speech_end_us: self.clock_of(u.speech_end),
            audio: u.audio,
            forced: u.forced,
            closed_us: self.clock_of(u.closed_at),
        }
    }
}

/// The id every satellite gives the utterance whose audio starts at `start_us` on the hub clock.
fn utterance_id(start_us: u64) -> String {
    format!("u{}", start_us / 1000)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A vowel-like harmonic tone with a syllable envelope (speech enough for the WebRTC detector), or silence.
    pub(crate) fn tone_pcm(ms: u32, loud: bool) -> Vec<u8> {
        let n = (HUB_RATE * ms / 1000) as usize;
        (0..n)
            .flat_map(|i| {
                let t = i as f32 / HUB_RATE as f32;
                let env = 0.6 + 0.4 * (2.0 * std::f32::consts::PI * 4.0 * t).sin();
                let s: f32 = (1..=12)
                    .map(|h| (2.0 * std::f32::consts::PI * 140.0 * h as f32 * t).sin() / h as f32)
                    .sum();
                let v = if loud { 0.15 * env * s } else { 0.0 };
                ((v * 32767.0) as i16).to_le_bytes()
            })
            .collect()
    }

    /// Publishes PCM as 20 ms messages stamped like a real-time publisher starting at `t0`.
    pub(crate) fn feed(
        stream: &mut AudioStream,
        pcm: &[u8],
        seq0: u64,
        t0: u64,
    ) -> Vec<StreamEvent> {
        feed_stamped(stream, pcm, seq0, |n| t0 + n * 20_000)
    }

    fn utterances(ev: &[StreamEvent]) -> Vec<&ClockedUtterance> {
        ev.iter()
            .filter_map(|e| match e {
                StreamEvent::Utterance(u) => Some(u),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn utterances_are_located_on_the_hub_clock() {
        let pcm = [
            tone_pcm(1000, false),
            tone_pcm(1200, true),
            tone_pcm(1000, false),
        ]
        .concat();
        let t0 = 1_700_000_000_000_000;
        let mut s = AudioStream::new(SegmenterConfig::default()).expect("pipeline");
        let ev = feed(&mut s, &pcm, 1, t0);
        let u = utterances(&ev);
        assert_eq!(u.len(), 1, "{ev:?}");
        // Speech from 1.0 s to 2.2 s after t0; the start includes up to 300 ms of pre-roll.
        assert!(
            (t0 + 650_000..=t0 + 1_000_000).contains(&u[0].start_us),
            "{}",
            u[0].start_us - t0
        );
        assert!(
            u[0].speech_end_us.abs_diff(t0 + 2_200_000) <= 60_000,
            "{}",
            u[0].speech_end_us - t0
        );
        assert_eq!(u[0].id, format!("u{}", u[0].start_us / 1000));
    }

    #[test]
    fn two_subscribers_find_identical_utterances() {
        let pcm = [
            tone_pcm(500, false),
            tone_pcm(900, true),
            tone_pcm(800, false),
            tone_pcm(700, true),
            tone_pcm(900, false),
        ]
        .concat();
        let mut a = AudioStream::new(SegmenterConfig::default()).expect("pipeline");
        let mut b = AudioStream::new(SegmenterConfig::default()).expect("pipeline");
        let ea = feed(&mut a, &pcm, 1, 5_000_000);
        let eb = feed(&mut b, &pcm, 1, 5_000_000);
        assert_eq!(utterances(&ea).len(), 2);
        assert_eq!(ea, eb);
    }

    #[test]
    fn a_new_stream_restarts_the_pipeline_and_closes_open_speech() {
        let mut s = AudioStream::new(SegmenterConfig::default()).expect("pipeline");
        let mut ev = feed(
            &mut s,
            &[tone_pcm(300, false), tone_pcm(800, true)].concat(),
            1,
            1_000_000,
        );
        // The publisher went away mid-word; a new stream starts at seq 1 ten seconds later.
        ev.extend(feed(&mut s, &tone_pcm(600, false), 1, 11_000_000));
        assert!(ev.contains(&StreamEvent::Restarted));
        let u = utterances(&ev);
        assert_eq!(u.len(), 1, "{ev:?}");
        assert!(u[0].start_us < 2_000_000);
    }

    /// Publishes PCM as 20 ms messages from `seq0`, each stamped by `stamp(n)` for its index `n`.
    pub(crate) fn feed_stamped(
        stream: &mut AudioStream,
        pcm: &[u8],
        seq0: u64,
        stamp: impl Fn(u64) -> u64,
    ) -> Vec<StreamEvent> {
        let mut out = Vec::new();
        for (n, chunk) in pcm.chunks(882).enumerate() {
            let msg = AudioMessage {
                seq: seq0 + n as u64,
                ts_us: stamp(n as u64),
                pcm: chunk,
            };
            stream.push(msg, &mut out).expect("push");
        }
        out
    }

    #[test]
    fn a_starved_publishers_late_bursts_are_one_stream_and_keep_the_utterance_whole() {
        let pcm = [
            tone_pcm(400, false),
            tone_pcm(2000, true),
            tone_pcm(1200, false),
        ]
        .concat();
        let t0 = 1_000_000_000;
        // The page's main thread is blocked 1.4 s of every 1.5 s: the chunks captured meanwhile reach the hub
        // together when it runs again, each stamped at the end of its block.
        let starved = |n: u64| {
            let captured = t0 + n * 20_000;
            let block = (captured - t0) / 1_500_000;
            (t0 + (block + 1) * 1_500_000).max(captured)
        };
        let mut s = AudioStream::new(SegmenterConfig::default()).expect("pipeline");
        let ev = feed_stamped(&mut s, &pcm, 1, starved);
        assert!(!ev.contains(&StreamEvent::Restarted), "{ev:?}");
        let u = utterances(&ev);
        assert_eq!(u.len(), 1, "one utterance, whole: {ev:?}");
        let voiced_s = u[0].audio.len() as f64 / f64::from(RATE);
        assert!(
            voiced_s >= 2.0,
            "the utterance holds all 2 s of voice: {voiced_s} s"
        );
    }

    #[test]
    fn a_hole_in_the_sequence_restarts_the_pipeline() {
        let mut s = AudioStream::new(SegmenterConfig::default()).expect("pipeline");
        let t0 = 1_000_000_000;
        let mut ev = feed(&mut s, &tone_pcm(400, false), 1, t0);
        assert!(!ev.contains(&StreamEvent::Restarted));
        // 20 messages were dropped before this subscriber (seq 21 to 40), on time otherwise.
        ev.extend(feed(&mut s, &tone_pcm(400, false), 41, t0 + 800_000));
        assert!(ev.contains(&StreamEvent::Restarted), "{ev:?}");
    }

    #[test]
    fn a_pause_in_publishing_longer_than_any_lateness_restarts_the_pipeline() {
        let mut s = AudioStream::new(SegmenterConfig::default()).expect("pipeline");
        let t0 = 1_000_000_000;
        let mut ev = feed(&mut s, &tone_pcm(400, false), 1, t0);
        // The same stream goes on (seq 21) after the publisher stopped sending for longer than any starvation.
        let later = t0 + 400_000 + MAX_LATENESS_US + 100_000;
        ev.extend(feed(&mut s, &tone_pcm(400, false), 21, later));
        assert!(ev.contains(&StreamEvent::Restarted), "{ev:?}");
    }

    #[test]
    fn a_stream_whose_first_messages_were_late_is_not_restarted_when_it_catches_up() {
        let mut s = AudioStream::new(SegmenterConfig::default()).expect("pipeline");
        let t0 = 1_000_000_000;
        // The first second arrives at once, a second late; then everything is on time.
        let ev = feed_stamped(&mut s, &tone_pcm(3000, false), 1, |n| {
            (t0 + n * 20_000).max(t0 + 1_000_000)
        });
        assert!(!ev.contains(&StreamEvent::Restarted), "{ev:?}");
    }

    #[test]
    fn a_paused_utterance_is_located_like_the_one_that_ends() {
        let pcm = [
            tone_pcm(600, false),
            tone_pcm(1000, true),
            tone_pcm(240, false),
            tone_pcm(700, true),
            tone_pcm(900, false),
        ]
        .concat();
        let mut s = AudioStream::new(SegmenterConfig::default()).expect("pipeline");
        let ev = feed(&mut s, &pcm, 1, 1_700_000_000_000_000);
        let u = utterances(&ev);
        assert_eq!(u.len(), 1, "{ev:?}");
        let paused: Vec<&ClockedUtterance> = ev
            .iter()
            .filter_map(|e| match e {
                StreamEvent::Paused(p) => Some(p),
                _ => None,
            })
            .collect();
        assert_eq!(paused.len(), 2, "{ev:?}");
        // The mid-utterance pause was withdrawn under the same id; the last pause is the utterance itself.
        assert!(ev.contains(&StreamEvent::Resumed {
            id: u[0].id.clone(),
            start_us: u[0].start_us
        }));
        assert_eq!(paused[0].id, u[0].id);
        assert!(paused[0].speech_end_us < u[0].speech_end_us);
        assert_eq!(paused[1], u[0]);
    }

    /// Feeds PCM like `feed`, letting `hook` act on the stream after each message.
    fn feed_hooked(
        stream: &mut AudioStream,
        pcm: &[u8],
        t0: u64,
        mut hook: impl FnMut(&mut AudioStream, &[StreamEvent], &mut Vec<StreamEvent>),
    ) -> Vec<StreamEvent> {
        let mut out = Vec::new();
        for (n, chunk) in pcm.chunks(882).enumerate() {
            let msg = AudioMessage {
                seq: 1 + n as u64,
                ts_us: t0 + n as u64 * 20_000,
                pcm: chunk,
            };
            let mut step = Vec::new();
            stream.push(msg, &mut step).expect("push");
            let mut caused = Vec::new();
            hook(stream, &step, &mut caused);
            out.extend(step);
            out.extend(caused);
        }
        stream.finish(&mut out).expect("finish");
        out
    }

    #[test]
    fn a_pipeline_told_where_the_decoder_ended_an_utterance_finds_the_decoders_utterances() {
        let pcm = [
            tone_pcm(500, false),
            tone_pcm(800, true),
            tone_pcm(400, false),
            tone_pcm(800, true),
            tone_pcm(1000, false),
        ]
        .concat();
        let t0 = 1_700_000_000_000_000;
        // The decoder held its pause for the transcript and ended it on a verdict that came 340 ms in.
        let mut pause: Option<(String, u64)> = None;
        let mut decoder = AudioStream::new(SegmenterConfig::default()).expect("pipeline");
        let decoded = feed_hooked(&mut decoder, &pcm, t0, |s, step, caused| {
            for e in step {
                if let StreamEvent::Paused(u) = e
                    && pause.is_none()
                {
                    pause = Some((u.id.clone(), u.speech_end_us));
                    s.turn(&u.id, u.speech_end_us, None, caused);
                }
            }
            if let Some((id, end)) = &pause {
                let now = s.clock_of(s.segmenter.position());
                if now >= end + 340_000 && now < end + 360_000 {
                    s.turn(id, *end, Some(Turn::Unknown), caused);
                }
            }
        });
        let theirs: Vec<&ClockedUtterance> = utterances(&decoded);
        assert_eq!(theirs.len(), 2, "{decoded:?}");
        // This pipeline heard of the decode but not of its verdict in time: the voice resumed here first.
        let first = theirs[0].clone();
        let mut told = false;
        let mut follower = AudioStream::new(SegmenterConfig::default()).expect("pipeline");
        let followed = feed_hooked(&mut follower, &pcm, t0, |s, step, caused| {
            for e in step {
                if let StreamEvent::Paused(u) = e
                    && !told
                {
                    s.turn(&u.id, u.speech_end_us, None, caused);
                }
            }
            let now = s.clock_of(s.segmenter.position());
            if !told && now >= first.closed_us + 200_000 {
                s.ended_elsewhere(&first.id, first.speech_end_us, first.closed_us, caused);
                told = true;
            }
        });
        assert!(
            followed
                .iter()
                .any(|e| matches!(e, StreamEvent::Resumed { .. })),
            "{followed:?}"
        );
        let summary = |u: &[&ClockedUtterance]| -> Vec<(String, u64, u64, usize, u64)> {
            u.iter()
                .map(|u| {
                    (
                        u.id.clone(),
                        u.start_us,
                        u.speech_end_us,
                        u.audio.len(),
                        u.closed_us,
                    )
                })
                .collect()
        };
        assert_eq!(summary(&utterances(&followed)), summary(&theirs));
        assert_eq!(utterances(&followed), theirs);
    }
}
