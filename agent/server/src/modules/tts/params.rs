//! The TTS module's parameters (`[modules.tts]`, `[modules.tts.piper]` and `[modules.tts.behaviour]`), checked
//! at start.

use std::path::PathBuf;
use std::time::Duration;

use agent_brain::Language;
use agent_voice::{Engine, PiperConfig, VoiceSettings};
use serde::Deserialize;

use super::behaviour::BehaviourParams;

/// `[modules.tts]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TtsParams {
    /// Read by the server to switch the module off; accepted and ignored here.
    #[serde(default, rename = "enabled")]
    _enabled: serde::de::IgnoredAny,
    /// The engine that speaks English: `piper` (the neural voice, `[modules.tts.piper]`) or `espeak`. Other
    /// languages, and requests that name an espeak-ng voice, always speak with espeak-ng.
    #[serde(default = "default_engine")]
    pub engine: Engine,
    /// The Piper voice and how it speaks.
    #[serde(default)]
    pub piper: PiperParams,
    /// espeak-ng voice or language (`en`, `en-us`, `it`, `en+f3`); by default that of `agent.language`.
    #[serde(default)]
    pub voice: Option<String>,
    /// Words per minute, 80-450.
    #[serde(default = "default_rate")]
    pub rate_wpm: u32,
    /// Base pitch, 0-100.
    #[serde(default = "default_fifty")]
    pub pitch: u32,
    /// Intonation range, 0-100.
    #[serde(default = "default_fifty")]
    pub range: u32,
    /// Volume, 0-200.
    #[serde(default = "default_volume")]
    pub volume: u32,
    /// Length of each PCM chunk on `Agent.speech`, 10-500 ms.
    #[serde(default = "default_chunk_ms")]
    pub chunk_ms: u32,
    /// How far ahead of real time speech is sent (ms): enough to ride out network jitter, little enough that a
    /// barge-in leaves little queued audio and that subscriber queues (64 messages) never overflow.
    #[serde(default = "default_lead_ms")]
    pub lead_ms: u64,
    /// Stop speaking when the user starts to speak (voice activity on `Agent.transcript`).
    #[serde(default = "default_true")]
    pub barge_in: bool,
    /// espeak-ng data directory; by default `$ESPEAK_DATA_PATH` or the system's (Debian `espeak-ng-data`).
    #[serde(default)]
    pub data_path: Option<PathBuf>,
    /// Blink, gaze and listening controllers.
    #[serde(default)]
    pub behaviour: BehaviourParams,
}

/// `[modules.tts.piper]`: every key may be left out; the paths default to the files `make model-voice`
/// provisions in the repository's `models/`.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PiperParams {
    /// The voice network with its durations output (`models/piper/en_US-joe-medium.durations.onnx`).
    pub voice: Option<PathBuf>,
    /// The voice's `.onnx.json` (`models/piper/en_US-joe-medium.onnx.json`).
    pub voice_json: Option<PathBuf>,
    /// The voice's sha256, for a voice that `config/models.sha256` does not list.
    pub voice_sha256: Option<String>,
    /// ONNX Runtime's shared library (`models/onnxruntime/libonnxruntime.so.1.32.0`).
    pub runtime: Option<PathBuf>,
    /// Variation of the sound, 0-2 (the voice's default 0.667).
    pub noise_scale: Option<f32>,
    /// Variation of the phoneme lengths, 0-2 (the voice's default 0.8).
    pub noise_w: Option<f32>,
    /// Slower (> 1) or faster (< 1), 0.25-4, before `rate_wpm` (175 = 1.0) scales it.
    pub length_scale: Option<f32>,
    /// ONNX Runtime threads for one sentence, 1-16 (default 2; the helpers sleep rather than spin).
    pub threads: Option<usize>,
    /// The first sentence of a reply is cut at its first natural break after this many words and its first part
    /// played while the rest is synthesised, 0-50 (default 3; 0: whole sentences).
    pub first_part_words: Option<usize>,
    /// Seconds of spoken sentences kept to be played again without the network, 0-3600 (default 60).
    pub cache_seconds: Option<u32>,
}

impl PiperParams {
    /// The engine's configuration, defaults filled in.
    pub fn config(&self) -> PiperConfig {
        let defaults = PiperConfig::default();
        PiperConfig {
            voice: self.voice.clone().unwrap_or(defaults.voice),
            voice_json: self.voice_json.clone().unwrap_or(defaults.voice_json),
            runtime: self.runtime.clone().unwrap_or(defaults.runtime),
            voice_sha256: self.voice_sha256.clone(),
            noise_scale: self.noise_scale,
            noise_w: self.noise_w,
            length_scale: self.length_scale,
            threads: self.threads.unwrap_or(defaults.threads),
            first_part_words: self.first_part_words.unwrap_or(defaults.first_part_words),
            cache_seconds: self.cache_seconds.unwrap_or(defaults.cache_seconds),
        }
    }
}

fn default_engine() -> Engine {
    Engine::Piper
}
fn default_rate() -> u32 {
    175
}
fn default_fifty() -> u32 {
    50
}
fn default_volume() -> u32 {
    100
}
fn default_chunk_ms() -> u32 {
    20
}
fn default_lead_ms() -> u64 {
    300
}
fn default_true() -> bool {
    true
}

