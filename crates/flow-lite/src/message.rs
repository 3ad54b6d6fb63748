//! The part of FlowProtocol a board speaks, as values that borrow their strings and payloads.
//!
//! Opcodes and layouts are those of `flow::protocol::message` (docs/protocol.md); the diagrams show the body
//! after the 9-byte frame header (see [`crate::frame`]). Primitive encodings, all little-endian:
//!
//! ```text
//! str   = len:u16 | UTF-8 bytes            (names, tokens, messages)
//! text  = len:u32 | UTF-8 bytes            (JSON documents)
//! chref = 0:u8 | id:i16                    (a channel by id)
//!       | 1:u8 | name:str                  (a channel by name)
//! rest  = every remaining byte of the frame (payloads; never length-prefixed)
//! ```
//!
//! A board sends [`Command`]s and reads [`Event`]s. Events it has no use for (channels added elsewhere, header
//! changes, database notices) and reply bodies it cannot hold without an allocator (channel lists, name lists)
//! decode as `Other`, with their raw body, so that a reader skips them and stays in step.

/// Channel identifier: unique while the channel exists, `0..=32767`.
pub type ChanId = i16;
/// Request id chosen by the client; echoed in the reply. 0 asks for no reply.
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
    /// The byte on the wire.
    pub const fn code(self) -> u8 {
        match self {
            ChannelKind::Stream => 0,
            ChannelKind::Service => 1,
        }
    }
}

/// A channel named either way.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ChanRef<'a> {
    Id(ChanId),
    Name(&'a str),
}

/// Client -> hub commands a board sends. The opcode of each is in brackets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command<'a> {
    /// [0x01] `version:u16 | token:str | name:str`. The only command accepted before authentication.
    Login {
        version: u16,
        token: &'a str,
        name: &'a str,
    },
    /// [0x02] empty. Switches the connection to asynchronous: events start flowing.
    SetAsync,
    /// [0x03] `kind:u8 | name:str | header:text`. Replies with the new channel's info.
    AddChannel {
        kind: ChannelKind,
        name: &'a str,
        header: &'a str,
    },
    /// [0x04] `chan:chref`. Owner (or admin) only.
    RemoveChannel { chan: ChanRef<'a> },
    /// [0x06] `chan:chref`. Replies with the channel's info, before its first `Data`.
    Subscribe { chan: ChanRef<'a> },
    /// [0x07] `chan:chref`.
    Unsubscribe { chan: ChanRef<'a> },
    /// [0x08] `chan:i16 | payload:rest`. Owner only, stream channels only; usually sent with req 0.
    Publish { chan: ChanId, payload: &'a [u8] },
    /// [0x09] `chan:chref | timeout_ms:u32 | payload:rest`. The reply carries the owner's response or an error.
    Call {
        chan: ChanRef<'a>,
        timeout_ms: u32,
        payload: &'a [u8],
    },
    /// [0x0a] `call:u64 | status:u8 (0 ok, 1 error) | payload:rest`. A service owner's answer to
    /// [`Event::ServiceRequest`]; an error payload is a UTF-8 message.
    Respond {
        call: CallId,
        result: Result<&'a [u8], &'a str>,
    },
    /// [0x1f] empty. Replies `Pong`; keeps idle links honest.
    Ping,
}

/// Live counters of a channel.
///
/// ```text
/// subscribers:u32 | msgs:u64 | bytes:u64 | dropped:u64 | msgs_per_s:f32 | bytes_per_s:f32
/// ```
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ChannelStats {
    pub subscribers: u32,
    pub msgs: u64,
    pub bytes: u64,
    pub dropped: u64,
    pub msgs_per_s: f32,
    pub bytes_per_s: f32,
}

/// Everything known about a channel.
///
/// ```text
/// id:i16 | hash:u64 | kind:u8 (0 stream, 1 service) | name:str | owner:str | header:text | stats
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChannelInfo<'a> {
    pub id: ChanId,
    /// FNV-1a 64 of the name.
    pub hash: u64,
    pub kind: ChannelKind,
    pub name: &'a str,
    pub owner: &'a str,
    /// JSON object describing the data.
    pub header: &'a str,
    pub stats: ChannelStats,
}

/// Successful reply bodies; each starts with a tag byte.
///
/// ```text
/// 0 Done                                   (empty)
/// 1 LoginOk   version:u16 | conn:u32 | admin:u8 | server:str
/// 2 Channel   channel-info
/// 3 Channels  count:u16 | channel-info * count      -> Other
/// 4 Value     json:text
/// 5 Names     count:u32 | str * count                -> Other
/// 6 Payload   rest
/// 7 Pong      (empty)
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reply<'a> {
    Done,
    LoginOk {
        version: u16,
        conn: u32,
        admin: bool,
        server: &'a str,
    },
    Channel(ChannelInfo<'a>),
    Value(&'a str),
    Payload(&'a [u8]),
    Pong,
    /// A reply this crate does not take apart (lists): its tag and the body after the tag, unchecked.
    Other {
        tag: u8,
        body: &'a [u8],
    },
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
        // The codes run 1..=17 in the order of ALL.
        let index = usize::from(code).checked_sub(1)?;
        ErrorCode::ALL.get(index).copied()
    }
}

/// A failed command: a code for programs and a message for people.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ErrorReply<'a> {
    pub code: ErrorCode,
    pub message: &'a str,
}

/// Hub -> client messages. The opcode of each is in brackets; `req` in the frame header is the request id for
/// `Reply` and 0 otherwise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event<'a> {
    /// [0x80] `tag:u8 | reply-body` (see [`Reply`]) or `0xff | code:u16 | message:str`.
    Reply {
        req: ReqId,
        result: Result<Reply<'a>, ErrorReply<'a>>,
    },
    /// [0x82] `id:i16 | name:str`. A channel went away (one this board subscribed to, perhaps).
    ChannelRemoved { id: ChanId, name: &'a str },
    /// [0x84] `id:i16`. To the owner: the first subscriber arrived, start publishing.
    StartPublishing { id: ChanId },
    /// [0x85] `id:i16`. To the owner: the last subscriber left, stop publishing.
    StopPublishing { id: ChanId },
    /// [0x86] `chan:i16 | call:u64 | payload:rest`. To a service owner, who answers with [`Command::Respond`].
    ServiceRequest {
        chan: ChanId,
        call: CallId,
        payload: &'a [u8],
    },
    /// [0x87] `chan:i16 | seq:u64 | ts_us:u64 | payload:rest`. To subscribers; `seq` counts from 1 (gaps are
    /// drops), `ts_us` is the hub's clock at publication.
    Data {
        chan: ChanId,
        seq: u64,
        ts_us: u64,
        payload: &'a [u8],
    },
    /// [0x89] `reason:str`. The hub is closing this connection.
    Goodbye { reason: &'a str },
    /// Any other event (channel added, header changed, database changed, or one newer than this crate), skipped
    /// whole: its opcode, request id and raw body.
    Other { op: u8, req: ReqId, body: &'a [u8] },
}

/// Opcodes, the same numbers as `flow::protocol::op`.
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
    pub const PING: u8 = 0x1f;

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
}

/// FNV-1a 64-bit hash of a channel name, as the hub computes it.
pub fn channel_hash(name: &str) -> u64 {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for byte in name.bytes() {
        hash ^= u64::from(byte);
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
    }
    hash
}
