//! Encoding commands into a caller's slice and decoding events from borrowed bytes; the layouts are documented on
//! the types in [`crate::message`] and are byte for byte those of `flow::protocol::codec`.
//!
//! Decoding is as strict as the hub's for what it takes apart (no trailing bytes, valid UTF-8, known enum values,
//! channel ids `>= 0`) and never panics on any input; what it does not take apart comes back as `Other`.

use core::fmt;

use crate::frame::{self, HEADER_LEN, RawFrame};
use crate::message::*;

/// Why a command could not be written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EncodeError {
    /// The output slice is shorter than the frame; `needed` is the frame's length.
    BufferTooSmall { needed: usize },
    /// A JSON text longer than a `u32` can announce, or a frame longer than its header can.
    TooLong,
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EncodeError::BufferTooSmall { needed } => {
                write!(f, "the frame needs a buffer of {needed} bytes")
            }
            EncodeError::TooLong => f.write_str("a field is too long for its length prefix"),
        }
    }
}

impl core::error::Error for EncodeError {}

/// A whole frame whose body does not form a valid message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DecodeError {
    /// The body ended while reading this field.
    Truncated(&'static str),
    /// Bytes were left after the message.
    Trailing(usize),
    /// This field is not UTF-8.
    Utf8(&'static str),
    /// This field holds a value outside its range.
    BadValue { field: &'static str, value: i64 },
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DecodeError::Truncated(what) => write!(f, "truncated body while reading {what}"),
            DecodeError::Trailing(n) => write!(f, "{n} trailing bytes after the message"),
            DecodeError::Utf8(what) => write!(f, "invalid UTF-8 in {what}"),
            DecodeError::BadValue { field, value } => {
                write!(f, "invalid value for {field}: {value}")
            }
        }
    }
}

impl core::error::Error for DecodeError {}

// ---------------------------------------------------------------- encoding

/// Writes one frame holding `command` with request id `req` into the front of `out`; returns its length.
///
/// `req` 0 asks the hub for no reply on success (the way `Publish` and `Respond` are normally sent).
pub fn encode_command(
    req: ReqId,
    command: &Command<'_>,
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    let mut w = Writer {
        out,
        pos: HEADER_LEN,
    };
    let op = match command {
        Command::Login {
            version,
            token,
            name,
        } => {
            w.u16(*version);
            w.str(token);
            w.str(name);
            op::LOGIN
        }
        Command::SetAsync => op::SET_ASYNC,
        Command::AddChannel { kind, name, header } => {
            w.u8(kind.code());
            w.str(name);
            w.text(header)?;
            op::ADD_CHANNEL
        }
        Command::RemoveChannel { chan } => {
            w.chref(chan);
            op::REMOVE_CHANNEL
        }
        Command::Subscribe { chan } => {
            w.chref(chan);
            op::SUBSCRIBE
        }
        Command::Unsubscribe { chan } => {
            w.chref(chan);
            op::UNSUBSCRIBE
        }
        Command::Publish { chan, payload } => {
            w.i16(*chan);
            w.bytes(payload);
            op::PUBLISH
        }
        Command::Call {
            chan,
            timeout_ms,
            payload,
        } => {
            w.chref(chan);
            w.u32(*timeout_ms);
            w.bytes(payload);
            op::CALL
        }
        Command::Respond { call, result } => {
            w.u64(*call);
            match result {
                Ok(payload) => {
                    w.u8(0);
                    w.bytes(payload);
                }
                Err(message) => {
                    w.u8(1);
                    w.bytes(message.as_bytes());
                }
            }
            op::RESPOND
        }
        Command::Ping => op::PING,
    };
    let total = w.pos;
    if total > w.out.len() {
        return Err(EncodeError::BufferTooSmall { needed: total });
    }
    frame::put_header(w.out, op, req, total - HEADER_LEN).ok_or(EncodeError::TooLong)?;
    Ok(total)
}

/// The length of the frame [`encode_command`] writes for `command`: the buffer it needs.
pub fn encoded_len(command: &Command<'_>) -> Result<usize, EncodeError> {
    match encode_command(0, command, &mut []) {
        Err(EncodeError::BufferTooSmall { needed }) => Ok(needed),
        Err(e) => Err(e),
        // Every frame has a header, so an empty slice is always too small.
        Ok(n) => Ok(n),
    }
}

/// Writes fields after the header's place; past the end of `out` it only counts, so that one pass both writes
/// and measures, and a short buffer is reported with the length it would have needed.
struct Writer<'o> {
    out: &'o mut [u8],
    pos: usize,
}

