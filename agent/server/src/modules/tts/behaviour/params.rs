//! The behaviour controllers' inputs: their parameters (`[modules.tts.behaviour]`) and the events they react to.
//! A leaf, so that the controllers (`blink.rs`, `gaze.rs`) and the file that runs them share it without a cycle.

use serde::Deserialize;
use tokio::time::Instant;

use crate::modules::tts::wire::Sighting;

/// `[modules.tts.behaviour]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BehaviourParams {
    /// Drive blinks, gaze and moods from the server (the page blinks by itself when nothing drives it).
    pub enabled: bool,
    /// Shortest and longest interval between spontaneous blinks.
    pub blink_min_ms: u64,
    pub blink_max_ms: u64,
    /// Idle saccades: interval range, and how far from the centre the eyes wander (normalised units).
    pub saccade_min_ms: u64,
    pub saccade_max_ms: u64,
    pub saccade_radius: f64,
    /// After this long without a face or motion the gaze goes idle.
    pub idle_after_ms: u64,
    /// Gaze moves smaller than this (normalised units) are not sent.
    pub gaze_deadband: f64,
    /// A gaze jump larger than this also triggers a blink.
    pub gaze_shift_blink: f64,
    /// How long the avatar looks away "thinking" after the user said something, unless it starts to speak.
    pub think_ms: u64,
    /// Nod at the user's pauses while listening.
    pub nod: bool,
}

impl Default for BehaviourParams {
    fn default() -> Self {
        BehaviourParams {
            enabled: true,
            blink_min_ms: 450,
            blink_max_ms: 4000,
            saccade_min_ms: 600,
            saccade_max_ms: 2500,
            saccade_radius: 0.06,
            idle_after_ms: 1500,
            gaze_deadband: 0.02,
            gaze_shift_blink: 0.2,
            think_ms: 1500,
            nod: true,
        }
    }
}

impl BehaviourParams {
    /// Checks the ranges; the error names the key.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if self.blink_min_ms < 100 || self.blink_min_ms > self.blink_max_ms {
            return Err((
                "blink_min_ms",
                format!(
                    "must be >= 100 and <= blink_max_ms, got {}",
                    self.blink_min_ms
                ),
            ));
        }
        if self.saccade_min_ms < 100 || self.saccade_min_ms > self.saccade_max_ms {
            return Err((
                "saccade_min_ms",
                format!(
                    "must be >= 100 and <= saccade_max_ms, got {}",
                    self.saccade_min_ms
                ),
            ));
        }
        for (key, value) in [
            ("saccade_radius", self.saccade_radius),
            ("gaze_deadband", self.gaze_deadband),
            ("gaze_shift_blink", self.gaze_shift_blink),
        ] {
            if !(0.0..=0.5).contains(&value) {
                return Err((key, format!("{value} is outside 0..=0.5")));
            }
        }
        Ok(())
    }
}

/// What the controllers react to.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A detections message: where to look, or nothing seen.
    Seen(Option<Sighting>),
    /// The user started speaking (voice activity, or a partial transcript).
    UserSpeaking,
    /// The user paused (end of voice activity).
    UserPaused,
    /// A final transcript: the agent is thinking about its answer.
    Heard,
    /// The agent's reply became audible.
    SpeechStarted,
    /// A sentence of the reply ends when the audio reaches `at`.
    PhraseBoundary { at: Instant },
    /// The reply stops being audible at `at`.
    SpeechEnded { at: Instant },
    /// A rule asked for an expression (`mood(M)`): shown for a few seconds, then back to neutral.
    Mood(&'static str),
}
