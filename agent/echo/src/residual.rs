//! The second line after the adaptive filter: a residual-echo gate on the cleaned frames.
//!
//! AEC3's linear filter covers the first tens of milliseconds of the echo path and its suppressor the rest by an
//! estimate; a long room reverb or a changing path leaves a residue some 6-30 dB under the echo (measured on sox's
//! reverb, docs/voice.md), and voice activity detection hears speech at any level. So, as whisper-sat's gate did on
//! the raw microphone (a Geigel detector with a learned gain), a cleaned frame heard while the agent was audible
//! within the last `window` counts as the user only when it is louder than the loudest recent reference level plus
//! the residue's learned gain plus a margin; quieter frames are echo and are silenced.
//!
//! The gain is learned from frames the filter took at least `learn_below_db` off (the microphone heard mostly the
//! agent): the 95th percentile of the last five seconds of their cleaned level against the reference, so the floor
//! covers how much the filter leaves in this room, its bad moments included. A user talking over the agent is
//! barely touched by the filter (it only removes what matches the reference), so those frames teach nothing,
//! whatever the floor was. The canceller asks the gate only while AEC3 finds an echo at all
//! ([`crate::canceller`]). Until half a second of such frames exists the gain is `initial_gain_db` (-12 dB, a
//! typical echo return loss; +7 dB, 10 dB over the agent's level, when the canceller holds before AEC3 has found
//! the echo). A user over the agent is heard once the residue is learned. Because the residue
//! is far under the echo once the filter has converged, a user is heard over a reply much quieter than a gate on
//! the raw microphone would need.

use std::collections::VecDeque;

/// Reference frames quieter than this (dBFS) are silence between words; they set no floor.
const SILENT_DBFS: f32 = -60.0;
/// Notes kept: five seconds of 10 ms frames.
const HISTORY: usize = 500;
/// The gain is learned once this many notes exist (half a second of the filter taking the echo off).
const LEARNED: usize = 50;

/// The gate's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResidualConfig {
    /// How far above the residue's learned loud end a frame must be to be the user (dB).
    pub margin_db: f32,
    /// The residue's gain against the reference before any has been measured (dB).
    pub initial_gain_db: f32,
    /// How long the reference keeps a floor after it played (µs): the echo's delay and the room's tail.
    pub window_us: u64,
    /// Frames the filter took at least this much off (dB, negative) are echo to learn the residue from.
    pub learn_below_db: f32,
}

impl Default for ResidualConfig {
    fn default() -> Self {
        Self {
            margin_db: 3.0,
            initial_gain_db: -12.0,
            window_us: 700_000,
            learn_below_db: -6.0,
        }
    }
}

/// The residual-echo gate.
#[derive(Debug)]
pub struct ResidualGate {
    cfg: ResidualConfig,
    /// (hub µs, dBFS) of audible reference frames, in time order.
    levels: VecDeque<(u64, f32)>,
    /// Cleaned level minus the loudest recent reference level, for frames judged to be echo.
    notes: VecDeque<f32>,
}

impl ResidualGate {
    pub fn new(cfg: ResidualConfig) -> Self {
        Self {
            cfg,
            levels: VecDeque::new(),
            notes: VecDeque::new(),
        }
    }

    /// The reference frame that plays at `at_us` had `dbfs`.
    pub fn reference(&mut self, at_us: u64, dbfs: f32) {
        if dbfs > SILENT_DBFS {
            self.levels.push_back((at_us, dbfs));
        }
    }

    /// A frame captured at `at_us`, `raw_dbfs` as the microphone heard it and `dbfs` after the filter: whether
    /// it is the agent's echo (to be silenced). Learns the residue's gain from it.
    pub fn is_echo(&mut self, at_us: u64, raw_dbfs: f32, dbfs: f32) -> bool {
        let Some(loudest) = self.loudest(at_us) else {
            return false;
        };
        if dbfs - raw_dbfs <= self.cfg.learn_below_db {
            self.notes.push_back(dbfs - loudest);
            while self.notes.len() > HISTORY {
                self.notes.pop_front();
            }
        }
        dbfs < loudest + self.gain_db() + self.cfg.margin_db
    }

