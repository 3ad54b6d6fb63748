//! The speech engine: one dedicated thread that owns espeak-ng (and, when configured, the Piper voice that
//! espeak-ng phonemises for), fed through a bounded request queue, streaming each utterance back sentence by
//! sentence and buffer by buffer.
//!
//! Queues and their overflow policy:
//! - Requests: bounded (`queue_capacity`); when full, [`Synthesizer::speak`] fails at once with
//!   [`VoiceError::QueueFull`] rather than blocking the caller.
//! - Output of one utterance: bounded (`chunk_queue` events). Speech cannot lose samples, so the engine waits
//!   for the consumer instead of dropping; it is faster than real time anyway. A consumer that stops reading
//!   must drop its [`Utterance`] (or keep draining after cancelling), which ends the wait.

mod job;
mod piper_speech;

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use tokio::sync::mpsc;

use crate::data_path::locate_data;
use crate::error::VoiceError;
use crate::espeak::{Espeak, Flow, Parameter, SynthOutcome};
use crate::piper::{PiperConfig, PiperVoice};
use crate::sentence::split_sentences;
use crate::timeline::{PhonemeMark, TimelineBuilder, VisemeCue};
use crate::voice::{Engine, VoiceSettings};

pub use job::{CancelToken, SpeechEvent};
use job::{Counters, Request};

/// How the engine is started.
#[derive(Debug, Clone)]
pub struct SynthesizerConfig {
    /// espeak-ng data directory; `None` searches `$ESPEAK_DATA_PATH` and the system locations.
    pub data_path: Option<PathBuf>,
    /// Length of the PCM buffers espeak-ng hands over, in milliseconds (10-500). Smaller buffers mean an
    /// earlier first chunk and quicker cancellation, larger ones fewer messages.
    pub chunk_ms: u32,
    /// Utterances that may wait for the engine.
    pub queue_capacity: usize,
    /// Events of one utterance that may wait for its consumer.
    pub chunk_queue: usize,
    /// The Piper voice, loaded at start (checksums verified) so that requests for [`Engine::Piper`] can use it;
    /// `None`: espeak-ng only.
    pub piper: Option<PiperConfig>,
}

impl Default for SynthesizerConfig {
    fn default() -> Self {
        SynthesizerConfig {
            data_path: None,
            chunk_ms: 20,
            queue_capacity: 8,
            chunk_queue: 64,
            piper: None,
        }
    }
}

/// The consumer's side of one utterance.
#[derive(Debug)]
pub struct Utterance {
    id: u64,
    events: mpsc::Receiver<SpeechEvent>,
    cancel: CancelToken,
    submitted: Instant,
}

impl Utterance {
    /// A number unique within the synthesizer, in submission order.
    pub fn id(&self) -> u64 {
        self.id
    }

    /// When `speak` accepted the request, for latency measurements.
    pub fn submitted(&self) -> Instant {
        self.submitted
    }

    /// The next event, or `None` after the last one. Once the utterance is cancelled, the audio still queued is
    /// skipped: what follows is its end.
    pub async fn next(&mut self) -> Option<SpeechEvent> {
        loop {
            let event = self.events.recv().await?;
            if !self.skips(&event) {
                return Some(event);
            }
        }
    }

    /// The next event, waiting on this thread; for code outside an async runtime (benchmarks, tools).
    pub fn blocking_next(&mut self) -> Option<SpeechEvent> {
        loop {
            let event = self.events.blocking_recv()?;
            if !self.skips(&event) {
                return Some(event);
            }
        }
    }

    /// Audio and sentence ends of a cancelled utterance are dropped on the consumer's side too, so that a cancel
    /// stops the stream at once rather than after the chunks the engine had already queued.
    fn skips(&self, event: &SpeechEvent) -> bool {
        self.cancel.is_cancelled()
            && matches!(
                event,
                SpeechEvent::Chunk(_) | SpeechEvent::SentenceEnd { .. }
            )
    }

