//! The Piper engine: a neural (VITS) voice that speaks espeak-ng's IPA phonemes, run on ONNX Runtime, with the
//! mouth shapes timed by the network's own phoneme durations on the PCM's sample clock (docs/voice.md, "Piper").
//!
//! espeak-ng (the library the crate links anyway) phonemises each sentence with the voice's espeak voice; the ids
//! go through the network in one run per sentence; the durations output (`/Ceil_output_0`, which
//! `make model-voice` exposes) gives every phoneme's start in samples.

mod align;
mod cache;
mod join;
mod network;
mod parts;
mod phonemes;
mod spoken;
mod voice_file;

use std::path::{Path, PathBuf};

use crate::checksum;
use crate::error::VoiceError;

pub(crate) use cache::{Key, SentenceCache};
pub(crate) use join::{append, end_part, start_part};
pub(crate) use network::Network;
pub(crate) use parts::first_break;
pub(crate) use spoken::Sentence;
pub(crate) use voice_file::VoiceFile;

/// Samples per frame of Piper's medium and high voices (the hop of their spectrogram).
const HOP: u64 = 256;

/// Where the Piper voice and ONNX Runtime are, and how the voice speaks.
#[derive(Debug, Clone, PartialEq)]
pub struct PiperConfig {
    /// The voice network with its durations output (`models/piper/en_US-joe-medium.durations.onnx`).
    pub voice: PathBuf,
    /// Its configuration (`models/piper/en_US-joe-medium.onnx.json`).
    pub voice_json: PathBuf,
    /// ONNX Runtime's shared library (`models/onnxruntime/libonnxruntime.so.1.32.0`).
    pub runtime: PathBuf,
    /// The voice's checksum when it is not one `config/models.sha256` lists.
    pub voice_sha256: Option<String>,
    /// Variation of the sound (the network's noise scale); `None`: the voice's own default (0.667).
    pub noise_scale: Option<f32>,
    /// Variation of the phoneme lengths (noise w); `None`: the voice's default (0.8).
    pub noise_w: Option<f32>,
    /// Slower (> 1) or faster (< 1) speech before the rate of each request; `None`: the voice's default (1.0).
    pub length_scale: Option<f32>,
    /// ONNX Runtime threads inside one run, the caller's included. Its helpers sleep rather than spin while they
    /// wait, so they only take cores that are idle: two made the first audio ~30% sooner on two quiet cores and no
    /// later on busy ones (docs/voice.md, "Threads").
    pub threads: usize,
    /// The first sentence of an utterance is cut at its first natural break after this many words, and its first
    /// part spoken while the rest is synthesised (`piper::parts`); 0 speaks every sentence in one run.
    pub first_part_words: usize,
    /// Seconds of spoken sentences kept to be played again without the network (fixed replies, greetings);
    /// 0 keeps none.
    pub cache_seconds: u32,
}

/// The repository root, found from this crate's manifest directory (agent/voice).
fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// The files `make model-voice` provisions, relative to the repository root.
pub const VOICE_FILE: &str = "models/piper/en_US-joe-medium.durations.onnx";
pub const VOICE_JSON_FILE: &str = "models/piper/en_US-joe-medium.onnx.json";
pub const RUNTIME_FILE: &str = "models/onnxruntime/libonnxruntime.so.1.32.0";

impl Default for PiperConfig {
    fn default() -> Self {
        let root = repo_root();
        PiperConfig {
            voice: root.join(VOICE_FILE),
            voice_json: root.join(VOICE_JSON_FILE),
            runtime: root.join(RUNTIME_FILE),
            voice_sha256: None,
            noise_scale: None,
            noise_w: None,
            length_scale: None,
            threads: 2,
            first_part_words: 3,
            cache_seconds: 60,
        }
    }
}

