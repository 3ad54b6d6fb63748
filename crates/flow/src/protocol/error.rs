//! Errors raised while cutting frames and decoding messages.

use thiserror::Error;

/// The byte stream cannot be cut into frames any more; the connection must close.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum FrameError {
    #[error("frame length {0} is shorter than the 5-byte header")]
    TooShort(usize),
    #[error("frame of {len} bytes exceeds the maximum of {max}")]
    TooLarge { len: usize, max: usize },
}

/// A complete frame whose contents do not form a valid message.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum DecodeError {
    #[error("unknown opcode 0x{0:02x}")]
    UnknownOp(u8),
    #[error("truncated body while reading {0}")]
    Truncated(&'static str),
    #[error("{0} trailing bytes after the message")]
    Trailing(usize),
    #[error("invalid UTF-8 in {0}")]
    Utf8(&'static str),
    #[error("invalid value for {field}: {value}")]
    BadValue { field: &'static str, value: i64 },
    #[error("invalid {field}: {reason}")]
    Invalid {
        field: &'static str,
        reason: &'static str,
    },
}
