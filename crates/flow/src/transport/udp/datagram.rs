//! The UDP datagram of FlowProtocol: a 16-byte header and a payload, encoded and strictly decoded, no I/O.
//!
//! ```text
//!  0       2     3      4              8              12           14           16
//! +-------+-----+------+--------------+--------------+------------+------------+----------------+
//! | magic | ver | kind | session: u32 | seq: u32     | frag: u16  | frags: u16 | payload: rest  |
//! +-------+-----+------+--------------+--------------+------------+------------+----------------+
//!   "FU"    1
//! ```
//!
//! All integers little-endian. Per kind:
//!
//! - `hello` (1, client -> hub): `session` is the client's nonce, `seq`, `frag`, `frags` are 0; the payload is
//!   zeros padding the datagram to at least [`HELLO_MIN`] bytes, so that the answer is never larger than the ask.
//! - `hello-ack` (2, hub -> client): `session` is the new session id, `seq` echoes the nonce; no payload.
//! - `reliable` (3) and `best-effort` (4): fragment `frag` of `frags` (`frag < frags`, `frags >= 1`) of one frame,
//!   never empty.
//!   A reliable fragment's `seq` numbers datagrams (each fragment its own, consecutive within a frame); a best-effort
//!   fragment's `seq` numbers frames (all fragments of one frame share it).
//! - `ack` (5): `seq` is the next reliable sequence number expected (all before it arrived); the payload is a
//!   `u32` bitmap of those after it that arrived (bit `i`: `seq + 1 + i`).
//! - `close` (6) and `keepalive` (7): no payload; `seq`, `frag`, `frags` are 0.
//! - `nack` (8): the receiver of best-effort frame `seq` lacks some of its fragments; the payload (1 byte or more)
//!   is a bitmap of the missing ones (bit `i % 8` of byte `i / 8`: fragment `i`); `frag` and `frags` are 0. The
//!   sender sends those fragments again if it still has them (`engine.rs`).
//!
//! A datagram is at most [`MAX_DATAGRAM`] bytes. Anything else (short, long, wrong magic or version, unknown kind, inconsistent fields) is an error: the caller drops
//! the datagram and counts it, never answers it.

use thiserror::Error;

/// The header's size in bytes.
pub const HEADER: usize = 16;
/// The first two bytes of every datagram ("FU").
pub const MAGIC: [u8; 2] = *b"FU";
/// The datagram format's version.
pub const VERSION: u8 = 1;
/// The smallest hello datagram, padding included: an answer to it is never larger (no amplification).
pub const HELLO_MIN: usize = 1200;
/// The largest datagram either side sends or takes: what fits one 1500-byte Ethernet frame over IPv4 unfragmented.
/// Bounding it bounds what a queue of datagrams may hold.
pub const MAX_DATAGRAM: usize = 1472;

/// What a datagram is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Hello = 1,
    HelloAck = 2,
    Reliable = 3,
    BestEffort = 4,
    Ack = 5,
    Close = 6,
    Keepalive = 7,
    Nack = 8,
}

impl Kind {
    fn from_u8(b: u8) -> Option<Kind> {
        Some(match b {
            1 => Kind::Hello,
            2 => Kind::HelloAck,
            3 => Kind::Reliable,
            4 => Kind::BestEffort,
            5 => Kind::Ack,
            6 => Kind::Close,
            7 => Kind::Keepalive,
            8 => Kind::Nack,
            _ => return None,
        })
    }

    fn is_fragment(self) -> bool {
        matches!(self, Kind::Reliable | Kind::BestEffort)
    }
}

/// A decoded datagram, borrowing its payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Datagram<'a> {
    pub kind: Kind,
    pub session: u32,
    pub seq: u32,
    pub frag: u16,
    pub frags: u16,
    pub payload: &'a [u8],
}

/// Why a datagram was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum Malformed {
    #[error("shorter than the {HEADER}-byte header")]
    Short,
    #[error("longer than {MAX_DATAGRAM} bytes")]
    Long,
    #[error("not a FlowProtocol datagram (magic or version)")]
    Magic,
    #[error("unknown kind {0}")]
    Kind(u8),
    #[error("fragment fields out of range")]
    Fragment,
    #[error("a payload or field that this kind does not allow")]
    Shape,
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

