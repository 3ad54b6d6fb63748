//! The `Agent.avatar` publisher: one owner per channel, so the speaker (visemes, captions) and the behaviour
//! controllers (blink, gaze, listening) share this one handle. A leaf: it imports neither of them.

use std::sync::Arc;

use agent_contract::avatar::AvatarCommand;
use flow::Publisher;
use tracing::debug;

use super::wire;

/// The `Agent.avatar` publisher, shared by the speaker and the behaviour controllers (a channel has one owner).
#[derive(Debug, Clone)]
pub struct AvatarOut(pub Arc<Publisher>);

impl AvatarOut {
    pub async fn send(&self, command: &AvatarCommand) {
        if let Err(e) = self.0.publish(wire::avatar_json(command)).await {
            debug!("tts: avatar command not sent: {e}");
        }
    }

    /// Whether a page (or anyone) listens; the behaviour controllers rest while nobody does.
    pub fn watched(&self) -> tokio::sync::watch::Receiver<bool> {
        self.0.subscribers()
    }
}
