//! The satellite SDK: a cheap-to-clone handle on one hub connection.
//!
//! A [`Client`] owns a background task that reads events, matches replies to
//! requests by id, routes data to subscriptions and service requests to
//! services, and (unless disabled) reconnects after a failure, re-creating the
//! client's channels, subscriptions and database selection.
//!
//! Subscriptions are sticky by name: subscribing to a channel that does not
//! exist yet, or that is removed and later re-created, delivers its data as soon
//! as it (re)appears.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use bytes::{Bytes, BytesMut};
use tokio::sync::{broadcast, mpsc, oneshot, watch};

use crate::error::FlowError;
use crate::protocol::{
    ChanId, ChanRef, ChannelInfo, ChannelKind, Command, DEFAULT_MAX_FRAME, Envelope, ErrorCode,
    Reply, ReqId, encode_command,
};
use crate::queue::lock;
use crate::transport::{FlowAddr, Link};

mod publisher;
mod session;
mod subscription;

pub use publisher::{Publisher, Service, ServiceCall};
pub use subscription::{Data, Subscription};

use publisher::Owned;
use subscription::SubShared;

/// How to log in and behave.
#[derive(Debug, Clone)]
pub struct ConnectOptions {
    /// Login name, shown as the owner of this client's channels.
    pub name: String,
    pub token: String,
    /// Switch to asynchronous mode after login so events flow (satellites want this).
    pub asynchronous: bool,
    /// Reconnect after a lost connection, restoring channels and subscriptions.
    pub reconnect: bool,
    pub max_frame: usize,
    /// Capacity of each subscription's drop-oldest queue.
    pub queue: usize,
    /// How long to wait for a reply to an ordinary command.
    pub request_timeout: Duration,
}

impl ConnectOptions {
    pub fn new(name: impl Into<String>, token: impl Into<String>) -> Self {
        ConnectOptions {
            name: name.into(),
            token: token.into(),
            asynchronous: true,
            reconnect: true,
            max_frame: DEFAULT_MAX_FRAME,
            queue: 64,
            request_timeout: Duration::from_secs(10),
        }
    }
}

/// What the client observed, for whoever listens on [`Client::events`].
#[derive(Debug, Clone, PartialEq)]
pub enum ClientEvent {
    Connected,
    Disconnected(String),
    ChannelAdded(ChannelInfo),
    ChannelRemoved {
        id: ChanId,
        name: String,
    },
    HeaderChanged {
        id: ChanId,
        name: String,
        header: String,
    },
    DbChanged(String),
    /// The answer to [`Client::call_async`], matched by its request id.
    CallResult {
        req: ReqId,
        result: Result<Bytes, FlowError>,
    },
    Goodbye(String),
}

/// Facts from the login reply.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SessionInfo {
    pub conn: u32,
    pub admin: bool,
    pub server: String,
}

/// Handle on a hub connection. Clones share the connection.
#[derive(Debug, Clone)]
pub struct Client {
    inner: Arc<Inner>,
}

/// What runs after a reply arrives, inside the reader, before anything else is
/// read: so that data following a subscribe reply finds its subscription.
#[derive(Debug)]
enum Hook {
    Subscribed(String),
    Added(Arc<Owned>),
    CallAsync,
}

#[derive(Debug)]
struct Pending {
    tx: Option<oneshot::Sender<Result<Reply, FlowError>>>,
    hook: Option<Hook>,
}

#[derive(Debug, Default)]
struct State {
    pending: HashMap<ReqId, Pending>,
    subs: HashMap<String, Vec<Arc<SubShared>>>,
    sub_ids: HashMap<ChanId, String>,
    owned: HashMap<String, Arc<Owned>>,
    owned_ids: HashMap<ChanId, Arc<Owned>>,
    /// Start/stop-publishing news for a channel whose creation reply has not
    /// been read yet: another client may subscribe as soon as it sees the
    /// channel added, so the hub's news can overtake the reply.
    early_listening: HashMap<ChanId, bool>,
    db: Option<String>,
    session: Option<SessionInfo>,
}

