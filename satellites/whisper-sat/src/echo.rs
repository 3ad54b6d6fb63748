//! Own-voice suppression: while the agent's speech plays, the microphone hears it back through the room, and that
//! echo must not count as the user speaking (no `vad` start, no barge-in, no transcript).
//!
//! The gate follows the agent's speech (`Agent.speech`, the reference) on the hub clock, as the page plays it: an
//! utterance's sample 0 plays a jitter buffer after its first chunk arrived, and every later sample at its offset
//! from there (the same schedule the page keeps, docs/browser-link.md). While the reference was loud at any moment
//! of the last `window_ms` (the loudspeaker-to-microphone delay, the page's own buffering and the room's reverb
//! tail all fall inside it), a microphone frame counts as voice only when it is louder than the echo that loudest
//! reference level can make. How loud the echo comes back (the path from the digital signal through loudspeaker,
//! room and microphone, and whatever the browser's own canceller takes off) depends on the room and the volume, so
//! the gate learns it: for every microphone message heard while the agent was audible and judged to be echo (under
//! the floor of the moment) it notes how far the message's level was from the loudest recent reference level, and
//! takes the 90th percentile of the last five seconds of such notes as the echo's gain. Messages over the floor are
//! the user talking over the agent and are not learned from, so double talk does not teach the gate to gate the
//! user; with no echo at all (headphones, audio injected in tests) the notes are the microphone's silence and the
//! floor drops away. The floor sits `margin_db` above the echo's loud end. Until a second of notes exists the gain
//! is assumed to be `initial_gain_db`, a typical echo return loss with the browser's canceller on. This is a Geigel double-talk
//! detector on 20 ms levels with a learned echo return loss: no adaptive filter, cheap enough for every frame.
//! When the agent is silent there is no floor.
//!
//! Pure bookkeeping over timestamps; `stream::AudioStream` applies it to the segmenter.

use std::collections::{HashMap, VecDeque};

/// Tunable parameters of the gate.
#[derive(Debug, Clone, PartialEq)]
pub struct EchoConfig {
    /// How far above the echo's learned loud end a frame must be to be the user (dB).
    pub margin_db: f32,
    /// The echo's gain relative to the reference before any has been measured (dB).
    pub initial_gain_db: f32,
    /// How many microphone messages (20 ms each) the echo's gain is learned from.
    pub history: usize,
    /// How long the reference keeps a floor after it played: delay, buffering and reverb.
    pub window_ms: u32,
    /// The page's jitter buffer before an utterance's first chunk plays.
    pub jitter_ms: u32,
}

impl Default for EchoConfig {
    fn default() -> Self {
        Self {
            margin_db: 3.0,
            initial_gain_db: -12.0,
            history: 250,
            window_ms: 700,
            jitter_ms: 60,
        }
    }
}

/// The reference's rate (`Agent.speech`).
const RATE: u64 = 22_050;
/// Levels are kept per block of this many reference samples (20 ms).
const BLOCK: usize = 441;
/// Blocks quieter than this (dBFS) are silence between words; they set no floor.
const SILENT_DBFS: f32 = -60.0;
/// At most this many utterances' anchors are remembered.
const ANCHORS: usize = 16;
/// The echo's gain is learned once this many notes exist (a second of the agent speaking).
const LEARNED: usize = 50;

/// The gate's state.
#[derive(Debug)]
pub struct EchoGate {
    cfg: EchoConfig,
    /// When sample 0 of each framed utterance plays (hub µs).
    anchors: HashMap<u32, u64>,
    anchor_order: VecDeque<u32>,
    /// Where unframed reference audio plays next (hub µs).
    unframed_end: u64,
    /// (play time in hub µs, level in dBFS) of reference blocks, in arrival order.
    levels: VecDeque<(u64, f32)>,
    /// Microphone level minus the loudest recent reference level, for messages heard while the agent played.
    notes: VecDeque<f32>,
}

impl EchoGate {
    pub fn new(cfg: EchoConfig) -> Self {
        Self {
            cfg,
            anchors: HashMap::new(),
            anchor_order: VecDeque::new(),
            unframed_end: 0,
            levels: VecDeque::new(),
            notes: VecDeque::new(),
        }
    }

