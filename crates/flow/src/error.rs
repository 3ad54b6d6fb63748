//! The SDK's error type.

use thiserror::Error;

use crate::protocol::{DecodeError, ErrorCode, ErrorReply};

/// Anything that can go wrong talking to a hub.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FlowError {
    /// The hub refused the command; the code says why.
    #[error("hub refused: {0}")]
    Hub(ErrorReply),
    #[error("connection failed: {0}")]
    Connect(String),
    #[error("connection lost: {0}")]
    Disconnected(String),
    #[error("no reply within {0:?}")]
    Timeout(std::time::Duration),
    #[error("protocol violation from the hub: {0}")]
    Protocol(String),
    #[error("unexpected reply to {0}")]
    UnexpectedReply(&'static str),
    #[error("the client was closed")]
    Closed,
    #[error("channel {0} is not available on the hub right now")]
    NotReady(String),
    #[error("invalid JSON: {0}")]
    Json(String),
}

impl FlowError {
    /// The hub's error code, when the hub refused the command.
    pub fn code(&self) -> Option<ErrorCode> {
        match self {
            FlowError::Hub(e) => Some(e.code),
            _ => None,
        }
    }
}

impl From<DecodeError> for FlowError {
    fn from(e: DecodeError) -> Self {
        FlowError::Protocol(e.to_string())
    }
}
