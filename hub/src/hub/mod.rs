//! The hub core: channels, subscriptions, service calls and the events they
//! cause. It never touches a socket: connections are ids with an [`Outbox`],
//! and every operation is a synchronous method that updates state and queues
//! events. Transports and sessions live elsewhere.

use std::collections::{BTreeSet, HashMap};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use bytes::Bytes;
use flow::protocol::{
    CallId, ChanId, ChanRef, ChannelInfo, ChannelKind, ChannelStats, ErrorCode, ErrorReply, Event,
    Reply, ReqId, SegmentInfo, SlotRef, channel_hash, validate_name,
};

mod deadlines;
mod graph;
pub mod outbox;
pub mod segments;
mod shm_peer;

pub use deadlines::MAX_CALL_TIMEOUT_MS;
pub use graph::{Graph, GraphChannel, GraphNode};
pub use outbox::{Outbox, OutboxLimits};
pub use segments::{LeaseError, Segments, ShmSettings, ShmStats};
pub use shm_peer::ShmPeer;

/// A connection (satellite or module) as the hub knows it.
pub type ConnId = u32;

/// Largest number of channels (ids are non-negative `i16`).
pub const MAX_CHANNELS: usize = 32768;

/// Limits applied by the hub.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HubLimits {
    pub outbox: OutboxLimits,
    /// Service calls waiting for one service's owner before callers get `Overloaded`.
    pub service_inflight: usize,
    pub max_channels: usize,
}

type HubResult<T> = Result<T, ErrorReply>;

fn err<T>(code: ErrorCode, message: impl Into<String>) -> HubResult<T> {
    Err(ErrorReply::new(code, message))
}

#[derive(Debug)]
struct Conn {
    label: String,
    /// How it reached the hub: the peer address's scheme (`tcp`, `unix`, `ws`, `module`).
    transport: String,
    outbox: Arc<Outbox>,
    is_async: bool,
    admin: bool,
    owned: BTreeSet<ChanId>,
    subs: BTreeSet<ChanId>,
}

#[derive(Debug)]
struct Channel {
    id: ChanId,
    hash: u64,
    kind: ChannelKind,
    name: String,
    owner: ConnId,
    owner_label: String,
    header: String,
    subscribers: Vec<(ConnId, Arc<Outbox>)>,
    seq: u64,
    msgs: u64,
    bytes: u64,
    dropped: u64,
    inflight: usize,
    rate: Rate,
}

/// Messages and bytes per second over the last measurement window.
#[derive(Debug, Default, Clone, Copy)]
struct Rate {
    last_msgs: u64,
    last_bytes: u64,
    msgs_per_s: f32,
    bytes_per_s: f32,
}

#[derive(Debug)]
struct PendingCall {
    caller: ConnId,
    req: ReqId,
    chan: ChanId,
    /// When the caller gets `Timeout`; the same instant is in `State::deadlines`.
    deadline: Instant,
    /// The timeout applied, for the caller's error message.
    timeout_ms: u32,
}

#[derive(Debug, Default)]
struct State {
    conns: HashMap<ConnId, Conn>,
    next_conn: ConnId,
    channels: HashMap<ChanId, Channel>,
    by_name: HashMap<String, ChanId>,
    by_hash: HashMap<u64, ChanId>,
    next_id: u16,
    calls: HashMap<CallId, PendingCall>,
    /// The pending calls' deadlines, earliest first: what the timer task sleeps on.
    deadlines: deadlines::Deadlines,
    next_call: CallId,
    last_rate: Option<Instant>,
    /// How service calls ended, by service name: kept across a service's removal and re-creation, for `/metrics`.
    call_outcomes: HashMap<String, CallOutcomes>,
    /// The channels' shared-memory segments, retired with their channel.
    segments: Arc<Segments>,
}

