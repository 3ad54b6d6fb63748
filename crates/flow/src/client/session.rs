//! The client's background task: handshake, the read and write loops, event
//! dispatch, and reconnection with state restore.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use tokio::sync::mpsc;
use tracing::{debug, info, warn};

use super::core::{Client, Hook, Inner};
use super::frame::{OutFrame, encode};
use super::inbox::Data;
use super::options::{ClientEvent, SessionInfo};
use super::shm::ShmSession;
use crate::connection::{Connection, FrameReader, FrameWriter};
use crate::error::FlowError;
use crate::protocol::{ChanRef, Command, ErrorCode, Event, PROTOCOL_VERSION, Reply, decode_event};
use crate::queue::lock;
use crate::transport::{Link, LinkReader, LinkWriter};

/// A logged-in connection ready for the loops.
pub(super) struct Established {
    reader: FrameReader<LinkReader>,
    writer: FrameWriter<LinkWriter>,
    /// The session's shared memory, when the link is a Unix socket and the hub accepted it.
    shm: Option<Arc<ShmSession>>,
}

/// Logs in (and switches to async) over a fresh link, synchronously, before
/// any loop runs.
pub(super) async fn establish(inner: &Arc<Inner>, link: Link) -> Result<Established, FlowError> {
    let unix = matches!(link, Link::Unix(_));
    let Connection {
        mut reader,
        mut writer,
        peer,
    } = Connection::new(link, inner.opts.max_frame);
    let login = Command::Login {
        version: PROTOCOL_VERSION,
        token: inner.opts.token.clone(),
        name: inner.opts.name.clone(),
    };
    let reply = handshake_step(&mut reader, &mut writer, 1, login).await?;
    let Reply::LoginOk {
        conn,
        admin,
        server,
        ..
    } = reply
    else {
        return Err(FlowError::UnexpectedReply("login"));
    };
    if inner.opts.asynchronous {
        handshake_step(&mut reader, &mut writer, 2, Command::SetAsync).await?;
    }
    // Shared memory needs descriptors passed over the socket and events flowing (segments, data by reference).
    let mut shm = None;
    if unix && inner.opts.asynchronous && inner.opts.shm {
        match handshake_step(&mut reader, &mut writer, 3, Command::ShmAccept).await {
            Ok(Reply::Shm { threshold }) => {
                shm = Some(Arc::new(ShmSession::new(
                    threshold,
                    inner.shm_spilled.clone(),
                    inner.opts.release_ring,
                )));
            }
            Ok(_) => return Err(FlowError::UnexpectedReply("shared memory")),
            // A hub without shared memory (turned off, or older): payloads go as bytes.
            Err(FlowError::Hub(e)) => debug!(%peer, "no shared memory: {e}"),
            Err(e) => return Err(e),
        }
    }
    debug!(%peer, conn, shm = shm.is_some(), "logged in to {server}");
    // Known from now on, before the session's loops start (the client's owner may ask at once).
    *lock(&inner.shm) = shm.clone();
    lock(&inner.state).session = Some(SessionInfo {
        conn,
        admin,
        server,
    });
    Ok(Established {
        reader,
        writer,
        shm,
    })
}

async fn handshake_step(
    reader: &mut FrameReader<LinkReader>,
    writer: &mut FrameWriter<LinkWriter>,
    req: u32,
    command: Command,
) -> Result<Reply, FlowError> {
    encode(req, command).queue_on(writer);
    writer
        .flush()
        .await
        .map_err(|e| FlowError::Connect(e.to_string()))?;
    let wait = async {
        loop {
            let frame = reader
                .read_frame()
                .await
                .map_err(|e| FlowError::Connect(e.to_string()))?
                .ok_or_else(|| {
                    FlowError::Connect("hub closed the connection during login".into())
                })?;
            match decode_event(frame)? {
                Event::Reply { req: r, result } if r == req => {
                    return result.map_err(FlowError::Hub);
                }
                Event::Goodbye { reason } => return Err(FlowError::Connect(reason)),
                _ => continue,
            }
        }
    };
    tokio::time::timeout(Duration::from_secs(10), wait)
        .await
        .map_err(|_| FlowError::Connect("no reply to login within 10 s".into()))?
}

