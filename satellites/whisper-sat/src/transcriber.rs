//! Whisper inference on one utterance with whisper-rs, and the filter that rejects hallucinated output.
//!
//! Whisper invents text for audio without speech ("Thank you.", loops of one phrase), so every result passes a
//! filter: Whisper's own no-speech rule (high no-speech probability together with low token confidence), empty
//! output, repetition loops, and anything at all transcribed from near-silent audio.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::abort::AbortFlag;
use crate::cores::CoreShare;
use crate::restart_stop::{RestartStop, WordStarts};
use whisper_rs::{
    FullParams, SamplingStrategy, WhisperContext, WhisperContextParameters, WhisperState,
};

/// Whisper's input rate.
pub const RATE: usize = 16_000;

/// Errors from loading a model or running it.
#[derive(Debug, thiserror::Error)]
pub enum TranscribeError {
    #[error(
        "model file {0} does not exist (run `make model`, or pass --model / set WHISPER_MODEL)"
    )]
    MissingModel(PathBuf),
    #[error("loading model {path}: {source}")]
    Load {
        path: PathBuf,
        source: whisper_rs::WhisperError,
    },
    #[error("whisper inference failed: {0}")]
    Inference(#[from] whisper_rs::WhisperError),
    /// The caller set the abort flag: the result was no longer wanted.
    #[error("whisper inference aborted")]
    Aborted,
}

/// How much of Whisper's 30 s encoder window to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AudioContext {
    /// The whole 30 s window, as the model was trained (slowest, most robust).
    Full,
    /// Only the part the utterance covers plus a margin: far less encoder work on short utterances.
    Fit,
}

/// Inference and filter settings.
#[derive(Debug, Clone, PartialEq)]
pub struct TranscriberConfig {
    /// Most inference threads one decode runs; a satellite in a machine's core share runs its fair share of the
    /// cores, up to this (see [`crate::cores`]).
    pub threads: usize,
    pub audio_context: AudioContext,
    /// Whisper's no-speech rule: reject when the no-speech probability exceeds this...
    pub no_speech_threshold: f32,
    /// ...and the mean token log-probability is below this.
    pub logprob_threshold: f32,
    /// Reject any output from audio whose overall level is below this (dBFS).
    pub near_silence_dbfs: f32,
    pub language: String,
    /// Beams of whisper.cpp's beam search; 1 decodes greedily (the default: the fastest, and on the fixtures as
    /// accurate; docs/bench-asr.md has both).
    pub beam_size: usize,
    /// A fitted-window decode whose mean token log-probability is below this is unsure, and is decoded again with
    /// the full window, whose text is kept (`None`: never). The full window is what costs accuracy to leave out
    /// (docs/asr.md), and the fitted decode's confidence tells when it probably did.
    pub unsure_logprob: Option<f32>,
}

impl Default for TranscriberConfig {
    fn default() -> Self {
        Self {
            threads: 2,
            audio_context: AudioContext::Fit,
            no_speech_threshold: 0.6,
            logprob_threshold: -1.0,
            near_silence_dbfs: -45.0,
            language: "en".into(),
            beam_size: 1,
            unsure_logprob: None,
        }
    }
}

/// Raw decoder output for one utterance.
#[derive(Debug, Clone, PartialEq)]
pub struct Decoded {
    pub text: String,
    pub no_speech_prob: f32,
    pub avg_logprob: f32,
    pub tokens: usize,
    pub processing: Duration,
    /// The fitted encoder window looped and the text comes from a second decode with the full 30 s window.
    pub full_window_retry: bool,
    /// Inference threads the decode ran with (its lease of the machine's cores, when it shares them).
    pub threads: usize,
    /// Time spent waiting for a core before the decode could start (zero outside a core share), not counted in
    /// `processing`.
    pub core_wait: Duration,
}

/// Why an output was thrown away.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rejection {
    Empty,
    NoSpeech { prob: f32, avg_logprob: f32 },
    Repetition,
    NearSilence { dbfs: f32 },
}

