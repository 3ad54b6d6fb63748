//! Recognition options shared by `whisper-sat transcribe` and `run` (and by the ASR benchmark's satellite
//! processes, so they decode exactly as `run` does): model, threads, core share, segmentation and encoder window.

use std::path::PathBuf;

use crate::cores::{CoreShare, CoreShareError};
use crate::segmenter::SegmenterConfig;
use crate::transcriber::{AudioContext, TranscriberConfig};

/// The recognition flags, with `whisper-sat run`'s defaults; the methods turn them into the library's settings.
#[derive(Debug, Clone, clap::Args)]
pub struct RecognitionArgs {
    /// ggml model file, or the name of one `make model MODEL=<name>` provisions (`tiny.en`, `base`); default:
    /// models/ggml-tiny.en.bin in the repository, or WHISPER_MODEL.
    #[arg(long)]
    model: Option<PathBuf>,
    /// Language of the speech: a Whisper language code (`en`, `it`...), or `auto` to detect it per utterance.
    /// English-only models (`tiny.en`) understand only `en`.
    #[arg(long, default_value = "en")]
    language: String,
    /// Beams of the decoder's beam search; 1 decodes greedily (faster; docs/bench-asr.md has WER and latency of
    /// both).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=16))]
    beam: u16,
    /// Most inference threads per decode (default: the machine's cores, at most 4). Satellites on one machine
    /// share its cores: each decode runs on its fair share, cores / satellites, up to this (docs/asr.md).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..))]
    threads: Option<u16>,
    /// Cores that the satellites of this machine share between them (default: the cores this process may use).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..))]
    cores: Option<u16>,
    /// Directory of the machine's core share: satellites that name the same one share cores (default: per user,
    /// under $XDG_RUNTIME_DIR or the temporary directory).
    #[arg(long)]
    core_share_dir: Option<PathBuf>,
    /// Run --threads threads per decode whatever other satellites on the machine do. Satellites whose threads
    /// together outnumber the cores then slow each other down many times over (whisper.cpp's threads spin).
    #[arg(long)]
    no_core_share: bool,
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
    /// Decode an utterance again with the full window when the fitted decode's mean token log-probability is below
    /// this (e.g. -0.3): fewer word errors for the few unsure utterances, at the full window's cost on those
    /// (docs/asr.md, "Accuracy").
    #[arg(long, allow_hyphen_values = true, value_parser = unsure_logprob)]
    unsure_retry: Option<f32>,
}

/// A log-probability floor: a number below zero.
fn unsure_logprob(s: &str) -> Result<f32, String> {
    let v: f32 = s.parse().map_err(|e| format!("{s}: {e}"))?;
    if v.is_finite() && v < 0.0 {
        Ok(v)
    } else {
        Err(format!(
            "{s}: a mean log-probability floor is below zero, e.g. -0.3"
        ))
    }
}

impl RecognitionArgs {
    /// The model file `--model` names (or the default one).
    pub fn model(&self) -> PathBuf {
        self.model.as_deref().map_or_else(
            crate::model_path::default_model,
            crate::model_path::resolve_model,
        )
    }

    /// The transcriber's settings: threads, encoder window, language, beams and the unsure retry.
    pub fn transcriber(&self) -> TranscriberConfig {
        TranscriberConfig {
            threads: self
                .threads
                .map_or_else(|| crate::cores::machine_cores().min(4), usize::from),
            audio_context: if self.full_window {
                AudioContext::Full
            } else {
                AudioContext::Fit
            },
            language: self.language.clone(),
            beam_size: usize::from(self.beam),
            unsure_logprob: self.unsure_retry,
            ..TranscriberConfig::default()
        }
    }

    /// The machine's core share to join, unless switched off.
    pub fn core_share(&self) -> Result<Option<CoreShare>, CoreShareError> {
        if self.no_core_share {
            return Ok(None);
        }
        let dir = self
            .core_share_dir
            .clone()
            .unwrap_or_else(crate::cores::default_dir);
        let cores = self
            .cores
            .map_or_else(crate::cores::machine_cores, usize::from);
        CoreShare::join(&dir, cores).map(Some)
    }

    /// The segmenter's settings: hangover, post-roll, end of turn and pre-roll.
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
