//! The `Agent.recording` message: the recorder module's state, sent when it changes and every second while it
//! records, so the page shows whether the session is being recorded and into which file.

use serde::{Deserialize, Serialize};

/// The recorder's state.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RecordingState {
    pub recording: bool,
    /// The MCAP file being written, or the last one written once stopped (`None` before the first recording).
    pub file: Option<String>,
    /// When the current (or last) recording started (ms since the Unix epoch).
    pub started_ms: Option<u64>,
    /// Messages the last finished recording holds (0 while one is being written: the writer counts at the end).
    pub messages: u64,
    /// Why the last start or stop failed, if it did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}
