//! The hub modes: one publisher and N subscribers, each its own `flow::Client` connection to the `flow-hub`
//! process, over its Unix socket (`shm`: where the SDK negotiates the shared-memory data path) or over TCP
//! (`hub-tcp`). Subscribers are tasks of this process; each touches what it receives through [`Tally::record`].

use std::sync::Arc;

use anyhow::Context;
use bytes::Bytes;
use flow::{Client, ConnectOptions, FlowAddr, Publisher};
use tokio::task::JoinHandle;

use crate::stamp;
use crate::tally::Tally;

/// A publisher with its subscribers connected and subscribed.
#[derive(Debug)]
pub struct FlowRig {
    client: Client,
    publisher: Publisher,
    subscribers: Vec<JoinHandle<()>>,
    clients: Vec<Client>,
}

fn options(name: &str, token: &str, ring: bool) -> ConnectOptions {
    let mut opts = ConnectOptions::new(name, token);
    opts.reconnect = false;
    opts.release_ring = ring;
    // Far above the publisher's window, so that a subscriber's own drop-oldest queue never drops.
    opts.queue = 1024;
    opts
}

/// Connects a publisher of `channel` and `n` subscribers at `addr` (giving slots back through the hub's release ring
/// if `ring`); returns once every subscription is in place.
pub async fn connect(
    addr: &FlowAddr,
    token: &str,
    channel: &str,
    n: usize,
    ring: bool,
    tally: Arc<Tally>,
) -> anyhow::Result<FlowRig> {
    let client = Client::connect(addr, options("shm-bench-pub", token, ring))
        .await
        .with_context(|| format!("publisher connecting to flow-hub at {addr}"))?;
    let publisher = client
        .publisher(channel, r#"{"mime":"application/octet-stream"}"#)
        .await?;
    let mut clients = Vec::new();
    let mut subscribers = Vec::new();
    for i in 0..n {
        let sub_client = Client::connect(addr, options(&format!("shm-bench-sub-{i}"), token, ring))
            .await
            .with_context(|| format!("subscriber connecting to flow-hub at {addr}"))?;
        let sub = sub_client.subscribe(channel).await?;
        let tally = tally.clone();
        subscribers.push(tokio::spawn(async move {
            while let Some(data) = sub.recv().await {
                tally.record(i, &data.payload);
            }
            tally.end(i);
        }));
        clients.push(sub_client);
    }
    Ok(FlowRig {
        client,
        publisher,
        subscribers,
        clients,
    })
}

impl FlowRig {
    /// Publishes a stamped copy of `template`: the frame a producer makes. Where the link has shared memory it is
    /// made in place in a loaned slot (`Publisher::loan`, as iceoryx2's publisher loans its slice); otherwise, or
    /// while every slot is held, it is handed to the SDK as `Bytes`, as any satellite does.
    pub async fn send(&mut self, template: &[u8], seq: u64) -> anyhow::Result<()> {
        if let Some(mut loan) = self.publisher.loan(template.len()) {
            let frame = loan.as_mut_slice();
            frame.copy_from_slice(template);
            stamp::write(frame, seq);
            loan.publish().await?;
            return Ok(());
        }
        let mut payload = template.to_vec();
        stamp::write(&mut payload, seq);
        self.publisher.publish(Bytes::from(payload)).await?;
        Ok(())
    }

    /// Disconnects everyone.
    pub fn close(self) {
        for task in &self.subscribers {
            task.abort();
        }
        for client in &self.clients {
            client.close();
        }
        drop(self.publisher);
        self.client.close();
    }
}

/// Shared-memory file mappings (`memfd:`) in this process now: above zero once the SDK maps the hub's segments,
/// which shows whether the `shm` mode really took the shared-memory path or ran over bytes on the socket.
pub fn memfd_mappings() -> usize {
    std::fs::read_to_string("/proc/self/maps")
        .map(|maps| maps.lines().filter(|l| l.contains("/memfd:")).count())
        .unwrap_or(0)
}
