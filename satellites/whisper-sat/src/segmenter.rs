//! Utterance segmentation of a 16 kHz stream with WebRTC's voice activity detector, pre-roll and hangover.
//!
//! The detector classifies 20 ms frames. An utterance starts once most frames of a short onset window are voiced
//! (a single click does not open one) and takes some audio from before the onset with it (pre-roll), so the first
//! syllable is not cut. It ends after a run of unvoiced frames as long as the hangover; the audio handed on keeps a
//! little of that silence, which Whisper transcribes better than an abrupt cut. Frames quieter than an energy floor
//! count as unvoiced whatever the detector says, which keeps faint hiss from opening utterances.
//!
//! Closing waits for the whole hangover, but the audio a closed utterance hands on is fixed much earlier: once the
//! trailing silence holds the post-roll, nothing but resumed voice can change it. At that moment the segmenter
//! reports the utterance as paused, with exactly the audio it will carry when it ends, so the satellite can
//! transcribe during the rest of the hangover. Voice that comes back before the hangover is over withdraws the pause
//! (`Resumed`); the utterance goes on and pauses or ends later.
//!
//! Broadband noise can fool the detector (it is tuned for telephony), so an utterance must also contain some tonal
//! frames: voiced speech has harmonics, so its spectrum is far from flat, while hiss, fans and static have a flat
//! spectrum. Utterances with too few frames below a spectral-flatness limit are dropped as noise.
//!
//! `webrtc_vad::Vad` wraps a raw C pointer and is not `Send`; a segmenter therefore lives on one thread (the
//! satellite gives it a thread of its own).

use std::collections::VecDeque;
use std::sync::Arc;

use realfft::{RealFftPlanner, RealToComplex};

use crate::turn::Turn;
use webrtc_vad::{SampleRate, Vad, VadMode};

/// The rate the segmenter works at (Whisper's input rate; also one WebRTC VAD supports).
pub const RATE: u32 = 16_000;
pub(crate) const FRAME: usize = 320; // 20 ms at 16 kHz

/// Tunable segmentation parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmenterConfig {
    /// WebRTC aggressiveness 0 (quality) .. 3 (very aggressive: fewest false positives).
    pub aggressiveness: u8,
    /// Audio kept from before the detected onset.
    pub pre_roll_ms: u32,
    /// Unvoiced time that ends an utterance (end-of-speech hangover).
    pub hangover_ms: u32,
    /// Onset window: an utterance opens when `onset_voiced_ms` of the last `onset_ms` are voiced.
    pub onset_ms: u32,
    pub onset_voiced_ms: u32,
    /// Utterances with less voiced time than this are dropped as clicks or bursts.
    pub min_voiced_ms: u32,
    /// Longer utterances are cut here (Whisper sees at most 30 s at once).
    pub max_utterance_ms: u32,
    /// Trailing silence kept after the last voiced frame.
    pub post_roll_ms: u32,
    /// Frames below this RMS level (dBFS) count as unvoiced.
    pub energy_floor_dbfs: f32,
    /// A frame is tonal when its spectral flatness (150 Hz - 4 kHz) is below this (white noise is about 0.56).
    pub tonal_flatness: f32,
    /// Utterances with less tonal voiced time than this are dropped as noise.
    pub min_tonal_ms: u32,
    /// Silence after which a pause whose transcript reads as a complete turn ends the utterance (the end-of-turn
    /// confirmation; at least the post-roll).
    pub turn_confirm_ms: u32,
    /// How long the end of a paused utterance waits for the verdict on its transcript, and how long an utterance
    /// whose transcript trails off is held open for the rest of the sentence.
    pub turn_wait_ms: u32,
}

impl Default for SegmenterConfig {
    fn default() -> Self {
        Self {
            aggressiveness: 3,
            pre_roll_ms: 300,
            hangover_ms: 300,
            onset_ms: 100,
            onset_voiced_ms: 80,
            min_voiced_ms: 200,
            max_utterance_ms: 25_000,
            post_roll_ms: 30,
            energy_floor_dbfs: -50.0,
            tonal_flatness: 0.3,
            min_tonal_ms: 100,
            turn_confirm_ms: 150,
            turn_wait_ms: 600,
        }
    }
}

/// Errors in a configuration.
#[derive(Debug, thiserror::Error)]
pub enum SegmenterError {
    #[error("vad aggressiveness must be 0..=3, got {0}")]
    Aggressiveness(u8),
    #[error(
        "onset_voiced_ms ({voiced}) must not exceed onset_ms ({window}), which must be at least 20"
    )]
    Onset { voiced: u32, window: u32 },
    #[error(
        "turn_confirm_ms ({confirm}) must be at least post_roll_ms ({post_roll}): a turn ends after its pause"
    )]
    Turn { confirm: u32, post_roll: u32 },
}

/// One detected utterance. Sample indices count 16 kHz samples from the start of the stream.
///
/// Two utterances are equal when their speech is (start, end of speech, audio, cut): where each was closed is
/// left out, so that a `Paused` utterance equals the `Ended` one it becomes, which is what speculation relies on.
#[derive(Debug, Clone)]
pub struct Utterance {
    /// First sample of `audio` (onset minus pre-roll).
    pub start: u64,
    /// End of the last voiced frame: the end of speech.
    pub speech_end: u64,
    /// Audio from `start`, including the post-roll.
    pub audio: Vec<f32>,
    /// True when the utterance was cut at the maximum length rather than ended by silence.
    pub forced: bool,
    /// Where the segmenter stood when it closed the utterance (for a `Paused` one, when it reported the pause):
    /// whatever comes after is the next utterance's, so another segmenter told to end the same utterance at the
    /// same pause (`Segmenter::end_as_decided`) cuts it here too.
    pub closed_at: u64,
}

impl PartialEq for Utterance {
    fn eq(&self, other: &Self) -> bool {
        (self.start, self.speech_end, self.forced) == (other.start, other.speech_end, other.forced)
            && self.audio == other.audio
    }
}

/// What became of an end decided by another segmenter (`Segmenter::end_as_decided`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DecidedEnd {
    /// The open utterance was ended at that pause, and what came after replayed as new speech.
    Applied,
    /// The stream has not reached the end's position yet: ask again later.
    Later,
    /// Not this segmenter's open utterance, or its frames say otherwise (voice inside the other's silence).
    Ignored,
}