/// The result of transcribing one utterance.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    Speech(Decoded),
    Rejected(Rejection, Decoded),
}

/// A loaded model with its reusable inference state.
pub struct Transcriber {
    ctx: WhisperContext,
    state: WhisperState,
    cfg: TranscriberConfig,
    model_name: String,
    /// The machine's core share this transcriber's decodes lease their threads from, if it joined one.
    cores: Option<CoreShare>,
    /// Which tokens begin a word, for ending a decode that restarts (crate::restart_stop).
    words: WordStarts,
}

impl std::fmt::Debug for Transcriber {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Transcriber")
            .field("model", &self.model_name)
            .field("cfg", &self.cfg)
            .field("cores", &self.cores)
            .finish()
    }
}

/// Routes whisper.cpp's own logging into `tracing` once per process, so it does not flood stderr.
fn quiet_native_logging() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(whisper_rs::install_logging_hooks);
}

impl Transcriber {
    /// Loads a ggml model file.
    pub fn load(path: &Path, cfg: TranscriberConfig) -> Result<Self, TranscribeError> {
        if !path.is_file() {
            return Err(TranscribeError::MissingModel(path.to_path_buf()));
        }
        quiet_native_logging();
        let ctx = WhisperContext::new_with_params(path, WhisperContextParameters::default())
            .map_err(|source| TranscribeError::Load {
                path: path.to_path_buf(),
                source,
            })?;
        let state = ctx.create_state().map_err(|source| TranscribeError::Load {
            path: path.to_path_buf(),
            source,
        })?;
        let model_name = path
            .file_stem()
            .map(|s| s.to_string_lossy().trim_start_matches("ggml-").to_owned())
            .unwrap_or_else(|| "whisper".into());
        let words = WordStarts::of(&ctx);
        Ok(Self {
            ctx,
            state,
            cfg,
            model_name,
            cores: None,
            words,
        })
    }

    /// Runs every later decode on a lease from `share` instead of a fixed `threads` (see [`crate::cores`]).
    pub fn share_cores(&mut self, share: CoreShare) {
        self.cores = Some(share);
    }

    /// The core share joined, if any.
    pub fn core_share(&self) -> Option<&CoreShare> {
        self.cores.as_ref()
    }

    /// Short model name for transcripts ("tiny.en" for `ggml-tiny.en.bin`).
    pub fn model_name(&self) -> &str {
        &self.model_name
    }

    /// The settings in use.
    pub fn config(&self) -> &TranscriberConfig {
        &self.cfg
    }

    /// Decodes on 16 kHz mono audio and applies the hallucination filter.
    pub fn transcribe(&mut self, audio: &[f32]) -> Result<Outcome, TranscribeError> {
        self.transcribe_abortable(audio, &AbortFlag::new())
    }

    /// `transcribe`, stopped early with [`TranscribeError::Aborted`] once `abort` is set.
    pub fn transcribe_abortable(
        &mut self,
        audio: &[f32],
        abort: &AbortFlag,
    ) -> Result<Outcome, TranscribeError> {
        let decoded = self.decode_abortable(audio, abort)?;
        Ok(judge(&self.cfg, audio, decoded))
    }

    /// Decodes without filtering. With a fitted encoder window, an output that runs into the token
    /// cap or loops on one phrase is decoded again with the full window: a cut window makes the decoder repeat
    /// itself, and the full window is what the model was trained on. The commonest failure, on short utterances, is
    /// the whole utterance transcribed and then said again and again; that output is kept, once, since the second
    /// decode costs the full 30 s encoder (over a second on two cores, most of the voice-to-voice latency).
    pub fn decode(&mut self, audio: &[f32]) -> Result<Decoded, TranscribeError> {
        self.decode_abortable(audio, &AbortFlag::new())
    }

