//! Speaking: plays utterances one after another on `Agent.speech`, paced to real time plus a small lead, with
//! their visemes and caption on `Agent.avatar`, and keeps track of what is queued so it can be cancelled.
//!
//! Pacing matters twice: hub subscriber queues hold 64 messages and drop the oldest, so a whole reply published
//! at synthesis speed would lose audio; and audio already sent cannot be taken back, so a small lead keeps a
//! barge-in effective. The first `lead` of each utterance goes out at once, the rest as it becomes due.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use agent_contract::avatar::AvatarCommand;
use agent_voice::{CancelToken, SpeechEvent, Synthesizer, Utterance, Viseme, VoiceSettings};
use flow::Publisher;
use flow_telemetry::{SpanRecord, Telemetry, TraceContext, now_us};
use tokio::sync::{Notify, mpsc};
use tokio::time::Instant;
use tracing::warn;

use super::avatar_out::AvatarOut;
use super::behaviour::{self, Event};
use super::wire::{self, CancelTarget};

/// Utterances accepted but not yet finished; a caller asking for more gets an error instead of a growing queue.
const JOB_QUEUE: usize = 16;

/// Viseme cues are sent in batches once they cover this much published audio (and at every sentence end), so the
/// page gets them well before the audio they describe plays (`lead` later) without one message per 20 ms.
const VISEME_BATCH: Duration = Duration::from_millis(100);

/// Figures shown at `/api/status`.
#[derive(Debug, Default)]
pub struct Counters {
    pub utterances: AtomicU64,
    pub chunks: AtomicU64,
    pub cancelled: AtomicU64,
    pub failed: AtomicU64,
    pub viseme_messages: AtomicU64,
    pub barge_ins: AtomicU64,
}

impl Counters {
    pub fn bump(counter: &AtomicU64) {
        counter.fetch_add(1, Ordering::Relaxed);
    }

    pub fn to_json(&self) -> serde_json::Value {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        serde_json::json!({
            "utterances": get(&self.utterances), "chunks": get(&self.chunks), "cancelled": get(&self.cancelled),
            "failed": get(&self.failed), "viseme_messages": get(&self.viseme_messages),
            "barge_ins": get(&self.barge_ins),
        })
    }
}

/// Where the speaker's output goes.
#[derive(Debug, Clone)]
pub struct Outputs {
    pub speech: Arc<Publisher>,
    pub avatar: AvatarOut,
    pub behaviour: behaviour::Sender,
    pub sample_rate: u32,
    pub lead: Duration,
    pub counters: Arc<Counters>,
    pub telemetry: Telemetry,
}

/// An utterance and its text, for the caption.
#[derive(Debug)]
struct Job {
    utterance: Utterance,
    text: String,
    /// The reply span it starts, and when it was asked for (µs, Unix clock): its synthesis span.
    trace: Option<TraceContext>,
    asked_us: u64,
}

#[derive(Debug, Default)]
struct State {
    /// Every accepted utterance that has not finished, with its cancel token.
    pending: BTreeMap<u64, CancelToken>,
    /// When the audio sent so far stops playing, while an utterance is audible.
    audible_until: Option<Instant>,
}

/// The handle the module uses to speak and to stop.
#[derive(Debug, Clone)]
pub struct Speaker {
    jobs: mpsc::Sender<Job>,
    state: Arc<Mutex<State>>,
    cancelled: Arc<Notify>,
}

impl Speaker {
    /// Starts the play loop.
    pub fn start(outputs: Outputs) -> Speaker {
        let (jobs, queue) = mpsc::channel(JOB_QUEUE);
        let speaker = Speaker {
            jobs,
            state: Arc::default(),
            cancelled: Arc::new(Notify::new()),
        };
        tokio::spawn(play_all(queue, speaker.clone(), outputs));
        speaker
    }

    /// Queues `text`; returns its utterance number.
    pub fn say(
        &self,
        synth: &Synthesizer,
        text: &str,
        voice: &VoiceSettings,
        trace: Option<TraceContext>,
    ) -> Result<u64, String> {
        let asked_us = now_us();
        let utterance = synth.speak(text, voice).map_err(|e| e.to_string())?;
        let id = utterance.id();
        self.state().pending.insert(id, utterance.cancel_token());
        if let Err(error) = self.jobs.try_send(Job {
            utterance,
            text: text.to_owned(),
            trace,
            asked_us,
        }) {
            self.state().pending.remove(&id);
            // The utterance is dropped with the error, which stops it in the engine.
            return Err(match error {
                mpsc::error::TrySendError::Full(_) => {
                    format!("{JOB_QUEUE} utterances are already waiting")
                }
                mpsc::error::TrySendError::Closed(_) => "the speaker has stopped".to_owned(),
            });
        }
        Ok(id)
    }

    /// Cancels the matching utterances (queued or playing); returns their numbers.
    pub fn cancel(&self, target: CancelTarget) -> Vec<u64> {
        let ids: Vec<u64> = {
            let state = self.state();
            state
                .pending
                .iter()
                .filter(|(id, _)| target == CancelTarget::All || target == CancelTarget::One(**id))
                .map(|(id, token)| {
                    token.cancel();
                    *id
                })
                .collect()
        };
        if !ids.is_empty() {
            self.cancelled.notify_waiters();
        }
        ids
    }