/// Most distinct service names whose call outcomes are kept; more share the name [`OTHER_SERVICES`], so that a
/// client inventing names cannot grow the table without bound.
const MAX_SERVICE_NAMES: usize = 1024;
const OTHER_SERVICES: &str = "(other)";

/// How the calls to one service ended.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct CallOutcomes {
    pub answered: u64,
    /// The service answered with an error.
    pub failed: u64,
    pub timeout: u64,
    /// The owner left, or could not be reached, before answering.
    pub gone: u64,
    pub overloaded: u64,
}

impl CallOutcomes {
    pub fn by_outcome(&self) -> [(&'static str, u64); 5] {
        [
            ("answered", self.answered),
            ("failed", self.failed),
            ("timeout", self.timeout),
            ("gone", self.gone),
            ("overloaded", self.overloaded),
        ]
    }
}

/// The outcome counters of service `name`.
fn outcomes<'a>(st: &'a mut State, name: &str) -> &'a mut CallOutcomes {
    let key = if st.call_outcomes.contains_key(name) || st.call_outcomes.len() < MAX_SERVICE_NAMES {
        name
    } else {
        OTHER_SERVICES
    };
    st.call_outcomes.entry(key.to_string()).or_default()
}

/// The outcome counters of the service behind channel `id`, if it still exists.
fn outcomes_of(st: &mut State, id: ChanId) -> Option<&mut CallOutcomes> {
    let name = st.channels.get(&id)?.name.clone();
    Some(outcomes(st, &name))
}

/// The hub: shared by every connection task.
#[derive(Debug)]
pub struct Hub {
    /// Shared with the call timer task, which holds it weakly.
    state: Arc<Mutex<State>>,
    limits: HubLimits,
    timer: deadlines::CallTimer,
    /// The same registry as the state's, reachable without the state's lock: a message published by reference
    /// leases its slot here before it takes the lock once, to publish.
    segments: Arc<Segments>,
}

impl Drop for Hub {
    fn drop(&mut self) {
        self.timer.stop();
    }
}

fn lock_state(state: &Mutex<State>) -> MutexGuard<'_, State> {
    // Methods validate before they mutate, so state stays consistent even
    // if a panic poisoned the lock; keep serving rather than crash the hub.
    state.lock().unwrap_or_else(PoisonError::into_inner)
}

fn now_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_micros() as u64)
        .unwrap_or(0)
}

impl Hub {
    pub fn new(limits: HubLimits) -> Self {
        Self::with_shm(limits, ShmSettings::default())
    }

    /// A hub whose shared-memory path has `shm`'s settings.
    pub fn with_shm(limits: HubLimits, shm: ShmSettings) -> Self {
        let segments = Arc::new(Segments::new(shm));
        Hub {
            state: Arc::new(Mutex::new(State {
                next_conn: 1,
                next_call: 1,
                segments: segments.clone(),
                ..State::default()
            })),
            limits,
            timer: deadlines::CallTimer::default(),
            segments,
        }
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        lock_state(&self.state)
    }

    // ------------------------------------------------------------ connections

    /// Registers a new, not yet logged-in connection.
    pub fn connect(&self, peer: &str) -> (ConnId, Arc<Outbox>) {
        let outbox = Arc::new(Outbox::new(self.limits.outbox));
        let mut st = self.lock();
        let id = st.next_conn;
        st.next_conn = st.next_conn.wrapping_add(1).max(1);
        st.conns.insert(
            id,
            Conn {
                label: format!("{peer}#{id}"),
                transport: peer.split(':').next().unwrap_or(peer).to_string(),
                outbox: outbox.clone(),
                is_async: false,
                admin: false,
                owned: BTreeSet::new(),
                subs: BTreeSet::new(),
            },
        );
        (id, outbox)
    }

    /// Records the login name and rights of a connection.
    pub fn login(&self, conn: ConnId, name: &str, admin: bool) {
        if let Some(c) = self.lock().conns.get_mut(&conn) {
            c.label = format!("{name}#{conn}");
            c.admin = admin;
        }
    }

