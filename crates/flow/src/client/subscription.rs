//! Receiving side of a subscription: a drop-oldest queue the client's reader fills.

use std::sync::Arc;

use super::core::Client;
use super::inbox::{Data, SubShared};
use crate::protocol::ChannelInfo;

/// A sticky subscription by channel name. Dropping it unsubscribes.
#[derive(Debug)]
pub struct Subscription {
    shared: Arc<SubShared>,
    client: Client,
}

impl Subscription {
    pub(super) fn new(shared: Arc<SubShared>, client: Client) -> Self {
        Subscription { shared, client }
    }

    /// The next message in order; `None` once the client has shut down.
    pub async fn recv(&self) -> Option<Data> {
        self.shared.queue.pop().await
    }

    /// The newest queued message, discarding older ones, with how many were
    /// skipped: for consumers that must never build a backlog (video).
    pub async fn recv_latest(&self) -> Option<(Data, usize)> {
        loop {
            if !self.shared.queue.wait().await {
                return None;
            }
            if let Some(latest) = self.shared.queue.pop_latest() {
                return Some(latest);
            }
        }
    }

    /// A queued message, without waiting.
    pub fn try_recv(&self) -> Option<Data> {
        self.shared.queue.try_pop()
    }

    /// Messages this subscription dropped locally because its reader fell behind.
    pub fn dropped(&self) -> u64 {
        self.shared.queue.dropped()
    }

    pub fn name(&self) -> &str {
        &self.shared.name
    }

    /// The subscription as an async stream of messages.
    pub fn into_stream(self) -> impl futures_util::Stream<Item = Data> + Send {
        futures_util::stream::unfold(self, |sub| async move {
            let next = sub.recv().await?;
            Some((next, sub))
        })
    }

    /// Calls `on_data` for every message on a task of its own, until the client
    /// shuts down or the returned handle is aborted (which unsubscribes).
    pub fn spawn_callback<F>(self, mut on_data: F) -> tokio::task::JoinHandle<()>
    where
        F: FnMut(Data) + Send + 'static,
    {
        tokio::spawn(async move {
            while let Some(data) = self.recv().await {
                on_data(data);
            }
        })
    }

    /// The channel's properties as of the last (re)subscription, header included.
    pub fn info(&self) -> Option<ChannelInfo> {
        self.shared.info()
    }
}

impl Drop for Subscription {
    fn drop(&mut self) {
        self.client.release_subscription(&self.shared);
    }
}
