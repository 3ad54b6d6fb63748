//! A blocking FlowProtocol client for a board: one serial line, the caller's buffers, no allocator, no threads.
//!
//! Each command goes out as one packet of the line framing ([`crate::line`]) holding its one frame. Incoming
//! bytes go through a [`Deframer`]; a damaged packet is counted ([`Client::damaged`]) and dropped, never fatal:
//! the frames in it are lost as on any lossy link, the ones after it parse. A packet may hold several frames
//! (the hub batches), which are handed out one at a time.
//!
//! Requests (`login`, `set_async`, `publisher`, `subscribe`, `call`, `ping`) wait for their reply with at most
//! [`Client::set_read_limit`] reads of the link; whatever else arrives meanwhile is dropped and counted
//! ([`Client::skipped`]). So a satellite makes its requests first and then [`Client::poll`]s; on a synchronous
//! connection (no `set_async`) nothing but replies ever arrives. `publish` and `respond` go out with request id 0
//! and wait for nothing (a failure comes back later as a `Reply` with `req` 0, seen by `poll`).
//!
//! ```text
//!  rx buffer:  | read chunk (<= 64) | deframer: one encoded packet | the decoded packet's frames |
//!  tx buffer:  | one frame                  | that frame as a packet (line::max_encoded_len)    |
//! ```

use core::fmt;
use core::ops::Range;

use crate::codec::{self, DecodeError, EncodeError};
use crate::frame::{self, HEADER_LEN, Parsed, RawFrame};
use crate::line::{self, Deframed, Deframer};
use crate::message::*;

/// The byte stream under a client: a serial port, a USB CDC endpoint, a pseudo-terminal.
pub trait Link {
    type Error;
    /// Writes all of `bytes` (blocking until they are handed to the line).
    fn write(&mut self, bytes: &[u8]) -> Result<(), Self::Error>;
    /// Reads what has arrived into `buf`, waiting as long as the link waits; 0 means nothing came in that time.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error>;
}

/// Why a client call failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error<E> {
    /// The link failed.
    Link(E),
    /// The command does not fit the tx buffer.
    Encode(EncodeError),
    /// A frame for us was whole but not a valid message (the next one is read as usual).
    Decode(DecodeError),
    /// The hub answered with an error; [`Client::last_message`] has its message.
    Refused(ErrorCode),
    /// The hub answered with a reply of another kind than the command gets.
    Unexpected,
    /// No reply within the read limit.
    NoReply,
    /// The hub is closing the connection; [`Client::last_message`] has its reason.
    Goodbye,
}

impl<E: fmt::Display> fmt::Display for Error<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Link(e) => write!(f, "link: {e}"),
            Error::Encode(e) => e.fmt(f),
            Error::Decode(e) => e.fmt(f),
            Error::Refused(code) => write!(f, "the hub refused: {code:?}"),
            Error::Unexpected => f.write_str("the hub answered with a reply of another kind"),
            Error::NoReply => f.write_str("no reply within the read limit"),
            Error::Goodbye => f.write_str("the hub said goodbye"),
        }
    }
}

impl<E: fmt::Debug + fmt::Display> core::error::Error for Error<E> {}

/// What a successful login told.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Session {
    /// The hub's protocol version.
    pub version: u16,
    /// This connection's number on the hub.
    pub conn: u32,
    /// Whether the token gave admin rights.
    pub admin: bool,
}

/// Bytes read from the link at a time.
const CHUNK: usize = 64;
/// Bytes of a refusal or goodbye message kept for [`Client::last_message`].
const MESSAGE: usize = 64;
/// Reads a request waits for its reply by default.
const READ_LIMIT: u32 = 1024;

/// The place of a frame in the packet buffer.
#[derive(Debug, Clone)]
struct FrameAt {
    op: u8,
    req: ReqId,
    body: Range<usize>,
}

/// A FlowProtocol client over a [`Link`], in the caller's buffers.
#[derive(Debug)]
pub struct Client<'b, L> {
    link: L,
    chunk: &'b mut [u8],
    chunk_at: usize,
    chunk_end: usize,
    deframer: Deframer<&'b mut [u8]>,
    packet: &'b mut [u8],
    packet_at: usize,
    packet_len: usize,
    frame: &'b mut [u8],
    wire: &'b mut [u8],
    next_req: ReqId,
    reads: u32,
    read_limit: u32,
    damaged: u32,
    skipped: u32,
    message: [u8; MESSAGE],
    message_len: usize,
}

