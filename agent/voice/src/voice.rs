//! Voice, language and prosody of an utterance, validated before they reach espeak-ng or the Piper voice.

/// Which engine speaks an utterance.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Engine {
    /// espeak-ng's formant synthesiser, with `voice` naming its voice or language.
    #[default]
    Espeak,
    /// The Piper voice the synthesizer was started with (`voice` is then not used; `rate_wpm` and `volume` are,
    /// `pitch` and `range` are not: the network has its own intonation).
    Piper,
}

/// Which engine and voice speaks, and how fast and how high.
#[derive(Debug, Clone, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct VoiceSettings {
    /// espeak-ng, or the Piper voice.
    pub engine: Engine,
    /// espeak-ng voice name or language tag: `en`, `en-us`, `en-gb-x-rp`, `it`, optionally with a variant such
    /// as `en+f3`.
    pub voice: String,
    /// Speaking rate in words per minute (espeak-ng accepts 80-450).
    pub rate_wpm: u32,
    /// Base pitch, 0-100 (espeak-ng's default is 50).
    pub pitch: u32,
    /// Pitch range (how much intonation moves), 0-100 (default 50).
    pub range: u32,
    /// Volume, 0-200 (default 100).
    pub volume: u32,
}

impl Default for VoiceSettings {
    fn default() -> Self {
        VoiceSettings {
            engine: Engine::Espeak,
            voice: "en".into(),
            rate_wpm: 175,
            pitch: 50,
            range: 50,
            volume: 100,
        }
    }
}

/// Slowest and fastest rate espeak-ng synthesises without clamping.
pub const RATE_RANGE: std::ops::RangeInclusive<u32> = 80..=450;

impl VoiceSettings {
    /// The settings for a language at the default prosody.
    pub fn for_voice(voice: impl Into<String>) -> Self {
        VoiceSettings {
            voice: voice.into(),
            ..Self::default()
        }
    }

    /// The Piper voice at the default prosody.
    pub fn piper() -> Self {
        VoiceSettings {
            engine: Engine::Piper,
            ..Self::default()
        }
    }

    /// Checks every field against the range espeak-ng accepts, naming the first bad one.
    pub fn validate(&self) -> Result<(), crate::error::VoiceError> {
        let invalid = |name: &'static str, value: String, reason: &str| {
            crate::error::VoiceError::InvalidSetting {
                name,
                value,
                reason: reason.to_owned(),
            }
        };
        let name_ok = !self.voice.is_empty()
            && self.voice.len() <= 40
            && self
                .voice
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '+'));
        if !name_ok {
            return Err(invalid(
                "voice",
                self.voice.clone(),
                "expected an espeak-ng voice name such as en, en-us, it",
            ));
        }
        if !RATE_RANGE.contains(&self.rate_wpm) {
            return Err(invalid(
                "rate_wpm",
                self.rate_wpm.to_string(),
                "must be within 80-450 words per minute",
            ));
        }
        if self.pitch > 100 {
            return Err(invalid(
                "pitch",
                self.pitch.to_string(),
                "must be within 0-100",
            ));
        }
        if self.range > 100 {
            return Err(invalid(
                "range",
                self.range.to_string(),
                "must be within 0-100",
            ));
        }
        if self.volume > 200 {
            return Err(invalid(
                "volume",
                self.volume.to_string(),
                "must be within 0-200",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_bad_values_name_the_field() {
        assert!(VoiceSettings::default().validate().is_ok());
        let fast = VoiceSettings {
            rate_wpm: 1000,
            ..VoiceSettings::default()
        };
        let message = fast
            .validate()
            .expect_err("1000 wpm is out of range")
            .to_string();
        assert!(message.contains("rate_wpm"), "{message}");
        let odd = VoiceSettings::for_voice("en; rm -rf");
        assert!(odd.validate().is_err());
        let high = VoiceSettings {
            pitch: 101,
            ..VoiceSettings::default()
        };
        assert!(
            high.validate()
                .expect_err("pitch 101")
                .to_string()
                .contains("pitch")
        );
    }
}
