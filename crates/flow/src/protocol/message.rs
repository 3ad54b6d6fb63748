//! FlowProtocol messages as plain Rust values, apart from their encoding.
//!
//! Every message travels in a frame (see [`super::frame`]): `len:u32 | op:u8 |
//! req:u32 | body`. The diagrams below show only the body. Primitive encodings
//! (all little-endian):
//!
//! ```text
//! str   = len:u16 | UTF-8 bytes            (names, tokens, messages)
//! text  = len:u32 | UTF-8 bytes            (JSON documents)
//! chref = 0:u8 | id:i16                    (a channel by id)
//!       | 1:u8 | name:str                  (a channel by name)
//! rest  = every remaining byte of the frame (payloads; never length-prefixed)
//! ```
//!
//! Commands flow from a client to the hub, each with a request id in the frame
//! header (`req`). The hub answers a command with [`Event::Reply`] carrying the
//! same `req` unless `req` is 0, which asks for no answer (fire-and-forget, the
//! way `Publish` is normally sent). Events flow from the hub to the client; only
//! replies are sent to a synchronous connection, every event kind to an
//! asynchronous one.

use bytes::Bytes;

/// Channel identifier: unique while the channel exists, `0..=32767`.
pub type ChanId = i16;
/// Request id chosen by the client; echoed in the reply.
pub type ReqId = u32;
/// Service call id chosen by the hub; the owner echoes it in its response.
pub type CallId = u64;

/// Protocol version spoken by this crate, checked at login.
pub const PROTOCOL_VERSION: u16 = 1;

/// Kind of a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ChannelKind {
    /// 1:N streaming: the owner publishes, every subscriber receives.
    Stream,
    /// 1:1 request/response: callers send requests, the owner answers each.
    Service,
}

impl ChannelKind {
    pub fn as_str(self) -> &'static str {
        match self {
            ChannelKind::Stream => "stream",
            ChannelKind::Service => "service",
        }
    }
}

/// A channel named either way.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum ChanRef {
    Id(ChanId),
    Name(String),
}

impl std::fmt::Display for ChanRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ChanRef::Id(id) => write!(f, "#{id}"),
            ChanRef::Name(name) => f.write_str(name),
        }
    }
}

/// Live counters of a channel.
///
/// ```text
/// subscribers:u32 | msgs:u64 | bytes:u64 | dropped:u64 | msgs_per_s:f32 | bytes_per_s:f32
/// ```
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ChannelStats {
    pub subscribers: u32,
    /// Messages published since the channel was created.
    pub msgs: u64,
    /// Payload bytes published since the channel was created.
    pub bytes: u64,
    /// Messages dropped for subscribers that fell behind.
    pub dropped: u64,
    pub msgs_per_s: f32,
    pub bytes_per_s: f32,
}

/// Everything known about a channel.
///
/// ```text
/// id:i16 | hash:u64 | kind:u8 (0 stream, 1 service) | name:str | owner:str | header:text | stats
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelInfo {
    pub id: ChanId,
    /// FNV-1a 64 of the name; unique like the id and the name.
    pub hash: u64,
    pub kind: ChannelKind,
    pub name: String,
    /// Who created it: a satellite's login name with its connection number, or a module.
    pub owner: String,
    /// JSON object describing the data, e.g. `{"mime":"audio/pcm","rate":22050}`.
    pub header: String,
    pub stats: ChannelStats,
}

/// A command with the request id of its frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Envelope {
    pub req: ReqId,
    pub command: Command,
}

