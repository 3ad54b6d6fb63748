//! The canceller: microphone messages in, the same audio less the agent's echo out.
//!
//! Audio is processed in 10 ms frames (220 samples at 22050 Hz, as WebRTC frames that rate). For each microphone
//! frame the far-end frame fed before it is the reference `lead_ms` later than the frame's capture time: AEC3 can
//! only cancel an echo whose reference came first, and it finds the rest of the delay itself (up to about 500 ms),
//! so the lead covers a page that plays a little earlier than its schedule says and a stamp a little late. The
//! reference is fed on every frame, silence included, so the filter's notion of the echo path stays continuous.
//! Output comes frame by frame: a message's leftover samples (441 is not a multiple of 220) wait for the next one.

use sonora::config::EchoCanceller;
use sonora::{AudioProcessing, Config, StreamConfig};

use crate::clock::MicClock;
use crate::hold::{HOLD_FLOOR_DB, Hold};
use crate::rate::{RATE, samples_us};
use crate::reference::Reference;
use crate::residual::{ResidualConfig, ResidualGate, level_dbfs};

/// Samples per processing frame: WebRTC's 10 ms at 22050 Hz.
pub const FRAME: usize = RATE as usize / 100;
/// Samples by which AEC3's output lags its input at this rate (its resampling to the 16 kHz bands and back),
/// measured (`tests/room.rs`); the microphone passed through uncancelled is delayed as much, so that switching
/// between the two keeps the stream's timing.
pub const PROCESSING_DELAY: usize = 201;
/// AEC3 has found an echo once it has estimated a delay for it, or its own ERLE estimate reaches this (dB): with no
/// echo at all it reports a delay of 0 and about 0.2 dB, with one 84-352 ms and 8-10 dB (measured on sox's room,
/// tests/conversation.rs).
const ECHO_FOUND_DB: f64 = 3.0;
/// Speech that finished this long before the microphone's time is forgotten (AEC3's filter covers well under it).
const REFERENCE_KEPT_US: u64 = 2_000_000;

/// The canceller's settings (`[modules.echo]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CancellerConfig {
    /// How far ahead of the microphone the reference is fed (ms, 0..=200).
    pub lead_ms: u32,
    /// The page's jitter buffer before an utterance's first chunk plays, used until the page says when it played
    /// (ms, 0..=1000).
    pub jitter_ms: u32,
    /// Silence what the filter leaves of the echo ([`crate::residual`]).
    pub residual_gate: bool,
    /// How much of the agent's speech the canceller hears before it decides there is no echo to find (ms of frames
    /// with speech and no echo found, counted across streams until one finds an echo; 0..=10000). Until AEC3 has
    /// found the echo or this much has played without it, a frame under the agent's own level plus 10 dB is held as
    /// possible echo ([`crate::hold`]); after it, with no echo found (headphones, no loudspeaker), the microphone
    /// passes through untouched. 0 (the default): never hold; the microphone passes through until AEC3 has found
    /// the echo (docs/voice.md says what each costs).
    pub hold_ms: u32,
}

impl Default for CancellerConfig {
    fn default() -> Self {
        Self {
            lead_ms: 60,
            jitter_ms: 60,
            residual_gate: true,
            hold_ms: 0,
        }
    }
}

/// A setting out of range.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CancellerError {
    #[error("{key}: {value} is outside {range}")]
    OutOfRange {
        key: &'static str,
        value: u32,
        range: &'static str,
    },
}

/// What the canceller has done so far.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CancellerStats {
    /// 10 ms frames processed.
    pub frames: u64,
    /// Frames processed while the agent's speech was playing.
    pub frames_with_speech: u64,
    /// Frames whose output is AEC3's (it had found an echo); the others pass the microphone through.
    pub frames_cancelled: u64,
    /// Frames the residual-echo gate silenced as the agent's echo.
    pub frames_silenced: u64,
    /// The residue's learned gain against the reference (dB).
    pub residue_gain_db: f32,
    /// Times the microphone stream started again (a hole in the sequence or a long pause).
    pub restarts: u64,
    /// AEC3's own estimate of the echo return loss enhancement (dB), once it has one.
    pub erle_db: Option<f64>,
    /// AEC3's estimate of the echo's delay behind the reference fed to it (ms), lead included.
    pub delay_ms: Option<i32>,
    /// Frames held as possible echo before AEC3 had found one.
    pub frames_held: u64,
    /// How much of the agent's speech the current stream had heard when AEC3 first found the echo (ms).
    pub echo_found_after_ms: Option<u64>,
    /// The agent's frame levels the residual gate keeps now: a window's worth, echo or not.
    pub residual_levels: usize,
}

