//! The hold before AEC3 has found the echo (`hold_ms`, off in the embedded configuration): a microphone frame
//! under the agent's level plus `HOLD_FLOOR_DB` may be the echo of a loudspeaker whose path AEC3 has not found yet,
//! so it is held (silenced), unless the levels show the microphone does not follow the agent at all
//! ([`crate::presence`]) or its voice began before the agent's ([`crate::onset`]). The canceller decides how long a
//! stream may be held without an echo found; this is one stream's state.

use crate::onset::Onsets;
use crate::presence::Presence;
use crate::residual::{ResidualConfig, ResidualGate};

/// A frame is held while it is quieter than the loudest recent reference plus this (dB): a loud loudspeaker's echo,
/// reverb added, comes back above the agent's own digital level (sox's room at 0 dB: 6 dB above it,
/// tests/room.rs), so only a user much louder than the agent is heard before the echo is found.
pub const HOLD_FLOOR_DB: f32 = 10.0;

/// One microphone stream's hold.
#[derive(Debug)]
pub struct Hold {
    /// The floor a frame must clear: the reference's level plus `HOLD_FLOOR_DB`, learning nothing.
    gate: ResidualGate,
    /// Whether the microphone follows the reference at all, from the levels.
    presence: Presence,
    /// The levels showed no echo in this stream (and AEC3 has found none since).
    no_echo: bool,
    /// Whether the microphone's voice began before the agent's speech.
    onsets: Onsets,
}

impl Default for Hold {
    fn default() -> Self {
        Hold {
            gate: ResidualGate::new(ResidualConfig {
                margin_db: 0.0,
                initial_gain_db: HOLD_FLOOR_DB,
                learn_below_db: f32::NEG_INFINITY,
                ..ResidualConfig::default()
            }),
            presence: Presence::default(),
            no_echo: false,
            onsets: Onsets::default(),
        }
    }
}

impl Hold {
    /// The frame captured at `at_us` (levels in dBFS) whose reference plays at `reference_at_us`; `speaking`: the
    /// reference has the agent's speech, `found`: AEC3 has found the echo. Returns whether the hold may apply to it:
    /// the levels have not shown there is no echo, and the microphone's voice did not begin before the agent's.
    pub fn frame(
        &mut self,
        at_us: u64,
        reference_at_us: u64,
        reference_db: f32,
        microphone_db: f32,
        speaking: bool,
        found: bool,
    ) -> bool {
        self.gate.reference(reference_at_us, reference_db);
        self.presence.frame(reference_db, microphone_db);
        if found {
            self.no_echo = false;
        } else if !self.no_echo && self.presence.no_echo() {
            self.no_echo = true;
        }
        // The earliest the page may play this frame's reference is the frame's own time (the lead covers a page
        // ahead of its schedule): a voice under way before it is the user's.
        let users = self
            .onsets
            .frame(at_us, microphone_db, speaking.then_some(at_us));
        !self.no_echo && !users
    }

    /// Whether a frame the hold applies to, at `at_us` with `microphone_db`, is under the floor: possible echo.
    pub fn is_echo(&mut self, at_us: u64, microphone_db: f32) -> bool {
        self.gate.is_echo(at_us, microphone_db, microphone_db)
    }
}
