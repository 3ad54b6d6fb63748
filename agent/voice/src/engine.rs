//! The speech engine: one dedicated thread that owns espeak-ng, fed through a bounded request queue, streaming
//! each utterance back sentence by sentence and buffer by buffer.
//!
//! Queues and their overflow policy:
//! - Requests: bounded (`queue_capacity`); when full, [`Synthesizer::speak`] fails at once with
//!   [`VoiceError::QueueFull`] rather than blocking the caller.
//! - Output of one utterance: bounded (`chunk_queue` events). Speech cannot lose samples, so the engine waits
//!   for the consumer instead of dropping; it is faster than real time anyway. A consumer that stops reading
//!   must drop its [`Utterance`] (or keep draining after cancelling), which ends the wait.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use tokio::sync::mpsc;

use crate::data_path::locate_data;
use crate::error::VoiceError;
use crate::espeak::{Espeak, Flow, Parameter, SynthOutcome};
use crate::sentence::split_sentences;
use crate::timeline::{PhonemeMark, SpeechChunk, TimelineBuilder, VisemeCue};
use crate::voice::VoiceSettings;

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
}

impl Default for SynthesizerConfig {
    fn default() -> Self {
        SynthesizerConfig {
            data_path: None,
            chunk_ms: 20,
            queue_capacity: 8,
            chunk_queue: 64,
        }
    }
}

/// What an utterance produces, in order: chunks and sentence ends, then exactly one `Finished` or `Failed`.
#[derive(Debug, Clone, PartialEq)]
pub enum SpeechEvent {
    Chunk(SpeechChunk),
    /// Sentence `sentence` is complete; its audio spans `start_sample..end_sample`.
    SentenceEnd {
        sentence: usize,
        text: String,
        start_sample: u64,
        end_sample: u64,
    },
    /// The utterance ended; `cancelled` when it was stopped before its end.
    Finished {
        total_samples: u64,
        cancelled: bool,
    },
    /// espeak-ng failed (unknown voice, synthesis error); nothing more follows.
    Failed {
        message: String,
    },
}

/// Stops an utterance: before it starts, between sentences, or inside a sentence at the next buffer.
#[derive(Debug, Clone, Default)]
pub struct CancelToken(Arc<AtomicBool>);

impl CancelToken {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn cancel(&self) {
        self.0.store(true, Ordering::Release);
    }

    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::Acquire)
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

    /// The next event, or `None` after the last one.
    pub async fn next(&mut self) -> Option<SpeechEvent> {
        self.events.recv().await
    }

    /// The next event, waiting on this thread; for code outside an async runtime (benchmarks, tools).
    pub fn blocking_next(&mut self) -> Option<SpeechEvent> {
        self.events.blocking_recv()
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

struct Request {
    text: String,
    voice: VoiceSettings,
    cancel: CancelToken,
    out: mpsc::Sender<SpeechEvent>,
}

/// A handle to the engine thread; cheap to clone. The thread and espeak-ng stop when the last handle is
/// dropped and the queued utterances are done.
#[derive(Debug, Clone)]
pub struct Synthesizer {
    requests: mpsc::Sender<Request>,
    sample_rate: u32,
    next_id: Arc<AtomicU64>,
    queue_capacity: usize,
    chunk_queue: usize,
}

impl std::fmt::Debug for Request {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Request")
            .field("text", &self.text)
            .field("voice", &self.voice)
            .finish_non_exhaustive()
    }
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
        let (requests, request_rx) = mpsc::channel::<Request>(config.queue_capacity.max(1));
        let (ready_tx, ready_rx) = std::sync::mpsc::sync_channel(1);
        let chunk_ms = config.chunk_ms;
        std::thread::Builder::new()
            .name("espeak-engine".into())
            .spawn(move || match Espeak::initialize(&data, chunk_ms) {
                Ok(espeak) => {
                    // The receiver only goes away if `start` itself is gone, in which case nobody listens.
                    let _ = ready_tx.send(Ok(espeak.sample_rate()));
                    run_engine(espeak, request_rx);
                }
                Err(error) => {
                    let _ = ready_tx.send(Err(error));
                }
            })
            .map_err(|error| VoiceError::Init {
                path: PathBuf::new(),
                message: format!("cannot spawn: {error}"),
            })?;
        let sample_rate = ready_rx.recv().map_err(|_| VoiceError::EngineStopped)??;
        tracing::info!(sample_rate, chunk_ms, "espeak-ng engine started");
        Ok(Synthesizer {
            requests,
            sample_rate,
            next_id: Arc::new(AtomicU64::new(1)),
            queue_capacity: config.queue_capacity.max(1),
            chunk_queue: config.chunk_queue.max(1),
        })
    }

    /// Sample rate of all PCM this engine produces (22050 Hz with espeak-ng's standard data).
    pub fn sample_rate(&self) -> u32 {
        self.sample_rate
    }

    /// Queues `text` to be spoken with `voice`; the returned utterance streams the result.
    pub fn speak(&self, text: &str, voice: &VoiceSettings) -> Result<Utterance, VoiceError> {
        voice.validate()?;
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

/// The engine thread's loop: one utterance at a time until every handle is gone.
fn run_engine(mut espeak: Espeak, mut requests: mpsc::Receiver<Request>) {
    let mut current: Option<VoiceSettings> = None;
    while let Some(request) = requests.blocking_recv() {
        let end = match speak_one(&mut espeak, &mut current, &request) {
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
    tracing::info!("espeak-ng engine stopped");
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