impl Writer<'_> {
    fn bytes(&mut self, v: &[u8]) {
        let end = self.pos.saturating_add(v.len());
        if let Some(dst) = self.out.get_mut(self.pos..end) {
            dst.copy_from_slice(v);
        }
        self.pos = end;
    }
    fn u8(&mut self, v: u8) {
        self.bytes(&[v]);
    }
    fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes());
    }
    fn i16(&mut self, v: i16) {
        self.bytes(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }
    /// Short string, cut at a character boundary below 64 KiB exactly as the SDK's encoder cuts it.
    fn str(&mut self, v: &str) {
        let mut end = v.len().min(u16::MAX as usize);
        while !v.is_char_boundary(end) {
            end -= 1;
        }
        self.u16(end as u16);
        self.bytes(&v.as_bytes()[..end]);
    }
    fn text(&mut self, v: &str) -> Result<(), EncodeError> {
        let len = u32::try_from(v.len()).map_err(|_| EncodeError::TooLong)?;
        self.u32(len);
        self.bytes(v.as_bytes());
        Ok(())
    }
    fn chref(&mut self, chan: &ChanRef<'_>) {
        match chan {
            ChanRef::Id(id) => {
                self.u8(0);
                self.i16(*id);
            }
            ChanRef::Name(name) => {
                self.u8(1);
                self.str(name);
            }
        }
    }
}

// ---------------------------------------------------------------- decoding

/// Decodes a hub frame into an event, borrowing its strings and payloads from the frame's body.
pub fn decode_event(frame: RawFrame<'_>) -> Result<Event<'_>, DecodeError> {
    let mut r = Reader { buf: frame.body };
    let event = match frame.op {
        op::REPLY => Event::Reply {
            req: frame.req,
            result: r.reply()?,
        },
        op::CHANNEL_REMOVED => Event::ChannelRemoved {
            id: r.chan_id()?,
            name: r.str("name")?,
        },
        op::START_PUBLISHING => Event::StartPublishing { id: r.chan_id()? },
        op::STOP_PUBLISHING => Event::StopPublishing { id: r.chan_id()? },
        op::SERVICE_REQUEST => Event::ServiceRequest {
            chan: r.chan_id()?,
            call: r.u64("call id")?,
            payload: r.rest(),
        },
        op::DATA => Event::Data {
            chan: r.chan_id()?,
            seq: r.u64("seq")?,
            ts_us: r.u64("timestamp")?,
            payload: r.rest(),
        },
        op::GOODBYE => Event::Goodbye {
            reason: r.str("reason")?,
        },
        other => Event::Other {
            op: other,
            req: frame.req,
            body: r.rest(),
        },
    };
    r.end()?;
    Ok(event)
}

/// Cuts the first frame off `buf` and decodes it: the event and the bytes it took. `None` when `buf` does not
/// hold a whole frame yet.
pub fn decode_event_from(
    buf: &[u8],
    max_frame: usize,
) -> Result<Option<(Event<'_>, usize)>, FrameOrDecode> {
    match frame::parse(buf, max_frame).map_err(FrameOrDecode::Frame)? {
        frame::Parsed::Incomplete(_) => Ok(None),
        frame::Parsed::Frame(raw, used) => Ok(Some((
            decode_event(raw).map_err(FrameOrDecode::Decode)?,
            used,
        ))),
    }
}

/// Either failure of [`decode_event_from`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameOrDecode {
    /// The stream cannot be cut into frames any more.
    Frame(frame::FrameError),
    /// The frame was whole but its body is not a valid message; the next frame starts after it.
    Decode(DecodeError),
}

impl fmt::Display for FrameOrDecode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FrameOrDecode::Frame(e) => e.fmt(f),
            FrameOrDecode::Decode(e) => e.fmt(f),
        }
    }
}

impl core::error::Error for FrameOrDecode {}