    /// Starts delivering events to a connection.
    pub fn set_async(&self, conn: ConnId) {
        if let Some(c) = self.lock().conns.get_mut(&conn) {
            c.is_async = true;
        }
    }

    /// Forgets a connection: its channels are removed (everyone is told), its
    /// subscriptions end, and calls to its services fail.
    pub fn disconnect(&self, conn: ConnId) {
        let mut st = self.lock();
        let Some(c) = st.conns.remove(&conn) else {
            return;
        };
        for chan in c.subs {
            unsubscribe_locked(&mut st, conn, chan);
        }
        for chan in c.owned {
            remove_channel_locked(&mut st, chan);
        }
        // Calls this connection was waiting on: nobody will read the answers.
        let abandoned: Vec<CallId> = st
            .calls
            .iter()
            .filter(|(_, p)| p.caller == conn)
            .map(|(k, _)| *k)
            .collect();
        for call in abandoned {
            finish_call(&mut st, call);
        }
    }

    /// Sends a goodbye to every connection and closes their outboxes.
    pub fn shutdown(&self, reason: &str) {
        let st = self.lock();
        for c in st.conns.values() {
            c.outbox.push_control(Event::Goodbye {
                reason: reason.to_string(),
            });
            c.outbox.close(reason);
        }
    }

    pub fn connection_count(&self) -> usize {
        self.lock().conns.len()
    }

    // ------------------------------------------------------------ channels

    /// Creates a channel owned by `conn`.
    pub fn add_channel(
        &self,
        conn: ConnId,
        kind: ChannelKind,
        name: &str,
        header: &str,
    ) -> HubResult<ChannelInfo> {
        if let Err(reason) = validate_name(name) {
            return err(
                ErrorCode::BadRequest,
                format!("channel name {name:?}: {reason}"),
            );
        }
        let mut st = self.lock();
        let Some(owner) = st.conns.get(&conn) else {
            return err(ErrorCode::Internal, "unknown connection");
        };
        if kind == ChannelKind::Service && !owner.is_async {
            return err(
                ErrorCode::BadRequest,
                "a service owner must be an asynchronous connection",
            );
        }
        let owner_label = owner.label.clone();
        if st.by_name.contains_key(name) {
            return err(ErrorCode::Exists, format!("channel {name} already exists"));
        }
        let hash = channel_hash(name);
        if st.by_hash.contains_key(&hash) {
            return err(
                ErrorCode::Exists,
                format!("channel {name} collides with another channel's hash"),
            );
        }
        if st.channels.len() >= self.limits.max_channels.min(MAX_CHANNELS) {
            return err(ErrorCode::Limit, "too many channels");
        }
        // Ids rotate instead of reusing the lowest free one, so a late message
        // for a removed channel cannot land on its successor.
        let id = loop {
            let candidate = (st.next_id % MAX_CHANNELS as u16) as ChanId;
            st.next_id = st.next_id.wrapping_add(1) % MAX_CHANNELS as u16;
            if !st.channels.contains_key(&candidate) {
                break candidate;
            }
        };
        let channel = Channel {
            id,
            hash,
            kind,
            name: name.to_string(),
            owner: conn,
            owner_label,
            header: header.to_string(),
            subscribers: Vec::new(),
            seq: 0,
            msgs: 0,
            bytes: 0,
            dropped: 0,
            inflight: 0,
            rate: Rate::default(),
        };
        let info = channel.info();
        st.channels.insert(id, channel);
        st.by_name.insert(name.to_string(), id);
        st.by_hash.insert(hash, id);
        if let Some(owner) = st.conns.get_mut(&conn) {
            owner.owned.insert(id);
        }
        broadcast(&st, |_| Event::ChannelAdded(info.clone()));
        Ok(info)
    }