#[derive(Debug)]
struct Inner {
    opts: ConnectOptions,
    addr: Option<FlowAddr>,
    out: mpsc::Sender<OutFrame>,
    state: Mutex<State>,
    next_req: AtomicU32,
    events: broadcast::Sender<ClientEvent>,
    connected: watch::Sender<bool>,
    closing: watch::Sender<bool>,
    closed: AtomicBool,
}

/// Frames queued for the writer; a full queue makes `publish` wait and
/// `try_publish` drop.
const OUT_QUEUE: usize = 1024;

impl Client {
    /// Connects to `addr`, logs in and, for asynchronous options, starts events.
    /// Fails if the first attempt fails; later losses reconnect in the background.
    pub async fn connect(addr: &FlowAddr, opts: ConnectOptions) -> Result<Client, FlowError> {
        let link = Link::connect(addr)
            .await
            .map_err(|e| FlowError::Connect(format!("{addr}: {e}")))?;
        Self::start(link, Some(addr.clone()), opts).await
    }

    /// Uses an already opened link (e.g. an in-process pipe); never reconnects.
    pub async fn connect_link(link: Link, mut opts: ConnectOptions) -> Result<Client, FlowError> {
        opts.reconnect = false;
        Self::start(link, None, opts).await
    }

    async fn start(
        link: Link,
        addr: Option<FlowAddr>,
        opts: ConnectOptions,
    ) -> Result<Client, FlowError> {
        let (out, out_rx) = mpsc::channel(OUT_QUEUE);
        let inner = Arc::new(Inner {
            opts,
            addr,
            out,
            state: Mutex::new(State::default()),
            next_req: AtomicU32::new(1),
            events: broadcast::channel(1024).0,
            connected: watch::channel(false).0,
            closing: watch::channel(false).0,
            closed: AtomicBool::new(false),
        });
        let established = session::establish(&inner, link).await?;
        // Connected from now: requests may be queued before the task first runs.
        inner.connected.send_replace(true);
        tokio::spawn(session::supervise(inner.clone(), out_rx, established));
        Ok(Client { inner })
    }

    /// Events seen on this connection (channel changes, reconnections, async call results).
    pub fn events(&self) -> broadcast::Receiver<ClientEvent> {
        self.inner.events.subscribe()
    }

    /// Whether the connection is up now.
    pub fn is_connected(&self) -> bool {
        *self.inner.connected.borrow()
    }

    /// Watches the connection state.
    pub fn connection_state(&self) -> watch::Receiver<bool> {
        self.inner.connected.subscribe()
    }

    /// Facts from the current session's login reply.
    pub fn session(&self) -> Option<SessionInfo> {
        lock(&self.inner.state).session.clone()
    }

    /// Closes the connection for good; pending requests fail with `Closed`.
    /// Frames already queued are still sent; see [`Client::close_and_wait`].
    pub fn close(&self) {
        self.inner.closed.store(true, Ordering::SeqCst);
        self.inner.closing.send_replace(true);
    }

    /// Closes the connection and waits, at most `grace`, until the queued
    /// frames are written and the link is down: what a short-lived tool does
    /// before it exits.
    pub async fn close_and_wait(&self, grace: std::time::Duration) {
        let mut connected = self.connection_state();
        self.close();
        let _ = tokio::time::timeout(grace, connected.wait_for(|up| !*up)).await;
    }

    // ------------------------------------------------------------ channels

    /// Creates (or re-creates after a reconnect) a streaming channel owned by this client.
    pub async fn publisher(&self, name: &str, header: &str) -> Result<Publisher, FlowError> {
        let owned = self
            .add_owned(name, ChannelKind::Stream, header, None)
            .await?;
        Ok(Publisher::new(owned, self.clone()))
    }

    /// Creates a service channel; requests arrive on the returned [`Service`].
    pub async fn serve(&self, name: &str, header: &str) -> Result<Service, FlowError> {
        // Bounded: a service that falls this far behind answers "overloaded"
        // instead of queueing without limit (the hub also caps calls in flight).
        let (tx, rx) = mpsc::channel(256);
        let owned = self
            .add_owned(name, ChannelKind::Service, header, Some(tx))
            .await?;
        Ok(Service::new(owned, rx, self.clone()))
    }

