//! The audio rate of the microphone and of the agent's speech, and durations in samples.

/// The rate of the microphone (`Agent.audio`) and of the agent's speech (`Agent.speech`).
pub const RATE: u32 = 22_050;

/// Microseconds that `samples` samples at [`RATE`] last.
pub fn samples_us(samples: u64) -> u64 {
    samples * 1_000_000 / u64::from(RATE)
}