    /// Removes a channel; only its owner or an admin may.
    pub fn remove_channel(&self, conn: ConnId, chan: &ChanRef) -> HubResult<()> {
        let mut st = self.lock();
        let id = resolve(&st, chan)?;
        let admin = st.conns.get(&conn).is_some_and(|c| c.admin);
        let owner = st.channels.get(&id).map(|c| c.owner);
        if owner != Some(conn) && !admin {
            return err(
                ErrorCode::NotOwner,
                format!("channel {chan} belongs to someone else"),
            );
        }
        remove_channel_locked(&mut st, id);
        Ok(())
    }

    /// Replaces a channel's JSON header; owner only.
    pub fn set_header(&self, conn: ConnId, id: ChanId, header: &str) -> HubResult<()> {
        let mut st = self.lock();
        let ch = owned_channel(&mut st, conn, id)?;
        ch.header = header.to_string();
        let (name, header) = (ch.name.clone(), ch.header.clone());
        broadcast(&st, |_| Event::HeaderChanged {
            id,
            name: name.clone(),
            header: header.clone(),
        });
        Ok(())
    }

    /// Subscribes `conn` to a streaming channel with no request to answer (the unit tests' way in).
    #[cfg(test)]
    pub fn subscribe(&self, conn: ConnId, chan: &ChanRef) -> HubResult<ChannelInfo> {
        self.subscribe_acked(conn, chan, 0)
    }

    /// Subscribes `conn` to a streaming channel (idempotent) and, when `req` is not 0, queues the reply to request `req` on the subscriber's control
    /// lane under the same lock, before any publish can queue data for it. A client learns the channel's id from
    /// that reply, so its first data event must not overtake it: the owner hears of its first subscriber at
    /// once and may publish before the session would have queued the reply, and a message the client cannot
    /// place is lost.
    pub fn subscribe_acked(
        &self,
        conn: ConnId,
        chan: &ChanRef,
        req: ReqId,
    ) -> HubResult<ChannelInfo> {
        let mut st = self.lock();
        let id = resolve(&st, chan)?;
        let Some(c) = st.conns.get(&conn) else {
            return err(ErrorCode::Internal, "unknown connection");
        };
        if !c.is_async {
            return err(
                ErrorCode::BadRequest,
                "subscribing needs an asynchronous connection",
            );
        }
        let outbox = c.outbox.clone();
        let Some(ch) = st.channels.get_mut(&id) else {
            return err(ErrorCode::NotFound, "no such channel");
        };
        if ch.kind != ChannelKind::Stream {
            return err(
                ErrorCode::WrongKind,
                format!("{} is a service channel; call it instead", ch.name),
            );
        }
        if !ch.subscribers.iter().any(|(c, _)| *c == conn) {
            ch.subscribers.push((conn, outbox.clone()));
            if ch.subscribers.len() == 1 {
                let owner = ch.owner;
                notify_owner(&st, owner, Event::StartPublishing { id });
            }
        }
        let info = st
            .channels
            .get(&id)
            .map(Channel::info)
            .ok_or_else(|| ErrorReply::new(ErrorCode::Internal, "channel vanished"))?;
        // Still under the lock that every publish takes, so no data event for this subscriber is queued yet.
        if req != 0 {
            outbox.push_control(Event::Reply {
                req,
                result: Ok(Reply::Channel(info.clone())),
            });
        }
        if let Some(c) = st.conns.get_mut(&conn) {
            c.subs.insert(id);
        }
        Ok(info)
    }

    /// Ends a subscription; not being subscribed is not an error.
    pub fn unsubscribe(&self, conn: ConnId, chan: &ChanRef) -> HubResult<()> {
        let mut st = self.lock();
        let id = resolve(&st, chan)?;
        unsubscribe_locked(&mut st, conn, id);
        if let Some(c) = st.conns.get_mut(&conn) {
            c.subs.remove(&id);
        }
        Ok(())
    }