    /// A token that cancels this utterance from elsewhere (a barge-in handler).
    pub fn cancel_token(&self) -> CancelToken {
        self.cancel.clone()
    }

    /// Asks the engine to stop this utterance; keep reading until `Finished` (or drop the utterance).
    pub fn cancel(&self) {
        self.cancel.cancel();
    }

    /// Waits for the whole utterance and joins it into one recording.
    pub async fn collect(mut self) -> Result<Recording, VoiceError> {
        let mut recording = Recording::default();
        while let Some(event) = self.next().await {
            if recording.absorb(event)? {
                break;
            }
        }
        Ok(recording)
    }

    /// [`Utterance::collect`] for code outside an async runtime.
    pub fn collect_blocking(mut self) -> Result<Recording, VoiceError> {
        let mut recording = Recording::default();
        while let Some(event) = self.blocking_next() {
            if recording.absorb(event)? {
                break;
            }
        }
        Ok(recording)
    }
}

/// A whole utterance: PCM, cues, phonemes and sentence spans, all on one sample clock.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Recording {
    pub pcm: Vec<i16>,
    pub cues: Vec<VisemeCue>,
    pub phonemes: Vec<PhonemeMark>,
    /// `(text, start_sample, end_sample)` of every sentence.
    pub sentences: Vec<(String, u64, u64)>,
    pub cancelled: bool,
}

impl Recording {
    /// Adds one event; returns `true` at the end of the utterance.
    fn absorb(&mut self, event: SpeechEvent) -> Result<bool, VoiceError> {
        match event {
            SpeechEvent::Chunk(chunk) => {
                self.pcm.extend_from_slice(&chunk.pcm);
                self.cues.extend(chunk.cues);
                self.phonemes.extend(chunk.phonemes);
            }
            SpeechEvent::SentenceEnd {
                text,
                start_sample,
                end_sample,
                ..
            } => {
                self.sentences.push((text, start_sample, end_sample));
            }
            SpeechEvent::Finished { cancelled, .. } => {
                self.cancelled = cancelled;
                return Ok(true);
            }
            SpeechEvent::Failed { message } => return Err(VoiceError::Synthesis(message)),
        }
        Ok(false)
    }
}

/// The engine's counts since it started.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SpeechStats {
    /// Runs of the Piper network: one per sentence, two for a first sentence spoken in two parts.
    pub piper_runs: u64,
    /// Sentences the Piper voice played from its cache, without the network.
    pub piper_cache_hits: u64,
}

/// A handle to the engine thread; cheap to clone. The thread and espeak-ng stop when the last handle is
/// dropped and the queued utterances are done.
#[derive(Debug, Clone)]
pub struct Synthesizer {
    requests: mpsc::Sender<Request>,
    counters: Arc<Counters>,
    sample_rate: u32,
    piper: bool,
    next_id: Arc<AtomicU64>,
    queue_capacity: usize,
    chunk_queue: usize,
}

