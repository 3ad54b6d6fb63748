//! Whisper ASR satellite: model conversion, voice activity detection and transcription.
//!
//! The library holds the pieces and the satellite's runtime (`satellite`); `src/main.rs` parses the `whisper-sat`
//! command (convert, transcribe, run, wer) and calls into it. The ASR benchmark (`bench/asr`, `asr-bench`) drives
//! the same pieces: `recognition` gives its satellite processes `run`'s flags.

pub mod abort;
pub mod activity;
pub mod claim;
pub mod convert;
pub mod cores;
pub mod echo;
pub mod ledger;
pub mod model_path;
pub mod offline;
pub mod recognition;
pub mod resample;
pub mod restart_stop;
pub mod satellite;
pub mod segmenter;
pub mod speculation;
pub mod stream;
pub mod transcriber;
pub mod transcript;
pub mod turn;
pub mod wav;
pub mod wer;