/// What a frame's output is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Route {
    /// AEC3's output, then the residual gate.
    Cancelled,
    /// The microphone, held while it could be the echo AEC3 has not found yet.
    Held,
    /// The microphone as it came: no echo to cancel.
    Passed,
}

/// The echo canceller of one microphone.
pub struct Canceller {
    cfg: CancellerConfig,
    apm: AudioProcessing,
    clock: MicClock,
    reference: Reference,
    residual: Option<ResidualGate>,
    /// The hold of the frames AEC3 has not cleaned yet, when `hold_ms` is on.
    hold: Hold,
    /// Frames with speech in this stream, and how many there had been when AEC3 first found the echo.
    stream_speech_frames: u64,
    found_after: Option<u64>,
    /// Frames with speech heard without an echo found, across streams until one finds an echo: a page that showed
    /// no echo over a whole hold is not held again when its stream starts anew (tests/asr.rs and
    /// tests/conversation.rs stream each recording on its own), one that had an echo is.
    unfound_speech_frames: u64,
    /// Microphone samples not yet processed (fewer than a frame) and the hub time of the first.
    pending: Vec<f32>,
    pending_us: u64,
    render: Vec<f32>,
    /// The microphone, `PROCESSING_DELAY` samples late.
    raw: std::collections::VecDeque<f32>,
    /// Processed samples not yet handed out: each message gives back as many samples as it brought, a frame
    /// later (whisper-sat's segmenter frames 20 ms messages as they come).
    ready: std::collections::VecDeque<f32>,
    raw_frame: Vec<f32>,
    scratch: Vec<f32>,
    cleaned: Vec<f32>,
    stats: CancellerStats,
}

