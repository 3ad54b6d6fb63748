//! flow-record: MCAP recording and replay of flow hub channels.
//!
//! [`Recorder`] subscribes to the channels a [`Selection`] matches (and to those that appear later) and writes
//! each hub channel as an MCAP channel of the same name, with its JSON header in the channel metadata
//! (`flow.header`): JSON as JSON, the agent's PCM as `foxglove.RawAudio`, camera JPEGs as
//! `foxglove.CompressedImage`, detections also as `foxglove.ImageAnnotations`, anything else as raw bytes.
//! [`Replayer`] publishes a recording again, byte for byte, on its recorded schedule. `flowctl record` and
//! `flowctl replay` use them; see docs/recording.md.

pub mod annotations;
pub mod contract_schemas;
pub mod encoding;
pub mod error;
pub mod lateness;
pub mod reader;
pub mod recorder;
pub mod replayer;
pub mod schemas;
pub mod select;
pub mod sink;
#[cfg(test)]
mod tests;

pub use error::RecordError;
pub use lateness::LatenessSummary;
pub use reader::{Entry, RecordedChannel, RecordedMessage, RecordingReader};
pub use recorder::{ChannelReport, RecordOptions, RecordReport, Recorder};
pub use replayer::{ReplayOptions, ReplayReport, Replayer};
pub use select::{Remap, Selection};
pub use sink::SinkOptions;
