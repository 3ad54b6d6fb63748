//! The TTS module's parameters (`[modules.tts]` and `[modules.tts.behaviour]`), checked at start.

use std::path::PathBuf;
use std::time::Duration;

use agent_brain::Language;
use agent_voice::VoiceSettings;
use serde::Deserialize;

use super::behaviour::BehaviourParams;

/// `[modules.tts]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TtsParams {
    /// Read by the server to switch the module off; accepted and ignored here.
    #[serde(default, rename = "enabled")]
    _enabled: serde::de::IgnoredAny,
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
        Ok(params)
    }

    /// The default voice of every utterance that does not choose its own: the configured one, or espeak-ng's
    /// voice for the agent's language.
    pub fn voice_settings(&self, language: Language) -> VoiceSettings {
        VoiceSettings {
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
        assert_eq!(
            params.voice_settings(Language::En),
            VoiceSettings::default()
        );
        // Without a voice of its own, the module speaks the agent's language.
        assert_eq!(params.voice_settings(Language::It).voice, "it");
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
