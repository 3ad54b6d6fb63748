//! The framing of a serial line: each packet is a checksummed body, COBS-encoded and ended by a zero byte.
//!
//! ```text
//!  on the wire:   | COBS( body | CRC-32 LE ) | 0x00 |
//!
//!  body           1 or more bytes: whole FlowProtocol frames (docs/protocol.md), never part of one
//!  CRC-32 LE      4 bytes, crc::crc32(body), little-endian
//!  COBS           consistent-overhead byte stuffing: no zero byte inside, 1 byte added per 254 (and 1 at the start)
//!  0x00           the delimiter: a reader that lost its place (a dropped or flipped byte) finds the next packet
//!                 at the next zero, so one damaged packet costs that packet and nothing after it
//! ```
//!
//! A serial line loses and flips bytes. A packet whose COBS code bytes do not add up, whose checksum fails or that
//! outgrows the reader's buffer is [`Deframed::Damaged`]: the reader drops it, counts it, and reads the next one.
//! Since a body holds whole frames, the FlowProtocol stream stays in step across a dropped packet. Empty packets
//! (two zeros in a row) are no packets at all: a writer may send a zero first to end whatever noise came before.
//!
//! Overhead for a 1 KiB body: 4 bytes of checksum, 6 bytes of COBS and the delimiter, 1.1%.
//!
//! Both halves are pure functions over caller buffers: [`encode`] writes one packet into a slice, and
//! [`Deframer`] collects bytes in a buffer of the caller's choosing (an array on a board, a boxed slice on a host).

use crate::crc::{Crc32, crc32};

/// Bytes of checksum after the body.
pub const CRC_LEN: usize = 4;

/// The most bytes a packet with a body of `body_len` bytes takes on the wire, delimiter included.
pub const fn max_encoded_len(body_len: usize) -> usize {
    let n = body_len + CRC_LEN;
    n + n / 254 + 1 + 1
}

/// `encode` was given an empty body, or an output slice shorter than [`max_encoded_len`] of the body.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EncodeError {
    EmptyBody,
    BufferTooSmall { needed: usize },
}

/// Writes `body` as one packet (COBS over body and checksum, then the zero delimiter) into `out`; returns the bytes
/// written.
pub fn encode(body: &[u8], out: &mut [u8]) -> Result<usize, EncodeError> {
    if body.is_empty() {
        return Err(EncodeError::EmptyBody);
    }
    let needed = max_encoded_len(body.len());
    if out.len() < needed {
        return Err(EncodeError::BufferTooSmall { needed });
    }
    let crc = crc32(body).to_le_bytes();
    let mut code_at = 0;
    let mut w = 1;
    let mut code: u8 = 1;
    for &b in body.iter().chain(crc.iter()) {
        if b == 0 {
            out[code_at] = code;
            code_at = w;
            w += 1;
            code = 1;
        } else {
            out[w] = b;
            w += 1;
            code += 1;
            if code == 0xFF {
                out[code_at] = code;
                code_at = w;
                w += 1;
                code = 1;
            }
        }
    }
    out[code_at] = code;
    out[w] = 0;
    Ok(w + 1)
}

/// Why a packet was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Damage {
    /// The packet outgrew the reader's buffer (or a delimiter was lost and two packets ran together past it).
    Oversize,
    /// A COBS code byte points past the end of the packet.
    Malformed,
    /// Shorter than one body byte and the checksum.
    Short,
    /// The checksum does not match the body.
    Checksum,
}

/// What [`Deframer::push`] found at the end of a packet.
#[derive(Debug, PartialEq, Eq)]
pub enum Deframed<'a> {
    /// A whole, intact body.
    Packet(&'a [u8]),
    /// A packet that must be dropped; the next one is read as usual.
    Damaged(Damage),
}

/// Collects line bytes into packets, in a buffer of the caller's (its length bounds the encoded packet).
#[derive(Debug)]
pub struct Deframer<B> {
    buf: B,
    len: usize,
    /// The packet being collected outgrew the buffer: drop it at its delimiter.
    overflow: bool,
    /// The last call returned a packet, which lives in `buf` until the next call.
    returned: bool,
}

