//! The benchmark's flags, a leaf that `main.rs` parses and `report.rs` reads.

use std::path::PathBuf;

/// The benchmark's flags (those `whisper-sat bench` took).
#[derive(Debug, clap::Args)]
pub struct Args {
    #[arg(long, default_value_t = 2)]
    pub(crate) threads: usize,
    /// Timed runs per clip (after one warm-up run).
    #[arg(long, default_value_t = 3)]
    pub(crate) runs: usize,
    /// ggml model (default: models/ggml-tiny.en.bin or WHISPER_MODEL).
    #[arg(long)]
    pub(crate) model: Option<PathBuf>,
    /// The CTranslate2 model directory the ggml file was converted from (the baseline runs on it).
    #[arg(long)]
    pub(crate) ct2_dir: Option<PathBuf>,
    /// Python with faster-whisper installed (default: models/bench-venv/bin/python).
    #[arg(long)]
    pub(crate) python: Option<PathBuf>,
    /// Write the results as Markdown to this file (e.g. docs/bench-asr.md).
    #[arg(long)]
    pub(crate) write: Option<PathBuf>,
    /// Measure only the 1, 2 and 3 satellite fleets (no faster-whisper needed).
    #[arg(long)]
    pub(crate) fleet_only: bool,
    /// Measure only the word error rates (and each model's RTF, latency and memory).
    #[arg(long)]
    pub(crate) wer_only: bool,
}