    /// One chunk of the agent's speech, s16le, that reached the hub at `arrival_us`; `framing` is its utterance
    /// and sample offset when the channel frames its payloads.
    pub fn reference(&mut self, arrival_us: u64, framing: Option<(u32, u32)>, pcm: &[u8]) {
        let jitter = u64::from(self.cfg.jitter_ms) * 1000;
        let samples: Vec<i16> = pcm
            .chunks_exact(2)
            .map(|b| i16::from_le_bytes([b[0], b[1]]))
            .collect();
        let play_at = match framing {
            Some((utterance, offset)) => {
                let offset_us = u64::from(offset) * 1_000_000 / RATE;
                let anchor = match self.anchors.get(&utterance) {
                    Some(anchor) => *anchor,
                    None => {
                        let anchor = (arrival_us + jitter).saturating_sub(offset_us);
                        self.anchors.insert(utterance, anchor);
                        self.anchor_order.push_back(utterance);
                        while self.anchor_order.len() > ANCHORS {
                            if let Some(old) = self.anchor_order.pop_front() {
                                self.anchors.remove(&old);
                            }
                        }
                        anchor
                    }
                };
                anchor + offset_us
            }
            None => {
                let at = self.unframed_end.max(arrival_us + jitter);
                self.unframed_end = at + samples.len() as u64 * 1_000_000 / RATE;
                at
            }
        };
        for (i, block) in samples.chunks(BLOCK).enumerate() {
            let energy =
                block.iter().map(|&s| f64::from(s).powi(2)).sum::<f64>() / block.len() as f64;
            let dbfs = (10.0 * (energy / (32768.0 * 32768.0)).max(1e-12).log10()) as f32;
            if dbfs > SILENT_DBFS {
                let at = play_at + (i * BLOCK) as u64 * 1_000_000 / RATE;
                self.levels.push_back((at, dbfs));
            }
        }
    }

    /// A microphone message heard at `at_us` with `mic_dbfs`: returns the level (dBFS) its frames must exceed
    /// to be the user rather than the agent's echo (`None` when the agent has not been audible within the window),
    /// and learns the echo's gain from it.
    pub fn heard(&mut self, at_us: u64, mic_dbfs: f32) -> Option<f32> {
        let loudest = self.loudest_reference(at_us)?;
        let floor = loudest + self.echo_gain() + self.cfg.margin_db;
        if mic_dbfs < floor {
            self.notes.push_back(mic_dbfs - loudest);
            while self.notes.len() > self.cfg.history {
                self.notes.pop_front();
            }
        }
        Some(floor)
    }

    /// The agent's speech was stopped at `at_us` (a cancel or a barge-in): the page plays nothing of what was sent
    /// ahead, so it sets no floor; what already played keeps its reverb tail.
    pub fn stopped(&mut self, at_us: u64) {
        self.levels.retain(|(t, _)| *t <= at_us);
        self.anchors.clear();
        self.anchor_order.clear();
        self.unframed_end = self.unframed_end.min(at_us);
    }

    /// The echo's gain relative to the reference: the 90th percentile of the notes, once there are enough.
    pub fn echo_gain(&self) -> f32 {
        if self.notes.len() < LEARNED {
            return self.cfg.initial_gain_db;
        }
        let mut sorted: Vec<f32> = self.notes.iter().copied().collect();
        sorted.sort_by(f32::total_cmp);
        sorted[(sorted.len() * 9 / 10).min(sorted.len() - 1)]
    }

    /// The loudest reference level (dBFS) played within the window before `at_us`.
    fn loudest_reference(&mut self, at_us: u64) -> Option<f32> {
        let window = u64::from(self.cfg.window_ms) * 1000;
        let oldest = at_us.saturating_sub(window);
        // Levels older than the window never matter again: microphone time only moves forward.
        while self.levels.front().is_some_and(|(t, _)| *t < oldest) {
            self.levels.pop_front();
        }
        self.levels
            .iter()
            .filter(|(t, _)| *t <= at_us)
            .map(|(_, level)| *level)
            .reduce(f32::max)
    }
}