impl<B: AsRef<[u8]> + AsMut<[u8]>> Deframer<B> {
    /// A reader that holds packets of up to `buf.len()` encoded bytes (see [`max_encoded_len`]).
    pub fn new(buf: B) -> Self {
        Deframer {
            buf,
            len: 0,
            overflow: false,
            returned: false,
        }
    }

    /// Bytes of the packet collected so far.
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Consumes `input` up to and including the first delimiter that ends a non-empty packet. Returns how many
    /// bytes it consumed and, when a packet ended, what it was; `None` means every byte was taken and more are
    /// needed. Call again with the rest of the input.
    pub fn push(&mut self, input: &[u8]) -> (usize, Option<Deframed<'_>>) {
        if self.returned {
            self.returned = false;
            self.len = 0;
            self.overflow = false;
        }
        for (i, &b) in input.iter().enumerate() {
            if b != 0 {
                let cap = self.buf.as_ref().len();
                if self.len < cap {
                    self.buf.as_mut()[self.len] = b;
                    self.len += 1;
                } else {
                    self.overflow = true;
                }
                continue;
            }
            if self.len == 0 && !self.overflow {
                // An empty packet: a writer's resynchronising zero, or two delimiters in a row.
                continue;
            }
            self.returned = true;
            let outcome = if self.overflow {
                Deframed::Damaged(Damage::Oversize)
            } else {
                match decode_in_place(&mut self.buf.as_mut()[..self.len]) {
                    Err(damage) => Deframed::Damaged(damage),
                    Ok(n) if n <= CRC_LEN => Deframed::Damaged(Damage::Short),
                    Ok(n) => {
                        let decoded = &self.buf.as_ref()[..n];
                        let (body, crc) = decoded.split_at(n - CRC_LEN);
                        let mut sum = Crc32::new();
                        sum.update(body);
                        if crc == sum.value().to_le_bytes() {
                            Deframed::Packet(body)
                        } else {
                            Deframed::Damaged(Damage::Checksum)
                        }
                    }
                }
            };
            return (i + 1, Some(outcome));
        }
        (input.len(), None)
    }
}

