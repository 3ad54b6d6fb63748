//! Speech synthesis with espeak-ng: streamed PCM plus a viseme timeline from espeak-ng's phoneme events.
//!
//! [`Synthesizer`] owns espeak-ng on one dedicated thread (espeak-ng is a global, non-thread-safe C engine);
//! [`Synthesizer::speak`] queues a text and returns an [`Utterance`] that streams [`SpeechEvent`]s sentence by
//! sentence: PCM chunks (22050 Hz, s16le mono) that carry the [`VisemeCue`]s falling inside them, so audio and
//! mouth shapes share one sample clock. See docs/voice.md.

mod data_path;
mod engine;
mod error;
mod espeak;
mod sentence;
mod timeline;
mod viseme;
mod voice;

pub use data_path::{DATA_PATH_ENV, locate_data};
pub use engine::{CancelToken, Recording, SpeechEvent, Synthesizer, SynthesizerConfig, Utterance};
pub use error::VoiceError;
pub use sentence::split_sentences;
pub use timeline::{PhonemeMark, SpeechChunk, VisemeCue, samples_to_ms};
pub use viseme::{MouthShape, Viseme, mouth_shape};
pub use voice::{RATE_RANGE, VoiceSettings};

/// The sample rate of espeak-ng's standard voices and of the `Agent.speech` channel.
pub const SAMPLE_RATE: u32 = 22050;
