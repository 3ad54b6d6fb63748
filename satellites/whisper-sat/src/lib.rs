//! Whisper ASR satellite: model conversion, voice activity detection and transcription.
//!
//! The library holds the pieces; `src/main.rs` wires them into the `whisper-sat` command (convert, transcribe, run,
//! bench).

pub mod abort;
pub mod activity;
pub mod claim;
pub mod convert;
pub mod cores;
pub mod echo;
pub mod ledger;
pub mod model_path;
pub mod offline;
pub mod resample;
pub mod restart_stop;
pub mod segmenter;
pub mod speculation;
pub mod stream;
pub mod transcriber;
pub mod transcript;
pub mod turn;
pub mod wav;
pub mod wer;
