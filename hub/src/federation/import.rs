//! Import: remote channels that match `[federation] import`, made local channels that this module owns.
//!
//! The liveliness tokens of every hub say which channels exist where. For each matching name one import is in
//! force at a time (the first announcing hub in name order; another takes over when it leaves). An imported stream
//! declares its Zenoh subscriber only while the local channel has subscribers; an imported service turns each local
//! call into a Zenoh query. A remote channel whose name is already taken here is not imported until the local one
//! goes away.

use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use bytes::Bytes;
use flow::client::ClientEvent;
use flow::queue::DropOldest;
use flow::{ChannelKind, ErrorCode, FlowError};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tracing::{debug, info, warn};
use zenoh::sample::SampleKind;

use super::link::{Counted, Link, lock, selected};
use super::remote_error::RemoteError;
use super::stamp::{GapCounter, Stamp};

/// Why an import task ended.
#[derive(Debug)]
enum Ended {
    /// A local channel already has the name; retried when it is removed.
    Blocked,
    /// The remote service's owner left; the import waits for the announcement to change.
    Gone,
    /// Anything else; retried after a second.
    Failed(String),
}

/// Messages to the import manager from its tasks.
#[derive(Debug)]
enum Note {
    Ended {
        channel: String,
        hub: String,
        why: Ended,
    },
    Retry(String),
}

struct Active {
    hub: String,
    task: JoinHandle<()>,
    headers: mpsc::Sender<String>,
}

/// Follows the federation's announcements and keeps the matching imports in force, until aborted.
pub(super) async fn run(link: Arc<Link>, globs: Vec<glob::Pattern>) {
    if globs.is_empty() {
        return;
    }
    if let Err(e) = manage(link, globs).await {
        warn!("federation: importing stopped: {e}");
    }
}

async fn manage(link: Arc<Link>, globs: Vec<glob::Pattern>) -> anyhow::Result<()> {
    let tokens = link
        .session
        .liveliness()
        .declare_subscriber(link.keys.all_tokens())
        .history(true)
        .await
        .map_err(|e| anyhow::anyhow!("subscribing to announcements: {e}"))?;
    let header_changes = link
        .session
        .declare_subscriber(link.keys.all_headers())
        .await
        .map_err(|e| anyhow::anyhow!("subscribing to header changes: {e}"))?;
    let mut events = link.client.events();
    // Bounded by the number of imports (each task sends one note when it ends); retries are one per name.
    let (notes_tx, mut notes) = mpsc::channel::<Note>(256);
    let mut offers: HashMap<String, BTreeMap<String, ChannelKind>> = HashMap::new();
    let mut active: HashMap<String, Active> = HashMap::new();
    let ensure = |name: &str,
                  offers: &HashMap<String, BTreeMap<String, ChannelKind>>,
                  active: &mut HashMap<String, Active>| {
        if active.contains_key(name) {
            return;
        }
        let Some((hub, kind)) = offers.get(name).and_then(|o| o.iter().next()) else {
            return;
        };
        let (headers_tx, headers_rx) = mpsc::channel(8);
        let task = tokio::spawn(import(
            link.clone(),
            hub.clone(),
            *kind,
            name.to_string(),
            headers_rx,
            notes_tx.clone(),
        ));
        active.insert(
            name.to_string(),
            Active {
                hub: hub.clone(),
                task,
                headers: headers_tx,
            },
        );
    };
    loop {
        tokio::select! {
            sample = tokens.recv_async() => {
                let Ok(sample) = sample else { break };
                let Some(a) = link.keys.parse_token(sample.key_expr().as_str()) else { continue };
                if a.hub == link.hub || !selected(&globs, &a.channel) {
                    continue;
                }
                match sample.kind() {
                    SampleKind::Put => {
                        debug!(hub = %a.hub, channel = %a.channel, "federation: announced");
                        offers.entry(a.channel.clone()).or_default().insert(a.hub, a.kind);
                        ensure(&a.channel, &offers, &mut active);
                    }
                    SampleKind::Delete => {
                        debug!(hub = %a.hub, channel = %a.channel, "federation: withdrawn");
                        if let Some(o) = offers.get_mut(&a.channel) {
                            o.remove(&a.hub);
                            if o.is_empty() {
                                offers.remove(&a.channel);
                            }
                        }
                        if active.get(&a.channel).is_some_and(|x| x.hub == a.hub) {
                            if let Some(x) = active.remove(&a.channel) {
                                info!(hub = %a.hub, channel = %a.channel, "federation: import removed (the remote channel is gone)");
                                x.task.abort();
                            }
                            ensure(&a.channel, &offers, &mut active);
                        }
                    }
                }
            }
            sample = header_changes.recv_async() => {
                let Ok(sample) = sample else { break };
                let Some((hub, channel)) = link.keys.parse_header(sample.key_expr().as_str()) else { continue };
                if let Some(x) = active.get(&channel).filter(|x| x.hub == hub) {
                    let header = String::from_utf8_lossy(&sample.payload().to_bytes()).into_owned();
                    let _ = x.headers.try_send(header);
                }
            }
            event = events.recv() => match event {
                Ok(ClientEvent::ChannelRemoved { name, .. }) => ensure(&name, &offers, &mut active),
                Ok(_) => {}
                Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => {
                    let names: Vec<String> = offers.keys().cloned().collect();
                    for name in names {
                        ensure(&name, &offers, &mut active);
                    }
                }
                Err(tokio::sync::broadcast::error::RecvError::Closed) => break,
            },
            note = notes.recv() => match note {
                Some(Note::Ended { channel, hub, why }) => {
                    if active.get(&channel).is_some_and(|x| x.hub == hub) {
                        active.remove(&channel);
                    }
                    let delay = match why {
                        Ended::Blocked => {
                            info!(%hub, %channel, "federation: not imported, a local channel has the name");
                            None
                        }
                        Ended::Gone => Some(link.lease),
                        Ended::Failed(e) => {
                            warn!(%hub, %channel, "federation: import failed: {e}");
                            Some(Duration::from_secs(1))
                        }
                    };
                    if let Some(delay) = delay {
                        let tx = notes_tx.clone();
                        tokio::spawn(async move {
                            tokio::time::sleep(delay).await;
                            let _ = tx.send(Note::Retry(channel)).await;
                        });
                    }
                }
                Some(Note::Retry(channel)) => ensure(&channel, &offers, &mut active),
                None => break,
            },
        }
    }
    for (_, x) in active {
        x.task.abort();
    }
    Ok(())
}