impl<'a> Datagram<'a> {
    /// Decodes `bytes` strictly.
    pub fn decode(bytes: &'a [u8]) -> Result<Datagram<'a>, Malformed> {
        if bytes.len() < HEADER {
            return Err(Malformed::Short);
        }
        if bytes.len() > MAX_DATAGRAM {
            return Err(Malformed::Long);
        }
        if bytes[0..2] != MAGIC || bytes[2] != VERSION {
            return Err(Malformed::Magic);
        }
        let kind = Kind::from_u8(bytes[3]).ok_or(Malformed::Kind(bytes[3]))?;
        let d = Datagram {
            kind,
            session: u32_at(bytes, 4),
            seq: u32_at(bytes, 8),
            frag: u16_at(bytes, 12),
            frags: u16_at(bytes, 14),
            payload: &bytes[HEADER..],
        };
        if kind.is_fragment() {
            if d.frags == 0 || d.frag >= d.frags {
                return Err(Malformed::Fragment);
            }
            // A frame is never empty, nor is any piece of it.
            if d.payload.is_empty() {
                return Err(Malformed::Shape);
            }
            return Ok(d);
        }
        if d.frag != 0 || d.frags != 0 {
            return Err(Malformed::Fragment);
        }
        let shape_ok = match kind {
            Kind::Hello => {
                d.seq == 0 && bytes.len() >= HELLO_MIN && d.payload.iter().all(|&b| b == 0)
            }
            Kind::Ack => d.payload.len() == 4,
            Kind::HelloAck => d.payload.is_empty() && d.session != 0,
            Kind::Close | Kind::Keepalive => d.seq == 0 && d.payload.is_empty(),
            Kind::Nack => !d.payload.is_empty(),
            Kind::Reliable | Kind::BestEffort => true,
        };
        if !shape_ok {
            return Err(Malformed::Shape);
        }
        Ok(d)
    }

    /// Appends the encoded datagram to `out`. A hello is padded to [`HELLO_MIN`] here.
    pub fn encode(&self, out: &mut Vec<u8>) {
        let start = out.len();
        out.extend_from_slice(&MAGIC);
        out.push(VERSION);
        out.push(self.kind as u8);
        out.extend_from_slice(&self.session.to_le_bytes());
        out.extend_from_slice(&self.seq.to_le_bytes());
        out.extend_from_slice(&self.frag.to_le_bytes());
        out.extend_from_slice(&self.frags.to_le_bytes());
        out.extend_from_slice(self.payload);
        if self.kind == Kind::Hello && out.len() - start < HELLO_MIN {
            out.resize(start + HELLO_MIN, 0);
        }
    }

    /// The encoded datagram.
    pub fn to_vec(&self) -> Vec<u8> {
        let mut v = Vec::with_capacity(HEADER + self.payload.len());
        self.encode(&mut v);
        v
    }

    /// A datagram of `kind` without fragment fields or payload.
    pub fn bare(kind: Kind, session: u32, seq: u32) -> Datagram<'static> {
        Datagram {
            kind,
            session,
            seq,
            frag: 0,
            frags: 0,
            payload: &[],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_datagram(rng: &mut impl Rng, payload: &mut Vec<u8>) -> (Kind, u32, u32, u16, u16) {
        payload.clear();
        let kind = Kind::from_u8(rng.random_range(1..=8)).expect("kind");
        let session = rng.random::<u32>() | 1;
        let (mut seq, mut frag, mut frags) = (rng.random(), 0, 0);
        match kind {
            Kind::Reliable | Kind::BestEffort => {
                frags = rng.random_range(1..=u16::MAX);
                frag = rng.random_range(0..frags);
                payload.extend(
                    (0..rng.random_range(1..=MAX_DATAGRAM - HEADER)).map(|_| rng.random::<u8>()),
                );
            }
            Kind::Ack => payload.extend(rng.random::<u32>().to_le_bytes()),
            Kind::Nack => payload.extend((0..rng.random_range(1..=8)).map(|_| rng.random::<u8>())),
            Kind::Hello | Kind::Close | Kind::Keepalive => seq = 0,
            Kind::HelloAck => {}
        }
        (kind, session, seq, frag, frags)
    }

    #[test]
    fn random_datagrams_round_trip() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(38);
        let mut payload = Vec::new();
        for _ in 0..5000 {
            let (kind, session, seq, frag, frags) = random_datagram(&mut rng, &mut payload);
            let d = Datagram {
                kind,
                session,
                seq,
                frag,
                frags,
                payload: &payload,
            };
            let wire = d.to_vec();
            let back = Datagram::decode(&wire).expect("decodes");
            if kind == Kind::Hello {
                assert_eq!(wire.len(), HELLO_MIN);
                assert_eq!((back.kind, back.session), (kind, session));
            } else {
                assert_eq!(back, d);
            }
        }
    }

    #[test]
    fn malformed_datagrams_are_refused_without_panicking() {
        let good = Datagram {
            kind: Kind::Reliable,
            session: 7,
            seq: 1,
            frag: 0,
            frags: 1,
            payload: b"x",
        }
        .to_vec();
        let mut corpus: Vec<(Vec<u8>, Malformed)> = vec![
            (vec![], Malformed::Short),
            (good[..15].to_vec(), Malformed::Short),
            (
                [b"GET / HTTP/1.1\r\n".as_slice()].concat(),
                Malformed::Magic,
            ),
        ];
        let mut bad = good.clone();
        bad[2] = 2;
        corpus.push((bad, Malformed::Magic));
        let mut bad = good.clone();
        bad[3] = 9;
        corpus.push((bad, Malformed::Kind(9)));
        // A nack that names no fragment.
        corpus.push((Datagram::bare(Kind::Nack, 5, 3).to_vec(), Malformed::Shape));
        let mut bad = good.clone();
        bad[14] = 0; // frags = 0
        corpus.push((bad, Malformed::Fragment));
        let mut bad = good.clone();
        bad[12] = 1; // frag 1 of 1
        corpus.push((bad, Malformed::Fragment));
        // A hello too short to answer, and one whose padding carries data.
        let mut short_hello = Datagram::bare(Kind::Hello, 5, 0).to_vec();
        short_hello.truncate(HELLO_MIN - 1);
        corpus.push((short_hello, Malformed::Shape));
        let mut dirty_hello = Datagram::bare(Kind::Hello, 5, 0).to_vec();
        dirty_hello[100] = 1;
        corpus.push((dirty_hello, Malformed::Shape));
        let mut huge = good.clone();
        huge.resize(MAX_DATAGRAM + 1, 1);
        corpus.push((huge, Malformed::Long));
        let mut long_ack = Datagram::bare(Kind::Ack, 5, 3).to_vec();
        long_ack.extend([0; 5]);
        corpus.push((long_ack, Malformed::Shape));
        let mut keepalive_with_payload = Datagram::bare(Kind::Keepalive, 5, 0).to_vec();
        keepalive_with_payload.push(1);
        corpus.push((keepalive_with_payload, Malformed::Shape));
        corpus.push((
            Datagram::bare(Kind::HelloAck, 0, 3).to_vec(),
            Malformed::Shape,
        ));
        for (bytes, why) in corpus {
            assert_eq!(Datagram::decode(&bytes), Err(why), "{bytes:?}");
        }
        // Random bytes and every cut of a good datagram never panic.
        let mut rng = rand::rngs::StdRng::seed_from_u64(1);
        for _ in 0..20_000 {
            let len = rng.random_range(0..64);
            let mut bytes: Vec<u8> = (0..len).map(|_| rng.random()).collect();
            if rng.random_bool(0.5) && bytes.len() >= 3 {
                bytes[..3].copy_from_slice(&[b'F', b'U', VERSION]);
            }
            let _ = Datagram::decode(&bytes);
        }
        for cut in 0..good.len() {
            assert!(Datagram::decode(&good[..cut]).is_err());
        }
    }
}