    /// Fans a message out to every subscriber of a stream; owner only. Never
    /// blocks: a subscriber that fell behind loses its oldest queued message.
    pub fn publish(&self, conn: ConnId, id: ChanId, payload: Bytes) -> HubResult<()> {
        let mut st = self.lock();
        let ch = owned_stream(&mut st, conn, id)?;
        ch.seq += 1;
        ch.msgs += 1;
        let len = payload.len();
        ch.bytes += len as u64;
        let event = Event::Data {
            chan: id,
            seq: ch.seq,
            ts_us: now_us(),
            payload,
        };
        let mut dropped = 0;
        for (_, outbox) in &ch.subscribers {
            dropped += outbox.push_data(id, event.clone(), len).dropped;
        }
        ch.dropped += dropped as u64;
        Ok(())
    }

    /// The shared-memory segments (their settings, figures, and the slots payloads lie in).
    pub fn segments(&self) -> Arc<Segments> {
        self.segments.clone()
    }

    /// A shared-memory segment for `conn`'s stream `id`, with slots of at least `slot_size` bytes.
    pub fn shm_open(&self, conn: ConnId, id: ChanId, slot_size: u32) -> HubResult<SegmentInfo> {
        let mut st = self.lock();
        owned_stream(&mut st, conn, id)?;
        drop(st);
        self.segments
            .open(conn, id, slot_size)
            .or_else(|e| err(ErrorCode::Limit, e))
    }

    /// Publishes the message `conn` wrote into a slot of its segment on `id`, like [`Hub::publish`]; the slot is
    /// freed once nobody holds the message.
    pub fn publish_ref(&self, conn: ConnId, id: ChanId, slot: SlotRef) -> Result<(), LeaseError> {
        let payload = self.segments.lease(conn, id, slot)?;
        self.publish(conn, id, payload)
            .map_err(|e| LeaseError::Unknown(e.message))
    }

    /// Forwards a service request to the channel's owner; the reply to the
    /// caller comes later from [`Hub::respond`], or as `Timeout` once
    /// `timeout_ms` (clamped to 1 ms ..= [`MAX_CALL_TIMEOUT_MS`]) has passed.
    /// The hub's one timer task meets the deadline; no task waits per call.
    pub fn call(
        &self,
        conn: ConnId,
        req: ReqId,
        chan: &ChanRef,
        payload: Bytes,
        timeout_ms: u32,
    ) -> HubResult<CallId> {
        let mut st = self.lock();
        let id = resolve(&st, chan)?;
        let limit = self.limits.service_inflight;
        let Some(ch) = st.channels.get_mut(&id) else {
            return err(ErrorCode::NotFound, "no such channel");
        };
        if ch.kind != ChannelKind::Service {
            return err(
                ErrorCode::WrongKind,
                format!("{} is a streaming channel", ch.name),
            );
        }
        if ch.inflight >= limit {
            let message = format!("{} already has {limit} calls in flight", ch.name);
            let name = ch.name.clone();
            outcomes(&mut st, &name).overloaded += 1;
            return err(ErrorCode::Overloaded, message);
        }
        ch.inflight += 1;
        ch.msgs += 1;
        ch.bytes += payload.len() as u64;
        let owner = ch.owner;
        let call = st.next_call;
        st.next_call += 1;
        let (deadline, timeout_ms) = deadlines::deadline(Instant::now(), timeout_ms);
        st.calls.insert(
            call,
            PendingCall {
                caller: conn,
                req,
                chan: id,
                deadline,
                timeout_ms,
            },
        );
        st.deadlines.insert((deadline, call));
        let delivered = st.conns.get(&owner).is_some_and(|o| {
            o.outbox.push_control(Event::ServiceRequest {
                chan: id,
                call,
                payload,
            })
        });
        if !delivered {
            finish_call(&mut st, call);
            if let Some(o) = outcomes_of(&mut st, id) {
                o.gone += 1;
            }
            return err(ErrorCode::ServiceGone, "the service owner is not reachable");
        }
        let earliest = st.deadlines.first().is_some_and(|&(_, c)| c == call);
        drop(st);
        if earliest {
            // The timer sleeps until a later deadline, or not at all: wake it.
            self.timer.earlier(&self.state, expire_due_locked);
        }
        Ok(call)
    }

