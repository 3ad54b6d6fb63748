//! Frame boundaries: a pure `check` / `parse` pair over bytes, with no I/O.
//!
//! Every FlowProtocol frame, in both directions, has the same fixed header:
//!
//! ```text
//!  0               4       5               9
//! +---------------+-------+---------------+---------------------------+
//! | len: u32 LE   | op:u8 | req: u32 LE   | body: len - 5 bytes       |
//! +---------------+-------+---------------+---------------------------+
//! ```
//!
//! `len` counts everything after itself (op + req + body), so the smallest legal
//! value is 5. The length is validated against the configured maximum *before*
//! any buffer grows to hold the frame, so a hostile peer cannot make us allocate
//! gigabytes by announcing them.

use bytes::{Buf, Bytes, BytesMut};

use super::error::FrameError;

/// Size of the length prefix.
pub const LEN_PREFIX: usize = 4;
/// Size of `op` + `req`, the part of the header counted by `len`.
pub const HEAD_AFTER_LEN: usize = 5;
/// Full fixed header size.
pub const HEADER_LEN: usize = LEN_PREFIX + HEAD_AFTER_LEN;
/// Default upper bound for one frame (header included): 16 MiB.
pub const DEFAULT_MAX_FRAME: usize = 16 * 1024 * 1024;

/// Outcome of looking at the start of a buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Check {
    /// A whole frame of this many bytes (prefix included) is at the front.
    Complete(usize),
    /// More bytes are needed; at least this many in total before the next look.
    Incomplete(usize),
}

/// A frame cut out of the stream: the opcode, the request id and the body.
///
/// The body is `body` followed by `tail`. `tail` is empty except where the end of the frame arrived as a shared
/// buffer of its own (a payload handed over an in-process link, [`parse_with_tail`]): it is kept apart instead of
/// being copied behind the rest.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawFrame {
    pub op: u8,
    pub req: u32,
    pub body: Bytes,
    pub tail: Bytes,
}

/// Looks at the front of `buf` and says whether a whole frame is there.
///
/// Errors only for a length that can never be valid: below the header size or
/// above `max_frame`. Needing more bytes is not an error.
pub fn check(buf: &[u8], max_frame: usize) -> Result<Check, FrameError> {
    let Some(prefix) = buf.get(..LEN_PREFIX) else {
        return Ok(Check::Incomplete(HEADER_LEN));
    };
    let len = u32::from_le_bytes([prefix[0], prefix[1], prefix[2], prefix[3]]) as usize;
    if len < HEAD_AFTER_LEN {
        return Err(FrameError::TooShort(len));
    }
    let total = len + LEN_PREFIX;
    if total > max_frame {
        return Err(FrameError::TooLarge {
            len: total,
            max: max_frame,
        });
    }
    if buf.len() < total {
        Ok(Check::Incomplete(total))
    } else {
        Ok(Check::Complete(total))
    }
}

/// Splits the frame that `check` found complete off the front of `buf`.
///
/// The body shares the buffer's allocation, so payloads are never copied on
/// the way in.
pub fn parse(buf: &mut BytesMut, total: usize) -> RawFrame {
    let mut frame = buf.split_to(total);
    frame.advance(LEN_PREFIX);
    let op = frame.get_u8();
    let req = frame.get_u32_le();
    RawFrame {
        op,
        req,
        body: frame.freeze(),
        tail: Bytes::new(),
    }
}

/// Splits off the frame whose first bytes are all of `buf` and whose remaining bytes are `tail`.
///
/// For a frame `check` found incomplete with at least [`HEADER_LEN`] bytes in `buf` and `tail` exactly the bytes it
/// still needs; the caller makes sure of both.
pub fn parse_with_tail(buf: &mut BytesMut, tail: Bytes) -> RawFrame {
    let held = buf.len();
    let mut frame = parse(buf, held);
    frame.tail = tail;
    frame
}

/// Writes a frame header for a body of `body_len` bytes.
pub fn put_header(out: &mut BytesMut, op: u8, req: u32, body_len: usize) {
    use bytes::BufMut;
    // The encoder never builds bodies near 4 GiB; the receiver's max-frame
    // check rejects anything over its limit anyway.
    out.put_u32_le((body_len + HEAD_AFTER_LEN) as u32);
    out.put_u8(op);
    out.put_u32_le(req);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn needs_prefix_then_body() {
        assert_eq!(check(&[], 100), Ok(Check::Incomplete(HEADER_LEN)));
        assert_eq!(check(&[7, 0, 0], 100), Ok(Check::Incomplete(HEADER_LEN)));
        let mut frame = BytesMut::new();
        put_header(&mut frame, 3, 9, 2);
        frame.extend_from_slice(&[1, 2]);
        assert_eq!(check(&frame[..10], 100), Ok(Check::Incomplete(11)));
        assert_eq!(check(&frame, 100), Ok(Check::Complete(11)));
        let raw = parse(&mut frame, 11);
        assert_eq!(
            raw,
            RawFrame {
                op: 3,
                req: 9,
                body: Bytes::from_static(&[1, 2]),
                tail: Bytes::new(),
            }
        );
        assert!(frame.is_empty());
    }

    #[test]
    fn a_frame_whose_end_came_apart_keeps_it_as_its_tail() {
        let mut frame = BytesMut::new();
        put_header(&mut frame, 3, 9, 5);
        frame.extend_from_slice(&[1, 2]);
        assert_eq!(check(&frame, 100), Ok(Check::Incomplete(14)));
        let raw = parse_with_tail(&mut frame, Bytes::from_static(&[3, 4, 5]));
        assert_eq!((raw.op, raw.req), (3, 9));
        assert_eq!(&raw.body[..], &[1, 2]);
        assert_eq!(&raw.tail[..], &[3, 4, 5]);
        assert!(frame.is_empty());
    }

    #[test]
    fn rejects_impossible_lengths_before_allocating() {
        assert_eq!(check(&[4, 0, 0, 0], 100), Err(FrameError::TooShort(4)));
        assert_eq!(
            check(&[0xff, 0xff, 0xff, 0xff], 1024),
            Err(FrameError::TooLarge {
                len: 0xffff_ffff + 4,
                max: 1024
            })
        );
    }
}
