//! Export: the local channels that match `[federation] export`, offered to the Zenoh network.
//!
//! Each exported channel gets a liveliness token (its announcement) and, for a stream, a Zenoh publisher whose
//! matching listener says whether anyone anywhere listens: only then does the exporter subscribe on its own hub,
//! so the producer's first/last-subscriber events follow the listeners of every hub. A service gets a queryable
//! whose queries become local calls. Channels this module owns (its imports) are never exported, so that hubs do
//! not echo each other's channels back.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use flow::client::ClientEvent;
use flow::{ChannelInfo, ChannelKind};
use tokio::sync::broadcast::error::RecvError;
use tokio::task::JoinHandle;
use tracing::{debug, info, warn};
use zenoh::qos::CongestionControl;

use super::link::{Counted, Link, lock, selected};
use super::remote_error::RemoteError;
use super::stamp::Stamp;
use crate::zenoh_names::check_literal;

/// The headers of the exported channels, which the header queryable answers from.
type Headers = Arc<Mutex<HashMap<String, String>>>;

/// Follows the local channels and exports those that match, until aborted.
pub(super) async fn run(link: Arc<Link>, globs: Vec<glob::Pattern>) {
    if globs.is_empty() {
        return;
    }
    let headers: Headers = Arc::default();
    let _header_queryable = match header_queryable(&link, headers.clone()).await {
        Ok(q) => q,
        Err(e) => {
            warn!("federation: cannot answer header queries, exporting nothing: {e}");
            return;
        }
    };
    let mut exports: HashMap<String, JoinHandle<()>> = HashMap::new();
    // Events first, then the list: a channel added in between is seen twice, never missed.
    let mut events = link.client.events();
    let mut resync = true;
    loop {
        if resync {
            resync = false;
            match link.client.channels().await {
                Ok(list) => {
                    let present: Vec<String> = list.iter().map(|c| c.name.clone()).collect();
                    exports.retain(|name, task| {
                        let keep = present.contains(name);
                        if !keep {
                            task.abort();
                        }
                        keep
                    });
                    for info in list {
                        consider(&link, &globs, &headers, &mut exports, info);
                    }
                }
                Err(e) => warn!("federation: listing the hub's channels: {e}"),
            }
        }
        match events.recv().await {
            Ok(ClientEvent::ChannelAdded(info)) => {
                consider(&link, &globs, &headers, &mut exports, info);
            }
            Ok(ClientEvent::ChannelRemoved { name, .. }) => {
                if let Some(task) = exports.remove(&name) {
                    info!(channel = %name, "federation: export withdrawn (the channel is gone)");
                    task.abort();
                    lock(&headers).remove(&name);
                }
            }
            Ok(ClientEvent::HeaderChanged { name, header, .. }) => {
                if exports.contains_key(&name) {
                    lock(&headers).insert(name.clone(), header.clone());
                    let key = link.keys.header(&link.hub, &name);
                    if let Err(e) = link.session.put(key, header).await {
                        warn!(channel = %name, "federation: announcing a new header: {e}");
                    }
                }
            }
            Ok(_) => {}
            Err(RecvError::Lagged(_)) => resync = true,
            Err(RecvError::Closed) => break,
        }
    }
    for (_, task) in exports {
        task.abort();
    }
}

fn consider(
    link: &Arc<Link>,
    globs: &[glob::Pattern],
    headers: &Headers,
    exports: &mut HashMap<String, JoinHandle<()>>,
    info: ChannelInfo,
) {
    if info.owner == link.me || exports.contains_key(&info.name) || !selected(globs, &info.name) {
        return;
    }
    if let Err(e) = check_literal(&info.name) {
        warn!(channel = %info.name, "federation: not exported: {e}");
        return;
    }
    info!(channel = %info.name, kind = ?info.kind, "federation: exporting");
    lock(headers).insert(info.name.clone(), info.header.clone());
    let task = match info.kind {
        ChannelKind::Stream => tokio::spawn(stream(link.clone(), info.name.clone())),
        ChannelKind::Service => tokio::spawn(service(link.clone(), info.name.clone())),
    };
    exports.insert(info.name, task);
}

/// Answers `<prefix>/@header/<hub>/<channel>` from the exported channels' headers.
async fn header_queryable(
    link: &Arc<Link>,
    headers: Headers,
) -> zenoh::Result<zenoh::query::Queryable<()>> {
    let keys = link.keys.clone();
    link.session
        .declare_queryable(keys.headers_of(&link.hub))
        .callback(move |query| {
            let Some((_, channel)) = keys.parse_header(query.key_expr().as_str()) else {
                return;
            };
            let header = lock(&headers).get(&channel).cloned();
            if let Some(header) = header {
                let key = query.key_expr().clone();
                tokio::spawn(async move {
                    if let Err(e) = query.reply(key, header).await {
                        debug!("federation: header reply: {e}");
                    }
                });
            }
        })
        .await
}