    /// Delivers a service owner's response to the caller.
    pub fn respond(
        &self,
        conn: ConnId,
        call: CallId,
        result: Result<Bytes, String>,
    ) -> HubResult<()> {
        let mut st = self.lock();
        let Some(pending) = st.calls.get(&call) else {
            // Late (after the timeout) or duplicate: the caller already has its answer.
            return Ok(());
        };
        if st.channels.get(&pending.chan).map(|c| c.owner) != Some(conn) {
            return err(ErrorCode::NotOwner, "only the service owner may respond");
        }
        let Some(pending) = finish_call(&mut st, call) else {
            return Ok(());
        };
        if let Some(o) = outcomes_of(&mut st, pending.chan) {
            match &result {
                Ok(_) => o.answered += 1,
                Err(_) => o.failed += 1,
            }
        }
        let result = match result {
            Ok(payload) => Ok(Reply::Payload(payload)),
            Err(message) => Err(ErrorReply::new(ErrorCode::ServiceFailed, message)),
        };
        reply_to(&st, pending.caller, pending.req, result);
        Ok(())
    }

    /// Fails every call whose deadline is at or before `now` with `Timeout`
    /// and returns the next deadline. The timer task calls this; tests call
    /// it with a `now` of their choosing.
    pub fn expire_due(&self, now: Instant) -> Option<Instant> {
        expire_due_locked(&mut self.lock(), now)
    }

    // ------------------------------------------------------------ queries

    pub fn list_channels(&self) -> Vec<ChannelInfo> {
        let st = self.lock();
        let mut list: Vec<_> = st.channels.values().map(Channel::info).collect();
        list.sort_by_key(|c| c.id);
        list
    }

    pub fn channel(&self, chan: &ChanRef) -> HubResult<ChannelInfo> {
        let st = self.lock();
        let id = resolve(&st, chan)?;
        st.channels
            .get(&id)
            .map(Channel::info)
            .ok_or_else(|| ErrorReply::new(ErrorCode::NotFound, "no such channel"))
    }

    /// Every connection and every channel between them, with their rates: the application graph.
    pub fn graph(&self) -> Graph {
        graph_of(&self.lock())
    }

    /// Open connections by transport (`tcp`, `unix`, `ws`, `module`).
    pub fn connections_by_transport(&self) -> std::collections::BTreeMap<String, usize> {
        let st = self.lock();
        let mut by = std::collections::BTreeMap::new();
        for c in st.conns.values() {
            *by.entry(c.transport.clone()).or_insert(0) += 1;
        }
        by
    }

    /// How calls to each service have ended, by service name.
    pub fn service_calls(&self) -> Vec<(String, CallOutcomes)> {
        let st = self.lock();
        let mut list: Vec<_> = st
            .call_outcomes
            .iter()
            .map(|(name, o)| (name.clone(), *o))
            .collect();
        list.sort_by(|a, b| a.0.cmp(&b.0));
        list
    }

    /// Updates each channel's msgs/s and bytes/s; call about once a second.
    pub fn update_rates(&self) {
        let mut st = self.lock();
        let now = Instant::now();
        let elapsed = st
            .last_rate
            .map(|t| now.duration_since(t).as_secs_f32())
            .unwrap_or(0.0);
        st.last_rate = Some(now);
        for ch in st.channels.values_mut() {
            if elapsed > 0.0 {
                ch.rate.msgs_per_s = (ch.msgs - ch.rate.last_msgs) as f32 / elapsed;
                ch.rate.bytes_per_s = (ch.bytes - ch.rate.last_bytes) as f32 / elapsed;
            }
            ch.rate.last_msgs = ch.msgs;
            ch.rate.last_bytes = ch.bytes;
        }
    }
}

