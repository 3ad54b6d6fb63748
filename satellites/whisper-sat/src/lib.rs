//! Whisper ASR satellite: model conversion, voice activity detection and transcription.
//!
//! The library holds the pieces; `src/main.rs` wires them into the `whisper-sat` command (convert, transcribe, run,
//! bench).

pub mod convert;
pub mod model_path;
pub mod offline;
pub mod resample;
pub mod segmenter;
pub mod transcriber;
pub mod wav;
pub mod wer;