/// Undoes COBS in place (the output is never longer than the input); returns the decoded length.
fn decode_in_place(buf: &mut [u8]) -> Result<usize, Damage> {
    let n = buf.len();
    let (mut r, mut w) = (0, 0);
    while r < n {
        let code = buf[r] as usize;
        // A zero cannot be inside a packet: the deframer split there.
        if code == 0 {
            return Err(Damage::Malformed);
        }
        r += 1;
        if r + code - 1 > n {
            return Err(Damage::Malformed);
        }
        buf.copy_within(r..r + code - 1, w);
        w += code - 1;
        r += code - 1;
        if code < 0xFF && r < n {
            buf[w] = 0;
            w += 1;
        }
    }
    Ok(w)
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::vec;
    use std::vec::Vec;

    use super::*;

    /// Deterministic bytes (xorshift), with zeros and 0xFF often enough to exercise COBS.
    fn bytes(seed: u32, n: usize) -> Vec<u8> {
        let mut x = seed | 1;
        (0..n)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                match x % 7 {
                    0 => 0,
                    1 => 0xFF,
                    _ => (x >> 8) as u8,
                }
            })
            .collect()
    }

    fn packet(body: &[u8]) -> Vec<u8> {
        let mut out = vec![0; max_encoded_len(body.len())];
        let n = encode(body, &mut out).expect("encodes");
        out.truncate(n);
        out
    }

    /// Every outcome of feeding `wire`, `step` bytes at a time.
    fn read_all(wire: &[u8], step: usize, cap: usize) -> Vec<Result<Vec<u8>, Damage>> {
        let mut d = Deframer::new(vec![0u8; cap]);
        let mut got = Vec::new();
        for chunk in wire.chunks(step) {
            let mut rest = chunk;
            while !rest.is_empty() {
                let (used, out) = d.push(rest);
                rest = &rest[used..];
                match out {
                    Some(Deframed::Packet(p)) => got.push(Ok(p.to_vec())),
                    Some(Deframed::Damaged(why)) => got.push(Err(why)),
                    None => {}
                }
            }
        }
        got
    }

    #[test]
    fn bodies_of_every_awkward_length_round_trip_whole_and_byte_at_a_time() {
        let lengths = [1, 2, 3, 250, 251, 253, 254, 255, 256, 508, 509, 1024, 4000];
        for (i, &n) in lengths.iter().enumerate() {
            for body in [bytes(i as u32 + 1, n), vec![0; n], vec![0xFF; n]] {
                let wire = packet(&body);
                assert!(wire.len() <= max_encoded_len(n));
                assert_eq!(wire.iter().filter(|&&b| b == 0).count(), 1);
                assert_eq!(*wire.last().expect("delimiter"), 0);
                for step in [1, 7, wire.len()] {
                    assert_eq!(
                        read_all(&wire, step, max_encoded_len(n)),
                        vec![Ok(body.clone())],
                        "length {n}, step {step}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_kilobyte_costs_under_one_and_a_half_percent() {
        let body = bytes(9, 1024);
        let overhead = packet(&body).len() - body.len();
        assert!(overhead * 1000 <= 15 * 1024, "{overhead} bytes");
    }

    #[test]
    fn a_flipped_byte_drops_its_packet_and_the_next_one_arrives() {
        let (a, b) = (bytes(1, 300), bytes(2, 300));
        for at in 0..packet(&a).len() - 1 {
            for bit in [0x01, 0x80] {
                let mut wire = packet(&a);
                wire[at] ^= bit;
                wire.extend(packet(&b));
                let got = read_all(&wire, 5, 4096);
                // The flip may make a zero (splitting the packet in two damaged ones) but never a good packet of a.
                assert_eq!(got.last(), Some(&Ok(b.clone())), "flip at {at}");
                assert!(
                    got[..got.len() - 1].iter().all(|g| g.is_err()),
                    "flip at {at}: {got:?}"
                );
                assert!(!got.is_empty());
            }
        }
    }

    #[test]
    fn a_lost_delimiter_costs_the_two_packets_it_joined() {
        let (a, b, c) = (bytes(1, 100), bytes(2, 100), bytes(3, 100));
        let mut wire = packet(&a);
        wire.pop();
        wire.extend(packet(&b));
        wire.extend(packet(&c));
        let got = read_all(&wire, 3, 4096);
        assert_eq!(got.len(), 2, "{got:?}");
        assert!(got[0].is_err());
        assert_eq!(got[1], Ok(c));
    }

    #[test]
    fn a_packet_longer_than_the_buffer_is_dropped_whole() {
        let (big, small) = (bytes(1, 600), bytes(2, 100));
        let mut wire = packet(&big);
        wire.extend(packet(&small));
        let got = read_all(&wire, 64, max_encoded_len(100));
        assert_eq!(got, vec![Err(Damage::Oversize), Ok(small)]);
    }

    #[test]
    fn noise_and_empty_packets_before_a_packet_are_no_packets() {
        let body = bytes(4, 50);
        let mut wire = vec![0, 0, 0];
        wire.extend(packet(&body));
        wire.extend([0, 0]);
        assert_eq!(read_all(&wire, 1, 4096), vec![Ok(body.clone())]);
        // Noise without a checksum that holds: damaged, then the packet.
        let mut wire = vec![0x05, 0x41, 0x42, 0];
        wire.extend(packet(&body));
        let got = read_all(&wire, 1, 4096);
        assert_eq!(got.len(), 2);
        assert!(got[0].is_err());
        assert_eq!(got[1], Ok(body));
    }

    #[test]
    fn malformed_corpus_never_yields_a_packet() {
        let corpus: [&[u8]; 6] = [
            &[0x01, 0],
            &[0x02, 0],
            &[0x09, 0x01, 0x02, 0],
            &[0xFF, 0x01, 0],
            &[0x03, 0x01, 0x01, 0x01, 0],
            &[0x06, 1, 2, 3, 4, 5, 0],
        ];
        for wire in corpus {
            let got = read_all(wire, 1, 64);
            assert!(got.iter().all(|g| g.is_err()), "{wire:?}: {got:?}");
        }
    }

    #[test]
    fn encode_refuses_an_empty_body_and_a_short_buffer() {
        let mut out = [0u8; 8];
        assert_eq!(encode(&[], &mut out), Err(EncodeError::EmptyBody));
        assert_eq!(
            encode(&[1, 2, 3, 4], &mut out),
            Err(EncodeError::BufferTooSmall { needed: 10 })
        );
    }
}