/// Reads primitives off a body, failing cleanly on truncation.
struct Reader<'a> {
    buf: &'a [u8],
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], DecodeError> {
        if self.buf.len() < n {
            return Err(DecodeError::Truncated(what));
        }
        let (head, rest) = self.buf.split_at(n);
        self.buf = rest;
        Ok(head)
    }
    fn array<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N], DecodeError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N, what)?);
        Ok(a)
    }
    fn u8(&mut self, what: &'static str) -> Result<u8, DecodeError> {
        Ok(self.take(1, what)?[0])
    }
    fn u16(&mut self, what: &'static str) -> Result<u16, DecodeError> {
        self.array(what).map(u16::from_le_bytes)
    }
    fn u32(&mut self, what: &'static str) -> Result<u32, DecodeError> {
        self.array(what).map(u32::from_le_bytes)
    }
    fn u64(&mut self, what: &'static str) -> Result<u64, DecodeError> {
        self.array(what).map(u64::from_le_bytes)
    }
    fn f32(&mut self, what: &'static str) -> Result<f32, DecodeError> {
        self.array(what).map(f32::from_le_bytes)
    }
    fn chan_id(&mut self) -> Result<ChanId, DecodeError> {
        let id = i16::from_le_bytes(self.array("channel id")?);
        if id < 0 {
            return Err(DecodeError::BadValue {
                field: "channel id",
                value: id.into(),
            });
        }
        Ok(id)
    }
    fn utf8(&mut self, len: usize, what: &'static str) -> Result<&'a str, DecodeError> {
        let raw = self.take(len, what)?;
        core::str::from_utf8(raw).map_err(|_| DecodeError::Utf8(what))
    }
    fn str(&mut self, what: &'static str) -> Result<&'a str, DecodeError> {
        let len = self.u16(what)? as usize;
        self.utf8(len, what)
    }
    fn text(&mut self, what: &'static str) -> Result<&'a str, DecodeError> {
        let len = self.u32(what)?;
        // A length beyond the address space is beyond the body too.
        let len = usize::try_from(len).map_err(|_| DecodeError::Truncated(what))?;
        self.utf8(len, what)
    }
    fn rest(&mut self) -> &'a [u8] {
        core::mem::take(&mut self.buf)
    }
    fn end(&self) -> Result<(), DecodeError> {
        match self.buf.len() {
            0 => Ok(()),
            n => Err(DecodeError::Trailing(n)),
        }
    }
    fn kind(&mut self) -> Result<ChannelKind, DecodeError> {
        match self.u8("channel kind")? {
            0 => Ok(ChannelKind::Stream),
            1 => Ok(ChannelKind::Service),
            other => Err(DecodeError::BadValue {
                field: "channel kind",
                value: other.into(),
            }),
        }
    }
    fn channel(&mut self) -> Result<ChannelInfo<'a>, DecodeError> {
        Ok(ChannelInfo {
            id: self.chan_id()?,
            hash: self.u64("hash")?,
            kind: self.kind()?,
            name: self.str("name")?,
            owner: self.str("owner")?,
            header: self.text("header")?,
            stats: ChannelStats {
                subscribers: self.u32("subscribers")?,
                msgs: self.u64("msgs")?,
                bytes: self.u64("bytes")?,
                dropped: self.u64("dropped")?,
                msgs_per_s: self.f32("msgs/s")?,
                bytes_per_s: self.f32("bytes/s")?,
            },
        })
    }
    fn reply(&mut self) -> Result<Result<Reply<'a>, ErrorReply<'a>>, DecodeError> {
        let reply = match self.u8("reply tag")? {
            0 => Reply::Done,
            1 => Reply::LoginOk {
                version: self.u16("version")?,
                conn: self.u32("connection id")?,
                admin: self.u8("admin")? != 0,
                server: self.str("server")?,
            },
            2 => Reply::Channel(self.channel()?),
            tag @ (3 | 5) => Reply::Other {
                tag,
                body: self.rest(),
            },
            4 => Reply::Value(self.text("value")?),
            6 => Reply::Payload(self.rest()),
            7 => Reply::Pong,
            0xff => {
                let raw = self.u16("error code")?;
                let code = ErrorCode::from_u16(raw).ok_or(DecodeError::BadValue {
                    field: "error code",
                    value: raw.into(),
                })?;
                return Ok(Err(ErrorReply {
                    code,
                    message: self.str("error message")?,
                }));
            }
            other => {
                return Err(DecodeError::BadValue {
                    field: "reply tag",
                    value: other.into(),
                });
            }
        };
        Ok(Ok(reply))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_short_buffer_is_told_the_length_it_needs() {
        let ping = Command::Ping;
        assert_eq!(encoded_len(&ping), Ok(HEADER_LEN));
        let publish = Command::Publish {
            chan: 3,
            payload: &[1, 2, 3],
        };
        assert_eq!(encoded_len(&publish), Ok(HEADER_LEN + 2 + 3));
        let mut out = [0u8; 12];
        assert_eq!(
            encode_command(0, &publish, &mut out),
            Err(EncodeError::BufferTooSmall { needed: 14 })
        );
        let mut out = [0u8; 14];
        assert_eq!(encode_command(0, &publish, &mut out), Ok(14));
        assert_eq!(out, [10, 0, 0, 0, 0x08, 0, 0, 0, 0, 3, 0, 1, 2, 3]);
    }

    #[test]
    fn an_unknown_event_is_skipped_whole() {
        let raw = RawFrame {
            op: 0x99,
            req: 7,
            body: &[1, 2, 3],
        };
        assert_eq!(
            decode_event(raw),
            Ok(Event::Other {
                op: 0x99,
                req: 7,
                body: &[1, 2, 3]
            })
        );
    }

    #[test]
    fn error_codes_are_numbered_from_one_in_wire_order() {
        for (i, code) in ErrorCode::ALL.iter().enumerate() {
            assert_eq!(*code as usize, i + 1);
            assert_eq!(ErrorCode::from_u16(i as u16 + 1), Some(*code));
        }
        assert_eq!(ErrorCode::from_u16(0), None);
        assert_eq!(ErrorCode::from_u16(18), None);
    }
}
