//! What a client is told when it connects and what it reports back: the login
//! options, the events it observes and the facts of its session.

use std::time::Duration;

use bytes::Bytes;

use crate::error::FlowError;
use crate::protocol::{ChanId, ChannelInfo, DEFAULT_MAX_FRAME, ReqId};

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
    /// Over a Unix socket, move large payloads through shared memory when the hub offers it (docs/protocol.md,
    /// "Shared memory"). On by default; the environment variable `FLOW_SHM=0` turns it off for a whole process.
    pub shm: bool,
    /// Give slots received by reference back through the hub's release ring, with no frame each (on by default).
    /// `FLOW_SHM_RING=0` (or false here) sends each batch in a `Release` frame instead, as clients did before the
    /// ring: how shm-bench measures what the ring saves, side by side.
    pub release_ring: bool,
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
            shm: std::env::var("FLOW_SHM").map_or(true, |v| v != "0"),
            release_ring: std::env::var("FLOW_SHM_RING").map_or(true, |v| v != "0"),
        }
    }
}

/// What the client observed, for whoever listens on
/// [`Client::events`](crate::Client::events).
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
    /// The answer to [`Client::call_async`](crate::Client::call_async), matched
    /// by its request id.
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