/// Client -> hub commands. The opcode of each is in brackets.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// [0x01] `version:u16 | token:str | name:str`. The only command accepted before authentication.
    Login {
        version: u16,
        token: String,
        name: String,
    },
    /// [0x02] empty. Switches the connection to asynchronous: events start flowing.
    SetAsync,
    /// [0x03] `kind:u8 | name:str | header:text`. Replies with the new channel's info.
    AddChannel {
        kind: ChannelKind,
        name: String,
        header: String,
    },
    /// [0x04] `chan:chref`. Owner (or admin) only.
    RemoveChannel { chan: ChanRef },
    /// [0x05] `chan:i16 | header:text`. Owner only.
    SetHeader { chan: ChanId, header: String },
    /// [0x06] `chan:chref`.
    Subscribe { chan: ChanRef },
    /// [0x07] `chan:chref`.
    Unsubscribe { chan: ChanRef },
    /// [0x08] `chan:i16 | payload:rest`. Owner only, stream channels only.
    Publish { chan: ChanId, payload: Bytes },
    /// [0x09] `chan:chref | timeout_ms:u32 | payload:rest`. The reply carries the
    /// owner's response, or an error when the owner is gone, overloaded, fails or
    /// does not answer within the timeout.
    Call {
        chan: ChanRef,
        timeout_ms: u32,
        payload: Bytes,
    },
    /// [0x0a] `call:u64 | status:u8 (0 ok, 1 error) | payload:rest`. A service owner's
    /// answer to [`Event::ServiceRequest`]; an error payload is a UTF-8 message.
    Respond {
        call: CallId,
        result: Result<Bytes, String>,
    },
    /// [0x0b] empty. Replies with every channel.
    ListChannels,
    /// [0x0c] `chan:chref`. Replies with one channel.
    GetChannel { chan: ChanRef },
    /// [0x10] `name:str`. Selects this connection's current pair database.
    DbSelect { name: String },
    /// [0x11] `name:str`.
    DbCreate { name: String },
    /// [0x12] `name:str`. Removes a database and all its variables.
    DbRemove { name: String },
    /// [0x13] empty. Replies with the database names.
    DbList,
    /// [0x14] `key:str | value:text`. Replies once the write is durable.
    VarSet { key: String, value: String },
    /// [0x15] `key:str`. Replies with the JSON value.
    VarGet { key: String },
    /// [0x16] `key:str`.
    VarDel { key: String },
    /// [0x17] empty. Replies with the keys of the current database.
    VarList,
    /// [0x1f] empty. Replies `Pong`; keeps idle links honest.
    Ping,
    /// [0x18] empty. This connection takes shared memory: segments handed over with their descriptors and messages
    /// by reference ([`Event::Segment`], [`Event::DataRef`]). Unix socket only. Replies [`Reply::Shm`].
    ShmAccept,
    /// [0x19] `chan:i16 | slot_size:u32`. Asks for a segment to publish on `chan` (owner only) with slots of at least
    /// `slot_size` bytes. Replies [`Reply::Segment`]; the segment's descriptor travels with the reply.
    ShmOpen { chan: ChanId, slot_size: u32 },
    /// [0x1a] `chan:i16 | slot-ref`. Publishes the message the owner wrote into a slot of its segment on `chan`.
    PublishRef { chan: ChanId, slot: SlotRef },
    /// [0x1b] `count:u16 | slot-ref * count`. Gives back slots received by reference ([`Event::DataRef`]). With a
    /// release ring ([`Event::ReleaseRing`]) the slots go there instead, and an empty `Release` rings the hub: look
    /// at the ring now.
    Release { slots: Vec<SlotRef> },
}

/// A message in a slot of a shared-memory segment: `segment:u32 | slot:u32 | len:u32` (`slot-ref`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SlotRef {
    pub segment: u32,
    pub slot: u32,
    /// Bytes of the message, from the start of the slot.
    pub len: u32,
}

/// A shared-memory segment: `id:u32 | chan:i16 | slots:u32 | slot_size:u32` (`segment-info`). Its layout is in
/// [`crate::shm::layout`]; its descriptor is passed beside the frame (`SCM_RIGHTS`), read-write to the publisher,
/// read-only to subscribers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SegmentInfo {
    pub id: u32,
    /// The channel the segment carries (its messages are published there only).
    pub chan: ChanId,
    pub slots: u32,
    pub slot_size: u32,
}

/// Successful reply bodies. Each starts with a tag byte so a reply decodes
/// without knowing which command it answers.
///
/// ```text
/// 0 Done                                   (empty)
/// 1 LoginOk   version:u16 | conn:u32 | admin:u8 | server:str
/// 2 Channel   channel-info
/// 3 Channels  count:u16 | channel-info * count
/// 4 Value     json:text
/// 5 Names     count:u32 | str * count
/// 6 Payload   rest
/// 7 Pong      (empty)
/// 8 Shm       threshold:u32                (shared memory on; payloads from this size go by reference)
/// 9 Segment   segment-info                 (its descriptor travels beside the frame)
/// ```
#[derive(Debug, Clone, PartialEq)]
pub enum Reply {
    Done,
    LoginOk {
        version: u16,
        conn: u32,
        admin: bool,
        server: String,
    },
    Channel(ChannelInfo),
    Channels(Vec<ChannelInfo>),
    Value(String),
    Names(Vec<String>),
    Payload(Bytes),
    Pong,
    Shm {
        threshold: u32,
    },
    Segment(SegmentInfo),
}