    /// The residue's gain against the reference (dB): the 95th percentile of the notes, once there are enough.
    pub fn gain_db(&self) -> f32 {
        if self.notes.len() < LEARNED {
            return self.cfg.initial_gain_db;
        }
        let mut sorted: Vec<f32> = self.notes.iter().copied().collect();
        sorted.sort_by(f32::total_cmp);
        sorted[(sorted.len() * 19 / 20).min(sorted.len() - 1)]
    }

    /// The microphone has reached `at_us`: forgets the levels older than the window before it, which no later
    /// frame looks at (the microphone's time only moves forward). Called for every frame, echo or not: the gate is
    /// asked about a frame only once AEC3 has found an echo, and with none to find (headphones) the levels of
    /// everything the agent said would otherwise pile up (the soak's heap profile found them).
    pub fn advance(&mut self, at_us: u64) {
        let oldest = at_us.saturating_sub(self.cfg.window_us);
        while self.levels.front().is_some_and(|(t, _)| *t < oldest) {
            self.levels.pop_front();
        }
    }

    /// Reference levels kept now: at most a window's worth (and the lead's) once [`ResidualGate::advance`] runs.
    pub fn levels_kept(&self) -> usize {
        self.levels.len()
    }

    /// The loudest reference level within the window before `at_us`.
    fn loudest(&mut self, at_us: u64) -> Option<f32> {
        self.advance(at_us);
        self.levels
            .iter()
            .take_while(|(t, _)| *t <= at_us)
            .map(|(_, level)| *level)
            .reduce(f32::max)
    }
}

/// The level of samples in [-1, 1] in dBFS (-120 for digital silence).
pub fn level_dbfs(samples: &[f32]) -> f32 {
    if samples.is_empty() {
        return -120.0;
    }
    let mean = samples.iter().map(|&s| f64::from(s).powi(2)).sum::<f64>() / samples.len() as f64;
    (10.0 * mean.max(1e-12).log10()) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_residue_under_the_learned_floor_is_echo_and_a_user_over_it_is_not() {
        let mut gate = ResidualGate::new(ResidualConfig::default());
        let t0 = 1_000_000;
        // No reference yet: nothing is echo.
        assert!(!gate.is_echo(t0, -50.0, -50.0));
        // Three seconds of a reply at -10 dBFS. Before the filter has converged its echo comes through whole: under
        // the initial floor (-12 dB + 3 dB) it is echo all the same.
        for k in 0..300u64 {
            gate.reference(t0 + k * 10_000, -10.0);
        }
        assert!(gate.is_echo(t0, -22.0, -22.0));
        // Then the filter takes 25 dB off: the residue is learned at -35 dB.
        for k in 1..200u64 {
            assert!(gate.is_echo(t0 + k * 10_000, -20.0, -45.0));
        }
        assert!((gate.gain_db() + 35.0).abs() < 0.1, "{}", gate.gain_db());
        // A user 25 dB under the reply, which the filter leaves alone, is heard over the residue and teaches
        // nothing; the residue still is echo.
        for k in 0..200u64 {
            assert!(!gate.is_echo(t0 + 2_000_000 + k, -34.0, -35.0));
        }
        assert!((gate.gain_db() + 35.0).abs() < 0.1, "{}", gate.gain_db());
        assert!(gate.is_echo(t0 + 2_020_000, -20.0, -44.0));
        // The floor lifts once the reference has been silent for the window.
        assert!(!gate.is_echo(t0 + 3_000_000 + 710_000, -20.0, -44.0));
    }

    #[test]
    fn levels_are_in_dbfs() {
        assert!((level_dbfs(&[0.5, -0.5]) + 6.02).abs() < 0.01);
        assert_eq!(level_dbfs(&[0.0; 4]), -120.0);
    }
}