async fn import(
    link: Arc<Link>,
    hub: String,
    kind: ChannelKind,
    channel: String,
    headers: mpsc::Receiver<String>,
    notes: mpsc::Sender<Note>,
) {
    let why = match kind {
        ChannelKind::Stream => import_stream(&link, &hub, &channel, headers).await,
        ChannelKind::Service => import_service(&link, &hub, &channel).await,
    };
    let _ = notes.send(Note::Ended { channel, hub, why }).await;
}

/// The remote channel's header, or `{}` when its hub does not answer (a plain Zenoh client announcing a stream).
async fn fetch_header(link: &Link, hub: &str, channel: &str) -> String {
    let replies = link
        .session
        .get(link.keys.header(hub, channel))
        .timeout(Duration::from_secs(2))
        .await;
    if let Ok(replies) = replies {
        while let Ok(reply) = replies.recv_async().await {
            if let Ok(sample) = reply.result() {
                let text = String::from_utf8_lossy(&sample.payload().to_bytes()).into_owned();
                if serde_json::from_str::<serde_json::Value>(&text).is_ok_and(|v| v.is_object()) {
                    return text;
                }
            }
        }
    }
    "{}".to_string()
}

fn blocked_or_failed(e: FlowError) -> Ended {
    if e.code() == Some(ErrorCode::Exists) {
        Ended::Blocked
    } else {
        Ended::Failed(e.to_string())
    }
}

