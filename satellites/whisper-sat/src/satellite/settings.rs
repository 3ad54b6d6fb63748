//! What one satellite is told at start: its name, the segmenter, and the behaviours that can be switched off.

use std::time::Duration;

use crate::segmenter::SegmenterConfig;

/// Settings of one satellite.
#[derive(Debug, Clone)]
pub struct Settings {
    pub name: String,
    pub segmenter: SegmenterConfig,
    /// How long a finished claim channel is kept, so late segmenters still see the utterance as taken.
    pub claim_retention: Duration,
    /// Claim and decode utterances when they pause, before the hangover ends them.
    pub speculate: bool,
    /// End an utterance early when the transcript of its pause reads as a complete turn, and hold it open longer
    /// when the transcript trails off (speculation only).
    pub judge_turns: bool,
    /// Hold the agent's own voice, heard back through loudspeakers, under a floor learned from `Agent.speech`
    /// (`crate::echo`).
    pub echo_gate: bool,
    /// Take the transcript relay role when it is free. Off for a satellite on a hub that imports the relay's
    /// channels from another hub (docs/federation.md): the relay lives there.
    pub relay: bool,
    /// Where this satellite's decode spans go (docs/telemetry.md); off unless a collector is named.
    pub telemetry: flow_telemetry::Telemetry,
}