/// Runs sessions until the client is closed or reconnection is impossible.
pub(super) async fn supervise(
    inner: Arc<Inner>,
    mut out_rx: mpsc::Receiver<OutFrame>,
    first: Established,
) {
    let mut session = first;
    let mut restore = false;
    loop {
        inner.connected.send_replace(true);
        let _ = inner.events.send(ClientEvent::Connected);
        if restore {
            tokio::spawn(restore_state(inner.clone()));
        }
        let reason = run(&inner, session, &mut out_rx).await;
        inner.connected.send_replace(false);
        forget_session(&inner, &reason);
        let _ = inner.events.send(ClientEvent::Disconnected(reason.clone()));
        if inner.closed.load(Ordering::SeqCst) || !inner.opts.reconnect {
            close_all(&inner);
            return;
        }
        warn!("flow link lost ({reason}); reconnecting");
        match reconnect(&inner).await {
            Some(next) => {
                session = next;
                restore = true;
                // Frames queued while disconnected name channel ids from the old
                // session; sending them now could hit someone else's channel.
                while out_rx.try_recv().is_ok() {}
            }
            None => {
                close_all(&inner);
                return;
            }
        }
    }
}

async fn reconnect(inner: &Arc<Inner>) -> Option<Established> {
    let addr = inner.addr.clone()?;
    let mut closing = inner.closing.subscribe();
    let mut delay = Duration::from_millis(100);
    loop {
        tokio::select! {
            _ = tokio::time::sleep(delay) => {}
            _ = closing.changed() => return None,
        }
        match Link::connect(&addr).await {
            Ok(link) => match establish(inner, link).await {
                Ok(s) => {
                    info!("flow link re-established to {addr}");
                    return Some(s);
                }
                Err(FlowError::Hub(e)) if e.code == ErrorCode::AuthFailed => {
                    warn!("reconnect refused: {e}; giving up");
                    return None;
                }
                Err(e) => debug!("reconnect failed: {e}"),
            },
            Err(e) => debug!("reconnect to {addr} failed: {e}"),
        }
        delay = (delay * 2).min(Duration::from_secs(5));
    }
}

/// Upper bound for one batched write.
const WRITE_BATCH: usize = 256 * 1024;
/// How long a closing client waits for the hub to close its side.
const LINGER: Duration = Duration::from_secs(2);

/// Runs the read and write loops of one session; returns why it ended.
async fn run(
    inner: &Arc<Inner>,
    session: Established,
    out_rx: &mut mpsc::Receiver<OutFrame>,
) -> String {
    let Established {
        mut reader,
        mut writer,
        shm,
    } = session;
    *lock(&inner.shm) = shm.clone();
    let mut closing = inner.closing.subscribe();
    let read_loop = async {
        loop {
            match reader.read_frame().await {
                Ok(Some(frame)) => match decode_event(frame) {
                    Ok(event) => {
                        let event = match &shm {
                            Some(shm) => match shm.receive(event, || reader.take_fd()) {
                                Ok(Some(event)) => event,
                                Ok(None) => continue,
                                Err(reason) => return reason,
                            },
                            None => event,
                        };
                        if let Some(reason) = dispatch(inner, event) {
                            return reason;
                        }
                    }
                    Err(e) => return format!("undecodable event: {e}"),
                },
                Ok(None) => return "hub closed the connection".to_string(),
                Err(e) => return e.to_string(),
            }
        }
    };
    let releases = shm.as_ref().map(|shm| shm.releases().clone());
    let write_loop = async {
        // When an idle hub is rung for releases written into its ring (`shm.rs`), if it has not woken by then.
        let mut ring_at: Option<tokio::time::Instant> = None;
        loop {
            tokio::select! {
                first = out_rx.recv() => {
                    let Some(first) = first else { break };
                    outgoing(inner, &shm, first).queue_on(&mut writer);
                    while writer.pending() < WRITE_BATCH {
                        match out_rx.try_recv() {
                            Ok(more) => outgoing(inner, &shm, more).queue_on(&mut writer),
                            Err(_) => break,
                        }
                    }
                }
                // Slots given back go out even while nothing is published.
                () = async {
                    match &releases {
                        Some(releases) => releases.wake.notified().await,
                        None => std::future::pending().await,
                    }
                } => {}
                () = async {
                    match ring_at {
                        Some(at) => tokio::time::sleep_until(at).await,
                        None => std::future::pending().await,
                    }
                } => {}
            }
            let now = tokio::time::Instant::now();
            if let Some(release) = shm
                .as_ref()
                .and_then(|shm| shm.take_releases(now, &mut ring_at))
            {
                release.queue_on(&mut writer);
            }
            if let Err(e) = writer.flush().await {
                return e.to_string();
            }
        }
        "client dropped".to_string()
    };
    tokio::select! {
        reason = read_loop => reason,
        reason = write_loop => reason,
        _ = closing.changed() => {
            // Frames already handed over (asynchronous publishes return once
            // queued) still go out before the connection closes, so a tool that
            // publishes and then closes does not lose its last messages.
            while let Ok(more) = out_rx.try_recv() {
                more.queue_on(&mut writer);
            }
            let _ = writer.flush().await;
            let _ = writer.shutdown().await;
            // Then read (and drop) what the hub still sends until it closes its
            // side. Closing a socket with unread data in it makes the kernel
            // reset the connection instead, and a reset can throw away frames
            // the hub has received but not read yet: a publisher's last
            // messages, lost one time in six in tests/hub.rs.
            let _ = tokio::time::timeout(LINGER, async {
                while let Ok(Some(_)) = reader.read_frame().await {}
            })
            .await;
            "client closed".to_string()
        }
    }
}