impl PiperConfig {
    /// Checks the settings' ranges, naming the first bad one.
    pub fn validate(&self) -> Result<(), VoiceError> {
        let check =
            |name: &'static str, value: Option<f32>, range: std::ops::RangeInclusive<f32>| {
                match value {
                    Some(v) if !range.contains(&v) => Err(VoiceError::InvalidSetting {
                        name,
                        value: v.to_string(),
                        reason: format!("must be within {}-{}", range.start(), range.end()),
                    }),
                    _ => Ok(()),
                }
            };
        check("noise_scale", self.noise_scale, 0.0..=2.0)?;
        check("noise_w", self.noise_w, 0.0..=2.0)?;
        check("length_scale", self.length_scale, 0.25..=4.0)?;
        if self.first_part_words > 50 {
            return Err(VoiceError::InvalidSetting {
                name: "first_part_words",
                value: self.first_part_words.to_string(),
                reason: "must be within 0-50".into(),
            });
        }
        if self.cache_seconds > 3600 {
            return Err(VoiceError::InvalidSetting {
                name: "cache_seconds",
                value: self.cache_seconds.to_string(),
                reason: "must be within 0-3600".into(),
            });
        }
        if !(1..=16).contains(&self.threads) {
            return Err(VoiceError::InvalidSetting {
                name: "threads",
                value: self.threads.to_string(),
                reason: "must be within 1-16".into(),
            });
        }
        Ok(())
    }

    /// Checks the settings and that the voice, its configuration and ONNX Runtime are there with the checksums
    /// `config/models.sha256` lists (reading ~100 MB: a few hundred milliseconds). Errors name the file, both
    /// checksums and `make model-voice`.
    pub fn verify(&self) -> Result<(), VoiceError> {
        self.validate()?;
        checksum::verify(&self.voice, self.voice_sha256.as_deref(), "Piper voice")?;
        if self.voice_sha256.is_none() {
            checksum::verify(&self.voice_json, None, "Piper voice configuration")?;
        } else if !self.voice_json.is_file() {
            return Err(VoiceError::Piper(format!(
                "{} is missing",
                self.voice_json.display()
            )));
        }
        checksum::verify(&self.runtime, None, "ONNX Runtime library")
    }
}

/// A loaded voice: configuration plus network, and the sentences it spoke last.
#[derive(Debug)]
pub(crate) struct PiperVoice {
    pub file: VoiceFile,
    network: Network,
    scales: [f32; 3],
    pub first_part_words: usize,
    pub cache: SentenceCache,
}

impl PiperVoice {
    /// Verifies and loads the voice (about half a second).
    pub(crate) fn load(config: &PiperConfig) -> Result<PiperVoice, VoiceError> {
        config.verify()?;
        let file = VoiceFile::load(&config.voice_json)?;
        let network = Network::load(&config.runtime, &config.voice, config.threads)?;
        let [noise_scale, length_scale, noise_w] = file.scales;
        let scales = [
            config.noise_scale.unwrap_or(noise_scale),
            config.length_scale.unwrap_or(length_scale),
            config.noise_w.unwrap_or(noise_w),
        ];
        let cache = SentenceCache::new(config.cache_seconds as usize * file.sample_rate as usize);
        Ok(PiperVoice {
            file,
            network,
            scales,
            first_part_words: config.first_part_words,
            cache,
        })
    }