impl Synthesizer {
    /// Finds the data, starts the engine thread and waits until espeak-ng is initialised (a few
    /// milliseconds; call it from `spawn_blocking` inside an async runtime if that matters).
    pub fn start(config: SynthesizerConfig) -> Result<Self, VoiceError> {
        if !(10..=500).contains(&config.chunk_ms) {
            return Err(VoiceError::InvalidSetting {
                name: "chunk_ms",
                value: config.chunk_ms.to_string(),
                reason: "must be within 10-500".into(),
            });
        }
        let data = locate_data(config.data_path.as_deref())?;
        if let Some(piper) = &config.piper {
            // Before the thread, so that a missing or damaged voice fails here with its own message.
            piper.verify()?;
        }
        let (requests, request_rx) = mpsc::channel::<Request>(config.queue_capacity.max(1));
        let (ready_tx, ready_rx) = std::sync::mpsc::sync_channel(1);
        let chunk_ms = config.chunk_ms;
        let piper_config = config.piper.clone();
        let piper = piper_config.is_some();
        let counters = Arc::new(Counters::default());
        let engine_counters = Arc::clone(&counters);
        std::thread::Builder::new()
            .name("espeak-engine".into())
            .spawn(move || {
                // The voice first: a voice that cannot be used is reported as such, even while another
                // espeak-ng engine holds the process's one slot.
                let voice = piper_config.as_ref().map(PiperVoice::load).transpose();
                let started = voice.and_then(|voice| {
                    let espeak = Espeak::initialize(&data, chunk_ms)?;
                    if let Some(voice) = &voice
                        && voice.file.sample_rate != espeak.sample_rate()
                    {
                        return Err(VoiceError::Piper(format!(
                            "the voice speaks at {} Hz, espeak-ng at {} Hz; both must share one clock",
                            voice.file.sample_rate,
                            espeak.sample_rate()
                        )));
                    }
                    Ok((espeak, voice))
                });
                match started {
                    Ok((espeak, voice)) => {
                        // The receiver only goes away if `start` itself is gone, in which case nobody listens.
                        let _ = ready_tx.send(Ok(espeak.sample_rate()));
                        run_engine(
                            Engines {
                                espeak,
                                piper: voice,
                                chunk_ms,
                                counters: engine_counters,
                            },
                            request_rx,
                        );
                    }
                    Err(error) => {
                        let _ = ready_tx.send(Err(error));
                    }
                }
            })
            .map_err(|error| VoiceError::Init {
                path: PathBuf::new(),
                message: format!("cannot spawn: {error}"),
            })?;
        let sample_rate = ready_rx.recv().map_err(|_| VoiceError::EngineStopped)??;
        tracing::info!(sample_rate, chunk_ms, piper, "speech engine started");
        Ok(Synthesizer {
            requests,
            counters,
            sample_rate,
            piper,
            next_id: Arc::new(AtomicU64::new(1)),
            queue_capacity: config.queue_capacity.max(1),
            chunk_queue: config.chunk_queue.max(1),
        })
    }

    /// Sample rate of all PCM this engine produces (22050 Hz with espeak-ng's standard data).
    pub fn sample_rate(&self) -> u32 {
        self.sample_rate
    }

    /// Whether a Piper voice is loaded, so that [`Engine::Piper`] requests can be spoken.
    pub fn has_piper(&self) -> bool {
        self.piper
    }

    /// What the engine has done since it started.
    pub fn stats(&self) -> SpeechStats {
        SpeechStats {
            piper_runs: self.counters.piper_runs.load(Ordering::Relaxed),
            piper_cache_hits: self.counters.piper_cache_hits.load(Ordering::Relaxed),
        }
    }

    /// Queues `text` to be spoken with `voice`; the returned utterance streams the result.
    pub fn speak(&self, text: &str, voice: &VoiceSettings) -> Result<Utterance, VoiceError> {
        voice.validate()?;
        if voice.engine == Engine::Piper && !self.piper {
            return Err(VoiceError::PiperUnavailable);
        }
        if text.contains('\0') {
            return Err(VoiceError::InvalidText(
                "it contains a NUL character".into(),
            ));
        }
        let (out, events) = mpsc::channel(self.chunk_queue);
        let cancel = CancelToken::new();
        let request = Request {
            text: text.to_owned(),
            voice: voice.clone(),
            cancel: cancel.clone(),
            out,
        };
        self.requests
            .try_send(request)
            .map_err(|error| match error {
                mpsc::error::TrySendError::Full(_) => VoiceError::QueueFull {
                    capacity: self.queue_capacity,
                },
                mpsc::error::TrySendError::Closed(_) => VoiceError::EngineStopped,
            })?;
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        Ok(Utterance {
            id,
            events,
            cancel,
            submitted: Instant::now(),
        })
    }
}

/// What the engine thread owns.
struct Engines {
    espeak: Espeak,
    piper: Option<PiperVoice>,
    chunk_ms: u32,
    counters: Arc<Counters>,
}