    /// `decode`, stopped early with [`TranscribeError::Aborted`] once `abort` is set.
    pub fn decode_abortable(
        &mut self,
        audio: &[f32],
        abort: &AbortFlag,
    ) -> Result<Decoded, TranscribeError> {
        let waiting = Instant::now();
        // The lease is held for the fitted decode and its full-window retry alike, and given back on return.
        let lease = match &self.cores {
            Some(share) => Some(
                share
                    .acquire(self.cfg.threads, abort)
                    .ok_or(TranscribeError::Aborted)?,
            ),
            None => None,
        };
        let threads = lease.as_ref().map_or(self.cfg.threads, |l| l.threads());
        let core_wait = waiting.elapsed();
        let started = Instant::now();
        let mut decoded = self.decode_with(audio, self.cfg.audio_context, threads, abort)?;
        let seconds = audio.len() as f32 / RATE as f32;
        // The cut window's signature failure: the whole utterance said again, up to the token cap or only twice
        // (nobody says one sentence twice in one breath; a phrase too short for the audio is not taken).
        let repeated = (self.cfg.audio_context == AudioContext::Fit)
            .then(|| repeated_utterance(&decoded.text, seconds))
            .flatten();
        if let Some(once) = repeated {
            tracing::debug!(text = %decoded.text, "fitted window repeated the utterance; kept once");
            decoded.text = once;
        } else if self.cfg.audio_context == AudioContext::Fit
            && (decoded.tokens >= token_cap(audio.len()) || is_repetition_loop(&decoded.text))
        {
            tracing::debug!(text = %decoded.text, "fitted window looped; decoding with the full window");
            decoded = self.decode_with(audio, AudioContext::Full, threads, abort)?;
            decoded.full_window_retry = true;
        } else if self.cfg.audio_context == AudioContext::Fit
            && decoded.tokens > 0
            && self
                .cfg
                .unsure_logprob
                .is_some_and(|floor| decoded.avg_logprob < floor)
            // What the filter will reject anyway (near silence, or no speech by Whisper's own rule) is usually
            // unsure too; it is not worth the full window.
            && decoded.no_speech_prob <= self.cfg.no_speech_threshold
            && level_dbfs(audio) >= self.cfg.near_silence_dbfs
        {
            tracing::debug!(text = %decoded.text, logprob = decoded.avg_logprob, "fitted window unsure; decoding with the full window");
            decoded = self.decode_with(audio, AudioContext::Full, threads, abort)?;
            decoded.full_window_retry = true;
        }
        drop(lease);
        decoded.processing = started.elapsed();
        decoded.core_wait = core_wait;
        Ok(decoded)
    }