impl<'b, L: Link> Client<'b, L> {
    /// The rx buffer that holds packets with bodies of up to `body` bytes (the largest batch of frames the hub
    /// sends at once).
    pub const fn rx_len(body: usize) -> usize {
        // The deframer holds the encoded packet without its delimiter; the packet buffer a little less.
        let line = line::max_encoded_len(body) - 1;
        CHUNK + 2 * line
    }

    /// The tx buffer that sends frames of up to `frame` bytes (header included).
    pub const fn tx_len(frame: usize) -> usize {
        frame + line::max_encoded_len(frame)
    }

    /// A client over `link`, receiving in `rx` and sending from `tx` (see [`Client::rx_len`], [`Client::tx_len`]:
    /// 1 KiB each carries frames of some 500 bytes). Nothing is sent until [`Client::login`].
    pub fn new(link: L, rx: &'b mut [u8], tx: &'b mut [u8]) -> Self {
        let chunk_len = CHUNK.min(rx.len() / 4).max(1).min(rx.len());
        let (chunk, rest) = rx.split_at_mut(chunk_len);
        // The decoded packet is at least 5 bytes shorter than the encoded one, so the half of `rest` left to the
        // packet (the smaller half) always holds what the deframer's half decodes to.
        let line_len = rest.len().div_ceil(2);
        let (line_buf, packet) = rest.split_at_mut(line_len);
        let mut frame_len = tx.len() / 2;
        while frame_len > 0 && frame_len + line::max_encoded_len(frame_len) > tx.len() {
            frame_len -= 1;
        }
        let (frame, wire) = tx.split_at_mut(frame_len);
        Client {
            link,
            chunk,
            chunk_at: 0,
            chunk_end: 0,
            deframer: Deframer::new(line_buf),
            packet,
            packet_at: 0,
            packet_len: 0,
            frame,
            wire,
            next_req: 1,
            reads: 0,
            read_limit: READ_LIMIT,
            damaged: 0,
            skipped: 0,
            message: [0; MESSAGE],
            message_len: 0,
        }
    }

    /// How many reads of the link a request waits for its reply (default 1024). With a link whose `read` returns
    /// 0 after a timeout, this times the wait.
    pub fn set_read_limit(&mut self, reads: u32) {
        self.read_limit = reads.max(1);
    }

    /// Packets dropped as damaged (bad stuffing or checksum, too long for the rx buffer, not whole frames).
    pub fn damaged(&self) -> u32 {
        self.damaged
    }

    /// Frames dropped while a request waited for its reply.
    pub fn skipped(&self) -> u32 {
        self.skipped
    }

    /// The message of the last refusal or the reason of the last goodbye (its first 64 bytes).
    pub fn last_message(&self) -> &str {
        core::str::from_utf8(&self.message[..self.message_len]).unwrap_or_default()
    }

    /// The largest frame (header included) this client can send.
    pub fn max_frame(&self) -> usize {
        self.frame.len()
    }

    pub fn link(&self) -> &L {
        &self.link
    }

    pub fn link_mut(&mut self) -> &mut L {
        &mut self.link
    }

    pub fn into_link(self) -> L {
        self.link
    }

    /// Logs in with protocol version 1. The hub closes the connection after a refusal (`AuthFailed`,
    /// `VersionMismatch`).
    pub fn login(&mut self, token: &str, name: &str) -> Result<Session, Error<L::Error>> {
        // A zero first ends whatever noise the line carried before: the hub's deframer starts afresh.
        self.link.write(&[0]).map_err(Error::Link)?;
        let command = Command::Login {
            version: PROTOCOL_VERSION,
            token,
            name,
        };
        match self.request(&command)? {
            Reply::LoginOk {
                version,
                conn,
                admin,
                ..
            } => Ok(Session {
                version,
                conn,
                admin,
            }),
            _ => Err(Error::Unexpected),
        }
    }

    /// Makes the connection asynchronous: data, service requests and channel events start coming to `poll`.
    pub fn set_async(&mut self) -> Result<(), Error<L::Error>> {
        self.done(&Command::SetAsync)
    }