/// One exported stream: announce it, and forward it while anyone on the network listens.
async fn stream(link: Arc<Link>, name: String) {
    let _counted = Counted::new(&link.counters.exports);
    if let Err(e) = forward_stream(&link, &name).await {
        warn!(channel = %name, "federation: export stopped: {e}");
    }
}

async fn forward_stream(link: &Link, name: &str) -> anyhow::Result<()> {
    let key = link.keys.data(&link.hub, name);
    // Streams are best effort: when the network backs up, Zenoh drops the sample rather than block this task,
    // and the local subscription below is a drop-oldest queue, so the producer never waits for another hub.
    // Express: each sample leaves at once instead of waiting to be batched with others; a robot's streams are
    // few and latency-bound (a camera frame, 20 ms of sound), not a flood of tiny messages.
    let publisher = link
        .session
        .declare_publisher(key)
        .congestion_control(CongestionControl::Drop)
        .express(true)
        .await
        .map_err(|e| anyhow::anyhow!("declaring the publisher: {e}"))?;
    let matching = publisher
        .matching_listener()
        .await
        .map_err(|e| anyhow::anyhow!("declaring the matching listener: {e}"))?;
    let _token = link
        .session
        .liveliness()
        .declare_token(link.keys.token(&link.hub, ChannelKind::Stream, name))
        .await
        .map_err(|e| anyhow::anyhow!("declaring the liveliness token: {e}"))?;
    let mut listened = publisher
        .matching_status()
        .await
        .map_err(|e| anyhow::anyhow!("reading the matching status: {e}"))?
        .matching();
    loop {
        if !listened {
            match matching.recv_async().await {
                Ok(status) => listened = status.matching(),
                Err(_) => return Ok(()),
            }
            continue;
        }
        debug!(channel = %name, "federation: a remote listener appeared, subscribing here");
        let sub = link.client.subscribe(name).await?;
        loop {
            tokio::select! {
                status = matching.recv_async() => match status {
                    Ok(s) if s.matching() => {}
                    Ok(_) => { listened = false; break; }
                    Err(_) => return Ok(()),
                },
                data = sub.recv() => {
                    let Some(data) = data else { return Ok(()) };
                    let stamp = Stamp { seq: data.seq, ts_us: data.ts_us }.encode();
                    publisher
                        .put(data.payload)
                        .attachment(&stamp[..])
                        .await
                        .map_err(|e| anyhow::anyhow!("putting a sample: {e}"))?;
                    link.counters.sent.inc();
                }
            }
        }
        debug!(channel = %name, "federation: the last remote listener left, unsubscribing here");
        drop(sub);
    }
}

/// One exported service: announce it and turn each Zenoh query into a local call.
async fn service(link: Arc<Link>, name: String) {
    let _counted = Counted::new(&link.counters.exports);
    if let Err(e) = answer_queries(&link, &name).await {
        warn!(channel = %name, "federation: export stopped: {e}");
    }
}

async fn answer_queries(link: &Arc<Link>, name: &str) -> anyhow::Result<()> {
    let queryable = link
        .session
        .declare_queryable(link.keys.data(&link.hub, name))
        .await
        .map_err(|e| anyhow::anyhow!("declaring the queryable: {e}"))?;
    let _token = link
        .session
        .liveliness()
        .declare_token(link.keys.token(&link.hub, ChannelKind::Service, name))
        .await
        .map_err(|e| anyhow::anyhow!("declaring the liveliness token: {e}"))?;
    while let Ok(query) = queryable.recv_async().await {
        let link = link.clone();
        let name = name.to_string();
        link.counters.calls_in.inc();
        tokio::spawn(async move {
            let payload = query
                .payload()
                .map(|p| bytes::Bytes::from(p.to_bytes().into_owned()))
                .unwrap_or_default();
            let result = link.client.call(&name, payload, link.call_timeout).await;
            let sent = match result {
                Ok(answer) => query.reply(query.key_expr().clone(), answer).await,
                Err(e) => query.reply_err(RemoteError::from_flow(&e).to_json()).await,
            };
            if let Err(e) = sent {
                debug!(channel = %name, "federation: replying to a remote call: {e}");
            }
        });
    }
    Ok(())
}
