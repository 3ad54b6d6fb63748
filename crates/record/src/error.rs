//! The errors of recording and replay.

use flow::FlowError;

/// Why a recording or a replay failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("{path}: {source}")]
    File {
        path: String,
        source: std::io::Error,
    },
    #[error("MCAP: {0}")]
    Mcap(#[from] mcap::McapError),
    #[error("hub: {0}")]
    Flow(#[from] FlowError),
    #[error("JSON: {0}")]
    Json(#[from] serde_json::Error),
    #[error("bad channel pattern {pattern:?}: {reason}")]
    Pattern { pattern: String, reason: String },
    #[error("bad remap {0:?}: expected OLD=NEW")]
    Remap(String),
    #[error("a recorded message does not decode: {0}")]
    Form(String),
    #[error("the recording's writer stopped: {0}")]
    Writer(String),
    /// Writing failed mid-recording (a full disk): the file was cut back to its last whole chunk and ended there,
    /// so it opens with the `kept` messages written before.
    #[error(
        "writing {path} failed ({reason}); the file ends cleanly after the {kept} messages written before"
    )]
    Interrupted {
        path: String,
        reason: String,
        kept: u64,
    },
    #[error("{0} is not an MCAP recording (or is cut before its first record)")]
    NotMcap(String),
}

impl RecordError {
    pub(crate) fn file(path: &std::path::Path, source: std::io::Error) -> RecordError {
        RecordError::File {
            path: path.display().to_string(),
            source,
        }
    }
}