    /// Creates a stream channel owned by this connection; its id is what [`Client::publish`] takes.
    pub fn publisher(&mut self, name: &str, header: &str) -> Result<ChanId, Error<L::Error>> {
        self.add_channel(ChannelKind::Stream, name, header)
    }

    /// Creates a service channel owned by this connection (needs `set_async`): its requests come to `poll` as
    /// [`Event::ServiceRequest`], answered with [`Client::respond`].
    pub fn service(&mut self, name: &str, header: &str) -> Result<ChanId, Error<L::Error>> {
        self.add_channel(ChannelKind::Service, name, header)
    }

    fn add_channel(
        &mut self,
        kind: ChannelKind,
        name: &str,
        header: &str,
    ) -> Result<ChanId, Error<L::Error>> {
        match self.request(&Command::AddChannel { kind, name, header })? {
            Reply::Channel(info) => Ok(info.id),
            _ => Err(Error::Unexpected),
        }
    }

    /// Publishes `payload` on a stream channel this connection owns; waits for nothing.
    pub fn publish(&mut self, chan: ChanId, payload: &[u8]) -> Result<(), Error<L::Error>> {
        self.send(0, &Command::Publish { chan, payload })
    }

    /// Subscribes to a stream channel by name (needs `set_async`); its data comes to `poll` as [`Event::Data`]
    /// with the id returned here.
    pub fn subscribe(&mut self, name: &str) -> Result<ChanId, Error<L::Error>> {
        match self.request(&Command::Subscribe {
            chan: ChanRef::Name(name),
        })? {
            Reply::Channel(info) => Ok(info.id),
            _ => Err(Error::Unexpected),
        }
    }

    /// Calls a service and waits for its response; the hub answers `Timeout` after `timeout_ms`. The response
    /// lives in the rx buffer until the next call.
    pub fn call(
        &mut self,
        service: &str,
        payload: &[u8],
        timeout_ms: u32,
    ) -> Result<&[u8], Error<L::Error>> {
        let command = Command::Call {
            chan: ChanRef::Name(service),
            timeout_ms,
            payload,
        };
        match self.request(&command)? {
            Reply::Payload(payload) => Ok(payload),
            _ => Err(Error::Unexpected),
        }
    }

    /// Answers a [`Event::ServiceRequest`]; waits for nothing.
    pub fn respond(
        &mut self,
        call: CallId,
        result: Result<&[u8], &str>,
    ) -> Result<(), Error<L::Error>> {
        self.send(0, &Command::Respond { call, result })
    }

    /// Asks the hub for a `Pong`: once it comes, the hub has read everything sent before.
    pub fn ping(&mut self) -> Result<(), Error<L::Error>> {
        match self.request(&Command::Ping)? {
            Reply::Pong => Ok(()),
            _ => Err(Error::Unexpected),
        }
    }