    /// Speaks one sentence (or part of one) given espeak-ng's clauses for it, in one run of the network.
    /// `length` multiplies the length scale (the request's rate), `gain` the samples (volume / 100) after they are
    /// scaled to full range, as Piper does, by at most `scale` when it is given: the later parts of a sentence keep
    /// its first part's loudness unless they would clip. Returns the sentence and the scale its samples got.
    pub(crate) fn speak<'a>(
        &mut self,
        clauses: impl IntoIterator<Item = (&'a str, &'a str)>,
        length: f32,
        gain: f32,
        scale: Option<f32>,
    ) -> Result<(Sentence, Option<f32>), VoiceError> {
        let phonemes = phonemes::sentence_phonemes(clauses);
        if phonemes.iter().all(|c| c.is_whitespace()) {
            return Ok((Sentence::default(), scale));
        }
        let (ids, owners, mut unknown) = phonemes::to_ids(&self.file, &phonemes);
        let [noise_scale, length_scale, noise_w] = self.scales;
        let output = self
            .network
            .run(&ids, [noise_scale, length_scale * length, noise_w])?;
        let spans = align::spans(&phonemes, &owners, &output.frames, HOP);
        let (mut cues, unmapped) = align::cues(&spans);
        unknown.extend(unmapped);
        let total = spans.last().map_or(0, |s| s.end);
        if total != output.audio.len() as u64 {
            tracing::debug!(
                frames_samples = total,
                audio = output.audio.len(),
                "the durations do not add up to the audio"
            );
        }
        let (pcm, used) = to_pcm(&output.audio, gain, scale);
        align::close_at_silence(&mut cues, &pcm);
        let sentence = Sentence {
            pcm,
            cues,
            phonemes: spans
                .iter()
                .filter_map(|s| s.phoneme.map(|p| (s.start, p)))
                .collect(),
            unknown,
        };
        Ok((sentence, used))
    }
}

/// Scales the audio to full range (Piper's default) or by `cap` if that is lower, applies the gain and converts it
/// to s16. Returns the samples and the scale used (`None` for silence, which sets no loudness).
fn to_pcm(audio: &[f32], gain: f32, cap: Option<f32>) -> (Vec<i16>, Option<f32>) {
    let peak = audio.iter().fold(0.0f32, |m, s| m.max(s.abs()));
    let full = (peak >= 1e-8).then(|| gain / peak);
    let scale = match (full, cap) {
        (Some(full), Some(cap)) => Some(full.min(cap)),
        (full, None) => full,
        (None, cap) => cap,
    };
    let factor = scale.unwrap_or(0.0);
    let pcm = audio
        .iter()
        .map(|s| ((s * factor).clamp(-1.0, 1.0) * 32767.0) as i16)
        .collect();
    (pcm, scale)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_are_range_checked_by_name() {
        assert!(PiperConfig::default().validate().is_ok());
        let noisy = PiperConfig {
            noise_scale: Some(5.0),
            ..PiperConfig::default()
        };
        let message = noisy.validate().expect_err("5.0").to_string();
        assert!(message.contains("noise_scale"), "{message}");
        let threads = PiperConfig {
            threads: 0,
            ..PiperConfig::default()
        };
        assert!(
            threads
                .validate()
                .expect_err("0")
                .to_string()
                .contains("threads")
        );
    }

    #[test]
    fn pcm_is_scaled_to_full_range_times_the_gain() {
        assert_eq!(
            to_pcm(&[0.0, 0.25, -0.5], 1.0, None),
            (vec![0, 16383, -32767], Some(2.0))
        );
        assert_eq!(
            to_pcm(&[0.0, 0.25, -0.5], 0.5, None),
            (vec![0, 8191, -16383], Some(1.0))
        );
        assert_eq!(to_pcm(&[0.0, 0.0], 1.0, None), (vec![0, 0], None));
    }

    #[test]
    fn a_later_part_keeps_the_first_parts_scale_unless_it_would_clip() {
        // Quieter than the first part: the first part's scale, not its own full range.
        assert_eq!(
            to_pcm(&[0.25, -0.25], 1.0, Some(2.0)),
            (vec![16383, -16383], Some(2.0))
        );
        // Louder: scaled down to full range instead of clipping.
        assert_eq!(
            to_pcm(&[1.0, -0.5], 1.0, Some(2.0)),
            (vec![32767, -16383], Some(1.0))
        );
        // A silent first part sets nothing.
        assert_eq!(to_pcm(&[0.5], 1.0, None).1, Some(2.0));
        assert_eq!(to_pcm(&[0.0], 1.0, Some(2.0)), (vec![0], Some(2.0)));
    }
}
