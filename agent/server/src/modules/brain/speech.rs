//! The brain's mouth and ear for its own voice: asks the TTS module to speak or to stop, and follows `Agent.speech`
//! to know when the agent is speaking (the `speaking` percept).

use std::collections::HashMap;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use flow::Client;
use flow_telemetry::TraceContext;
use tokio::sync::mpsc;
use tokio::time::Instant;
use tracing::{debug, info, warn};

/// The TTS module's service: `{"text": "..."}` queues an utterance and answers `{"utterance": N}`;
/// `{"cancel": "all"}` or `{"cancel": N}` stops speech (see docs/voice.md).
use agent_contract::channels::SAY;
use agent_contract::say::{PrepareAnswer, SayAnswer, SayRequest};

/// Requests waiting for the speech task; when it is this far behind (the TTS module is not answering), new
/// requests are dropped and logged rather than queued without bound.
const REQUEST_QUEUE: usize = 16;

/// How long one request to the TTS module may take.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(2);

#[derive(Debug)]
enum Request {
    Say {
        text: String,
        durative: bool,
        trace: Option<TraceContext>,
    },
    StopDurative {
        text: String,
    },
    CancelAll,
    Mood {
        mood: String,
    },
}

/// A handle on the speech task, which sends requests to the TTS module in order.
#[derive(Debug, Clone)]
pub struct Speech {
    requests: mpsc::Sender<Request>,
    /// The reply span of the turn just heard, given to the next utterance (the reply's first speech), so that the
    /// TTS module's synthesis span joins the turn's trace (docs/telemetry.md).
    reply: Arc<Mutex<Option<TraceContext>>>,
}

impl Speech {
    /// Starts the speech task on `client`.
    pub fn start(client: Client) -> Self {
        let (requests, queue) = mpsc::channel(REQUEST_QUEUE);
        tokio::spawn(speak_in_order(client, queue));
        Speech {
            requests,
            reply: Arc::default(),
        }
    }

    /// The turn heard now will be answered under `reply` (its reply span); `None` when what was heard carried no
    /// trace.
    pub fn answering(&self, reply: Option<TraceContext>) {
        *self.reply.lock().unwrap_or_else(PoisonError::into_inner) = reply;
    }

    /// Speaks `text`; a durative utterance can be stopped with [`Speech::stop_durative`].
    pub async fn say(&self, text: &str, durative: bool) {
        let trace = self
            .reply
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take();
        self.send(Request::Say {
            text: text.to_owned(),
            durative,
            trace,
        });
    }

    /// Stops the durative utterance of `text` (its rule is no longer active).
    pub async fn stop_durative(&self, text: &str) {
        self.send(Request::StopDurative {
            text: text.to_owned(),
        });
    }

    /// Stops all speech now.
    pub async fn cancel_all(&self) {
        self.send(Request::CancelAll);
    }

    /// Shows an expression on the avatar for a few seconds, in the order of the speech requests.
    pub async fn mood(&self, mood: &str) {
        self.send(Request::Mood {
            mood: mood.to_owned(),
        });
    }

    fn send(&self, request: Request) {
        if let Err(e) = self.requests.try_send(request) {
            warn!("brain: speech request dropped, the TTS module is not keeping up: {e}");
        }
    }
}

/// Sends the requests one at a time, so utterances are queued in the order the rules fired them.
async fn speak_in_order(client: Client, mut queue: mpsc::Receiver<Request>) {
    // Durative utterances in progress, by text, with the TTS module's utterance number.
    let mut durative: HashMap<String, u64> = HashMap::new();
    while let Some(request) = queue.recv().await {
        let body = match &request {
            Request::Say { text, trace, .. } => serde_json::to_value(SayRequest {
                text: text.clone(),
                voice: None,
                rate_wpm: None,
                pitch: None,
                trace: trace.map(|t| t.traceparent()),
                prepare: false,
            })
            .unwrap_or_default(),
            Request::StopDurative { text } => match durative.remove(text) {
                Some(utterance) => serde_json::json!({ "cancel": utterance }),
                None => continue,
            },
            Request::CancelAll => {
                durative.clear();
                serde_json::json!({ "cancel": "all" })
            }
            Request::Mood { mood } => serde_json::json!({ "mood": mood }),
        };
        let body = serde_json::to_vec(&body).unwrap_or_default();
        match client.call(SAY.name, body, REQUEST_TIMEOUT).await {
            Ok(answer) => {
                if let Request::Say {
                    text,
                    durative: true,
                    ..
                } = request
                    && let Ok(SayAnswer { utterance }) = serde_json::from_slice(&answer)
                {
                    durative.insert(text, utterance);
                }
            }
            Err(e) => warn!("brain: {} failed: {e}", SAY.name),
        }
    }
    debug!("brain: speech task ended");
}

