//! The Piper engine: a neural (VITS) voice that speaks espeak-ng's IPA phonemes, run on ONNX Runtime, with the
//! mouth shapes timed by the network's own phoneme durations on the PCM's sample clock (docs/voice.md, "Piper").
//!
//! espeak-ng (the library the crate links anyway) phonemises each sentence with the voice's espeak voice; the ids
//! go through the network in one run per sentence; the durations output (`/Ceil_output_0`, which
//! `make model-voice` exposes) gives every phoneme's start in samples.

mod align;
mod network;
mod phonemes;
mod voice_file;

use std::path::{Path, PathBuf};

use crate::checksum;
use crate::error::VoiceError;
use crate::viseme::Viseme;

pub(crate) use network::Network;
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
    /// ONNX Runtime threads inside one run. One by default: the agent shares its cores with whisper-sat, and on
    /// two busy cores a second spinning thread made each run two to three times slower (docs/voice.md).
    pub threads: usize,
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
            threads: 1,
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

/// One sentence spoken by the voice.
#[derive(Debug, Clone, Default)]
pub(crate) struct Sentence {
    pub pcm: Vec<i16>,
    /// Viseme cues, in samples from the sentence's start.
    pub cues: Vec<(u64, Viseme)>,
    /// Every phoneme with its start in samples.
    pub phonemes: Vec<(u64, char)>,
    /// Phonemes without an id in the voice, or without a mouth shape.
    pub unknown: Vec<char>,
}

/// A loaded voice: configuration plus network.
#[derive(Debug)]
pub(crate) struct PiperVoice {
    pub file: VoiceFile,
    network: Network,
    scales: [f32; 3],
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
        Ok(PiperVoice {
            file,
            network,
            scales,
        })
    }

    /// Speaks one sentence given espeak-ng's clauses for it. `length` multiplies the length scale (the request's
    /// rate), `gain` the samples (volume / 100) after they are scaled to full range, as Piper does.
    pub(crate) fn speak<'a>(
        &mut self,
        clauses: impl IntoIterator<Item = (&'a str, &'a str)>,
        length: f32,
        gain: f32,
    ) -> Result<Sentence, VoiceError> {
        let phonemes = phonemes::sentence_phonemes(clauses);
        if phonemes.iter().all(|c| c.is_whitespace()) {
            return Ok(Sentence::default());
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
        let pcm = to_pcm(&output.audio, gain);
        align::close_at_silence(&mut cues, &pcm);
        Ok(Sentence {
            pcm,
            cues,
            phonemes: spans
                .iter()
                .filter_map(|s| s.phoneme.map(|p| (s.start, p)))
                .collect(),
            unknown,
        })
    }
}

/// Scales the audio to full range (Piper's default), applies the gain and converts it to s16.
fn to_pcm(audio: &[f32], gain: f32) -> Vec<i16> {
    let peak = audio.iter().fold(0.0f32, |m, s| m.max(s.abs()));
    let scale = if peak < 1e-8 { 0.0 } else { gain / peak };
    audio
        .iter()
        .map(|s| ((s * scale).clamp(-1.0, 1.0) * 32767.0) as i16)
        .collect()
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
        assert_eq!(to_pcm(&[0.0, 0.25, -0.5], 1.0), vec![0, 16383, -32767]);
        assert_eq!(to_pcm(&[0.0, 0.25, -0.5], 0.5), vec![0, 8191, -16383]);
        assert_eq!(to_pcm(&[0.0, 0.0], 1.0), vec![0, 0]);
    }
}