/// A frame as it goes out: a large publish through shared memory when the session has it.
fn outgoing(inner: &Arc<Inner>, shm: &Option<Arc<ShmSession>>, frame: OutFrame) -> OutFrame {
    match shm {
        Some(shm) => shm.publish(frame, |chan, slot_size| {
            Client {
                inner: inner.clone(),
            }
            .ask_segment(chan, slot_size)
        }),
        None => frame,
    }
}

/// Handles one event; returns a reason to end the session, if any.
fn dispatch(inner: &Arc<Inner>, event: Event) -> Option<String> {
    match event {
        Event::Data {
            chan,
            seq,
            ts_us,
            payload,
        } => {
            let state = lock(&inner.state);
            if let Some(subs) = state
                .sub_ids
                .get(&chan)
                .and_then(|name| state.subs.get(name))
            {
                for sub in subs {
                    sub.queue.push(Data {
                        channel: chan,
                        seq,
                        ts_us,
                        payload: payload.clone(),
                    });
                }
            }
        }
        Event::Reply { req, result } => on_reply(inner, req, result),
        Event::ServiceRequest {
            chan,
            call,
            payload,
        } => {
            let owned = lock(&inner.state).owned_ids.get(&chan).cloned();
            match owned {
                Some(owned) => owned.deliver_call(chan, call, payload, &inner.out),
                None => {
                    let _ = inner.out.try_send(encode(
                        0,
                        Command::Respond {
                            call,
                            result: Err("no such service here".into()),
                        },
                    ));
                }
            }
        }
        Event::StartPublishing { id } | Event::StopPublishing { id } => {
            let listening = matches!(event, Event::StartPublishing { .. });
            let mut state = lock(&inner.state);
            match state.owned_ids.get(&id) {
                Some(owned) => owned.set_listening(listening),
                None => {
                    state.early_listening.insert(id, listening);
                }
            }
        }
        Event::ChannelAdded(info) => {
            let wanted = {
                let state = lock(&inner.state);
                state.subs.contains_key(&info.name)
                    && !state.sub_ids.values().any(|n| *n == info.name)
            };
            if wanted {
                let client = Client {
                    inner: inner.clone(),
                };
                let name = info.name.clone();
                tokio::spawn(async move {
                    if let Err(e) = client.activate_subscription(&name).await {
                        debug!("late subscribe to {name} failed: {e}");
                    }
                });
            }
            let _ = inner.events.send(ClientEvent::ChannelAdded(info));
        }
        Event::ChannelRemoved { id, name } => {
            {
                let mut state = lock(&inner.state);
                state.sub_ids.remove(&id);
                state.early_listening.remove(&id);
                if let Some(owned) = state.owned_ids.remove(&id) {
                    owned.set_id(None);
                }
            }
            let _ = inner.events.send(ClientEvent::ChannelRemoved { id, name });
        }
        Event::HeaderChanged { id, name, header } => {
            let _ = inner
                .events
                .send(ClientEvent::HeaderChanged { id, name, header });
        }
        Event::DbChanged { name } => {
            let _ = inner.events.send(ClientEvent::DbChanged(name));
        }
        Event::Goodbye { reason } => {
            let _ = inner.events.send(ClientEvent::Goodbye(reason.clone()));
            return Some(format!("hub said goodbye: {reason}"));
        }
        // `shm.rs` turns these into data and mappings before dispatch; a session without shared memory never asked.
        Event::Segment(_) | Event::DataRef { .. } | Event::ReleaseRing { .. } => {
            return Some("the hub sent shared memory this session did not ask for".into());
        }
    }
    None
}

