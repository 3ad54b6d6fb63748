//! A Piper voice's `.onnx.json`: its sample rate, the espeak-ng voice its phonemes come from, its default noise and
//! length scales, and the map from phoneme (one Unicode character) to the network's input ids.

use std::collections::HashMap;
use std::path::Path;

use serde::Deserialize;

use crate::error::VoiceError;

/// The ids around every sentence and after every phoneme, as Piper voices are trained.
pub(crate) const BOS: char = '^';
pub(crate) const EOS: char = '$';
pub(crate) const PAD: char = '_';

#[derive(Debug, Clone, Deserialize)]
struct Audio {
    sample_rate: u32,
}

#[derive(Debug, Clone, Deserialize)]
struct Espeak {
    voice: String,
}

#[derive(Debug, Clone, Deserialize)]
struct Inference {
    noise_scale: f32,
    length_scale: f32,
    noise_w: f32,
}

#[derive(Debug, Clone, Deserialize)]
struct Raw {
    audio: Audio,
    espeak: Espeak,
    inference: Inference,
    #[serde(default)]
    phoneme_type: Option<String>,
    #[serde(default = "one")]
    num_speakers: u32,
    phoneme_id_map: HashMap<String, Vec<i64>>,
}

fn one() -> u32 {
    1
}

/// What the engine needs from the voice's configuration.
#[derive(Debug, Clone)]
pub(crate) struct VoiceFile {
    pub sample_rate: u32,
    /// The espeak-ng voice that phonemises text for this network (`en-us`).
    pub espeak_voice: String,
    /// The voice's own defaults for `[noise_scale, length_scale, noise_w]`.
    pub scales: [f32; 3],
    ids: HashMap<char, Vec<i64>>,
}

impl VoiceFile {
    /// Reads and checks the file: an espeak-phoneme, single-speaker voice with ids for the sentence markers.
    pub(crate) fn load(path: &Path) -> Result<VoiceFile, VoiceError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| VoiceError::Piper(format!("reading {}: {e}", path.display())))?;
        Self::parse(&text).map_err(|e| VoiceError::Piper(format!("{}: {e}", path.display())))
    }

    pub(crate) fn parse(text: &str) -> Result<VoiceFile, String> {
        let raw: Raw = serde_json::from_str(text).map_err(|e| e.to_string())?;
        if raw.phoneme_type.as_deref().is_some_and(|t| t != "espeak") {
            return Err(format!(
                "phoneme_type {:?}: only espeak voices are supported",
                raw.phoneme_type
            ));
        }
        if raw.num_speakers != 1 {
            return Err(format!(
                "{} speakers: only single-speaker voices are supported",
                raw.num_speakers
            ));
        }
        let mut ids = HashMap::new();
        for (phoneme, list) in raw.phoneme_id_map {
            let mut chars = phoneme.chars();
            match (chars.next(), chars.next()) {
                (Some(c), None) if !list.is_empty() => {
                    ids.insert(c, list);
                }
                _ => {
                    return Err(format!(
                        "phoneme_id_map entry {phoneme:?} is not one character with ids"
                    ));
                }
            }
        }
        for marker in [BOS, EOS, PAD] {
            if !ids.contains_key(&marker) {
                return Err(format!("phoneme_id_map has no {marker:?}"));
            }
        }
        Ok(VoiceFile {
            sample_rate: raw.audio.sample_rate,
            espeak_voice: raw.espeak.voice,
            scales: [
                raw.inference.noise_scale,
                raw.inference.length_scale,
                raw.inference.noise_w,
            ],
            ids,
        })
    }

    /// The ids of one phoneme; `None` for a character the voice does not know.
    pub(crate) fn ids(&self, phoneme: char) -> Option<&[i64]> {
        self.ids.get(&phoneme).map(Vec::as_slice)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_a_voice_and_refuses_what_it_cannot_speak() {
        let json = r#"{"audio":{"sample_rate":22050},"espeak":{"voice":"en-us"},
            "inference":{"noise_scale":0.667,"length_scale":1,"noise_w":0.8},"phoneme_type":"espeak",
            "num_speakers":1,"phoneme_id_map":{"_":[0],"^":[1],"$":[2],"a":[14]}}"#;
        let voice = VoiceFile::parse(json).expect("valid");
        assert_eq!(voice.sample_rate, 22050);
        assert_eq!(voice.espeak_voice, "en-us");
        assert_eq!(voice.ids('a'), Some(&[14][..]));
        assert_eq!(voice.ids('ʘ'), None);
        let many = json.replace("\"num_speakers\":1", "\"num_speakers\":4");
        assert!(
            VoiceFile::parse(&many)
                .expect_err("speakers")
                .contains("speakers")
        );
        let no_pad = json.replace("\"_\":[0],", "");
        assert!(VoiceFile::parse(&no_pad).expect_err("pad").contains("'_'"));
    }
}