    async fn add_owned(
        &self,
        name: &str,
        kind: ChannelKind,
        header: &str,
        calls: Option<mpsc::Sender<ServiceCall>>,
    ) -> Result<Arc<Owned>, FlowError> {
        check_json(header)?;
        let owned = Arc::new(Owned::new(name, kind, header, calls));
        let cmd = owned.add_command();
        self.request_hooked(cmd, Some(Hook::Added(owned.clone())))
            .await?;
        lock(&self.inner.state)
            .owned
            .insert(name.to_string(), owned.clone());
        Ok(owned)
    }

    /// Subscribes to a channel by name; sticky across removals and reconnects.
    pub async fn subscribe(&self, name: &str) -> Result<Subscription, FlowError> {
        let shared = Arc::new(SubShared::new(name, self.inner.opts.queue));
        lock(&self.inner.state)
            .subs
            .entry(name.to_string())
            .or_default()
            .push(shared.clone());
        match self.activate_subscription(name).await {
            Ok(()) => {}
            // Not there yet: the reader subscribes when the hub announces it.
            Err(FlowError::Hub(e)) if e.code == ErrorCode::NotFound => {}
            Err(e) => {
                if let Some(list) = lock(&self.inner.state).subs.get_mut(name) {
                    list.retain(|s| !Arc::ptr_eq(s, &shared));
                }
                return Err(e);
            }
        }
        Ok(Subscription::new(shared, self.clone()))
    }

    async fn activate_subscription(&self, name: &str) -> Result<(), FlowError> {
        let cmd = Command::Subscribe {
            chan: ChanRef::Name(name.to_string()),
        };
        self.request_hooked(cmd, Some(Hook::Subscribed(name.to_string())))
            .await
            .map(drop)
    }

    /// Called when a local subscription handle goes away.
    fn release_subscription(&self, shared: &Arc<SubShared>) {
        let name = shared.name.clone();
        let now_unused = {
            let mut state = lock(&self.inner.state);
            let Some(list) = state.subs.get_mut(&name) else {
                return;
            };
            list.retain(|s| !Arc::ptr_eq(s, shared));
            if list.is_empty() {
                state.subs.remove(&name);
                state.sub_ids.retain(|_, n| *n != name);
                true
            } else {
                false
            }
        };
        if now_unused {
            self.send_nowait(Command::Unsubscribe {
                chan: ChanRef::Name(name),
            });
        }
    }

    /// Called when a publisher or service handle goes away.
    fn release_owned(&self, owned: &Arc<Owned>) {
        {
            let mut state = lock(&self.inner.state);
            state.owned.remove(&owned.name);
            state.owned_ids.retain(|_, o| !Arc::ptr_eq(o, owned));
        }
        if let Some(id) = owned.id() {
            self.send_nowait(Command::RemoveChannel {
                chan: ChanRef::Id(id),
            });
        }
    }

    /// Every channel on the hub with its counters.
    pub async fn channels(&self) -> Result<Vec<ChannelInfo>, FlowError> {
        match self.request(Command::ListChannels).await? {
            Reply::Channels(list) => Ok(list),
            _ => Err(FlowError::UnexpectedReply("list channels")),
        }
    }

    /// One channel by name.
    pub async fn channel(&self, name: &str) -> Result<ChannelInfo, FlowError> {
        match self
            .request(Command::GetChannel {
                chan: ChanRef::Name(name.into()),
            })
            .await?
        {
            Reply::Channel(info) => Ok(info),
            _ => Err(FlowError::UnexpectedReply("get channel")),
        }
    }

    /// Removes any channel by name (owners, or admins for others' channels).
    pub async fn remove_channel(&self, name: &str) -> Result<(), FlowError> {
        self.request(Command::RemoveChannel {
            chan: ChanRef::Name(name.into()),
        })
        .await
        .map(drop)
    }

    // ------------------------------------------------------------ services