impl Channel {
    fn info(&self) -> ChannelInfo {
        ChannelInfo {
            id: self.id,
            hash: self.hash,
            kind: self.kind,
            name: self.name.clone(),
            owner: self.owner_label.clone(),
            header: self.header.clone(),
            stats: ChannelStats {
                subscribers: self.subscribers.len() as u32,
                msgs: self.msgs,
                bytes: self.bytes,
                dropped: self.dropped,
                msgs_per_s: self.rate.msgs_per_s,
                bytes_per_s: self.rate.bytes_per_s,
            },
        }
    }
}

fn resolve(st: &State, chan: &ChanRef) -> HubResult<ChanId> {
    let found = match chan {
        ChanRef::Id(id) => st.channels.contains_key(id).then_some(*id),
        ChanRef::Name(name) => st.by_name.get(name).copied(),
    };
    found.ok_or_else(|| ErrorReply::new(ErrorCode::NotFound, format!("no channel {chan}")))
}

fn owned_channel(st: &mut State, conn: ConnId, id: ChanId) -> HubResult<&mut Channel> {
    let Some(ch) = st.channels.get_mut(&id) else {
        return err(ErrorCode::NotFound, format!("no channel #{id}"));
    };
    if ch.owner != conn {
        return err(
            ErrorCode::NotOwner,
            format!("channel {} belongs to {}", ch.name, ch.owner_label),
        );
    }
    Ok(ch)
}

/// [`owned_channel`], which must be a stream: what a publisher may write to.
fn owned_stream(st: &mut State, conn: ConnId, id: ChanId) -> HubResult<&mut Channel> {
    let ch = owned_channel(st, conn, id)?;
    if ch.kind != ChannelKind::Stream {
        return err(
            ErrorCode::WrongKind,
            format!("{} is a service channel", ch.name),
        );
    }
    Ok(ch)
}

/// Queues an event for every asynchronous connection.
fn broadcast(st: &State, event: impl Fn(ConnId) -> Event) {
    broadcast_except(st, &[], event);
}

/// [`broadcast`] to every async connection but those in `skip`.
fn broadcast_except(st: &State, skip: &[ConnId], event: impl Fn(ConnId) -> Event) {
    for (id, c) in &st.conns {
        if c.is_async && !skip.contains(id) {
            c.outbox.push_control(event(*id));
        }
    }
}

fn notify_owner(st: &State, owner: ConnId, event: Event) {
    if let Some(c) = st.conns.get(&owner).filter(|c| c.is_async) {
        c.outbox.push_control(event);
    }
}

fn reply_to(st: &State, conn: ConnId, req: ReqId, result: Result<Reply, ErrorReply>) {
    if let Some(c) = st.conns.get(&conn) {
        c.outbox.push_control(Event::Reply { req, result });
    }
}

/// Takes a call out of the pending ones, deadline included, wherever it is answered.
fn take_call(st: &mut State, call: CallId) -> Option<PendingCall> {
    let pending = st.calls.remove(&call)?;
    st.deadlines.remove(&(pending.deadline, call));
    Some(pending)
}

fn finish_call(st: &mut State, call: CallId) -> Option<PendingCall> {
    let pending = take_call(st, call)?;
    if let Some(ch) = st.channels.get_mut(&pending.chan) {
        ch.inflight = ch.inflight.saturating_sub(1);
    }
    Some(pending)
}

