//! Sequence number and send time written over the first bytes of every payload.
//!
//! Publisher and subscribers are tasks of this one process, so a single
//! monotonic clock serves both ends and a publish-to-receive latency is a plain
//! subtraction. The stamp overwrites the start of the real payload rather than
//! being prepended, so every system carries exactly the payload size under test.

use std::sync::OnceLock;
use std::time::Instant;

use bytes::{BufMut, Bytes, BytesMut};

/// Bytes the stamp takes at the start of a payload: `seq: u64 LE | sent_ns: u64 LE`.
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

/// A copy of `template` with `seq` and the current time stamped at `offset`
/// bytes into `out` (after whatever framing the caller wrote first).
pub fn stamp_into(out: &mut BytesMut, template: &[u8], seq: u64) {
    let start = out.len();
    out.extend_from_slice(template);
    let mut stamp = [0u8; STAMP_LEN];
    stamp[..8].copy_from_slice(&seq.to_le_bytes());
    stamp[8..].copy_from_slice(&clock_ns().to_le_bytes());
    out[start..start + STAMP_LEN].copy_from_slice(&stamp);
}

/// The payload `template` stamped with `seq` and the current time.
pub fn stamped(template: &[u8], seq: u64) -> Bytes {
    let mut out = BytesMut::with_capacity(template.len());
    stamp_into(&mut out, template, seq);
    out.freeze()
}

/// The payload stamped and preceded by a `u32 LE` length, the raw-TCP framing.
pub fn framed(template: &[u8], seq: u64) -> Bytes {
    let mut out = BytesMut::with_capacity(4 + template.len());
    // Payloads come from the bench itself and are far below 4 GiB.
    out.put_u32_le(template.len() as u32);
    stamp_into(&mut out, template, seq);
    out.freeze()
}

/// `(seq, sent_ns)` from a received payload, or `None` if it is too short to
/// carry a stamp (which would mean the system under test corrupted it).
pub fn read(payload: &[u8]) -> Option<(u64, u64)> {
    let seq = u64::from_le_bytes(payload.get(..8)?.try_into().ok()?);
    let sent = u64::from_le_bytes(payload.get(8..STAMP_LEN)?.try_into().ok()?);
    Some((seq, sent))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamp_round_trips_and_keeps_size() {
        let template = vec![7u8; 100];
        let before = clock_ns();
        let p = stamped(&template, 42);
        assert_eq!(p.len(), 100);
        let (seq, sent) = read(&p).expect("stamp");
        assert_eq!(seq, 42);
        assert!(sent >= before && sent <= clock_ns());
        assert_eq!(&p[STAMP_LEN..], &template[STAMP_LEN..]);
        let f = framed(&template, 3);
        assert_eq!(f.len(), 104);
        assert_eq!(&f[..4], &100u32.to_le_bytes());
        assert_eq!(read(&f[4..]).map(|s| s.0), Some(3));
        assert_eq!(read(&[1, 2, 3]), None);
    }
}