fn on_reply(inner: &Arc<Inner>, req: u32, result: Result<Reply, crate::protocol::ErrorReply>) {
    let Some(pending) = lock(&inner.state).pending.remove(&req) else {
        match result {
            // A fire-and-forget command on a channel that is gone (an unsubscribe while its owner shuts down) has
            // nothing left to do.
            Err(e) if e.code == crate::protocol::ErrorCode::NotFound => {
                debug!("hub: {e} (a fire-and-forget command on a channel that is gone)");
            }
            // Any other failure of a fire-and-forget command: nobody waits for it, so say it here.
            Err(e) => warn!("hub refused a command: {e}"),
            Ok(_) => {}
        }
        return;
    };
    match (&pending.hook, &result) {
        (Some(Hook::Subscribed(name)), Ok(Reply::Channel(info))) => {
            let mut state = lock(&inner.state);
            if state.subs.contains_key(name) {
                state.sub_ids.insert(info.id, name.clone());
                for sub in state.subs.get(name).into_iter().flatten() {
                    sub.set_info(info.clone());
                }
            }
        }
        (Some(Hook::Added(owned)), Ok(Reply::Channel(info))) => {
            owned.set_id(Some(info.id));
            let mut state = lock(&inner.state);
            state.owned_ids.insert(info.id, owned.clone());
            if let Some(listening) = state.early_listening.remove(&info.id) {
                owned.set_listening(listening);
            }
        }
        (Some(Hook::CallAsync), _) => {
            let result = match result {
                Ok(Reply::Payload(p)) => Ok(p),
                Ok(_) => Err(FlowError::UnexpectedReply("call")),
                Err(e) => Err(FlowError::Hub(e)),
            };
            let _ = inner.events.send(ClientEvent::CallResult { req, result });
            return;
        }
        _ => {}
    }
    if let Some(tx) = pending.tx {
        let _ = tx.send(result.map_err(FlowError::Hub));
    }
}

/// Forgets everything that belonged to the lost session: pending requests fail
/// and channel ids become unknown until restored.
fn forget_session(inner: &Arc<Inner>, reason: &str) {
    let pending = {
        let mut state = lock(&inner.state);
        state.sub_ids.clear();
        for owned in state.owned_ids.values() {
            owned.set_id(None);
        }
        state.owned_ids.clear();
        state.early_listening.clear();
        state.session = None;
        *lock(&inner.shm) = None;
        std::mem::take(&mut state.pending)
    };
    for (req, p) in pending {
        if let Some(tx) = p.tx {
            let _ = tx.send(Err(FlowError::Disconnected(reason.to_string())));
        } else if matches!(p.hook, Some(Hook::CallAsync)) {
            let result = Err(FlowError::Disconnected(reason.to_string()));
            let _ = inner.events.send(ClientEvent::CallResult { req, result });
        }
    }
}

/// Ends every subscription and service so their consumers see the end.
fn close_all(inner: &Arc<Inner>) {
    let state = lock(&inner.state);
    for sub in state.subs.values().flatten() {
        sub.queue.close();
    }
    for owned in state.owned.values() {
        owned.close();
    }
}

/// Re-creates channels, the database selection and subscriptions after a reconnect.
async fn restore_state(inner: Arc<Inner>) {
    let client = Client {
        inner: inner.clone(),
    };
    let (owned, subs, db) = {
        let state = lock(&inner.state);
        let owned: Vec<_> = state.owned.values().cloned().collect();
        let subs: Vec<_> = state.subs.keys().cloned().collect();
        (owned, subs, state.db.clone())
    };
    for o in owned {
        if let Err(e) = client
            .request_hooked(o.add_command(), Some(Hook::Added(o.clone())))
            .await
        {
            warn!("could not re-create channel {}: {e}", o.name);
        }
    }
    if let Some(db) = db
        && let Err(e) = client.request(Command::DbSelect { name: db.clone() }).await
    {
        warn!("could not re-select database {db}: {e}");
    }
    for name in subs {
        let cmd = Command::Subscribe {
            chan: ChanRef::Name(name.clone()),
        };
        match client
            .request_hooked(cmd, Some(Hook::Subscribed(name.clone())))
            .await
        {
            Ok(_) => {}
            Err(FlowError::Hub(e)) if e.code == ErrorCode::NotFound => {}
            Err(e) => warn!("could not re-subscribe to {name}: {e}"),
        }
    }
}
