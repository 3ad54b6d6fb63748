//! Shared support for the integration tests: starting a real robot-agent on
//! free ports, running the workspace's binaries, raw protocol connections and
//! the shared fixtures.

pub mod agent;
pub mod binaries;
pub mod browser_chromium;
pub mod browser_link;
pub mod browser_media;
pub mod fixtures;
pub mod http;
pub mod metrics;
pub mod netns;
pub mod otlp;
pub mod raw;
pub mod recording;
pub mod satellite;
pub mod spoken;
pub mod wait;
pub mod wires;

pub use agent::{Agent, AgentOptions, DataDir};
pub use binaries::{binary, command, run, start_when_ready};
pub use fixtures::fixture;
pub use raw::RawConn;
pub use satellite::Satellite;
pub use wait::PATIENCE;

/// Where tests save screenshots and other files for people to look at (`artifacts/`, git-ignored).
pub fn artifacts_dir() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../artifacts")
}
pub use wait::{
    free_port, json_message, next_json, next_payload, recv, recv_until, until, until_channel,
    until_subscribed, until_subscribers, until_unsubscribed,
};