/// What the segmenter reports while it consumes audio.
#[derive(Debug, Clone, PartialEq)]
pub enum SegmentEvent {
    /// Speech began: the utterance's audio starts at `start` (pre-roll included), the voice at `onset`.
    /// `continued` is true when this only continues speech cut at the maximum length (the voice never stopped).
    Started {
        start: u64,
        onset: u64,
        continued: bool,
    },
    /// The voice of the utterance that started at `start` has lasted long enough, and been tonal enough, to be
    /// kept as speech (`min_voiced_ms`, `min_tonal_ms`): from here on it is the user speaking, not a click or a
    /// cough. Reported once per utterance, while the voice goes on.
    Confirmed { start: u64, onset: u64 },
    /// The open utterance has been silent for its post-roll: if no voice comes back before the hangover is over,
    /// it ends with exactly this utterance (the same start, end of speech and audio). Only utterances that would be
    /// kept are reported (enough voiced and tonal frames), so speech that will be dropped never pauses.
    Paused(Utterance),
    /// Voice came back after `Paused`: the utterance that started at `start` goes on, and the paused one will not
    /// be its end.
    Resumed { start: u64 },
    /// An utterance ended by silence (or the length cap).
    Ended(Utterance),
    /// What started at `start` was too short (or too noisy) to be speech and is dropped; its last voiced frame
    /// ended at `speech_end`. `confirmed` when it had been reported as `Confirmed` (enough voice, but the
    /// utterance as a whole failed a test, which cannot happen with the defaults).
    Dropped {
        start: u64,
        speech_end: u64,
        confirmed: bool,
    },
}

enum State {
    Idle,
    Speech {
        start: u64,
        audio: Vec<f32>,
        speech_end: u64,
        voiced_frames: u32,
        tonal_frames: u32,
        silent_frames: u32,
        /// A `Paused` was reported for the current silence (so voice coming back must withdraw it).
        paused: bool,
        /// What decides the end of the current silence.
        turn: TurnHold,
        /// The first voiced frame (without the pre-roll), and whether `Confirmed` was reported.
        onset: u64,
        confirmed: bool,
        /// Where the frames after the opening one begin, and how each of them was classified (voiced, tonal):
        /// what an end decided elsewhere replays (`Segmenter::end_as_decided`). At most `max_utterance_ms` of
        /// frames: the length cap closes the utterance.
        opened: u64,
        classes: Vec<(bool, bool)>,
    },
}

/// What ends the silence of an open utterance.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum TurnHold {
    /// The ordinary hangover: nobody is judging this pause.
    Hangover,
    /// A transcript of the pause is being decoded: wait up to `turn_wait_ms` for its verdict.
    Deciding,
    /// The transcript's verdict.
    Judged(Turn),
}

/// Spectral flatness of 20 ms frames (geometric over arithmetic mean of the power spectrum).
struct Flatness {
    fft: Arc<dyn RealToComplex<f32>>,
    window: Vec<f32>,
    input: Vec<f32>,
    spectrum: Vec<realfft::num_complex::Complex<f32>>,
}

impl Flatness {
    fn new() -> Self {
        let fft = RealFftPlanner::<f32>::new().plan_fft_forward(FRAME);
        let window = (0..FRAME)
            .map(|i| 0.5 - 0.5 * (2.0 * std::f32::consts::PI * i as f32 / FRAME as f32).cos())
            .collect();
        Self {
            input: fft.make_input_vec(),
            spectrum: fft.make_output_vec(),
            fft,
            window,
        }
    }

    fn of(&mut self, frame: &[f32]) -> f32 {
        for ((x, s), w) in self.input.iter_mut().zip(frame).zip(&self.window) {
            *x = s * w;
        }
        if self
            .fft
            .process(&mut self.input, &mut self.spectrum)
            .is_err()
        {
            return 1.0;
        }
        // Bins are 50 Hz apart: 150 Hz .. 4 kHz, where voiced speech has its harmonics.
        let band = &self.spectrum[3..=80];
        let powers = band.iter().map(|c| c.norm_sqr() + 1e-12);
        let (log_sum, sum) = powers.fold((0.0f64, 0.0f64), |(l, s), p| {
            (l + f64::from(p).ln(), s + f64::from(p))
        });
        let n = band.len() as f64;
        ((log_sum / n).exp() / (sum / n)) as f32
    }
}

/// The streaming segmenter.
pub struct Segmenter {
    cfg: SegmenterConfig,
    vad: Vad,
    state: State,
    /// Partial frame not yet classified.
    partial: Vec<f32>,
    /// Absolute index of the first sample of `partial`.
    position: u64,
    /// Recent audio while idle, for the pre-roll and the onset window.
    recent: VecDeque<f32>,
    /// Voiced flags of the frames in the onset window, and how many of them were tonal.
    onset: VecDeque<bool>,
    onset_tonal: VecDeque<bool>,
    flatness: Flatness,
    /// While the agent's own speech plays, the level a frame must exceed to be the user (`echo::EchoGate`).
    echo_floor_dbfs: Option<f32>,
}

impl std::fmt::Debug for Segmenter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Segmenter")
            .field("cfg", &self.cfg)
            .field("position", &self.position)
            .field("in_speech", &matches!(self.state, State::Speech { .. }))
            .finish()
    }
}

fn frames(ms: u32) -> u32 {
    ms.div_ceil(20)
}

fn samples(ms: u32) -> usize {
    ms as usize * RATE as usize / 1000
}

/// The silence that ends an utterance whose pause stands as `turn`.
fn hangover_of(cfg: &SegmenterConfig, turn: TurnHold) -> u32 {
    match turn {
        TurnHold::Hangover | TurnHold::Judged(Turn::Unknown) => cfg.hangover_ms,
        // Never shorter than the ordinary hangover: judging a pause only ever ends it earlier when complete.
        TurnHold::Deciding | TurnHold::Judged(Turn::Incomplete) => {
            cfg.turn_wait_ms.max(cfg.hangover_ms)
        }
        TurnHold::Judged(Turn::Complete) => cfg.turn_confirm_ms,
    }
}

impl Segmenter {
    /// A segmenter starting at sample 0.
    pub fn new(cfg: SegmenterConfig) -> Result<Self, SegmenterError> {
        let mode = match cfg.aggressiveness {
            0 => VadMode::Quality,
            1 => VadMode::LowBitrate,
            2 => VadMode::Aggressive,
            3 => VadMode::VeryAggressive,
            a => return Err(SegmenterError::Aggressiveness(a)),
        };
        if cfg.onset_ms < 20 || cfg.onset_voiced_ms > cfg.onset_ms {
            return Err(SegmenterError::Onset {
                voiced: cfg.onset_voiced_ms,
                window: cfg.onset_ms,
            });
        }
        if cfg.turn_confirm_ms < cfg.post_roll_ms {
            return Err(SegmenterError::Turn {
                confirm: cfg.turn_confirm_ms,
                post_roll: cfg.post_roll_ms,
            });
        }
        Ok(Self {
            vad: Vad::new_with_rate_and_mode(SampleRate::Rate16kHz, mode),
            cfg,
            state: State::Idle,
            partial: Vec::with_capacity(FRAME),
            position: 0,
            recent: VecDeque::new(),
            onset: VecDeque::new(),
            onset_tonal: VecDeque::new(),
            flatness: Flatness::new(),
            echo_floor_dbfs: None,
        })
    }