/// How long the preparation of one text may take: a few runs of the voice on a busy machine.
const PREPARE_TIMEOUT: Duration = Duration::from_secs(10);

/// Asks the TTS module to prepare the program's fixed replies (`Program::fixed_sayings`) one at a time, so that
/// the first time each is said its audio comes from the voice's cache; stops at the first answer that the voice
/// keeps none (espeak-ng) or at the first failure (no TTS module). A preparation that speech stopped is not
/// retried: that reply is cached when it is first said.
pub async fn prepare_sayings(client: Client, sayings: Vec<String>) {
    let mut cached = 0;
    for text in &sayings {
        let request = SayRequest {
            text: text.clone(),
            voice: None,
            rate_wpm: None,
            pitch: None,
            trace: None,
            prepare: true,
        };
        let body = serde_json::to_vec(&request).unwrap_or_default();
        match client.call(SAY.name, body, PREPARE_TIMEOUT).await {
            Ok(answer) => match serde_json::from_slice::<PrepareAnswer>(&answer) {
                Ok(PrepareAnswer { cached: true }) => cached += 1,
                Ok(PrepareAnswer { cached: false }) if cached == 0 => {
                    debug!("brain: the voice keeps no cache; nothing to prepare");
                    return;
                }
                Ok(PrepareAnswer { cached: false }) => {}
                Err(e) => {
                    debug!("brain: {} answered a preparation with {e}", SAY.name);
                    return;
                }
            },
            Err(e) => {
                debug!("brain: preparing the fixed replies stopped: {e}");
                return;
            }
        }
    }
    info!(
        cached,
        of = sayings.len(),
        "brain: the fixed replies are prepared in the voice's cache"
    );
}

/// Follows the agent's speech output to tell when it is audible: every chunk on `Agent.speech` extends the
/// play-out by its duration, from whichever is later of now and the end of what was already queued (speech is
/// synthesised faster than real time, so chunks arrive ahead of playback).
#[derive(Debug, Clone, Default)]
pub struct PlayoutClock {
    until: Option<Instant>,
}

/// `Agent.speech`: 22050 Hz s16le mono.
const SPEECH_RATE: f64 = 22050.0;

impl PlayoutClock {
    /// Accounts for one `Agent.speech` payload; `framed` when it starts with the 8-byte utterance/offset header.
    pub fn chunk(&mut self, now: Instant, payload_len: usize, framed: bool) {
        let pcm = payload_len.saturating_sub(if framed { 8 } else { 0 });
        let duration = Duration::from_secs_f64((pcm / 2) as f64 / SPEECH_RATE);
        let start = self.until.filter(|until| *until > now).unwrap_or(now);
        self.until = Some(start + duration);
    }

    /// Speech was stopped (cancelled, or a barge-in on `Agent.avatar`).
    pub fn stop(&mut self) {
        self.until = None;
    }

    /// When the speech heard now ends, if the agent is speaking at `now`.
    pub fn speaking_until(&self, now: Instant) -> Option<Instant> {
        self.until.filter(|until| *until > now)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_playout_clock_adds_up_chunks_queued_ahead() {
        let t0 = Instant::now();
        let mut clock = PlayoutClock::default();
        // Ten 20 ms chunks arriving at once play for 200 ms.
        for _ in 0..10 {
            clock.chunk(t0, 8 + 441 * 2, true);
        }
        let until = clock.speaking_until(t0);
        assert_eq!(until, Some(t0 + Duration::from_millis(200)));
        assert_eq!(clock.speaking_until(t0 + Duration::from_millis(250)), None);
        // A chunk after a pause starts from its arrival.
        let later = t0 + Duration::from_secs(1);
        clock.chunk(later, 441 * 2, false);
        assert_eq!(
            clock.speaking_until(later),
            Some(later + Duration::from_millis(20))
        );
        clock.stop();
        assert_eq!(clock.speaking_until(later), None);
    }
}