impl TtsParams {
    /// Reads and checks the parameters; errors name the key and the reason.
    pub fn from_json(params: &serde_json::Value) -> anyhow::Result<TtsParams> {
        let params: TtsParams = serde_path_to_error::deserialize(params)
            .map_err(|e| anyhow::anyhow!("[modules.tts] {}: {}", e.path(), e.inner()))?;
        params
            .voice_settings(Language::En)
            .validate()
            .map_err(|e| anyhow::anyhow!("[modules.tts] {e}"))?;
        if !(10..=500).contains(&params.chunk_ms) {
            anyhow::bail!(
                "[modules.tts] chunk_ms: {} is outside 10..=500",
                params.chunk_ms
            );
        }
        if !(20..=5000).contains(&params.lead_ms) {
            anyhow::bail!(
                "[modules.tts] lead_ms: {} is outside 20..=5000",
                params.lead_ms
            );
        }
        params
            .behaviour
            .validate()
            .map_err(|(key, reason)| anyhow::anyhow!("[modules.tts.behaviour] {key}: {reason}"))?;
        params
            .piper
            .config()
            .validate()
            .map_err(|e| anyhow::anyhow!("[modules.tts.piper] {e}"))?;
        Ok(params)
    }

    /// The Piper voice to load for an agent speaking `language`: only English has one, and only with
    /// `engine = "piper"`.
    pub fn piper_for(&self, language: Language) -> Option<PiperConfig> {
        (self.engine == Engine::Piper && language == Language::En).then(|| self.piper.config())
    }

    /// Checks, at start, that the Piper voice this agent would load is there and whole (the checksums of
    /// `config/models.sha256`); the error names the file, both checksums and `make model-voice`.
    pub fn check_files(&self, language: Language) -> anyhow::Result<()> {
        if let Some(piper) = self.piper_for(language) {
            piper
                .verify()
                .map_err(|e| anyhow::anyhow!("[modules.tts.piper] {e}"))?;
        }
        Ok(())
    }

    /// The default voice of every utterance that does not choose its own: the Piper voice for English with
    /// `engine = "piper"`, otherwise the configured espeak-ng voice, or espeak-ng's voice for the agent's language.
    pub fn voice_settings(&self, language: Language) -> VoiceSettings {
        VoiceSettings {
            engine: if self.piper_for(language).is_some() {
                Engine::Piper
            } else {
                Engine::Espeak
            },
            voice: self
                .voice
                .clone()
                .unwrap_or_else(|| language.code().to_owned()),
            rate_wpm: self.rate_wpm,
            pitch: self.pitch,
            range: self.range,
            volume: self.volume,
        }
    }

    pub fn lead(&self) -> Duration {
        Duration::from_millis(self.lead_ms)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_and_named_errors() {
        let params = TtsParams::from_json(&serde_json::json!({})).expect("defaults are valid");
        // English speaks with the Piper voice by default, Italian with espeak-ng's Italian voice.
        assert_eq!(params.voice_settings(Language::En), VoiceSettings::piper());
        assert_eq!(params.voice_settings(Language::It).voice, "it");
        assert_eq!(params.voice_settings(Language::It).engine, Engine::Espeak);
        assert!(params.piper_for(Language::It).is_none());
        let espeak =
            TtsParams::from_json(&serde_json::json!({ "engine": "espeak" })).expect("valid");
        assert_eq!(
            espeak.voice_settings(Language::En),
            VoiceSettings::default()
        );
        let error = TtsParams::from_json(&serde_json::json!({ "engine": "festival" }))
            .expect_err("unknown engine");
        assert!(error.to_string().contains("engine"), "{error}");
        let error = TtsParams::from_json(&serde_json::json!({ "piper": { "noise_scale": 7.5 } }))
            .expect_err("out of range");
        assert!(
            error.to_string().contains("[modules.tts.piper]")
                && error.to_string().contains("noise_scale"),
            "{error}"
        );
        let error = TtsParams::from_json(&serde_json::json!({ "piper": { "noise": 0.5 } }))
            .expect_err("typo");
        assert!(error.to_string().contains("piper.noise"), "{error}");
        let chosen = TtsParams::from_json(&serde_json::json!({ "voice": "en+f3" })).expect("valid");
        assert_eq!(chosen.voice_settings(Language::It).voice, "en+f3");
        let error = TtsParams::from_json(&serde_json::json!({ "rate_wpm": 9000 }))
            .expect_err("out of range");
        assert!(error.to_string().contains("rate_wpm"), "{error}");
        let error = TtsParams::from_json(&serde_json::json!({ "vioce": "it" })).expect_err("typo");
        assert!(error.to_string().contains("vioce"), "{error}");
        let error =
            TtsParams::from_json(&serde_json::json!({ "behaviour": { "blink_min_ms": 5000 } }))
                .expect_err("order");
        assert!(
            error.to_string().contains("[modules.tts.behaviour] blink"),
            "{error}"
        );
    }
}