    fn decode_with(
        &mut self,
        audio: &[f32],
        context: AudioContext,
        threads: usize,
        abort: &AbortFlag,
    ) -> Result<Decoded, TranscribeError> {
        let started = Instant::now();
        // whisper.cpp refuses input shorter than one second; pad short utterances with silence.
        let min_len = RATE + RATE / 10;
        let padded;
        let input = if audio.len() < min_len {
            padded = [audio, &vec![0.0; min_len - audio.len()]].concat();
            &padded[..]
        } else {
            audio
        };
        let strategy = if self.cfg.beam_size > 1 {
            SamplingStrategy::BeamSearch {
                beam_size: i32::try_from(self.cfg.beam_size).unwrap_or(i32::MAX),
                patience: -1.0,
            }
        } else {
            SamplingStrategy::Greedy { best_of: 1 }
        };
        let mut params = FullParams::new(strategy);
        params.set_n_threads(i32::try_from(threads).unwrap_or(i32::MAX));
        params.set_language(Some(&self.cfg.language));
        params.set_translate(false);
        params.set_no_context(true);
        params.set_no_timestamps(true);
        params.set_single_segment(true);
        params.set_print_special(false);
        params.set_print_progress(false);
        params.set_print_realtime(false);
        params.set_print_timestamps(false);
        params.set_suppress_blank(true);
        params.set_suppress_nst(true);
        // No temperature fallback, so the result is deterministic and latency bounded.
        params.set_temperature(0.0);
        params.set_temperature_inc(0.0);
        // Speech runs at about three tokens a second; a cap well above that stops a looping decoder early.
        params.set_max_tokens(token_cap(audio.len()) as i32);
        if context == AudioContext::Fit {
            params.set_audio_ctx(fit_audio_ctx(input.len(), self.ctx.n_audio_ctx()));
        }
        abort.attach(&mut params);
        // A greedy decode with the fitted window ends once it starts saying the utterance again (restart_stop.rs).
        let seconds = audio.len() as f32 / RATE as f32;
        let restart = RestartStop::new(
            &self.ctx,
            &self.words,
            MIN_WORDS_PER_SECOND * seconds,
            SENTENCE_WORDS_PER_SECOND * seconds,
        );
        if context == AudioContext::Fit && self.cfg.beam_size <= 1 {
            restart.attach(&mut params);
        }
        let result = self.state.full(params, input);
        // An aborted run fails inside whisper.cpp, or may finish with whatever it had; either way it is unwanted.
        if abort.is_aborted() {
            return Err(TranscribeError::Aborted);
        }
        result?;
        let eot = self.ctx.token_eot();
        // A decode ended on a restart keeps the phrase it restarted, once.
        let keep = restart.phrase();
        let mut text = String::new();
        // Token by token as bytes: a multilingual token may hold part of a character.
        let mut kept = Vec::new();
        let mut logprob_sum = 0.0f32;
        let mut tokens = 0usize;
        let mut no_speech_prob = 0.0f32;
        let mut decoded_tokens = 0usize;
        for i in 0..self.state.full_n_segments() {
            let Some(segment) = self.state.get_segment(i) else {
                continue;
            };
            decoded_tokens += usize::try_from(segment.n_tokens()).unwrap_or(0);
            no_speech_prob = no_speech_prob.max(segment.no_speech_probability());
            if keep.is_none() {
                text.push_str(&segment.to_str_lossy()?);
            }
            for t in 0..segment.n_tokens() {
                if let Some(token) = segment.get_token(t) {
                    let data = token.token_data();
                    if data.id < eot && keep.is_none_or(|k| tokens < k) {
                        if keep.is_some() {
                            kept.extend_from_slice(token.to_bytes()?);
                        }
                        logprob_sum += data.plog;
                        tokens += 1;
                    }
                }
            }
        }
        if keep.is_some() {
            text = String::from_utf8_lossy(&kept)
                .trim()
                .trim_end_matches([',', ';', ':'])
                .to_owned();
            tracing::debug!(%text, tokens, logprob = logprob_sum / tokens.max(1) as f32, "the decode restarted the utterance; ended it there");
        }
        tracing::debug!(
            audio_ms = audio.len() * 1000 / RATE,
            ?context,
            threads,
            decoded_tokens,
            kept_tokens = tokens,
            ms = started.elapsed().as_millis() as u64,
            text = %text.trim(),
            "decoded"
        );
        Ok(Decoded {
            text: text.trim().to_owned(),
            no_speech_prob,
            avg_logprob: if tokens == 0 {
                f32::NEG_INFINITY
            } else {
                logprob_sum / tokens as f32
            },
            tokens,
            processing: started.elapsed(),
            full_window_retry: false,
            threads,
            core_wait: Duration::ZERO,
        })
    }
}

/// Fewest words a second the repeated phrase must hold to stand for the whole utterance: read speech runs at two
/// to three, so a phrase below this covers only part of the audio and the output is not trusted.
const MIN_WORDS_PER_SECOND: f32 = 1.2;

/// Fewest words a second a sentence must hold to be taken for the whole utterance as soon as a repeat of it starts
/// (`RestartStop`): an ordinary pace over the whole audio, pre-roll and post-roll included, so that a first sentence
/// of two falls short of it.
const SENTENCE_WORDS_PER_SECOND: f32 = 2.0;

