//! What the engine thread works on and hands back: a queued request, the events of its utterance, the token that
//! stops it, and the counts the thread keeps (shared by `engine.rs` and the Piper path in `piper_speech.rs`).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use tokio::sync::mpsc;

use crate::timeline::SpeechChunk;
use crate::voice::VoiceSettings;

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

/// One utterance queued for the engine thread.
pub(super) struct Request {
    pub text: String,
    pub voice: VoiceSettings,
    pub cancel: CancelToken,
    pub out: mpsc::Sender<SpeechEvent>,
}

impl std::fmt::Debug for Request {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Request")
            .field("text", &self.text)
            .field("voice", &self.voice)
            .finish_non_exhaustive()
    }
}

/// What the engine thread counts, read through `Synthesizer::stats`.
#[derive(Debug, Default)]
pub(super) struct Counters {
    pub piper_runs: AtomicU64,
    pub piper_cache_hits: AtomicU64,
}