/// [`Hub::expire_due`] under the lock the caller holds.
fn expire_due_locked(st: &mut State, now: Instant) -> Option<Instant> {
    while let Some(&(deadline, call)) = st.deadlines.first() {
        if deadline > now {
            return Some(deadline);
        }
        let Some(pending) = finish_call(st, call) else {
            // A deadline without its call cannot happen (both go together);
            // drop it rather than spin on it.
            st.deadlines.remove(&(deadline, call));
            continue;
        };
        let name = st
            .channels
            .get(&pending.chan)
            .map(|c| c.name.clone())
            .unwrap_or_default();
        let message = format!(
            "service {name} did not answer within {} ms",
            pending.timeout_ms
        );
        outcomes(st, &name).timeout += 1;
        reply_to(
            st,
            pending.caller,
            pending.req,
            Err(ErrorReply::new(ErrorCode::Timeout, message)),
        );
    }
    None
}

fn unsubscribe_locked(st: &mut State, conn: ConnId, id: ChanId) {
    let Some(ch) = st.channels.get_mut(&id) else {
        return;
    };
    let before = ch.subscribers.len();
    ch.subscribers.retain(|(c, _)| *c != conn);
    let now_empty = before > 0 && ch.subscribers.is_empty();
    let owner = ch.owner;
    if let Some(c) = st.conns.get(&conn) {
        c.outbox.drop_lane(id);
    }
    if now_empty {
        notify_owner(st, owner, Event::StopPublishing { id });
    }
}

fn remove_channel_locked(st: &mut State, id: ChanId) {
    let Some(ch) = st.channels.remove(&id) else {
        return;
    };
    st.segments.retire_channel(id);
    st.by_name.remove(&ch.name);
    st.by_hash.remove(&ch.hash);
    if let Some(owner) = st.conns.get_mut(&ch.owner) {
        owner.owned.remove(&id);
    }
    // Subscribers still get what they have queued (it was published before
    // the removal), then the removal; everyone else hears of it at once.
    let removed = Event::ChannelRemoved {
        id,
        name: ch.name.clone(),
    };
    for (sub, outbox) in &ch.subscribers {
        outbox.push_after_lane(id, removed.clone());
        if let Some(c) = st.conns.get_mut(sub) {
            c.subs.remove(&id);
        }
    }
    // Calls waiting on this service will never be answered: fail them now.
    let orphaned: Vec<CallId> = st
        .calls
        .iter()
        .filter(|(_, p)| p.chan == id)
        .map(|(k, _)| *k)
        .collect();
    for call in orphaned {
        if let Some(p) = take_call(st, call) {
            outcomes(st, &ch.name).gone += 1;
            let e = ErrorReply::new(
                ErrorCode::ServiceGone,
                format!("service {} went away", ch.name),
            );
            reply_to(st, p.caller, p.req, Err(e));
        }
    }
    let subscribers: Vec<ConnId> = ch.subscribers.iter().map(|(c, _)| *c).collect();
    broadcast_except(st, &subscribers, |_| removed.clone());
}

/// The graph of the hub's state now.
fn graph_of(st: &State) -> Graph {
    let mut nodes: Vec<GraphNode> = st
        .conns
        .iter()
        .map(|(&id, c)| GraphNode {
            id,
            name: c
                .label
                .rsplit_once('#')
                .map_or(c.label.as_str(), |(n, _)| n)
                .to_string(),
            label: c.label.clone(),
            transport: c.transport.clone(),
        })
        .collect();
    nodes.sort_by_key(|n| n.id);
    let mut channels: Vec<GraphChannel> = st
        .channels
        .values()
        .map(|ch| {
            let mut to: Vec<ConnId> = ch.subscribers.iter().map(|(c, _)| *c).collect();
            to.sort_unstable();
            GraphChannel {
                name: ch.name.clone(),
                kind: ch.kind.as_str(),
                from: ch.owner,
                to,
                msgs_per_s: ch.rate.msgs_per_s,
                bytes_per_s: ch.rate.bytes_per_s,
                dropped: ch.dropped,
            }
        })
        .collect();
    channels.sort_by(|a, b| a.name.cmp(&b.name));
    Graph { nodes, channels }
}

#[cfg(test)]
mod tests;