/// When `text` is one phrase from its start said at least twice over (the last time possibly cut by the token
/// cap), and that phrase is long enough for `seconds` of speech, the phrase once; else `None`.
pub fn repeated_utterance(text: &str, seconds: f32) -> Option<String> {
    let words: Vec<(&str, String)> = text
        .split_whitespace()
        .map(|w| (w, crate::wer::normalise(w).concat()))
        .filter(|(_, n)| !n.is_empty())
        .collect();
    let n = words.len();
    let period = (1..=n / 2).find(|&p| (p..n).all(|i| words[i].1 == words[i % p].1))?;
    if (period as f32) < MIN_WORDS_PER_SECOND * seconds {
        return None;
    }
    let once = words[..period]
        .iter()
        .map(|(w, _)| *w)
        .collect::<Vec<_>>()
        .join(" ");
    Some(once.trim_end_matches([',', ';', ':']).to_owned())
}

/// Most text tokens an utterance of `samples` may yield: eight a second plus a sentence's worth.
pub fn token_cap(samples: usize) -> usize {
    samples * 8 / RATE + 16
}

/// The fitted encoder window grows in steps of this many positions (2.56 s). Measured on the fixture clips with
/// tiny.en: steps of 64 left some sizes (192, 320) where the decoder looped or ran slowly (LJ001-0004 at 320:
/// 2.0 s, at 384: 0.35 s, the same text); steps of 128 were as fast or faster on every clip, 256 no better.
const FIT_CTX_STEP: usize = 128;

/// Encoder positions (20 ms each) covering `samples` plus a one-second margin, rounded up to a multiple of
/// [`FIT_CTX_STEP`]; never more than the model's window.
pub fn fit_audio_ctx(samples: usize, model_ctx: i32) -> i32 {
    let positions = samples.div_ceil(320) + 50;
    (positions.div_ceil(FIT_CTX_STEP) * FIT_CTX_STEP).min(model_ctx.max(1) as usize) as i32
}

/// Level of the whole clip in dBFS.
pub fn level_dbfs(audio: &[f32]) -> f32 {
    if audio.is_empty() {
        return f32::NEG_INFINITY;
    }
    let energy = audio.iter().map(|s| s * s).sum::<f32>() / audio.len() as f32;
    10.0 * energy.max(1e-12).log10()
}

