//! Waiting on hub events with the tests' generous bound, failing with a clear
//! message instead of hanging.

use anyhow::Context;
use flow::{Data, Publisher, Subscription};

/// A generous bound for anything a test waits on: the machine may be busy
/// building other crates, and tests never assert on durations.
pub const PATIENCE: std::time::Duration = std::time::Duration::from_secs(30);

/// The next message of a subscription, or an error after [`PATIENCE`].
pub async fn recv(sub: &Subscription) -> anyhow::Result<Data> {
    tokio::time::timeout(PATIENCE, sub.recv())
        .await
        .with_context(|| format!("no message on {} in time", sub.name()))?
        .context("subscription ended")
}

/// Waits until the hub tells `publisher` that someone subscribes to its channel.
pub async fn until_subscribed(publisher: &Publisher) -> anyhow::Result<()> {
    let mut watch = publisher.subscribers();
    tokio::time::timeout(PATIENCE, watch.wait_for(|on| *on))
        .await
        .with_context(|| format!("nobody subscribed to {} in time", publisher.name()))?
        .context("client closed")?;
    Ok(())
}

/// Waits until the last subscriber of `publisher`'s channel has left.
pub async fn until_unsubscribed(publisher: &Publisher) -> anyhow::Result<()> {
    let mut watch = publisher.subscribers();
    tokio::time::timeout(PATIENCE, watch.wait_for(|on| !*on))
        .await
        .with_context(|| format!("{} kept its subscribers", publisher.name()))?
        .context("client closed")?;
    Ok(())
}

/// The next payload of a subscription, unbounded: for loops that wait on several subscriptions inside a timeout of
/// their own.
pub async fn next_payload(sub: &Subscription) -> anyhow::Result<bytes::Bytes> {
    Ok(sub
        .recv()
        .await
        .with_context(|| format!("{} ended", sub.name()))?
        .payload)
}

/// A payload read as JSON, if it is JSON.
pub fn json_message(payload: &[u8]) -> Option<serde_json::Value> {
    serde_json::from_slice(payload).ok()
}

/// Waits until `name` exists on the hub of `client` (made there by a satellite or imported from another hub), and
/// returns its header; `patience` bounds the wait.
pub async fn until_channel(
    client: &flow::Client,
    name: &str,
    patience: std::time::Duration,
) -> anyhow::Result<String> {
    tokio::time::timeout(patience, async {
        loop {
            if let Ok(info) = client.channel(name).await {
                return info.header;
            }
            tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        }
    })
    .await
    .with_context(|| format!("{name} did not appear"))
}

/// A free TCP port on loopback, for a listener a test configures (a Zenoh endpoint): bound and released, so the
/// process it is handed to binds it again at once.
pub fn free_port() -> anyhow::Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port())
}