    /// The next event, reading the link at most once; `None` when no whole frame came with that read.
    ///
    /// A frame that is not a valid message is an `Err(Error::Decode)`; the next call goes on after it.
    pub fn poll(&mut self) -> Result<Option<Event<'_>>, Error<L::Error>> {
        let Some(at) = self.next_frame()? else {
            return Ok(None);
        };
        let raw = RawFrame {
            op: at.op,
            req: at.req,
            body: &self.packet[at.body],
        };
        codec::decode_event(raw).map(Some).map_err(Error::Decode)
    }

    /// Sends any command with request id `req` (0: no reply on success), as one packet.
    pub fn send(&mut self, req: ReqId, command: &Command<'_>) -> Result<(), Error<L::Error>> {
        let n = codec::encode_command(req, command, self.frame).map_err(Error::Encode)?;
        let w = match line::encode(&self.frame[..n], self.wire) {
            Ok(w) => w,
            // The split in `new` gives the wire half room for any frame the frame half holds.
            Err(_) => {
                return Err(Error::Encode(EncodeError::BufferTooSmall {
                    needed: Self::tx_len(n),
                }));
            }
        };
        self.link.write(&self.wire[..w]).map_err(Error::Link)
    }

    fn done(&mut self, command: &Command<'_>) -> Result<(), Error<L::Error>> {
        match self.request(command)? {
            Reply::Done => Ok(()),
            _ => Err(Error::Unexpected),
        }
    }

    /// Sends `command` with a fresh request id and waits for its reply.
    fn request(&mut self, command: &Command<'_>) -> Result<Reply<'_>, Error<L::Error>> {
        let req = self.next_req;
        self.next_req = self.next_req.wrapping_add(1).max(1);
        self.send(req, command)?;
        let start = self.reads;
        let at = loop {
            if self.reads.wrapping_sub(start) >= self.read_limit {
                return Err(Error::NoReply);
            }
            let Some(at) = self.next_frame()? else {
                continue;
            };
            if at.op == op::REPLY && at.req == req {
                break at;
            }
            if at.op == op::GOODBYE {
                if let Ok(Event::Goodbye { reason }) = self.decode_at(&at) {
                    let reason = keep(reason);
                    self.remember(reason);
                }
                return Err(Error::Goodbye);
            }
            self.skipped = self.skipped.wrapping_add(1);
        };
        let result = match self.decode_at(&at).map_err(Error::Decode)? {
            Event::Reply { result, .. } => result,
            _ => return Err(Error::Unexpected),
        };
        if let Err(refusal) = result {
            let (code, message) = (refusal.code, keep(refusal.message));
            self.remember(message);
            return Err(Error::Refused(code));
        }
        // Decoded again so that the reply borrows `self` only on the way out.
        match self.decode_at(&at) {
            Ok(Event::Reply {
                result: Ok(reply), ..
            }) => Ok(reply),
            _ => Err(Error::Unexpected),
        }
    }

    fn decode_at(&self, at: &FrameAt) -> Result<Event<'_>, DecodeError> {
        codec::decode_event(RawFrame {
            op: at.op,
            req: at.req,
            body: &self.packet[at.body.clone()],
        })
    }

    fn remember(&mut self, message: ([u8; MESSAGE], usize)) {
        (self.message, self.message_len) = message;
    }

    /// The next frame of the packets read, reading the link at most once.
    fn next_frame(&mut self) -> Result<Option<FrameAt>, Error<L::Error>> {
        let mut read = false;
        loop {
            if self.packet_at < self.packet_len {
                let rest = &self.packet[self.packet_at..self.packet_len];
                match frame::parse(rest, rest.len()) {
                    Ok(Parsed::Frame(raw, used)) => {
                        let start = self.packet_at + HEADER_LEN;
                        let at = FrameAt {
                            op: raw.op,
                            req: raw.req,
                            body: start..self.packet_at + used,
                        };
                        self.packet_at += used;
                        return Ok(Some(at));
                    }
                    // A packet whose checksum held but that does not hold whole frames: its writer is broken,
                    // and the rest of it cannot be cut; drop it like a damaged one.
                    Ok(Parsed::Incomplete(_)) | Err(_) => {
                        self.damaged = self.damaged.wrapping_add(1);
                        self.packet_at = self.packet_len;
                    }
                }
                continue;
            }
            if self.chunk_at < self.chunk_end {
                let (used, out) = self
                    .deframer
                    .push(&self.chunk[self.chunk_at..self.chunk_end]);
                self.chunk_at += used;
                match out {
                    Some(Deframed::Packet(body)) if body.len() <= self.packet.len() => {
                        self.packet[..body.len()].copy_from_slice(body);
                        self.packet_at = 0;
                        self.packet_len = body.len();
                    }
                    Some(_) => self.damaged = self.damaged.wrapping_add(1),
                    None => {}
                }
                continue;
            }
            if read {
                return Ok(None);
            }
            read = true;
            self.reads = self.reads.wrapping_add(1);
            let n = self.link.read(self.chunk).map_err(Error::Link)?;
            self.chunk_at = 0;
            self.chunk_end = n.min(self.chunk.len());
        }
    }
}

/// The first bytes of a message, cut at a character boundary, to keep after its packet is gone.
fn keep(message: &str) -> ([u8; MESSAGE], usize) {
    let mut end = message.len().min(MESSAGE);
    while !message.is_char_boundary(end) {
        end -= 1;
    }
    let mut kept = [0u8; MESSAGE];
    kept[..end].copy_from_slice(&message.as_bytes()[..end]);
    (kept, end)
}