    /// Calls a service and waits for its response (or the hub's error after `timeout`).
    pub async fn call(
        &self,
        name: &str,
        payload: impl Into<Bytes>,
        timeout: Duration,
    ) -> Result<Bytes, FlowError> {
        let cmd = call_command(name, payload.into(), timeout);
        // The hub enforces the timeout and always answers; the margin only
        // covers a hub that has gone silent.
        match self
            .request_timeout(cmd, None, timeout + Duration::from_secs(2))
            .await?
        {
            Reply::Payload(p) => Ok(p),
            _ => Err(FlowError::UnexpectedReply("call")),
        }
    }

    /// Sends a call without waiting; the response arrives as
    /// [`ClientEvent::CallResult`] with the returned request id.
    pub async fn call_async(
        &self,
        name: &str,
        payload: impl Into<Bytes>,
        timeout: Duration,
    ) -> Result<ReqId, FlowError> {
        let req = self.register(None, Some(Hook::CallAsync));
        self.send_frame(req, call_command(name, payload.into(), timeout))
            .await?;
        Ok(req)
    }

    // ------------------------------------------------------------ pair database

    /// Selects the current database of this connection (restored on reconnect).
    pub async fn db_select(&self, name: &str) -> Result<(), FlowError> {
        self.request(Command::DbSelect { name: name.into() })
            .await?;
        lock(&self.inner.state).db = Some(name.to_string());
        Ok(())
    }

    pub async fn db_create(&self, name: &str) -> Result<(), FlowError> {
        self.request(Command::DbCreate { name: name.into() })
            .await
            .map(drop)
    }

    pub async fn db_remove(&self, name: &str) -> Result<(), FlowError> {
        self.request(Command::DbRemove { name: name.into() })
            .await
            .map(drop)
    }

    pub async fn db_list(&self) -> Result<Vec<String>, FlowError> {
        names(self.request(Command::DbList).await?)
    }

    /// Stores a JSON value; returns once the hub has made the write durable.
    pub async fn var_set(&self, key: &str, value: &serde_json::Value) -> Result<(), FlowError> {
        self.request(Command::VarSet {
            key: key.into(),
            value: value.to_string(),
        })
        .await
        .map(drop)
    }

    /// A variable's value in the current database, or `None` when the database
    /// has no such key. A current database that no longer exists (removed
    /// since it was selected) is an error, `ErrorCode::NoDatabase`, not `None`.
    pub async fn var_get(&self, key: &str) -> Result<Option<serde_json::Value>, FlowError> {
        match self.request(Command::VarGet { key: key.into() }).await {
            Ok(Reply::Value(text)) => serde_json::from_str(&text)
                .map(Some)
                .map_err(|e| FlowError::Json(e.to_string())),
            Ok(_) => Err(FlowError::UnexpectedReply("get variable")),
            // Only "no such key": `NoDatabase` and every other refusal stay errors.
            Err(FlowError::Hub(e)) if e.code == ErrorCode::NotFound => Ok(None),
            Err(e) => Err(e),
        }
    }

    pub async fn var_del(&self, key: &str) -> Result<(), FlowError> {
        self.request(Command::VarDel { key: key.into() })
            .await
            .map(drop)
    }

    pub async fn var_list(&self) -> Result<Vec<String>, FlowError> {
        names(self.request(Command::VarList).await?)
    }

    /// Round trip to the hub.
    pub async fn ping(&self) -> Result<(), FlowError> {
        self.request(Command::Ping).await.map(drop)
    }

    // ------------------------------------------------------------ plumbing

    /// Sends a command and waits for its reply.
    pub async fn request(&self, cmd: Command) -> Result<Reply, FlowError> {
        self.request_hooked(cmd, None).await
    }

    async fn request_hooked(&self, cmd: Command, hook: Option<Hook>) -> Result<Reply, FlowError> {
        self.request_timeout(cmd, hook, self.inner.opts.request_timeout)
            .await
    }

