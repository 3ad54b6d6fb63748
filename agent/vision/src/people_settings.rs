//! `[modules.vision.people]`: the per-face analysis as written in the configuration, checked into
//! [`PeopleParams`].

use std::path::PathBuf;

use agent_face::FaceModelPaths;
use serde::Deserialize;

use crate::error::VisionError;
use crate::people::PeopleParams;
use crate::setting_check::check;
use crate::speaker::SpeakerParams;

/// `[modules.vision.people]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PeopleSettings {
    pub enabled: bool,
    /// dlib's 68-point shape predictor (`make model-face`).
    pub landmarks: PathBuf,
    /// dlib's ResNet face descriptor (`make model-face`), read when `identities` is on.
    pub descriptor: PathBuf,
    /// Compute descriptors, so that a face the agent was introduced to is named (`learn_face`).
    pub identities: bool,
    /// The largest faces analysed per frame, 1-16.
    pub max_faces: usize,
    pub describe_every_ms: u64,
    pub forget_after_ms: u64,
    /// Descriptors closer than this are one person, 0.3-0.9.
    pub match_distance: f32,
    pub speaker_window_ms: u64,
    pub speaker_min_movement: f32,
    pub speaker_hold_ms: u64,
}

impl Default for PeopleSettings {
    fn default() -> Self {
        let params = PeopleParams::default();
        let models = FaceModelPaths::default();
        Self {
            enabled: true,
            landmarks: models.landmarks,
            descriptor: models.descriptor.unwrap_or_default(),
            identities: true,
            max_faces: params.max_faces,
            describe_every_ms: params.describe_every_us / 1000,
            forget_after_ms: params.forget_after_us / 1000,
            match_distance: params.match_distance,
            speaker_window_ms: params.speaker.window_us / 1000,
            speaker_min_movement: params.speaker.min_movement,
            speaker_hold_ms: params.speaker.hold_us / 1000,
        }
    }
}

impl PeopleSettings {
    /// The checked parameters; `None` when the analysis is off.
    pub fn params(&self) -> Result<Option<PeopleParams>, VisionError> {
        if !self.enabled {
            return Ok(None);
        }
        check(
            (1..=16).contains(&self.max_faces),
            "people.max_faces",
            "must be 1-16",
        )?;
        check(
            self.describe_every_ms >= 100,
            "people.describe_every_ms",
            "must be at least 100",
        )?;
        check(
            (100..=60_000).contains(&self.forget_after_ms),
            "people.forget_after_ms",
            "must be 100-60000",
        )?;
        check(
            (0.3..=0.9).contains(&self.match_distance),
            "people.match_distance",
            "must be 0.3-0.9",
        )?;
        check(
            (200..=5000).contains(&self.speaker_window_ms),
            "people.speaker_window_ms",
            "must be 200-5000",
        )?;
        check(
            self.speaker_min_movement > 0.0 && self.speaker_min_movement < 1.0,
            "people.speaker_min_movement",
            "must be in (0, 1)",
        )?;
        check(
            self.speaker_hold_ms <= 10_000,
            "people.speaker_hold_ms",
            "must be at most 10000",
        )?;
        Ok(Some(PeopleParams {
            models: FaceModelPaths {
                landmarks: self.landmarks.clone(),
                descriptor: self.identities.then(|| self.descriptor.clone()),
            },
            max_faces: self.max_faces,
            describe_every_us: self.describe_every_ms * 1000,
            forget_after_us: self.forget_after_ms * 1000,
            match_distance: self.match_distance,
            speaker: SpeakerParams {
                window_us: self.speaker_window_ms * 1000,
                min_movement: self.speaker_min_movement,
                hold_us: self.speaker_hold_ms * 1000,
                ..SpeakerParams::default()
            },
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_a_bad_value_names_its_key() {
        let params = PeopleSettings::default().params().expect("valid");
        assert!(params.is_some_and(|p| p.models.descriptor.is_some()));
        let off = PeopleSettings {
            identities: false,
            ..PeopleSettings::default()
        };
        assert!(
            off.params()
                .expect("valid")
                .is_some_and(|p| p.models.descriptor.is_none())
        );
        let bad = PeopleSettings {
            max_faces: 0,
            ..PeopleSettings::default()
        };
        let err = bad.params().expect_err("invalid").to_string();
        assert!(err.contains("people.max_faces"), "{err}");
    }
}