    /// The configuration in use.
    pub fn config(&self) -> &SegmenterConfig {
        &self.cfg
    }

    /// Index of the next sample the segmenter expects.
    pub fn position(&self) -> u64 {
        self.position + self.partial.len() as u64
    }

    /// Sets the own-voice floor for the frames that follow (`None`: the agent is silent).
    pub fn set_echo_floor(&mut self, floor_dbfs: Option<f32>) {
        self.echo_floor_dbfs = floor_dbfs;
    }

    /// True while an utterance is open.
    pub fn in_speech(&self) -> bool {
        matches!(self.state, State::Speech { .. })
    }

    /// Consumes 16 kHz samples, appending what happened to `events`.
    pub fn push(&mut self, mut input: &[f32], events: &mut Vec<SegmentEvent>) {
        while !input.is_empty() {
            let take = (FRAME - self.partial.len()).min(input.len());
            self.partial.extend_from_slice(&input[..take]);
            input = &input[take..];
            if self.partial.len() == FRAME {
                let frame = std::mem::take(&mut self.partial);
                self.frame(&frame, events);
                self.position += FRAME as u64;
                self.partial = frame;
                self.partial.clear();
            }
        }
    }

    /// Ends the stream: an open utterance is closed as if silence followed.
    pub fn finish(&mut self, events: &mut Vec<SegmentEvent>) {
        if let State::Speech { .. } = self.state {
            self.close(false, self.position, events);
        }
        self.reset_detector();
    }

    /// Forgets all state (a gap in the stream), keeping the sample position.
    pub fn reset_detector(&mut self) {
        self.vad.reset();
        self.state = State::Idle;
        self.recent.clear();
        self.onset.clear();
        self.onset_tonal.clear();
    }

    /// Moves the position forward without audio (the stream skipped), closing anything open first.
    pub fn skip_to(&mut self, position: u64, events: &mut Vec<SegmentEvent>) {
        self.finish(events);
        self.partial.clear();
        self.position = position;
    }

    /// A transcript of the pause that ended speech at `speech_end` in the utterance starting at `start` is being
    /// decoded (`None`) or has been judged (`Some`). While it is decoded, the end waits up to `turn_wait_ms` for
    /// the verdict; a complete turn then ends once the silence holds `turn_confirm_ms` (at once if it already
    /// does), an incomplete one is held open for `turn_wait_ms`, and an unknown one ends after the ordinary
    /// hangover. Ignored when the utterance is no longer at that pause (the voice resumed, or it ended).
    pub fn turn(
        &mut self,
        start: u64,
        speech_end: u64,
        verdict: Option<Turn>,
        events: &mut Vec<SegmentEvent>,
    ) {
        let State::Speech {
            start: open,
            speech_end: open_end,
            silent_frames,
            paused: true,
            turn,
            ..
        } = &mut self.state
        else {
            return;
        };
        if *open != start || *open_end != speech_end {
            return;
        }
        *turn = verdict.map_or(TurnHold::Deciding, TurnHold::Judged);
        if *silent_frames >= frames(hangover_of(&self.cfg, *turn)) {
            self.close(false, self.position, events);
        }
    }

    /// Where the open utterance starts and where its frames lie: `(start, opened)`, frame boundaries being
    /// `opened` plus whole frames (`None` when no utterance is open).
    pub fn open_utterance(&self) -> Option<(u64, u64)> {
        match &self.state {
            State::Speech { start, opened, .. } => Some((*start, *opened)),
            State::Idle => None,
        }
    }

    /// Another segmenter on the same stream (the satellite decoding the open utterance, which alone judges the
    /// end of its turn) ended the utterance that starts at `start` at the pause after `speech_end`, closing it at
    /// `closed_at`. Its verdict came in time there and late here (or never), so here the voice may have resumed
    /// since: the utterance is ended at that pause all the same, and the frames from `closed_at` on are replayed
    /// from the utterance's own audio and classification as new speech. Both segmenters then agree on the
    /// utterance and on the next one's start. Ignored unless the utterance is open here and its frames from
    /// `speech_end` to `closed_at` were silent here too.
    pub fn end_as_decided(
        &mut self,
        start: u64,
        speech_end: u64,
        closed_at: u64,
        events: &mut Vec<SegmentEvent>,
    ) -> DecidedEnd {
        let State::Speech {
            start: open,
            speech_end: open_end,
            opened,
            classes,
            ..
        } = &self.state
        else {
            return DecidedEnd::Ignored;
        };
        let on_grid = |p: u64| p >= *opened && (p - *opened).is_multiple_of(FRAME as u64);
        if *open != start
            || speech_end > *open_end
            || closed_at <= speech_end
            || !on_grid(speech_end)
            || !on_grid(closed_at)
        {
            return DecidedEnd::Ignored;
        }
        if self.position < closed_at {
            return DecidedEnd::Later;
        }
        let first = ((speech_end - *opened) / FRAME as u64) as usize;
        let last = ((closed_at - *opened) / FRAME as u64) as usize;
        if classes
            .get(first..last)
            .is_none_or(|c| c.iter().any(|&(v, _)| v))
        {
            return DecidedEnd::Ignored;
        }
        let State::Speech {
            audio,
            voiced_frames,
            tonal_frames,
            onset,
            opened,
            classes,
            ..
        } = std::mem::replace(&mut self.state, State::Idle)
        else {
            return DecidedEnd::Ignored;
        };
        // The utterance as it stood when the other segmenter closed it: the frames after `speech_end` count for
        // the speech that follows.
        let after = &classes[first..];
        let voiced = voiced_frames - after.iter().filter(|c| c.0).count() as u32;
        let tonal = tonal_frames - after.iter().filter(|c| c.1).count() as u32;
        let upto = ((closed_at - start) as usize).min(audio.len());
        self.state = State::Speech {
            start,
            audio: audio[..upto].to_vec(),
            speech_end,
            voiced_frames: voiced,
            tonal_frames: tonal,
            silent_frames: (last - first) as u32,
            paused: true,
            turn: TurnHold::Hangover,
            onset,
            confirmed: voiced >= frames(self.cfg.min_voiced_ms)
                && tonal >= frames(self.cfg.min_tonal_ms),
            opened,
            classes: Vec::new(),
        };
        self.close(false, closed_at, events);
        // From `closed_at` the other segmenter was idle: so is this one, over the same frames.
        self.recent.clear();
        self.onset.clear();
        self.onset_tonal.clear();
        let now = self.position;
        for (i, &(v, t)) in classes[last..].iter().enumerate() {
            let at = closed_at + (i * FRAME) as u64;
            let from = (at - start) as usize;
            let Some(frame) = audio.get(from..from + FRAME) else {
                break;
            };
            self.position = at;
            self.step(frame, v, t, events);
        }
        self.position = now;
        DecidedEnd::Applied
    }

