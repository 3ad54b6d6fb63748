//! The send time and sequence number written over the first bytes of every payload, and what a subscriber reads
//! back: the first 16 bytes and the last byte, never the rest (zero-copy is the point, so no mode pays for reading
//! a whole payload).
//!
//! Publisher and subscribers live in this one process, so one monotonic clock serves both ends and a latency is a
//! plain subtraction. The stamp overwrites the start of the real payload rather than being prepended, so every mode
//! carries exactly the payload size under test.

use std::sync::OnceLock;
use std::time::Instant;

/// Bytes the stamp takes: `sent_ns: u64 LE | seq: u64 LE`.
pub const STAMP_LEN: usize = 16;

fn epoch() -> Instant {
    static EPOCH: OnceLock<Instant> = OnceLock::new();
    *EPOCH.get_or_init(Instant::now)
}

/// Nanoseconds on the process-wide monotonic clock.
pub fn clock_ns() -> u64 {
    // A run lasts minutes, far from the 584 years a u64 of nanoseconds holds.
    epoch().elapsed().as_nanos() as u64
}

/// Writes the current time and `seq` over the first [`STAMP_LEN`] bytes of `payload` (at least that long: the
/// payloads are the bench's own).
pub fn write(payload: &mut [u8], seq: u64) {
    if let Some(head) = payload.get_mut(..STAMP_LEN) {
        head[..8].copy_from_slice(&clock_ns().to_le_bytes());
        head[8..].copy_from_slice(&seq.to_le_bytes());
    }
}

/// What a subscriber takes from a payload: its stamp and its last byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Touched {
    pub sent_ns: u64,
    pub seq: u64,
    pub last: u8,
}

/// Reads the stamp and the last byte of `payload`; `None` if it is too short to carry a stamp (the mode under test
/// damaged it).
pub fn touch(payload: &[u8]) -> Option<Touched> {
    let sent_ns = u64::from_le_bytes(payload.get(..8)?.try_into().ok()?);
    let seq = u64::from_le_bytes(payload.get(8..STAMP_LEN)?.try_into().ok()?);
    let last = *payload.last()?;
    Some(Touched { sent_ns, seq, last })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stamp_reads_back_and_keeps_the_rest() {
        let mut p = vec![7u8; 100];
        let before = clock_ns();
        write(&mut p, 42);
        let t = touch(&p).expect("stamp");
        assert_eq!(t.seq, 42);
        assert!(t.sent_ns >= before && t.sent_ns <= clock_ns());
        assert_eq!(t.last, 7);
        assert_eq!(&p[STAMP_LEN..], &[7u8; 100 - STAMP_LEN][..]);
        assert_eq!(touch(&[1, 2, 3]), None);
    }
}