/// The level of s16le PCM in dBFS (-120 for digital silence).
pub fn level_dbfs(pcm: &[u8]) -> f32 {
    let (sum, n) = pcm.chunks_exact(2).fold((0.0f64, 0usize), |(sum, n), b| {
        let s = f64::from(i16::from_le_bytes([b[0], b[1]]));
        (sum + s * s, n + 1)
    });
    if n == 0 {
        return -120.0;
    }
    (10.0 * (sum / n as f64 / (32768.0 * 32768.0)).max(1e-12).log10()) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 20 ms chunk of a square wave at `amplitude`.
    fn chunk(amplitude: i16) -> Vec<u8> {
        (0..441)
            .flat_map(|i| if i % 20 < 10 { amplitude } else { -amplitude }.to_le_bytes())
            .collect()
    }

    #[test]
    fn the_floor_follows_the_reference_as_the_page_plays_it() {
        let mut gate = EchoGate::new(EchoConfig::default());
        let t0 = 1_000_000_000;
        // Nothing played yet: no floor.
        assert_eq!(gate.heard(t0, -30.0), None);
        // Ten chunks of a reply arrive at once (sent ahead), framed at offsets 0, 441, ...
        for k in 0..10u32 {
            gate.reference(t0, Some((1, k * 441)), &chunk(16_384));
        }
        // The first plays after the jitter buffer: before it, no floor.
        assert_eq!(gate.heard(t0 + 30_000, -30.0), None);
        // While it plays, before anything is learned, the floor is the reply's level (-6 dBFS for a square wave at
        // half scale) with the initial gain (-12 dB) and the margin (3 dB).
        let floor = gate
            .heard(t0 + 100_000, -30.0)
            .expect("a floor while playing");
        assert!((floor - (-6.0 - 12.0 + 3.0)).abs() < 0.5, "{floor}");
        // It stays for the window after the last chunk played (60 + 200 ms), then lifts.
        assert!(gate.heard(t0 + 260_000 + 600_000, -30.0).is_some());
        assert_eq!(gate.heard(t0 + 260_000 + 800_000, -30.0), None);
    }

    #[test]
    fn the_echo_gain_is_learned_while_the_agent_speaks() {
        let mut gate = EchoGate::new(EchoConfig::default());
        let t0 = 2_000_000_000;
        // Three seconds of a reply at -6 dBFS, heard back 20 dB down, with the user silent.
        for k in 0..150u32 {
            gate.reference(t0, Some((1, k * 441)), &chunk(16_384));
        }
        let mut floor = None;
        for k in 0..140u64 {
            floor = gate.heard(t0 + 60_000 + k * 20_000, -26.0);
        }
        assert!(
            (gate.echo_gain() - (-20.0)).abs() < 0.5,
            "{}",
            gate.echo_gain()
        );
        // The floor sits just above the echo: the echo stays under it, a user at the reply's level clears it.
        let floor = floor.expect("a floor");
        assert!(floor > -26.0 && floor < -20.0, "{floor}");
        // A user talking over the agent for a while is not learned as echo: the floor stays.
        for k in 140..150u64 {
            gate.heard(t0 + 60_000 + k * 20_000, -8.0);
        }
        assert!(
            (gate.echo_gain() - (-20.0)).abs() < 0.5,
            "{}",
            gate.echo_gain()
        );
    }

    #[test]
    fn without_an_echo_the_floor_drops_away() {
        let mut gate = EchoGate::new(EchoConfig::default());
        let t0 = 3_000_000_000;
        for k in 0..150u32 {
            gate.reference(t0, Some((2, k * 441)), &chunk(16_384));
        }
        // Headphones: the microphone hears silence while the agent speaks.
        let mut floor = None;
        for k in 0..100u64 {
            floor = gate.heard(t0 + 60_000 + k * 20_000, -90.0);
        }
        assert!(floor.is_some_and(|f| f < -80.0), "{floor:?}");
    }

    #[test]
    fn quiet_reference_sets_no_floor_and_unframed_chunks_play_back_to_back() {
        let mut gate = EchoGate::new(EchoConfig::default());
        let t0 = 5_000_000;
        gate.reference(t0, None, &chunk(5));
        assert_eq!(gate.heard(t0 + 100_000, -40.0), None);
        gate.reference(t0, None, &chunk(8000));
        gate.reference(t0, None, &chunk(8000));
        // The two loud chunks play after the quiet one: from 80 ms to 120 ms.
        assert_eq!(gate.heard(t0 + 70_000, -40.0), None);
        assert!(gate.heard(t0 + 110_000, -40.0).is_some());
        assert!((level_dbfs(&chunk(16_384)) - (-6.02)).abs() < 0.05);
    }

    #[test]
    fn a_stop_drops_what_was_sent_ahead() {
        let mut gate = EchoGate::new(EchoConfig::default());
        let t0 = 9_000_000;
        for k in 0..50u32 {
            gate.reference(t0, Some((3, k * 441)), &chunk(16_384));
        }
        // Stopped 100 ms into the reply (40 ms into its playing): the second after it has no floor once the
        // window has passed what did play.
        gate.stopped(t0 + 100_000);
        assert!(gate.heard(t0 + 200_000, -30.0).is_some());
        assert_eq!(gate.heard(t0 + 100_000 + 710_000, -30.0), None);
    }
}
