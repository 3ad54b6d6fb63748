//! Frame boundaries: a pure `check` / `parse` pair over borrowed bytes, with no I/O and no copy.
//!
//! Every FlowProtocol frame, in both directions, has the same fixed header (the layout of `flow::protocol::frame`):
//!
//! ```text
//!  0               4       5               9
//! +---------------+-------+---------------+---------------------------+
//! | len: u32 LE   | op:u8 | req: u32 LE   | body: len - 5 bytes       |
//! +---------------+-------+---------------+---------------------------+
//! ```
//!
//! `len` counts everything after itself (op + req + body), so the smallest legal value is 5. A board checks the
//! length against the buffer it has before waiting for the rest, so a peer announcing gigabytes costs nothing.

use core::fmt;

/// Size of the length prefix.
pub const LEN_PREFIX: usize = 4;
/// Size of `op` + `req`, the part of the header counted by `len`.
pub const HEAD_AFTER_LEN: usize = 5;
/// Full fixed header size.
pub const HEADER_LEN: usize = LEN_PREFIX + HEAD_AFTER_LEN;

/// Outcome of looking at the start of a buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Check {
    /// A whole frame of this many bytes (prefix included) is at the front.
    Complete(usize),
    /// More bytes are needed; at least this many in total before the next look.
    Incomplete(usize),
}

/// The byte stream cannot be cut into frames any more.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// The announced length is below the 5 bytes of `op` and `req`.
    TooShort(usize),
    /// The frame (prefix included) would be larger than the reader accepts.
    TooLarge { len: usize, max: usize },
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FrameError::TooShort(len) => {
                write!(f, "frame length {len} is shorter than the 5-byte header")
            }
            FrameError::TooLarge { len, max } => {
                write!(f, "frame of {len} bytes exceeds the maximum of {max}")
            }
        }
    }
}

impl core::error::Error for FrameError {}

/// A frame cut out of a buffer: the opcode, the request id and the body, borrowed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawFrame<'a> {
    pub op: u8,
    pub req: u32,
    pub body: &'a [u8],
}

/// What [`parse`] found at the front of a buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Parsed<'a> {
    /// A whole frame, and the bytes it took (prefix included): the next frame starts there.
    Frame(RawFrame<'a>, usize),
    /// More bytes are needed; at least this many in total before the next look.
    Incomplete(usize),
}

/// Looks at the front of `buf` and says whether a whole frame is there.
///
/// Errors only for a length that can never be valid: below the header size or above `max_frame`. Needing more
/// bytes is not an error.
pub fn check(buf: &[u8], max_frame: usize) -> Result<Check, FrameError> {
    let Some(prefix) = buf.get(..LEN_PREFIX) else {
        return Ok(Check::Incomplete(HEADER_LEN));
    };
    let len = u32::from_le_bytes([prefix[0], prefix[1], prefix[2], prefix[3]]) as usize;
    if len < HEAD_AFTER_LEN {
        return Err(FrameError::TooShort(len));
    }
    // Saturating: on a 16-bit or 32-bit target a length near u32::MAX must not wrap into a small one.
    let total = len.saturating_add(LEN_PREFIX);
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

/// Cuts the frame at the front of `buf` when it is whole, without copying its body.
pub fn parse(buf: &[u8], max_frame: usize) -> Result<Parsed<'_>, FrameError> {
    match check(buf, max_frame)? {
        Check::Incomplete(n) => Ok(Parsed::Incomplete(n)),
        Check::Complete(total) => {
            let op = buf[LEN_PREFIX];
            let req = u32::from_le_bytes([buf[5], buf[6], buf[7], buf[8]]);
            Ok(Parsed::Frame(
                RawFrame {
                    op,
                    req,
                    body: &buf[HEADER_LEN..total],
                },
                total,
            ))
        }
    }
}

/// Writes the header of a frame whose body is `body_len` bytes into the first [`HEADER_LEN`] bytes of `out`;
/// `None` when `out` is shorter than that or the body cannot be announced in a `u32`.
pub fn put_header(out: &mut [u8], op: u8, req: u32, body_len: usize) -> Option<()> {
    let len = u32::try_from(body_len.checked_add(HEAD_AFTER_LEN)?).ok()?;
    let head = out.get_mut(..HEADER_LEN)?;
    head[..LEN_PREFIX].copy_from_slice(&len.to_le_bytes());
    head[LEN_PREFIX] = op;
    head[5..].copy_from_slice(&req.to_le_bytes());
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_needs_its_prefix_then_its_body() {
        assert_eq!(check(&[], 100), Ok(Check::Incomplete(HEADER_LEN)));
        assert_eq!(check(&[7, 0, 0], 100), Ok(Check::Incomplete(HEADER_LEN)));
        let mut frame = [0u8; 13];
        put_header(&mut frame, 3, 9, 2).expect("fits");
        frame[9..11].copy_from_slice(&[1, 2]);
        assert_eq!(check(&frame[..10], 100), Ok(Check::Incomplete(11)));
        assert_eq!(check(&frame, 100), Ok(Check::Complete(11)));
        assert_eq!(
            parse(&frame, 100),
            Ok(Parsed::Frame(
                RawFrame {
                    op: 3,
                    req: 9,
                    body: &[1, 2]
                },
                11
            ))
        );
    }

    #[test]
    fn impossible_lengths_are_errors_before_any_byte_of_the_body() {
        assert_eq!(check(&[4, 0, 0, 0], 100), Err(FrameError::TooShort(4)));
        assert_eq!(
            check(&[0xff, 0xff, 0xff, 0xff], 1024),
            Err(FrameError::TooLarge {
                len: 0xffff_ffff + 4,
                max: 1024
            })
        );
    }

    #[test]
    fn a_header_does_not_fit_a_short_buffer() {
        assert_eq!(put_header(&mut [0u8; 8], 1, 1, 0), None);
        let mut head = [0u8; HEADER_LEN];
        assert_eq!(put_header(&mut head, 0x87, 0x0102_0304, 0), Some(()));
        assert_eq!(head, [5, 0, 0, 0, 0x87, 4, 3, 2, 1]);
    }
}