/// The engine thread's loop: one utterance at a time until every handle is gone.
fn run_engine(mut engines: Engines, mut requests: mpsc::Receiver<Request>) {
    let mut current: Option<VoiceSettings> = None;
    while let Some(request) = requests.blocking_recv() {
        let spoken = match (request.voice.engine, engines.piper.as_mut()) {
            (Engine::Espeak, _) => speak_one(&mut engines.espeak, &mut current, &request),
            (Engine::Piper, Some(piper)) => {
                // Phonemising switches espeak-ng's voice: the next espeak-ng utterance sets its own again.
                current = None;
                piper_speech::speak_piper(
                    &mut engines.espeak,
                    piper,
                    engines.chunk_ms,
                    &engines.counters,
                    &request,
                )
            }
            (Engine::Piper, None) => Err(VoiceError::PiperUnavailable),
        };
        let end = match spoken {
            Ok((total_samples, cancelled)) => SpeechEvent::Finished {
                total_samples,
                cancelled,
            },
            Err(error) => {
                tracing::warn!(%error, "utterance failed");
                SpeechEvent::Failed {
                    message: error.to_string(),
                }
            }
        };
        // A consumer that has gone away does not need to hear how it ended.
        let _ = request.out.blocking_send(end);
    }
    tracing::info!("speech engine stopped");
}

/// Applies the voice if it changed since the last utterance.
fn apply_voice(
    espeak: &mut Espeak,
    current: &mut Option<VoiceSettings>,
    voice: &VoiceSettings,
) -> Result<(), VoiceError> {
    if current.as_ref() == Some(voice) {
        return Ok(());
    }
    // Forget the old settings first, so a failure half way leaves nothing assumed.
    let previous = current.take();
    if previous.as_ref().map(|p| &p.voice) != Some(&voice.voice) {
        espeak.set_voice(&voice.voice)?;
    }
    espeak.set_parameter(Parameter::Rate, voice.rate_wpm)?;
    espeak.set_parameter(Parameter::Pitch, voice.pitch)?;
    espeak.set_parameter(Parameter::Range, voice.range)?;
    espeak.set_parameter(Parameter::Volume, voice.volume)?;
    *current = Some(voice.clone());
    Ok(())
}

/// Speaks one request; returns the samples produced and whether it was cancelled.
fn speak_one(
    espeak: &mut Espeak,
    current: &mut Option<VoiceSettings>,
    request: &Request,
) -> Result<(u64, bool), VoiceError> {
    if request.cancel.is_cancelled() {
        return Ok((0, true));
    }
    apply_voice(espeak, current, &request.voice)?;
    let mut builder = TimelineBuilder::default();
    for (index, sentence) in split_sentences(&request.text).into_iter().enumerate() {
        builder.begin_sentence(index);
        let start_sample = builder.written();
        let mut consumer_gone = false;
        let outcome = espeak.synthesize(sentence, &mut |pcm, events| {
            if request.cancel.is_cancelled() {
                return Flow::Abort;
            }
            for chunk in builder.push(pcm, events) {
                if request
                    .out
                    .blocking_send(SpeechEvent::Chunk(chunk))
                    .is_err()
                {
                    consumer_gone = true;
                    return Flow::Abort;
                }
            }
            Flow::Continue
        })?;
        if outcome == SynthOutcome::Aborted || consumer_gone {
            return Ok((builder.written(), true));
        }
        for chunk in builder.end_sentence() {
            if request
                .out
                .blocking_send(SpeechEvent::Chunk(chunk))
                .is_err()
            {
                return Ok((builder.written(), true));
            }
        }
        let end = SpeechEvent::SentenceEnd {
            sentence: index,
            text: sentence.to_owned(),
            start_sample,
            end_sample: builder.written(),
        };
        if request.out.blocking_send(end).is_err() {
            return Ok((builder.written(), true));
        }
    }
    if !builder.unmapped.is_empty() {
        tracing::debug!(unmapped = ?builder.unmapped, "phonemes without a viseme kept the previous shape");
    }
    Ok((builder.written(), request.cancel.is_cancelled()))
}