    async fn request_timeout(
        &self,
        cmd: Command,
        hook: Option<Hook>,
        timeout: Duration,
    ) -> Result<Reply, FlowError> {
        if self.inner.closed.load(Ordering::SeqCst) {
            return Err(FlowError::Closed);
        }
        if !self.is_connected() {
            return Err(FlowError::Disconnected("not connected".into()));
        }
        let (tx, rx) = oneshot::channel();
        let req = self.register(Some(tx), hook);
        if let Err(e) = self.send_frame(req, cmd).await {
            lock(&self.inner.state).pending.remove(&req);
            return Err(e);
        }
        match tokio::time::timeout(timeout, rx).await {
            Ok(Ok(result)) => result,
            Ok(Err(_)) => Err(FlowError::Disconnected(
                "connection closed before the reply".into(),
            )),
            Err(_) => {
                lock(&self.inner.state).pending.remove(&req);
                Err(FlowError::Timeout(timeout))
            }
        }
    }

    fn register(
        &self,
        tx: Option<oneshot::Sender<Result<Reply, FlowError>>>,
        hook: Option<Hook>,
    ) -> ReqId {
        let req = loop {
            let req = self.inner.next_req.fetch_add(1, Ordering::Relaxed);
            // Request id 0 means "no reply wanted"; skip it when the counter wraps.
            if req != 0 {
                break req;
            }
        };
        lock(&self.inner.state)
            .pending
            .insert(req, Pending { tx, hook });
        req
    }

    async fn send_frame(&self, req: ReqId, command: Command) -> Result<(), FlowError> {
        let frame = encode(req, command);
        self.inner
            .out
            .send(frame)
            .await
            .map_err(|_| FlowError::Closed)
    }

    /// Queues a fire-and-forget command without waiting; used from `Drop`.
    fn send_nowait(&self, command: Command) {
        if self.is_connected() {
            // A full queue means the link is saturated; the hub cleans up after
            // a disconnect anyway, so losing a release command is harmless.
            let _ = self.inner.out.try_send(encode(0, command));
        }
    }
}

fn encode(req: ReqId, command: Command) -> OutFrame {
    let mut buf = BytesMut::new();
    encode_command(&Envelope { req, command }, &mut buf);
    OutFrame {
        head: buf.freeze(),
        payload: Bytes::new(),
    }
}

/// One frame on its way to the session's writer: encoded bytes, then a large
/// publish's payload, which follows its header uncopied (the writer sends it
/// from the caller's own buffer, as the hub does for subscribers).
#[derive(Debug)]
pub(crate) struct OutFrame {
    head: Bytes,
    payload: Bytes,
}

impl OutFrame {
    /// A `Publish` on `chan`: the payload is copied next to its header when
    /// small, and travels as its own piece when large.
    fn publish(chan: ChanId, payload: Bytes) -> OutFrame {
        if payload.len() < crate::connection::ZERO_COPY_MIN {
            return encode(0, Command::Publish { chan, payload });
        }
        let mut head = BytesMut::with_capacity(16);
        crate::protocol::codec::encode_publish_head(chan, payload.len(), &mut head);
        OutFrame {
            head: head.freeze(),
            payload,
        }
    }

    /// Hands the frame to `writer`'s next batch.
    fn queue_on<W: crate::transport::TransportWrite>(
        self,
        writer: &mut crate::connection::FrameWriter<W>,
    ) {
        writer.queue_encoded(self.head);
        if !self.payload.is_empty() {
            writer.queue_encoded(self.payload);
        }
    }
}

fn call_command(name: &str, payload: Bytes, timeout: Duration) -> Command {
    let timeout_ms = u32::try_from(timeout.as_millis()).unwrap_or(u32::MAX);
    Command::Call {
        chan: ChanRef::Name(name.into()),
        timeout_ms,
        payload,
    }
}

fn names(reply: Reply) -> Result<Vec<String>, FlowError> {
    match reply {
        Reply::Names(names) => Ok(names),
        _ => Err(FlowError::UnexpectedReply("list")),
    }
}

fn check_json(text: &str) -> Result<(), FlowError> {
    serde_json::from_str::<serde_json::Value>(text)
        .map(drop)
        .map_err(|e| FlowError::Json(e.to_string()))
}