/// Why a command failed. On the wire a failed reply is tag `0xff | code:u16 | message:str`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorCode {
    BadRequest = 1,
    AuthFailed = 2,
    NotAuthenticated = 3,
    VersionMismatch = 4,
    NotFound = 5,
    Exists = 6,
    NotOwner = 7,
    WrongKind = 8,
    Limit = 9,
    Timeout = 10,
    Overloaded = 11,
    ServiceGone = 12,
    ServiceFailed = 13,
    Database = 14,
    ShuttingDown = 15,
    Internal = 16,
    /// The pair database named by `DbSelect`, or the connection's current one,
    /// does not exist. Distinct from `NotFound`, which `VarGet` answers for a
    /// key that is not in an existing database.
    NoDatabase = 17,
}

impl ErrorCode {
    /// Every code, in wire order.
    pub const ALL: [ErrorCode; 17] = [
        ErrorCode::BadRequest,
        ErrorCode::AuthFailed,
        ErrorCode::NotAuthenticated,
        ErrorCode::VersionMismatch,
        ErrorCode::NotFound,
        ErrorCode::Exists,
        ErrorCode::NotOwner,
        ErrorCode::WrongKind,
        ErrorCode::Limit,
        ErrorCode::Timeout,
        ErrorCode::Overloaded,
        ErrorCode::ServiceGone,
        ErrorCode::ServiceFailed,
        ErrorCode::Database,
        ErrorCode::ShuttingDown,
        ErrorCode::Internal,
        ErrorCode::NoDatabase,
    ];

    pub fn from_u16(code: u16) -> Option<Self> {
        use ErrorCode::*;
        Some(match code {
            1 => BadRequest,
            2 => AuthFailed,
            3 => NotAuthenticated,
            4 => VersionMismatch,
            5 => NotFound,
            6 => Exists,
            7 => NotOwner,
            8 => WrongKind,
            9 => Limit,
            10 => Timeout,
            11 => Overloaded,
            12 => ServiceGone,
            13 => ServiceFailed,
            14 => Database,
            15 => ShuttingDown,
            16 => Internal,
            17 => NoDatabase,
            _ => return None,
        })
    }
}

/// A failed command: a code for programs and a message for people.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ErrorReply {
    pub code: ErrorCode,
    pub message: String,
}

impl ErrorReply {
    pub fn new(code: ErrorCode, message: impl Into<String>) -> Self {
        ErrorReply {
            code,
            message: message.into(),
        }
    }
}

impl std::fmt::Display for ErrorReply {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:?}: {}", self.code, self.message)
    }
}

/// Hub -> client messages. The opcode of each is in brackets; `req` in the frame
/// header is the request id for `Reply` and 0 otherwise.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// [0x80] `tag:u8 | reply-body` (see [`Reply`]) or `0xff | code:u16 | message:str`.
    Reply {
        req: ReqId,
        result: Result<Reply, ErrorReply>,
    },
    /// [0x81] `channel-info`. To every asynchronous connection.
    ChannelAdded(ChannelInfo),
    /// [0x82] `id:i16 | name:str`. To every asynchronous connection.
    ChannelRemoved { id: ChanId, name: String },
    /// [0x83] `id:i16 | name:str | header:text`. To every asynchronous connection.
    HeaderChanged {
        id: ChanId,
        name: String,
        header: String,
    },
    /// [0x84] `id:i16`. To the owner: the first subscriber arrived, start publishing.
    StartPublishing { id: ChanId },
    /// [0x85] `id:i16`. To the owner: the last subscriber left, stop publishing.
    StopPublishing { id: ChanId },
    /// [0x86] `chan:i16 | call:u64 | payload:rest`. To a service owner.
    ServiceRequest {
        chan: ChanId,
        call: CallId,
        payload: Bytes,
    },
    /// [0x87] `chan:i16 | seq:u64 | ts_us:u64 | payload:rest`. To subscribers.
    /// `seq` counts messages on the channel from 1 (gaps mean drops); `ts_us` is
    /// the hub's clock (µs since the Unix epoch) when the message was published,
    /// identical for every subscriber.
    Data {
        chan: ChanId,
        seq: u64,
        ts_us: u64,
        payload: Bytes,
    },
    /// [0x88] `name:str`. To the connection that selected a new current database.
    DbChanged { name: String },
    /// [0x89] `reason:str`. The hub is closing this connection (shutdown, overflow).
    Goodbye { reason: String },
    /// [0x8a] `segment-info`. A segment whose messages follow by reference; its read-only descriptor travels beside
    /// the frame. Sent once per segment and connection, before the first [`Event::DataRef`] into it.
    Segment(SegmentInfo),
    /// [0x8b] `chan:i16 | seq:u64 | ts_us:u64 | slot-ref`. [`Event::Data`] whose payload lies in a shared-memory slot;
    /// the slot is the subscriber's until it gives it back with [`Command::Release`].
    DataRef {
        chan: ChanId,
        seq: u64,
        ts_us: u64,
        slot: SlotRef,
    },
    /// [0x8c] `capacity:u32`. The ring where this subscriber may give slots back without a frame each
    /// ([`crate::shm::ring`]); its read-write descriptor travels beside the frame. Sent once per connection, before
    /// its first [`Event::Segment`]. A client that never maps it gives slots back with [`Command::Release`] as before.
    ReleaseRing { capacity: u32 },
}