    /// Whether the frame is voiced, and whether it is also tonal.
    fn classify(&mut self, frame: &[f32]) -> (bool, bool) {
        let voiced = self.voiced(frame);
        let tonal = voiced && self.flatness.of(frame) < self.cfg.tonal_flatness;
        (voiced, tonal)
    }

    fn voiced(&mut self, frame: &[f32]) -> bool {
        let energy = frame.iter().map(|s| s * s).sum::<f32>() / frame.len() as f32;
        let dbfs = 10.0 * energy.max(1e-12).log10();
        let pcm: Vec<i16> = frame
            .iter()
            .map(|s| (s * 32768.0).clamp(-32768.0, 32767.0) as i16)
            .collect();
        // A frame of the right length at a supported rate is always accepted by the detector.
        let vad_says = self.vad.is_voice_segment(&pcm).unwrap_or(false);
        let floor = self
            .echo_floor_dbfs
            .map_or(self.cfg.energy_floor_dbfs, |echo| {
                echo.max(self.cfg.energy_floor_dbfs)
            });
        vad_says && dbfs >= floor
    }

    fn frame(&mut self, frame: &[f32], events: &mut Vec<SegmentEvent>) {
        let (voiced, tonal) = self.classify(frame);
        self.step(frame, voiced, tonal, events);
    }

    /// Moves the state on by one frame (starting at `self.position`) classified as `voiced` and `tonal`.
    fn step(&mut self, frame: &[f32], voiced: bool, tonal: bool, events: &mut Vec<SegmentEvent>) {
        let frame_end = self.position + FRAME as u64;
        match &mut self.state {
            State::Idle => {
                self.recent.extend(frame);
                let keep = samples(self.cfg.pre_roll_ms) + samples(self.cfg.onset_ms) + FRAME;
                while self.recent.len() > keep {
                    self.recent.pop_front();
                }
                self.onset.push_back(voiced);
                self.onset_tonal.push_back(tonal);
                while self.onset.len() > frames(self.cfg.onset_ms) as usize {
                    self.onset.pop_front();
                    self.onset_tonal.pop_front();
                }
                let voiced_in_window = self.onset.iter().filter(|&&v| v).count() as u32;
                if voiced && voiced_in_window >= frames(self.cfg.onset_voiced_ms) {
                    // Speech began at the first voiced frame of the window; the pre-roll reaches back from there.
                    let first = self.onset.iter().position(|&v| v).unwrap_or(0);
                    let window_start = frame_end - (self.onset.len() * FRAME) as u64;
                    let onset_at = window_start + (first * FRAME) as u64;
                    let recent_start = frame_end - self.recent.len() as u64;
                    let start = onset_at
                        .saturating_sub(samples(self.cfg.pre_roll_ms) as u64)
                        .max(recent_start);
                    let audio: Vec<f32> = self
                        .recent
                        .iter()
                        .skip((start - recent_start) as usize)
                        .copied()
                        .collect();
                    let tonal_frames = self.onset_tonal.iter().filter(|&&t| t).count() as u32;
                    self.recent.clear();
                    self.onset.clear();
                    self.onset_tonal.clear();
                    self.state = State::Speech {
                        start,
                        audio,
                        speech_end: frame_end,
                        voiced_frames: voiced_in_window,
                        tonal_frames,
                        silent_frames: 0,
                        paused: false,
                        turn: TurnHold::Hangover,
                        onset: onset_at,
                        confirmed: false,
                        opened: frame_end,
                        classes: Vec::new(),
                    };
                    events.push(SegmentEvent::Started {
                        start,
                        onset: onset_at,
                        continued: false,
                    });
                }
            }
            State::Speech {
                start,
                audio,
                speech_end,
                voiced_frames,
                tonal_frames,
                silent_frames,
                paused,
                turn,
                onset,
                confirmed,
                classes,
                ..
            } => {
                audio.extend_from_slice(frame);
                classes.push((voiced, tonal));
                if voiced {
                    if std::mem::take(paused) {
                        events.push(SegmentEvent::Resumed { start: *start });
                    }
                    *speech_end = frame_end;
                    *voiced_frames += 1;
                    *tonal_frames += u32::from(tonal);
                    *silent_frames = 0;
                    // Whatever was judged was the speech before this voice.
                    *turn = TurnHold::Hangover;
                    if !*confirmed
                        && *voiced_frames >= frames(self.cfg.min_voiced_ms)
                        && *tonal_frames >= frames(self.cfg.min_tonal_ms)
                    {
                        *confirmed = true;
                        events.push(SegmentEvent::Confirmed {
                            start: *start,
                            onset: *onset,
                        });
                    }
                } else {
                    *silent_frames += 1;
                }
                let too_long = audio.len() >= samples(self.cfg.max_utterance_ms);
                if *silent_frames >= frames(hangover_of(&self.cfg, *turn)) {
                    self.close(false, frame_end, events);
                } else if too_long {
                    self.close(true, frame_end, events);
                } else if !voiced && !*paused {
                    // The first frame whose silence covers the post-roll: the audio a close would keep is complete.
                    let keep = (*speech_end - *start) as usize + samples(self.cfg.post_roll_ms);
                    let kept = *voiced_frames >= frames(self.cfg.min_voiced_ms)
                        && *tonal_frames >= frames(self.cfg.min_tonal_ms);
                    if kept && audio.len() >= keep {
                        *paused = true;
                        events.push(SegmentEvent::Paused(Utterance {
                            start: *start,
                            speech_end: *speech_end,
                            audio: audio[..keep].to_vec(),
                            forced: false,
                            closed_at: frame_end,
                        }));
                    }
                }
            }
        }
    }