    /// Whether speech sent to the page is still playing at `now`.
    pub fn is_audible(&self, now: Instant) -> bool {
        self.state().audible_until.is_some_and(|until| until > now)
    }

    fn state(&self) -> MutexGuard<'_, State> {
        // The state is only ever left consistent (single assignments), so a poisoned lock is still usable.
        self.state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

async fn play_all(mut queue: mpsc::Receiver<Job>, speaker: Speaker, out: Outputs) {
    while let Some(job) = queue.recv().await {
        let id = job.utterance.id();
        play(job, &speaker, &out).await;
        speaker.state().pending.remove(&id);
    }
}

/// Collects cues and sends them in batches.
struct VisemeBatch {
    utterance: u64,
    items: Vec<(f64, Viseme)>,
    since_sample: u64,
}

impl VisemeBatch {
    async fn flush(&mut self, out: &Outputs, published_until: u64) {
        self.since_sample = published_until;
        if self.items.is_empty() {
            return;
        }
        let items = std::mem::take(&mut self.items);
        out.avatar
            .send(&wire::visemes(self.utterance, &items))
            .await;
        Counters::bump(&out.counters.viseme_messages);
    }
}

/// Plays one utterance to its end or until it is cancelled.
async fn play(job: Job, speaker: &Speaker, out: &Outputs) {
    let Job {
        mut utterance,
        text,
        trace,
        asked_us,
    } = job;
    let id = utterance.id();
    let token = utterance.cancel_token();
    let rate = f64::from(out.sample_rate);
    let at_sample =
        |anchor: Instant, sample: u64| anchor + Duration::from_secs_f64(sample as f64 / rate);
    let batch_samples = (VISEME_BATCH.as_secs_f64() * rate) as u64;
    let mut anchor: Option<Instant> = None;
    let mut published = 0u64;
    let mut batch = VisemeBatch {
        utterance: id,
        items: Vec::new(),
        since_sample: 0,
    };
    let mut stopped = false;
    while let Some(event) = utterance.next().await {
        if token.is_cancelled() {
            stopped = true;
            break;
        }
        match event {
            SpeechEvent::Chunk(chunk) => {
                if !chunk.pcm.is_empty() {
                    let start = match anchor {
                        Some(start) => {
                            let send_at = at_sample(start, chunk.start_sample)
                                .checked_sub(out.lead)
                                .unwrap_or(start);
                            if send_at > Instant::now() {
                                // Cues of audio already out go first: they must reach the page before it plays.
                                batch.flush(out, published).await;
                                tokio::select! {
                                    () = tokio::time::sleep_until(send_at) => {}
                                    () = speaker.cancelled.notified() => {}
                                }
                                if token.is_cancelled() {
                                    stopped = true;
                                    break;
                                }
                            }
                            start
                        }
                        None => {
                            Counters::bump(&out.counters.utterances);
                            out.avatar
                                .send(&AvatarCommand::Say { text: text.clone() })
                                .await;
                            out.behaviour.send(Event::SpeechStarted);
                            *anchor.insert(Instant::now())
                        }
                    };
                    let payload = wire::speech_payload(id, chunk.start_sample, &chunk.pcm);
                    if let Err(e) = out.speech.publish(payload).await {
                        warn!("tts: speech not sent: {e}");
                    }
                    if chunk.start_sample == 0
                        && out.telemetry.is_on()
                        && let Some(reply) = trace
                    {
                        // From the request to its first PCM on the hub: the synthesis the user waits for.
                        out.telemetry.record(
                            SpanRecord::under(reply, "synthesis", asked_us, now_us())
                                .with("utterance", id)
                                .with("samples", chunk.end_sample()),
                        );
                    }
                    Counters::bump(&out.counters.chunks);
                    published = chunk.end_sample();
                    speaker.state().audible_until = Some(at_sample(start, published));
                }
                batch.items.extend(
                    chunk
                        .cues
                        .iter()
                        .map(|cue| (cue.at_ms(out.sample_rate), cue.viseme)),
                );
                if published.saturating_sub(batch.since_sample) >= batch_samples {
                    batch.flush(out, published).await;
                }
            }
            SpeechEvent::SentenceEnd { end_sample, .. } => {
                batch.flush(out, published).await;
                if let Some(start) = anchor {
                    out.behaviour.send(Event::PhraseBoundary {
                        at: at_sample(start, end_sample),
                    });
                }
            }
            SpeechEvent::Finished { cancelled, .. } => {
                stopped |= cancelled;
                break;
            }
            SpeechEvent::Failed { message } => {
                warn!("tts: utterance {id} failed: {message}");
                Counters::bump(&out.counters.failed);
                break;
            }
        }
    }
    if stopped {
        Counters::bump(&out.counters.cancelled);
        if anchor.is_some() {
            out.avatar
                .send(&AvatarCommand::SpeechStop {
                    utterance: Some(id),
                    barge_in: false,
                })
                .await;
            speaker.state().audible_until = None;
            out.behaviour
                .send(Event::SpeechEnded { at: Instant::now() });
        }
    } else {
        batch.flush(out, published).await;
        if let Some(start) = anchor {
            out.behaviour.send(Event::SpeechEnded {
                at: at_sample(start, published),
            });
        }
    }
}
