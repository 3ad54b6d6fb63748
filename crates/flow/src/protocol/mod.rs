//! FlowProtocol: frames, messages and their binary encoding (no I/O here).
//!
//! The split follows the layers: [`frame`] finds frame boundaries in a byte
//! buffer, [`message`] defines the domain values, [`codec`] maps one to the
//! other. `docs/protocol.md` at the repository root shows every layout.

pub mod codec;
pub mod error;
pub mod frame;
pub mod message;

pub use codec::{decode_command, decode_event, encode_command, encode_event};
pub use error::{DecodeError, FrameError};
pub use frame::{Check, DEFAULT_MAX_FRAME, RawFrame};
pub use message::*;
