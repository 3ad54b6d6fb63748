//! Speech synthesis with espeak-ng, and with a Piper (neural) voice that espeak-ng phonemises for: streamed PCM
//! plus a viseme timeline from espeak-ng's phoneme events or from the Piper network's own phoneme durations.
//!
//! [`Synthesizer`] owns espeak-ng on one dedicated thread (espeak-ng is a global, non-thread-safe C engine), and
//! the Piper voice beside it when [`SynthesizerConfig::piper`] names one; each request picks its [`Engine`];
//! [`Synthesizer::speak`] queues a text and returns an [`Utterance`] that streams [`SpeechEvent`]s sentence by
//! sentence: PCM chunks (22050 Hz, s16le mono) that carry the [`VisemeCue`]s falling inside them, so audio and
//! mouth shapes share one sample clock. See docs/voice.md.

mod checksum;
mod data_path;
mod engine;
mod error;
mod espeak;
mod piper;
mod sentence;
mod timeline;
mod viseme;
mod voice;

pub use checksum::{MAKE_TARGET, file_sha256, listed_sha256};
pub use data_path::{DATA_PATH_ENV, locate_data};
pub use engine::{
    CancelToken, Recording, SpeechEvent, SpeechStats, Synthesizer, SynthesizerConfig, Utterance,
};
pub use error::VoiceError;
pub use piper::{PiperConfig, RUNTIME_FILE, VOICE_FILE, VOICE_JSON_FILE};
pub use sentence::split_sentences;
pub use timeline::{PhonemeMark, SpeechChunk, VisemeCue, samples_to_ms};
pub use viseme::{MouthShape, Viseme, mouth_shape};
pub use voice::{Engine, RATE_RANGE, VoiceSettings};

/// The sample rate of espeak-ng's standard voices, of the Piper voice, and of the `Agent.speech` channel.
pub const SAMPLE_RATE: u32 = 22050;