impl std::fmt::Debug for Canceller {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Canceller")
            .field("cfg", &self.cfg)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl Canceller {
    /// A canceller with AEC3's default settings (high-pass filter on, no noise suppression or gain control).
    pub fn new(cfg: CancellerConfig) -> Result<Self, CancellerError> {
        if cfg.lead_ms > 200 {
            return Err(CancellerError::OutOfRange {
                key: "lead_ms",
                value: cfg.lead_ms,
                range: "0..=200",
            });
        }
        if cfg.hold_ms > 10_000 {
            return Err(CancellerError::OutOfRange {
                key: "hold_ms",
                value: cfg.hold_ms,
                range: "0..=10000",
            });
        }
        if cfg.jitter_ms > 1000 {
            return Err(CancellerError::OutOfRange {
                key: "jitter_ms",
                value: cfg.jitter_ms,
                range: "0..=1000",
            });
        }
        Ok(Self {
            cfg,
            apm: echo_canceller3(),
            clock: MicClock::default(),
            reference: Reference::new(cfg.jitter_ms),
            residual: cfg.residual_gate.then(|| residual_gate(cfg)),
            hold: Hold::default(),
            stream_speech_frames: 0,
            found_after: None,
            unfound_speech_frames: 0,
            pending: Vec::with_capacity(FRAME),
            pending_us: 0,
            render: vec![0.0; FRAME],
            raw: std::iter::repeat_n(0.0, PROCESSING_DELAY).collect(),
            ready: std::iter::repeat_n(0.0, FRAME).collect(),
            raw_frame: vec![0.0; FRAME],
            scratch: vec![0.0; FRAME],
            cleaned: vec![0.0; FRAME],
            stats: CancellerStats::default(),
        })
    }

    /// A chunk of the agent's speech (s16le) that reached the hub at `arrival_us` ([`Reference::speech`]).
    pub fn speech(&mut self, arrival_us: u64, framing: Option<(u32, u32)>, pcm: &[u8]) {
        let samples: Vec<i16> = pcm
            .chunks_exact(2)
            .map(|b| i16::from_le_bytes([b[0], b[1]]))
            .collect();
        self.reference.speech(arrival_us, framing, &samples);
    }

    /// The page began playing `utterance` at `at_us` ([`Reference::played`]).
    pub fn played(&mut self, utterance: u32, at_us: u64) {
        self.reference.played(utterance, at_us);
    }

    /// The speech was stopped at `at_us` ([`Reference::stopped`]).
    pub fn stopped(&mut self, at_us: u64, utterance: Option<u32>) {
        self.reference.stopped(at_us, utterance);
    }

    /// Microphone message `seq` (s16le), stamped `ts_us` by the hub: appends as many cleaned samples as it brought
    /// to `out` (s16le). Over a stream, the output is the input less the echo, sample for sample,
    /// `PROCESSING_DELAY` samples and a frame behind. When this message starts a new stream (a hole in the
    /// sequence, or the publisher was silent for 4 s) the old stream's last samples are written first, as they
    /// were heard, and the byte offset in `out` where the new stream begins is returned.
    pub fn microphone(
        &mut self,
        seq: u64,
        ts_us: u64,
        pcm: &[u8],
        out: &mut Vec<u8>,
    ) -> Option<usize> {
        let placed = self.clock.place(seq, ts_us, pcm.len() / 2);
        let mut restarted_at = None;
        if placed.restarted {
            // The old stream's tail, still in the delay line and the unfinished frame, passes through.
            for &s in self.ready.iter().chain(&self.raw).chain(&self.pending) {
                push_s16(out, s);
            }
            self.pending.clear();
            self.ready = std::iter::repeat_n(0.0, FRAME).collect();
            restarted_at = Some(out.len());
            // A new stream may be another microphone, room or loudspeaker, or the same one with another delay: the
            // filter and the learned residue start again rather than unlearn the old path while the echo leaks (a
            // filter kept across tests/conversation.rs's streams, each some tens of ms off the last, leaked).
            self.stats.restarts += 1;
            if self.found_after.is_some() {
                self.unfound_speech_frames = 0;
            }
            self.apm = echo_canceller3();
            self.raw = std::iter::repeat_n(0.0, PROCESSING_DELAY).collect();
            self.residual = self.cfg.residual_gate.then(|| residual_gate(self.cfg));
            self.hold = Hold::default();
            self.stream_speech_frames = 0;
            self.found_after = None;
        }
        // The samples waiting from the last message come right before this one's.
        self.pending_us = placed
            .first_us
            .saturating_sub(samples_us(self.pending.len() as u64));
        for b in pcm.chunks_exact(2) {
            self.pending
                .push(f32::from(i16::from_le_bytes([b[0], b[1]])) / 32768.0);
            if self.pending.len() == FRAME {
                self.frame();
                self.pending.clear();
                self.pending_us += samples_us(FRAME as u64);
            }
        }
        // A frame of zeros was ready before the first message, so there are always enough.
        let n = (pcm.len() / 2).min(self.ready.len());
        for s in self.ready.drain(..n) {
            push_s16(out, s);
        }
        self.reference
            .forget_before(self.pending_us.saturating_sub(REFERENCE_KEPT_US));
        restarted_at
    }

    /// What the canceller has done so far, with AEC3's current estimates.
    pub fn stats(&self) -> CancellerStats {
        let aec = self.apm.statistics();
        CancellerStats {
            erle_db: aec.echo_return_loss_enhancement,
            delay_ms: aec.delay_ms,
            residue_gain_db: self.residual.as_ref().map_or(0.0, ResidualGate::gain_db),
            echo_found_after_ms: self.found_after.map(|frames| frames * 10),
            residual_levels: self.residual.as_ref().map_or(0, ResidualGate::levels_kept),
            ..self.stats.clone()
        }
    }

    /// Processes the pending frame: its reference first, then the microphone.
    fn frame(&mut self) {
        let lead = u64::from(self.cfg.lead_ms) * 1000;
        let speaking = self
            .reference
            .render(self.pending_us + lead, &mut self.render);
        self.stats.frames += 1;
        if speaking {
            self.stats.frames_with_speech += 1;
            self.stream_speech_frames += 1;
        }
        // Both calls fail only on a frame whose length or channel count does not match the stream's, which
        // `FRAME` rules out; a frame that failed anyway passes through uncancelled rather than being lost.
        let rendered = self
            .apm
            .process_render_f32(&[&self.render], &mut [&mut self.scratch]);
        // No delay hint: AEC3 estimates it (the call only sets what the echo canceller is told is external delay).
        let _ = self.apm.set_stream_delay_ms(0);
        let captured = self
            .apm
            .process_capture_f32(&[&self.pending], &mut [&mut self.cleaned]);
        self.raw.extend(self.pending.iter().copied());
        for (o, s) in self.raw_frame.iter_mut().zip(self.raw.drain(..FRAME)) {
            *o = s;
        }
        // Without an echo (headphones, no loudspeaker, audio injected in tests) AEC3 would still hold a user down
        // while the agent speaks, assuming an echo it has not found: its output is used once it has found one.
        // Before that a frame under the agent's level is held (it may be the echo: the first words of the first
        // reply, at any room's loudness), unless the microphone's voice began before the agent's, and until the
        // levels show the microphone does not follow the agent at all or enough speech has played without an echo
        // being found.
        let aec = self.apm.statistics();
        let found = rendered.is_ok()
            && captured.is_ok()
            && (aec.delay_ms.is_some_and(|d| d > 0)
                || aec
                    .echo_return_loss_enhancement
                    .is_some_and(|erle| erle >= ECHO_FOUND_DB));
        if found && self.found_after.is_none() {
            self.found_after = Some(self.stream_speech_frames);
        }
        if speaking && !found {
            self.unfound_speech_frames += 1;
        }
        let render_db = level_dbfs(&self.render);
        let raw_db = level_dbfs(&self.raw_frame);
        let held = self.holding(found, speaking, render_db, raw_db);
        let route = if found {
            Route::Cancelled
        } else if held {
            Route::Held
        } else {
            Route::Passed
        };
        let mut cleaned = match route {
            Route::Cancelled => {
                self.stats.frames_cancelled += 1;
                &self.cleaned
            }
            Route::Held | Route::Passed => &self.raw_frame,
        };
        if let Some(gate) = &mut self.residual {
            gate.reference(self.pending_us + lead, render_db);
            gate.advance(self.pending_us);
            if route == Route::Cancelled
                && gate.is_echo(self.pending_us, raw_db, level_dbfs(cleaned))
            {
                self.stats.frames_silenced += 1;
                self.scratch.fill(0.0);
                cleaned = &self.scratch;
            }
        }
        if route == Route::Held && self.hold.is_echo(self.pending_us, raw_db) {
            self.stats.frames_held += 1;
            self.scratch.fill(0.0);
            cleaned = &self.scratch;
        }
        self.ready.extend(cleaned.iter().copied());
    }
}

/// The residual gate: with the hold on, its floor starts where the hold's was (10 dB over the agent's level) until
/// the residue is learned, since AEC3 reports an echo some frames before its filter has converged and a loud room's
/// echo comes back above the agent's level (tests/room.rs); without it, at the typical -12 dB.
fn residual_gate(cfg: CancellerConfig) -> ResidualGate {
    let initial_gain_db = if cfg.hold_ms > 0 {
        HOLD_FLOOR_DB - ResidualConfig::default().margin_db
    } else {
        ResidualConfig::default().initial_gain_db
    };
    ResidualGate::new(ResidualConfig {
        initial_gain_db,
        ..ResidualConfig::default()
    })
}

/// WebRTC's audio processing with AEC3 alone, on the microphone's rate.
fn echo_canceller3() -> AudioProcessing {
    let stream = StreamConfig::new(RATE, 1);
    AudioProcessing::builder()
        .config(Config {
            echo_canceller: Some(EchoCanceller::default()),
            ..Default::default()
        })
        .capture_config(stream)
        .render_config(stream)
        .build()
}

impl Canceller {
    /// Whether a frame AEC3 has not cleaned is held as possible echo (`hold_ms`); the hold's bookkeeping runs only
    /// when it is on.
    fn holding(&mut self, found: bool, speaking: bool, render_db: f32, raw_db: f32) -> bool {
        if self.cfg.hold_ms == 0 {
            return false;
        }
        let lead = u64::from(self.cfg.lead_ms) * 1000;
        self.hold.frame(
            self.pending_us,
            self.pending_us + lead,
            render_db,
            raw_db,
            speaking,
            found,
        ) && (self.found_after.is_some()
            || self.unfound_speech_frames * 10 < u64::from(self.cfg.hold_ms))
    }
}

/// Appends a sample in [-1, 1] as s16le.
fn push_s16(out: &mut Vec<u8>, sample: f32) {
    let v = (sample * 32768.0).round().clamp(-32768.0, 32767.0) as i16;
    out.extend_from_slice(&v.to_le_bytes());
}
