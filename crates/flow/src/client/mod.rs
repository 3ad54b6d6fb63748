//! The satellite SDK: a cheap-to-clone handle on one hub connection.
//!
//! A [`Client`] owns a background task that reads events, matches replies to
//! requests by id, routes data to subscriptions and service requests to
//! services, and (unless disabled) reconnects after a failure, re-creating the
//! client's channels, subscriptions and database selection.
//!
//! Subscriptions are sticky by name: subscribing to a channel that does not
//! exist yet, or that is removed and later re-created, delivers its data once
//! it (re)appears. The client subscribes when the hub announces the channel, so
//! what the owner publishes before that subscribe reaches the hub goes to no
//! one; an owner that must not lose its first messages waits for a subscriber
//! ([`Publisher::subscribers`], the hub's `StartPublishing`).

use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use bytes::Bytes;
use tokio::sync::{broadcast, mpsc, watch};

use crate::error::FlowError;
use crate::protocol::{ChanRef, ChannelInfo, ChannelKind, Command, ErrorCode, Reply, ReqId};
use crate::queue::lock;
use crate::transport::{FlowAddr, Link};

mod core;
mod frame;
mod inbox;
mod options;
mod owned;
mod publisher;
mod session;
mod shm;
mod subscription;

pub use self::core::Client;
pub use inbox::Data;
pub use options::{ClientEvent, ConnectOptions, SessionInfo};
pub use owned::ServiceCall;
pub use publisher::{Loan, Publisher, Service};
pub use subscription::Subscription;

use self::core::{Hook, Inner, State};
use frame::check_json;
use inbox::SubShared;
use owned::Owned;

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
            shm: Mutex::new(None),
            shm_spilled: Default::default(),
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
            .request_timeout(cmd, None, timeout.saturating_add(Duration::from_secs(2)))
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