/// Opcodes, shared by the encoder and decoder.
pub mod op {
    pub const LOGIN: u8 = 0x01;
    pub const SET_ASYNC: u8 = 0x02;
    pub const ADD_CHANNEL: u8 = 0x03;
    pub const REMOVE_CHANNEL: u8 = 0x04;
    pub const SET_HEADER: u8 = 0x05;
    pub const SUBSCRIBE: u8 = 0x06;
    pub const UNSUBSCRIBE: u8 = 0x07;
    pub const PUBLISH: u8 = 0x08;
    pub const CALL: u8 = 0x09;
    pub const RESPOND: u8 = 0x0a;
    pub const LIST_CHANNELS: u8 = 0x0b;
    pub const GET_CHANNEL: u8 = 0x0c;
    pub const DB_SELECT: u8 = 0x10;
    pub const DB_CREATE: u8 = 0x11;
    pub const DB_REMOVE: u8 = 0x12;
    pub const DB_LIST: u8 = 0x13;
    pub const VAR_SET: u8 = 0x14;
    pub const VAR_GET: u8 = 0x15;
    pub const VAR_DEL: u8 = 0x16;
    pub const VAR_LIST: u8 = 0x17;
    pub const PING: u8 = 0x1f;
    pub const SHM_ACCEPT: u8 = 0x18;
    pub const SHM_OPEN: u8 = 0x19;
    pub const PUBLISH_REF: u8 = 0x1a;
    pub const RELEASE: u8 = 0x1b;

    pub const REPLY: u8 = 0x80;
    pub const CHANNEL_ADDED: u8 = 0x81;
    pub const CHANNEL_REMOVED: u8 = 0x82;
    pub const HEADER_CHANGED: u8 = 0x83;
    pub const START_PUBLISHING: u8 = 0x84;
    pub const STOP_PUBLISHING: u8 = 0x85;
    pub const SERVICE_REQUEST: u8 = 0x86;
    pub const DATA: u8 = 0x87;
    pub const DB_CHANGED: u8 = 0x88;
    pub const GOODBYE: u8 = 0x89;
    pub const SEGMENT: u8 = 0x8a;
    pub const DATA_REF: u8 = 0x8b;
    pub const RELEASE_RING: u8 = 0x8c;
}

/// FNV-1a 64-bit hash of a channel name: stable across processes and versions.
pub fn channel_hash(name: &str) -> u64 {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for byte in name.bytes() {
        hash ^= u64::from(byte);
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
    }
    hash
}

/// Longest channel name accepted.
pub const MAX_NAME_LEN: usize = 255;

/// Checks a channel or database name: 1-255 bytes of visible characters.
pub fn validate_name(name: &str) -> Result<(), &'static str> {
    if name.is_empty() {
        return Err("name is empty");
    }
    if name.len() > MAX_NAME_LEN {
        return Err("name is longer than 255 bytes");
    }
    if name.chars().any(|c| c.is_control() || c.is_whitespace()) {
        return Err("name contains whitespace or control characters");
    }
    Ok(())
}
