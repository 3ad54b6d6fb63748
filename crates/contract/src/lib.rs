//! The agent's contract: every `Agent.*` channel's name, kind and header ([`channels`]) and the messages they carry
//! ([`detections`], [`avatar`]), in one place that every producer and consumer uses. The page is held to the same shapes by the
//! JSON test vectors in `crates/contract/vectors/`, which a test here writes from these types and the page's `node --test`
//! suites read (`web/test/`).

pub mod acquaintance;
pub mod avatar;
pub mod channels;
pub mod chat;
pub mod ctrl;
pub mod detections;
pub mod latency;
pub mod link;
pub mod recording;
pub mod rules;
pub mod say;
pub mod spectrum;
pub mod transcript;
pub mod vectors;

pub use channels::{Channel, Kind};
