//! The microphone's samples on the hub clock.
//!
//! The hub stamps a message of `Agent.audio` when it arrives, just after its audio was captured: the first sample
//! of a message was captured about the message's length before its stamp. Messages are late by varying amounts (a
//! busy or starved page sends several at once), so the clock keeps the least late placement seen as its baseline,
//! follows the clocks' drift upwards slowly, and starts again on a hole in the sequence or a long silence of the
//! publisher (the same model as whisper-sat's `stream.rs`).

use crate::rate::samples_us;

/// Messages later than the baseline by more than this are a new stream, not a late delivery.
pub const MAX_LATENESS_US: u64 = 4_000_000;
/// The baseline follows a drift of up to this many µs per second of audio (sound cards drift by a few hundred
/// parts per million from the hub's clock).
const DRIFT_US_PER_S: u64 = 1_000;

/// Where the microphone's samples are on the hub clock.
#[derive(Debug, Default)]
pub struct MicClock {
    /// Hub time of the stream's first sample, from the least late message so far.
    origin_us: Option<u64>,
    /// Samples received since the stream (re)started.
    received: u64,
    last_seq: Option<u64>,
}

/// A message placed on the clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Placed {
    /// Hub time at which the message's first sample was captured.
    pub first_us: u64,
    /// The stream started again with this message (a hole in the sequence, or the publisher went quiet).
    pub restarted: bool,
}

impl MicClock {
    /// Places message `seq`, stamped `ts_us`, holding `samples` samples.
    pub fn place(&mut self, seq: u64, ts_us: u64, samples: usize) -> Placed {
        let length_us = samples_us(samples as u64);
        let restarted = match (self.last_seq, self.origin_us) {
            (Some(last), Some(origin)) => {
                let expected = origin + samples_us(self.received) + length_us;
                seq != last + 1 || ts_us.saturating_sub(expected) > MAX_LATENESS_US
            }
            _ => false,
        };
        if restarted {
            self.origin_us = None;
            self.received = 0;
        }
        let before_us = samples_us(self.received);
        let on_time = ts_us.saturating_sub(before_us + length_us);
        let origin = match self.origin_us {
            None => on_time,
            Some(origin) if on_time <= origin => on_time,
            Some(origin) => {
                let drift = samples as u64 * DRIFT_US_PER_S / u64::from(crate::rate::RATE);
                origin + (on_time - origin).min(drift)
            }
        };
        self.origin_us = Some(origin);
        self.last_seq = Some(seq);
        self.received += samples as u64;
        Placed {
            first_us: origin + before_us,
            restarted,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_message_starts_its_length_before_its_stamp_and_late_ones_keep_the_baseline() {
        let mut clock = MicClock::default();
        // 20 ms messages (441 samples), the second one 50 ms late.
        assert_eq!(
            clock.place(1, 1_020_000, 441),
            Placed {
                first_us: 1_000_000,
                restarted: false
            }
        );
        // It moves the baseline up by the drift allowed over 20 ms of audio only.
        assert_eq!(clock.place(2, 1_090_000, 441).first_us, 1_020_020);
        // An early one moves the baseline down.
        assert_eq!(clock.place(3, 1_055_000, 441).first_us, 1_035_000);
        assert_eq!(clock.place(4, 1_075_000, 441).first_us, 1_055_000);
    }

    #[test]
    fn a_hole_in_the_sequence_or_a_long_silence_starts_again() {
        let mut clock = MicClock::default();
        clock.place(1, 1_020_000, 441);
        let hole = clock.place(5, 2_020_000, 441);
        assert!(hole.restarted);
        assert_eq!(hole.first_us, 2_000_000);
        let quiet = clock.place(6, 9_020_000, 441);
        assert!(quiet.restarted);
        assert_eq!(quiet.first_us, 9_000_000);
        assert!(!clock.place(7, 9_040_000, 441).restarted);
    }
}
