//! The state a client's handle, its publishers and subscriptions and its
//! session task share, and the request plumbing they all use: the handle type
//! itself is defined here so that none of them needs the wiring file.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::{broadcast, mpsc, oneshot, watch};

use super::frame::{OutFrame, encode};
use super::inbox::SubShared;
use super::options::{ClientEvent, ConnectOptions, SessionInfo};
use super::owned::Owned;
use super::shm::ShmSession;
use crate::error::FlowError;
use crate::protocol::{ChanId, ChanRef, Command, Reply, ReqId};
use crate::queue::lock;
use crate::transport::FlowAddr;

/// Handle on a hub connection. Clones share the connection.
#[derive(Debug, Clone)]
pub struct Client {
    pub(super) inner: Arc<Inner>,
}

/// What runs after a reply arrives, inside the reader, before anything else is
/// read: so that data following a subscribe reply finds its subscription.
#[derive(Debug)]
pub(super) enum Hook {
    Subscribed(String),
    Added(Arc<Owned>),
    CallAsync,
}

/// A request waiting for its reply.
#[derive(Debug)]
pub(super) struct Pending {
    pub(super) tx: Option<oneshot::Sender<Result<Reply, FlowError>>>,
    pub(super) hook: Option<Hook>,
}

#[derive(Debug, Default)]
pub(super) struct State {
    pub(super) pending: HashMap<ReqId, Pending>,
    pub(super) subs: HashMap<String, Vec<Arc<SubShared>>>,
    pub(super) sub_ids: HashMap<ChanId, String>,
    pub(super) owned: HashMap<String, Arc<Owned>>,
    pub(super) owned_ids: HashMap<ChanId, Arc<Owned>>,
    /// Start/stop-publishing news for a channel whose creation reply has not
    /// been read yet: another client may subscribe as soon as it sees the
    /// channel added, so the hub's news can overtake the reply.
    pub(super) early_listening: HashMap<ChanId, bool>,
    pub(super) db: Option<String>,
    pub(super) session: Option<SessionInfo>,
}

#[derive(Debug)]
pub(super) struct Inner {
    pub(super) opts: ConnectOptions,
    pub(super) addr: Option<FlowAddr>,
    pub(super) out: mpsc::Sender<OutFrame>,
    pub(super) state: Mutex<State>,
    pub(super) next_req: AtomicU32,
    pub(super) events: broadcast::Sender<ClientEvent>,
    pub(super) connected: watch::Sender<bool>,
    pub(super) closing: watch::Sender<bool>,
    pub(super) closed: AtomicBool,
    /// The current session's shared memory, while it has some (`shm.rs`).
    pub(super) shm: Mutex<Option<Arc<ShmSession>>>,
    /// Large messages sent inline because their segment had no free slot, over every session.
    pub(super) shm_spilled: Arc<std::sync::atomic::AtomicU64>,
}

impl Client {
    /// The current session's shared memory, if it has some.
    pub(super) fn shm_session(&self) -> Option<Arc<ShmSession>> {
        lock(&self.inner.shm).clone()
    }

    /// Asks the hub for a shared-memory segment of `chan` on a task of its own; the session's reader maps it when
    /// the reply comes (`shm.rs`), and a refusal is recorded so that the channel's messages go inline.
    pub(super) fn ask_segment(&self, chan: ChanId, slot_size: u32) {
        let client = self.clone();
        tokio::spawn(async move {
            match client.request(Command::ShmOpen { chan, slot_size }).await {
                Ok(Reply::Segment(_)) => {}
                Ok(other) => tracing::warn!("the hub answered a segment request with {other:?}"),
                Err(e) => {
                    tracing::debug!(
                        "no shared-memory segment for channel {chan}: {e}; its messages go inline"
                    );
                    if let Some(shm) = client.shm_session() {
                        shm.refused(chan);
                    }
                }
            }
        });
    }

    /// Whether the current session moves large payloads through shared memory (a Unix-socket link whose hub
    /// accepted it).
    pub fn uses_shared_memory(&self) -> bool {
        lock(&self.inner.shm).is_some()
    }

    /// Large messages published inline because every slot of their segment was still held (by subscribers that had
    /// not let go of them yet): the publisher never waits for a slot.
    pub fn shm_spilled(&self) -> u64 {
        self.inner.shm_spilled.load(Ordering::Relaxed)
    }

    /// Whether the connection is up now.
    pub fn is_connected(&self) -> bool {
        *self.inner.connected.borrow()
    }

    /// Sends a command and waits for its reply.
    pub async fn request(&self, cmd: Command) -> Result<Reply, FlowError> {
        self.request_hooked(cmd, None).await
    }

    pub(super) async fn request_hooked(
        &self,
        cmd: Command,
        hook: Option<Hook>,
    ) -> Result<Reply, FlowError> {
        self.request_timeout(cmd, hook, self.inner.opts.request_timeout)
            .await
    }

    pub(super) async fn request_timeout(
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

    pub(super) fn register(
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

    pub(super) async fn send_frame(&self, req: ReqId, command: Command) -> Result<(), FlowError> {
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

    /// Subscribes on the hub for the local subscriptions to `name`.
    pub(super) async fn activate_subscription(&self, name: &str) -> Result<(), FlowError> {
        let cmd = Command::Subscribe {
            chan: ChanRef::Name(name.to_string()),
        };
        self.request_hooked(cmd, Some(Hook::Subscribed(name.to_string())))
            .await
            .map(drop)
    }

    /// Called when a local subscription handle goes away.
    pub(super) fn release_subscription(&self, shared: &Arc<SubShared>) {
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
    pub(super) fn release_owned(&self, owned: &Arc<Owned>) {
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
}