    /// Closes the open utterance, the segmenter standing at `closed_at`.
    fn close(&mut self, forced: bool, closed_at: u64, events: &mut Vec<SegmentEvent>) {
        let State::Speech {
            start,
            mut audio,
            speech_end,
            voiced_frames,
            tonal_frames,
            confirmed,
            ..
        } = std::mem::replace(&mut self.state, State::Idle)
        else {
            return;
        };
        if voiced_frames < frames(self.cfg.min_voiced_ms)
            || tonal_frames < frames(self.cfg.min_tonal_ms)
        {
            events.push(SegmentEvent::Dropped {
                start,
                speech_end,
                confirmed,
            });
            return;
        }
        let keep = (speech_end - start) as usize + samples(self.cfg.post_roll_ms);
        if forced {
            // Cut at the current position; the speech goes on in a new utterance that starts right here.
            let end = start + audio.len() as u64;
            events.push(SegmentEvent::Ended(Utterance {
                start,
                speech_end: end,
                audio,
                forced: true,
                closed_at: end,
            }));
            self.state = State::Speech {
                start: end,
                audio: Vec::new(),
                speech_end: end,
                voiced_frames: 0,
                tonal_frames: 0,
                silent_frames: 0,
                paused: false,
                turn: TurnHold::Hangover,
                onset: end,
                // The voice never stopped: it was confirmed in the piece before the cut.
                confirmed: true,
                opened: end,
                classes: Vec::new(),
            };
            events.push(SegmentEvent::Started {
                start: end,
                onset: end,
                continued: true,
            });
            return;
        }
        audio.truncate(keep);
        events.push(SegmentEvent::Ended(Utterance {
            start,
            speech_end,
            audio,
            forced,
            closed_at,
        }));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vowel-like harmonic tone with a 4 Hz syllable envelope: speech-like enough for the WebRTC detector.
    fn voice(ms: u32) -> Vec<f32> {
        let n = samples(ms);
        (0..n)
            .map(|i| {
                let t = i as f32 / RATE as f32;
                let env = 0.6 + 0.4 * (2.0 * std::f32::consts::PI * 4.0 * t).sin();
                let f0 = 140.0;
                let s: f32 = (1..=12)
                    .map(|h| (2.0 * std::f32::consts::PI * f0 * h as f32 * t).sin() / h as f32)
                    .sum();
                0.15 * env * s
            })
            .collect()
    }

    /// Deterministic loud white noise (xorshift), which the WebRTC detector takes for voice.
    fn white_noise(ms: u32) -> Vec<f32> {
        let mut x = 0x9e37_79b9_u32;
        (0..samples(ms))
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                (x as f32 / u32::MAX as f32 - 0.5) * 0.35
            })
            .collect()
    }

    fn silence(ms: u32) -> Vec<f32> {
        vec![0.0; samples(ms)]
    }

    fn run(cfg: SegmenterConfig, audio: &[f32]) -> Vec<SegmentEvent> {
        let mut seg = Segmenter::new(cfg).expect("valid config");
        let mut ev = Vec::new();
        for chunk in audio.chunks(441) {
            seg.push(chunk, &mut ev);
        }
        seg.finish(&mut ev);
        ev
    }

    fn ended(ev: &[SegmentEvent]) -> Vec<&Utterance> {
        ev.iter()
            .filter_map(|e| match e {
                SegmentEvent::Ended(u) => Some(u),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn silence_opens_nothing() {
        let ev = run(SegmenterConfig::default(), &silence(3000));
        assert!(ev.is_empty(), "{ev:?}");
    }

    #[test]
    fn one_burst_gives_one_utterance_with_pre_roll_and_hangover() {
        let audio = [silence(1000), voice(1500), silence(1000)].concat();
        let cfg = SegmenterConfig::default();
        let ev = run(cfg.clone(), &audio);
        let utts = ended(&ev);
        assert_eq!(utts.len(), 1, "{ev:?}");
        let u = utts[0];
        let onset = samples(1000) as u64;
        // The start reaches back into the silence by about the pre-roll.
        assert!(
            u.start < onset && u.start + samples(cfg.pre_roll_ms) as u64 >= onset - FRAME as u64,
            "{}",
            u.start
        );
        // The end of speech is within two frames of the true end.
        let true_end = samples(2500) as u64;
        assert!(
            u.speech_end.abs_diff(true_end) <= 2 * FRAME as u64,
            "{}",
            u.speech_end
        );
        assert_eq!(
            u.audio.len() as u64,
            u.speech_end - u.start + samples(cfg.post_roll_ms) as u64
        );
        assert!(matches!(ev[0], SegmentEvent::Started { .. }));
    }

    #[test]
    fn a_pause_shorter_than_the_hangover_does_not_split() {
        let audio = [
            silence(500),
            voice(800),
            silence(200),
            voice(800),
            silence(800),
        ]
        .concat();
        let ev = run(SegmenterConfig::default(), &audio);
        assert_eq!(ended(&ev).len(), 1, "{ev:?}");
        let longer = SegmenterConfig {
            hangover_ms: 100,
            ..SegmenterConfig::default()
        };
        assert_eq!(ended(&run(longer, &audio)).len(), 2);
    }

    #[test]
    fn clicks_are_dropped_and_long_speech_is_cut() {
        let audio = [silence(500), voice(60), silence(1000)].concat();
        let ev = run(SegmenterConfig::default(), &audio);
        assert!(ended(&ev).is_empty(), "{ev:?}");
        let capped = SegmenterConfig {
            max_utterance_ms: 1000,
            ..SegmenterConfig::default()
        };
        let ev = run(capped, &[voice(2500), silence(600)].concat());
        let utts = ended(&ev);
        assert!(utts.len() >= 2, "{ev:?}");
        assert!(utts[0].forced);
        assert_eq!(utts[1].start, utts[0].start + utts[0].audio.len() as u64);
    }

    /// Feeds 20 ms chunks and records each event with the position it was reported at.
    fn run_timed(cfg: SegmenterConfig, audio: &[f32]) -> Vec<(u64, SegmentEvent)> {
        let mut seg = Segmenter::new(cfg).expect("valid config");
        let mut out = Vec::new();
        let mut ev = Vec::new();
        for chunk in audio.chunks(FRAME) {
            seg.push(chunk, &mut ev);
            out.extend(ev.drain(..).map(|e| (seg.position(), e)));
        }
        seg.finish(&mut ev);
        out.extend(ev.drain(..).map(|e| (seg.position(), e)));
        out
    }

    /// The events by kind and position, short enough to print (utterance audio is not).
    fn kinds(ev: &[(u64, SegmentEvent)]) -> Vec<String> {
        ev.iter()
            .map(|(at, e)| match e {
                SegmentEvent::Started { .. } => "started".to_owned(),
                SegmentEvent::Confirmed { .. } => "confirmed".to_owned(),
                SegmentEvent::Paused(_) => "paused".to_owned(),
                SegmentEvent::Resumed { .. } => "resumed".to_owned(),
                SegmentEvent::Ended(u) if u.forced => format!("cut at {at}"),
                SegmentEvent::Ended(_) => "ended".to_owned(),
                SegmentEvent::Dropped { .. } => "dropped".to_owned(),
            })
            .collect()
    }

    fn paused(ev: &[(u64, SegmentEvent)]) -> Vec<(u64, &Utterance)> {
        ev.iter()
            .filter_map(|(at, e)| match e {
                SegmentEvent::Paused(u) => Some((*at, u)),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn a_pause_reports_exactly_the_utterance_that_ends_later() {
        let cfg = SegmenterConfig::default();
        let audio = [silence(1000), voice(1500), silence(1000)].concat();
        let ev = run_timed(cfg.clone(), &audio);
        let pauses = paused(&ev);
        assert_eq!(pauses.len(), 1, "{:?}", kinds(&ev));
        let (paused_at, p) = pauses[0];
        let (ended_at, e) = ev
            .iter()
            .find_map(|(at, e)| match e {
                SegmentEvent::Ended(u) => Some((*at, u)),
                _ => None,
            })
            .expect("the utterance ends");
        assert_eq!(p, e, "the paused utterance differs from the ended one");
        // Reported as soon as the silence covers the post-roll (rounded up to whole frames), well before the end.
        let post_roll_frames = u64::from(frames(cfg.post_roll_ms));
        assert_eq!(paused_at - p.speech_end, post_roll_frames * FRAME as u64);
        assert_eq!(
            ended_at - e.speech_end,
            u64::from(frames(cfg.hangover_ms)) * FRAME as u64
        );
        assert!(
            !ev.iter()
                .any(|(_, e)| matches!(e, SegmentEvent::Resumed { .. }))
        );
    }

    #[test]
    fn voice_after_a_pause_withdraws_it_and_the_last_pause_is_the_end() {
        let audio = [
            silence(500),
            voice(800),
            silence(240),
            voice(800),
            silence(800),
        ]
        .concat();
        let ev = run_timed(SegmenterConfig::default(), &audio);
        assert_eq!(
            kinds(&ev),
            [
                "started",
                "confirmed",
                "paused",
                "resumed",
                "paused",
                "ended"
            ]
        );
        let pauses = paused(&ev);
        let utts = ended(&ev.iter().map(|(_, e)| e.clone()).collect::<Vec<_>>())
            .into_iter()
            .cloned()
            .collect::<Vec<_>>();
        let Some(start) = ev.iter().find_map(|(_, e)| match e {
            SegmentEvent::Resumed { start } => Some(*start),
            _ => None,
        }) else {
            panic!("{:?}", kinds(&ev))
        };
        assert_eq!(start, utts[0].start);
        // The first pause was provisional: the utterance went on past it.
        assert_eq!(pauses[0].1.start, utts[0].start);
        assert!(pauses[0].1.speech_end < utts[0].speech_end);
        assert!(pauses[0].1.audio.len() < utts[0].audio.len());
        assert_eq!(pauses[1].1, &utts[0]);
    }

    /// Runs `audio` 20 ms at a time; at each pause the satellite's side answers with `judge` (what `turn` gets:
    /// `None` for a decode still running), or stays silent when `judge` gives `Err`.
    fn run_judged(
        cfg: SegmenterConfig,
        audio: &[f32],
        judge: impl Fn(usize) -> Result<Option<Turn>, ()>,
    ) -> Vec<(u64, SegmentEvent)> {
        let mut seg = Segmenter::new(cfg).expect("valid config");
        let mut out = Vec::new();
        let mut ev = Vec::new();
        let mut pauses = 0;
        for chunk in audio.chunks(FRAME) {
            seg.push(chunk, &mut ev);
            let pause = ev.iter().find_map(|e| match e {
                SegmentEvent::Paused(u) => Some((u.start, u.speech_end)),
                _ => None,
            });
            out.extend(ev.drain(..).map(|e| (seg.position(), e)));
            if let Some((start, speech_end)) = pause {
                if let Ok(verdict) = judge(pauses) {
                    seg.turn(start, speech_end, verdict, &mut ev);
                    out.extend(ev.drain(..).map(|e| (seg.position(), e)));
                }
                pauses += 1;
            }
        }
        seg.finish(&mut ev);
        out.extend(ev.drain(..).map(|e| (seg.position(), e)));
        out
    }

    fn ends(ev: &[(u64, SegmentEvent)]) -> Vec<(u64, &Utterance)> {
        ev.iter()
            .filter_map(|(at, e)| match e {
                SegmentEvent::Ended(u) => Some((*at, u)),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn a_complete_turn_ends_at_its_pause_with_the_audio_it_paused_with() {
        let cfg = SegmenterConfig::default();
        let audio = [silence(500), voice(1200), silence(1000)].concat();
        let ev = run_judged(cfg.clone(), &audio, |_| Ok(Some(Turn::Complete)));
        assert_eq!(kinds(&ev), ["started", "confirmed", "paused", "ended"]);
        let (paused_at, p) = paused(&ev)[0];
        let (ended_at, e) = ends(&ev)[0];
        assert_eq!(p, e);
        // Judged at once, the turn ends when the silence holds the confirmation (the pause already held the
        // post-roll), long before the hangover.
        let confirm = u64::from(frames(cfg.turn_confirm_ms).max(frames(cfg.post_roll_ms)));
        assert_eq!(ended_at - e.speech_end, confirm * FRAME as u64);
        assert!(ended_at >= paused_at);
        assert!(confirm < u64::from(frames(cfg.hangover_ms)));
    }

    #[test]
    fn an_incomplete_turn_is_held_open_across_a_pause_longer_than_the_hangover() {
        let cfg = SegmenterConfig::default();
        // "What time ... is it?": 400 ms of silence inside the sentence, more than the 300 ms hangover.
        let audio = [
            silence(500),
            voice(700),
            silence(400),
            voice(600),
            silence(1500),
        ]
        .concat();
        let unjudged = run_judged(cfg.clone(), &audio, |_| Err(()));
        assert_eq!(ends(&unjudged).len(), 2, "{:?}", kinds(&unjudged));
        let judged = run_judged(cfg.clone(), &audio, |n| {
            Ok(Some(if n == 0 {
                Turn::Incomplete
            } else {
                Turn::Complete
            }))
        });
        assert_eq!(
            kinds(&judged),
            [
                "started",
                "confirmed",
                "paused",
                "resumed",
                "paused",
                "ended"
            ]
        );
        let (_, whole) = ends(&judged)[0];
        assert!(whole.audio.len() >= samples(1600), "{}", whole.audio.len());
    }

    #[test]
    fn a_pause_waits_for_its_verdict_but_not_for_ever() {
        let cfg = SegmenterConfig::default();
        let audio = [silence(500), voice(1000), silence(2000)].concat();
        let ev = run_judged(cfg.clone(), &audio, |_| Ok(None));
        let (ended_at, e) = ends(&ev)[0];
        assert_eq!(
            ended_at - e.speech_end,
            u64::from(frames(cfg.turn_wait_ms)) * FRAME as u64
        );
        // An unknown verdict is the ordinary hangover.
        let ev = run_judged(cfg.clone(), &audio, |_| Ok(Some(Turn::Unknown)));
        let (ended_at, e) = ends(&ev)[0];
        assert_eq!(
            ended_at - e.speech_end,
            u64::from(frames(cfg.hangover_ms)) * FRAME as u64
        );
    }

    #[test]
    fn a_verdict_on_a_pause_the_voice_has_left_is_ignored() {
        let cfg = SegmenterConfig::default();
        let audio = [
            silence(500),
            voice(800),
            silence(200),
            voice(800),
            silence(1000),
        ]
        .concat();
        let mut seg = Segmenter::new(cfg.clone()).expect("valid config");
        let mut ev = Vec::new();
        let mut first_pause = None;
        let mut judged_late = false;
        for chunk in audio.chunks(FRAME) {
            let mut step = Vec::new();
            seg.push(chunk, &mut step);
            let mut after = Vec::new();
            for e in &step {
                match e {
                    SegmentEvent::Paused(u) => {
                        first_pause.get_or_insert((u.start, u.speech_end));
                    }
                    // Judged complete only once the voice is back: nothing may end early.
                    SegmentEvent::Resumed { .. } => {
                        let (start, speech_end) = first_pause.expect("a pause before");
                        seg.turn(start, speech_end, Some(Turn::Complete), &mut after);
                        judged_late = true;
                    }
                    _ => {}
                }
            }
            ev.extend(step);
            ev.extend(after);
        }
        assert!(judged_late);
        let utts = ended(&ev);
        assert_eq!(utts.len(), 1);
        assert!(utts[0].speech_end > first_pause.expect("a pause").1);
    }

    /// Feeds `audio` frame by frame; after each frame `hook` sees the segmenter, the frame's events and where to
    /// put events it causes. Returns every event.
    fn run_hooked(
        audio: &[f32],
        mut hook: impl FnMut(&mut Segmenter, &[SegmentEvent], &mut Vec<SegmentEvent>),
    ) -> Vec<SegmentEvent> {
        let mut seg = Segmenter::new(SegmenterConfig::default()).expect("valid config");
        let mut all = Vec::new();
        for chunk in audio.chunks(FRAME) {
            let mut step = Vec::new();
            seg.push(chunk, &mut step);
            let mut caused = Vec::new();
            hook(&mut seg, &step, &mut caused);
            all.extend(step);
            all.extend(caused);
        }
        seg.finish(&mut all);
        all
    }

    #[test]
    fn an_end_decided_by_the_decoder_splits_speech_that_resumed_here_as_the_decoder_did() {
        // 400 ms of silence: past the 300 ms hangover, short of the 600 ms a pause waits for its verdict.
        let audio = [
            silence(500),
            voice(800),
            silence(400),
            voice(800),
            silence(1000),
        ]
        .concat();
        // The decoder held the end for its transcript, whose verdict (unknown: the hangover) came 340 ms into the
        // silence, and ended the utterance there.
        let mut pause = None;
        let mut since_pause = 0;
        let decoder = run_hooked(&audio, |seg, step, caused| {
            for e in step {
                if let SegmentEvent::Paused(u) = e {
                    pause.get_or_insert((u.start, u.speech_end));
                    seg.turn(u.start, u.speech_end, None, caused);
                }
            }
            if let Some((start, speech_end)) = pause {
                since_pause += 1;
                if since_pause == 16 {
                    seg.turn(start, speech_end, Some(Turn::Unknown), caused);
                }
            }
        });
        let decoded = ended(&decoder);
        assert_eq!(decoded.len(), 2, "{:?}", kinds_of(&decoder));
        let first = decoded[0].clone();
        assert!(first.closed_at > first.speech_end + samples(300) as u64);
        // Here the verdict never came in time: the voice resumed, and the decoder's end arrives mid-sentence.
        let mut told = None;
        let follower = run_hooked(&audio, |seg, step, caused| {
            for e in step {
                if let SegmentEvent::Paused(u) = e {
                    seg.turn(u.start, u.speech_end, None, caused);
                }
            }
            if told.is_none() && seg.position() >= first.closed_at + samples(300) as u64 {
                told = Some(seg.end_as_decided(
                    first.start,
                    first.speech_end,
                    first.closed_at,
                    caused,
                ));
            }
        });
        assert_eq!(told, Some(DecidedEnd::Applied));
        assert!(
            kinds_of(&follower).contains(&"resumed"),
            "{:?}",
            kinds_of(&follower)
        );
        assert_eq!(ended(&follower), decoded);
        let closed =
            |ev: &[SegmentEvent]| ended(ev).iter().map(|u| u.closed_at).collect::<Vec<_>>();
        assert_eq!(closed(&follower), closed(&decoder));
    }

    #[test]
    fn an_end_decided_elsewhere_waits_for_the_stream_and_yields_to_voice_heard_here() {
        let audio = [silence(500), voice(800), silence(1000)].concat();
        let mut seg = Segmenter::new(SegmenterConfig::default()).expect("valid config");
        let mut ev = Vec::new();
        seg.push(&audio[..samples(1400)], &mut ev);
        let (start, opened) = seg.open_utterance().expect("speech open");
        let speech_end = ev
            .iter()
            .find_map(|e| match e {
                SegmentEvent::Paused(u) => Some(u.speech_end),
                _ => None,
            })
            .expect("paused");
        // Ahead of this stream: later. Inside the voice: not this stream's silence. Off the frames: not ours.
        let closed_at = speech_end + 8 * FRAME as u64;
        assert_eq!(
            seg.end_as_decided(start, speech_end, closed_at, &mut ev),
            DecidedEnd::Later
        );
        assert_eq!(
            seg.end_as_decided(start, speech_end - 20 * FRAME as u64, speech_end, &mut ev),
            DecidedEnd::Ignored
        );
        assert_eq!(
            seg.end_as_decided(start, speech_end, closed_at + 7, &mut ev),
            DecidedEnd::Ignored
        );
        assert_eq!(
            seg.end_as_decided(start + FRAME as u64, speech_end, closed_at, &mut ev),
            DecidedEnd::Ignored
        );
        assert!(opened <= speech_end);
        // Once the stream is there, the utterance ends at that pause, closed where the other segmenter closed it.
        seg.push(&audio[samples(1400)..samples(1500)], &mut ev);
        let before = ended(&ev).len();
        assert_eq!(
            seg.end_as_decided(start, speech_end, closed_at, &mut ev),
            DecidedEnd::Applied
        );
        let utts = ended(&ev);
        assert_eq!(utts.len(), before + 1);
        let u = utts[before];
        assert_eq!(
            (u.start, u.speech_end, u.closed_at),
            (start, speech_end, closed_at)
        );
        assert!(seg.open_utterance().is_none());
    }

    fn kinds_of(ev: &[SegmentEvent]) -> Vec<&'static str> {
        ev.iter()
            .map(|e| match e {
                SegmentEvent::Started { .. } => "started",
                SegmentEvent::Confirmed { .. } => "confirmed",
                SegmentEvent::Paused(_) => "paused",
                SegmentEvent::Resumed { .. } => "resumed",
                SegmentEvent::Ended(_) => "ended",
                SegmentEvent::Dropped { .. } => "dropped",
            })
            .collect()
    }

    #[test]
    fn a_confirmation_shorter_than_the_post_roll_is_refused() {
        let cfg = SegmenterConfig {
            turn_confirm_ms: 100,
            post_roll_ms: 150,
            ..SegmenterConfig::default()
        };
        assert!(matches!(
            Segmenter::new(cfg),
            Err(SegmenterError::Turn { .. })
        ));
    }

    #[test]
    fn voice_is_confirmed_once_it_has_lasted_the_minimum_voiced_time() {
        let cfg = SegmenterConfig::default();
        let ev = run_timed(
            cfg.clone(),
            &[silence(500), voice(1500), silence(1000)].concat(),
        );
        let confirmed: Vec<(u64, u64)> = ev
            .iter()
            .filter_map(|(at, e)| match e {
                SegmentEvent::Confirmed { onset, .. } => Some((*at, *onset)),
                _ => None,
            })
            .collect();
        assert_eq!(confirmed.len(), 1, "{:?}", kinds(&ev));
        let (at, onset) = confirmed[0];
        // Within two frames of the onset plus the minimum voiced time: the user has been speaking for 200 ms.
        let after = at - onset;
        let min = samples(cfg.min_voiced_ms) as u64;
        assert!(
            after >= min - FRAME as u64 && after <= min + 2 * FRAME as u64,
            "{after}"
        );
        assert_eq!(kinds(&ev)[..2], ["started", "confirmed"]);
    }

    #[test]
    fn speech_that_is_dropped_never_pauses() {
        // A click (never opens), a burst that opens but is under the minimum voiced time, and loud white noise.
        let noise = white_noise(2000);
        for audio in [
            [silence(500), voice(60), silence(1000)].concat(),
            [silence(500), voice(120), silence(1000)].concat(),
            [silence(500), noise, silence(1000)].concat(),
        ] {
            let ev = run_timed(SegmenterConfig::default(), &audio);
            assert!(paused(&ev).is_empty(), "{:?}", kinds(&ev));
            // Nor is it ever taken for the user speaking (no barge-in on a click or a cough).
            assert!(
                !ev.iter()
                    .any(|(_, e)| matches!(e, SegmentEvent::Confirmed { .. })),
                "{:?}",
                kinds(&ev)
            );
            assert!(
                !ev.iter().any(|(_, e)| matches!(e, SegmentEvent::Ended(_))),
                "{:?}",
                kinds(&ev)
            );
        }
    }

    #[test]
    fn the_length_cut_still_works_and_supersedes_a_pause() {
        let capped = SegmenterConfig {
            max_utterance_ms: 1000,
            ..SegmenterConfig::default()
        };
        // Continuous voice: cut at the maximum length, never paused.
        let ev = run_timed(capped.clone(), &[voice(2500), silence(600)].concat());
        let utts: Vec<&Utterance> = ev
            .iter()
            .filter_map(|(_, e)| match e {
                SegmentEvent::Ended(u) => Some(u),
                _ => None,
            })
            .collect();
        assert!(utts.len() >= 2 && utts[0].forced, "{:?}", kinds(&ev));
        assert_eq!(utts[0].audio.len(), samples(1000));
        assert_eq!(utts[1].start, utts[0].start + utts[0].audio.len() as u64);
        let pauses = paused(&ev);
        assert_eq!(
            pauses.len(),
            1,
            "only the last piece pauses: {:?}",
            kinds(&ev)
        );
        assert_eq!(pauses[0].1, *utts.last().expect("utterances"));
        // A cut that falls in the hangover after a pause: the forced end is not the paused utterance.
        let ev = run_timed(capped, &[voice(760), silence(600)].concat());
        let p = paused(&ev);
        let forced = ev.iter().find_map(|(_, e)| match e {
            SegmentEvent::Ended(u) if u.forced => Some(u),
            _ => None,
        });
        let (Some((_, p)), Some(forced)) = (p.first(), forced) else {
            panic!("expected a pause and then a cut: {:?}", kinds(&ev))
        };
        assert_eq!(p.start, forced.start);
        assert_ne!(*p, forced, "{:?}", kinds(&ev));
    }

    #[test]
    fn quiet_hiss_stays_below_the_energy_floor() {
        // Deterministic pseudo-random noise at about -60 dBFS.
        let mut x = 12345u32;
        let hiss: Vec<f32> = (0..samples(3000))
            .map(|_| {
                x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
                ((x >> 16) as f32 / 32768.0 - 1.0) * 0.0017
            })
            .collect();
        assert!(ended(&run(SegmenterConfig::default(), &hiss)).is_empty());
    }

    #[test]
    fn loud_white_noise_is_dropped_even_when_the_detector_fires() {
        let noise = white_noise(3000);
        let audio = [silence(500), noise, silence(1000)].concat();
        assert!(ended(&run(SegmenterConfig::default(), &audio)).is_empty());
        // The same noise with a voice over it is speech.
        let voiced: Vec<f32> = audio
            .iter()
            .zip([silence(700), voice(1500), silence(2300)].concat())
            .map(|(n, v)| n * 0.3 + v)
            .collect();
        assert_eq!(ended(&run(SegmenterConfig::default(), &voiced)).len(), 1);
    }

    #[test]
    fn invalid_configuration_is_rejected() {
        assert!(
            Segmenter::new(SegmenterConfig {
                aggressiveness: 4,
                ..SegmenterConfig::default()
            })
            .is_err()
        );
        assert!(
            Segmenter::new(SegmenterConfig {
                onset_voiced_ms: 200,
                ..SegmenterConfig::default()
            })
            .is_err()
        );
    }
}
