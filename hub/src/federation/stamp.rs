//! The attachment of a stream sample crossing hubs: where the message stood on its origin hub. A pure encoding,
//! checked then parsed, with no I/O.
//!
//! ```text
//!  0        1                 9                 17
//!  +--------+-----------------+-----------------+
//!  | ver=1  | seq: u64 LE     | ts_us: u64 LE   |
//!  +--------+-----------------+-----------------+
//! ```
//!
//! `seq` is the message's position on the origin hub's channel (from 1) and `ts_us` the origin hub's clock when it
//! was published (µs since the Unix epoch). The importing hub stamps messages with its own sequence and clock, as it
//! does every publication; the origin's are for counting what was lost between hubs and for measuring the delay.
//! Samples from plain Zenoh clients carry no attachment, which is allowed.

/// Bytes of an encoded stamp.
pub const STAMP_LEN: usize = 17;
const VERSION: u8 = 1;

/// A message's place on its origin hub.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stamp {
    pub seq: u64,
    pub ts_us: u64,
}

/// Why an attachment is not a stamp.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum StampError {
    #[error("attachment of {0} bytes, a stamp has {STAMP_LEN}")]
    Length(usize),
    #[error("stamp version {0}, this hub reads version {VERSION}")]
    Version(u8),
}

impl Stamp {
    pub fn encode(&self) -> [u8; STAMP_LEN] {
        let mut out = [0u8; STAMP_LEN];
        out[0] = VERSION;
        out[1..9].copy_from_slice(&self.seq.to_le_bytes());
        out[9..17].copy_from_slice(&self.ts_us.to_le_bytes());
        out
    }

    pub fn decode(bytes: &[u8]) -> Result<Stamp, StampError> {
        let Ok(fixed) = <&[u8; STAMP_LEN]>::try_from(bytes) else {
            return Err(StampError::Length(bytes.len()));
        };
        if fixed[0] != VERSION {
            return Err(StampError::Version(fixed[0]));
        }
        let mut seq = [0u8; 8];
        let mut ts = [0u8; 8];
        seq.copy_from_slice(&fixed[1..9]);
        ts.copy_from_slice(&fixed[9..17]);
        Ok(Stamp {
            seq: u64::from_le_bytes(seq),
            ts_us: u64::from_le_bytes(ts),
        })
    }
}

/// Counts messages lost between the origin hub and this one from the gaps in the origin's sequence.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct GapCounter {
    last: Option<u64>,
    pub lost: u64,
}

impl GapCounter {
    /// Notes one arrival; a sequence that goes back (the origin restarted its channel) starts counting anew.
    pub fn note(&mut self, seq: u64) {
        if let Some(last) = self.last
            && seq > last
        {
            self.lost += seq - last - 1;
        }
        self.last = Some(seq);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn random_stamps_survive_a_round_trip() {
        let mut rng = rand::rng();
        for _ in 0..1000 {
            let s = Stamp {
                seq: rng.random(),
                ts_us: rng.random(),
            };
            assert_eq!(Stamp::decode(&s.encode()), Ok(s));
        }
    }

    #[test]
    fn malformed_attachments_are_named_errors() {
        let good = Stamp { seq: 7, ts_us: 9 }.encode();
        for cut in 0..STAMP_LEN {
            assert_eq!(Stamp::decode(&good[..cut]), Err(StampError::Length(cut)));
        }
        let mut longer = good.to_vec();
        longer.push(0);
        assert_eq!(Stamp::decode(&longer), Err(StampError::Length(18)));
        let mut other = good;
        other[0] = 2;
        assert_eq!(Stamp::decode(&other), Err(StampError::Version(2)));
    }

    #[test]
    fn gaps_in_the_origin_sequence_count_as_lost() {
        let mut g = GapCounter::default();
        for seq in [1, 2, 5, 6, 9] {
            g.note(seq);
        }
        assert_eq!(g.lost, 4);
        g.note(1);
        g.note(2);
        assert_eq!(g.lost, 4, "a restarted origin is not a loss");
    }
}
