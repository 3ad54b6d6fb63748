//! Recognition options shared by `transcribe` and `run`: model, threads, segmentation and encoder window.

use std::path::PathBuf;

use whisper_sat::segmenter::SegmenterConfig;
use whisper_sat::transcriber::{AudioContext, TranscriberConfig};

#[derive(Debug, Clone, clap::Args)]
pub struct RecognitionArgs {
    /// ggml model file (default: models/ggml-tiny.en.bin in the repository, or WHISPER_MODEL).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Inference threads.
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// End-of-speech hangover in milliseconds.
    #[arg(long, default_value_t = SegmenterConfig::default().hangover_ms)]
    hangover_ms: u32,
    /// Trailing silence an utterance keeps, in milliseconds; once the silence holds it, the utterance pauses and
    /// its speculative decode starts.
    #[arg(long, default_value_t = SegmenterConfig::default().post_roll_ms)]
    post_roll_ms: u32,
    /// Silence after which a pause whose transcript reads as a complete turn ends the utterance, in
    /// milliseconds (at least --post-roll-ms).
    #[arg(long, default_value_t = SegmenterConfig::default().turn_confirm_ms)]
    turn_confirm_ms: u32,
    /// How long a pause waits for the verdict on its transcript, and how long an utterance whose transcript
    /// trails off is held open, in milliseconds.
    #[arg(long, default_value_t = SegmenterConfig::default().turn_wait_ms)]
    turn_wait_ms: u32,
    /// Pre-roll kept before the detected onset, in milliseconds.
    #[arg(long, default_value_t = SegmenterConfig::default().pre_roll_ms)]
    pre_roll_ms: u32,
    /// Run the full 30 s encoder window instead of fitting it to the utterance.
    #[arg(long)]
    full_window: bool,
}

impl RecognitionArgs {
    pub fn model(&self) -> PathBuf {
        self.model
            .clone()
            .unwrap_or_else(whisper_sat::model_path::default_model)
    }

    pub fn transcriber(&self) -> TranscriberConfig {
        TranscriberConfig {
            threads: self.threads,
            audio_context: if self.full_window {
                AudioContext::Full
            } else {
                AudioContext::Fit
            },
            ..TranscriberConfig::default()
        }
    }

    pub fn segmenter(&self) -> SegmenterConfig {
        SegmenterConfig {
            hangover_ms: self.hangover_ms,
            post_roll_ms: self.post_roll_ms,
            turn_confirm_ms: self.turn_confirm_ms,
            turn_wait_ms: self.turn_wait_ms,
            pre_roll_ms: self.pre_roll_ms,
            ..SegmenterConfig::default()
        }
    }
}