async fn import_stream(
    link: &Arc<Link>,
    hub: &str,
    channel: &str,
    mut headers: mpsc::Receiver<String>,
) -> Ended {
    let header = fetch_header(link, hub, channel).await;
    let publisher = match link.client.publisher(channel, &header).await {
        Ok(p) => p,
        Err(e) => return blocked_or_failed(e),
    };
    info!(%hub, %channel, "federation: imported stream");
    let _counted = Counted::new(&link.counters.imports);
    let mut listening = publisher.subscribers();
    let key = link.keys.data(hub, channel);
    loop {
        while !*listening.borrow() {
            tokio::select! {
                changed = listening.changed() => if changed.is_err() {
                    return Ended::Failed("the hub link closed".into());
                },
                Some(h) = headers.recv() => { let _ = publisher.set_header(&h).await; }
            }
        }
        debug!(%hub, %channel, "federation: local listeners, subscribing on the network");
        // Drop-oldest between the network and the local hub: a slow hub loses the oldest messages, counted, and
        // Zenoh's reader is never held up.
        let queue = Arc::new(DropOldest::<Bytes>::new(link.queue));
        let gaps = Arc::new(Mutex::new(GapCounter::default()));
        let sub = {
            let queue = queue.clone();
            let link = link.clone();
            link.session
                .clone()
                .declare_subscriber(key.clone())
                .callback(move |sample| {
                    if let Some(stamp) = sample
                        .attachment()
                        .and_then(|a| Stamp::decode(&a.to_bytes()).ok())
                    {
                        let mut g = lock(&gaps);
                        let before = g.lost;
                        g.note(stamp.seq);
                        link.counters.lost_between_hubs.inc_by(g.lost - before);
                    }
                    let payload = super::payload::received(sample.payload());
                    if queue.push(payload) {
                        link.counters.dropped_here.inc();
                    }
                })
                .await
        };
        let sub = match sub {
            Ok(s) => s,
            Err(e) => return Ended::Failed(format!("subscribing to {key}: {e}")),
        };
        loop {
            tokio::select! {
                changed = listening.changed() => {
                    if changed.is_err() {
                        return Ended::Failed("the hub link closed".into());
                    }
                    if !*listening.borrow() {
                        break;
                    }
                }
                payload = queue.pop() => {
                    let Some(payload) = payload else { break };
                    if let Err(e) = publisher.publish(payload).await {
                        return Ended::Failed(format!("publishing here: {e}"));
                    }
                    link.counters.received.inc();
                }
                Some(h) = headers.recv() => { let _ = publisher.set_header(&h).await; }
            }
        }
        debug!(%hub, %channel, "federation: no local listener left, unsubscribing on the network");
        queue.close();
        if let Err(e) = sub.undeclare().await {
            debug!("federation: undeclaring {key}: {e}");
        }
    }
}

async fn import_service(link: &Arc<Link>, hub: &str, channel: &str) -> Ended {
    let header = fetch_header(link, hub, channel).await;
    let mut service = match link.client.serve(channel, &header).await {
        Ok(s) => s,
        Err(e) => return blocked_or_failed(e),
    };
    info!(%hub, %channel, "federation: imported service");
    let _counted = Counted::new(&link.counters.imports);
    let key = link.keys.data(hub, channel);
    // A call whose remote owner turned out to be gone ends the import, so that the hub answers every caller
    // waiting on it `ServiceGone`, as it does when a local owner leaves.
    let (gone_tx, mut gone) = mpsc::channel::<()>(1);
    loop {
        tokio::select! {
            call = service.next() => {
                let Some(call) = call else { return Ended::Failed("the hub link closed".into()) };
                link.counters.calls_out.inc();
                let link = link.clone();
                let key = key.clone();
                let gone_tx = gone_tx.clone();
                tokio::spawn(async move {
                    match remote_call(&link, &key, call.payload.clone()).await {
                        Ok(answer) => { let _ = call.respond(Ok(answer)).await; }
                        Err(e) if e.is_gone() => {
                            // The channel goes first (callers get ServiceGone); this call's own answer is then
                            // for a call the hub has already ended, and it ignores it.
                            let _ = gone_tx.try_send(());
                            tokio::time::sleep(Duration::from_millis(200)).await;
                            let _ = call.respond(Err(e.to_string())).await;
                        }
                        Err(e) => { let _ = call.respond(Err(e.to_string())).await; }
                    }
                });
            }
            _ = gone.recv() => {
                info!(%hub, %channel, "federation: the remote service's owner left");
                return Ended::Gone;
            }
        }
    }
}

/// One query to the exporting hub's queryable: its answer, or why there is none.
async fn remote_call(link: &Link, key: &str, payload: Bytes) -> Result<Bytes, RemoteError> {
    let started = std::time::Instant::now();
    let replies = link
        .session
        .get(key)
        .payload(payload)
        .timeout(link.call_timeout)
        .await
        .map_err(|e| RemoteError {
            code: "Other".into(),
            message: format!("querying {key}: {e}"),
        })?;
    match replies.recv_async().await {
        Ok(reply) => match reply.into_result() {
            Ok(sample) => Ok(Bytes::from(sample.payload().to_bytes().into_owned())),
            Err(err) => Err(RemoteError::parse(&err.payload().to_bytes())),
        },
        // No reply within the timeout: the remote service is slow.
        Err(_) if started.elapsed() >= link.call_timeout => Err(RemoteError {
            code: format!("{:?}", ErrorCode::Timeout),
            message: format!("no answer from {key} within {:?}", link.call_timeout),
        }),
        // No reply, before the timeout: nobody answers on that key any more (its hub left).
        Err(_) => Err(RemoteError {
            code: format!("{:?}", ErrorCode::ServiceGone),
            message: format!("no hub answers {key}"),
        }),
    }
}