/// Strips non-speech annotations Whisper emits, like "[BLANK_AUDIO]" or "(music)".
pub fn strip_annotations(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut depth = 0usize;
    let mut starred = false;
    for c in text.chars() {
        match c {
            '[' | '(' => depth += 1,
            ']' | ')' => depth = depth.saturating_sub(1),
            '*' => starred = !starred,
            _ if depth == 0 && !starred => out.push(c),
            _ => {}
        }
    }
    out.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// True when the text is mostly one short phrase repeated: the decoder's failure loop.
pub fn is_repetition_loop(text: &str) -> bool {
    let words = crate::wer::normalise(text);
    if words.len() < 6 {
        return false;
    }
    for n in 1..=4 {
        let mut i = 0;
        while i + n <= words.len() {
            let mut repeats = 1;
            while i + (repeats + 1) * n <= words.len()
                && words[i + repeats * n..i + (repeats + 1) * n] == words[i..i + n]
            {
                repeats += 1;
            }
            if repeats >= 4 && repeats * n * 10 >= words.len() * 6 {
                return true;
            }
            i += 1;
        }
    }
    false
}

/// Applies the hallucination filter to a decoded utterance.
pub fn judge(cfg: &TranscriberConfig, audio: &[f32], mut decoded: Decoded) -> Outcome {
    decoded.text = strip_annotations(&decoded.text);
    let dbfs = level_dbfs(audio);
    let rejection = if crate::wer::normalise(&decoded.text).is_empty() {
        Some(Rejection::Empty)
    } else if decoded.no_speech_prob > cfg.no_speech_threshold
        && decoded.avg_logprob < cfg.logprob_threshold
    {
        Some(Rejection::NoSpeech {
            prob: decoded.no_speech_prob,
            avg_logprob: decoded.avg_logprob,
        })
    } else if dbfs < cfg.near_silence_dbfs {
        Some(Rejection::NearSilence { dbfs })
    } else if is_repetition_loop(&decoded.text) {
        Some(Rejection::Repetition)
    } else {
        None
    };
    match rejection {
        Some(r) => Outcome::Rejected(r, decoded),
        None => Outcome::Speech(decoded),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decoded(text: &str, no_speech_prob: f32, avg_logprob: f32) -> Decoded {
        Decoded {
            text: text.into(),
            no_speech_prob,
            avg_logprob,
            tokens: 3,
            processing: Duration::ZERO,
            full_window_retry: false,
            threads: 2,
            core_wait: Duration::ZERO,
        }
    }

    fn loud() -> Vec<f32> {
        (0..16_000)
            .map(|i| ((i as f32) * 0.05).sin() * 0.3)
            .collect()
    }

    #[test]
    fn filter_rejects_each_kind_of_hallucination() {
        let cfg = TranscriberConfig::default();
        let judge = |audio: &[f32], d| judge(&cfg, audio, d);
        assert!(matches!(
            judge(&loud(), decoded("Ask not.", 0.1, -0.3)),
            Outcome::Speech(_)
        ));
        assert!(matches!(
            judge(&loud(), decoded(" [BLANK_AUDIO] ", 0.1, -0.3)),
            Outcome::Rejected(Rejection::Empty, _)
        ));
        assert!(matches!(
            judge(&loud(), decoded("Thank you.", 0.9, -1.5)),
            Outcome::Rejected(Rejection::NoSpeech { .. }, _)
        ));
        // A confident decoder overrides a high no-speech probability, as in Whisper's own rule.
        assert!(matches!(
            judge(&loud(), decoded("Thank you.", 0.9, -0.2)),
            Outcome::Speech(_)
        ));
        assert!(matches!(
            judge(&vec![0.001; 16_000], decoded("Thank you.", 0.1, -0.2)),
            Outcome::Rejected(Rejection::NearSilence { .. }, _)
        ));
        assert!(matches!(
            judge(&loud(), decoded("so so so so so so so so", 0.1, -0.2)),
            Outcome::Rejected(Rejection::Repetition, _)
        ));
    }

    #[test]
    fn an_utterance_said_over_and_over_is_kept_once() {
        let looped = "produced the block books, produced the block books, Produced the block books, produced the";
        assert_eq!(
            repeated_utterance(looped, 1.5).as_deref(),
            Some("produced the block books")
        );
        assert_eq!(
            repeated_utterance(
                "in being comparatively modern. In being comparatively modern.",
                1.8
            )
            .as_deref(),
            Some("in being comparatively modern.")
        );
        // A phrase too short for the audio is a loop on part of it: not trusted.
        assert_eq!(repeated_utterance("the the the the the the", 3.0), None);
        // Not a repetition from the start.
        assert_eq!(
            repeated_utterance("so it goes on and on and on and on", 2.0),
            None
        );
        assert_eq!(repeated_utterance("", 1.0), None);
    }

    #[test]
    fn repetition_detection_spares_normal_sentences() {
        assert!(!is_repetition_loop(
            "ask not what your country can do for you ask what you can do"
        ));
        assert!(is_repetition_loop(
            "I'm sorry. I'm sorry. I'm sorry. I'm sorry. I'm sorry."
        ));
        assert!(!is_repetition_loop("no no no"));
    }

    #[test]
    fn annotations_are_stripped() {
        assert_eq!(
            strip_annotations("(music) Hello [BLANK_AUDIO] there *laughs*"),
            "Hello there"
        );
    }

    #[test]
    fn audio_context_covers_the_clip_and_is_capped() {
        assert_eq!(fit_audio_ctx(16_000, 1500), 128);
        assert_eq!(fit_audio_ctx(16_000 * 60, 1500), 1500);
        assert!(fit_audio_ctx(16_000 * 5, 1500) as usize >= 250);
        assert_eq!(fit_audio_ctx(16_000 * 5, 1500) % 128, 0);
    }
}
