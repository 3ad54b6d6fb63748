//! Encoding and decoding of messages to and from frame bodies; the layouts are
//! documented on the types in [`super::message`].

use bytes::{Buf, BufMut, Bytes, BytesMut};

use super::error::DecodeError;
use super::frame::{self, RawFrame};
use super::message::*;

// ---------------------------------------------------------------- encoding

/// Appends one frame holding `env` to `out`.
pub fn encode_command(env: &Envelope, out: &mut BytesMut) {
    let mut body = BodyWriter::start(out);
    let op = match &env.command {
        Command::Login {
            version,
            token,
            name,
        } => {
            body.u16(*version);
            body.str(token);
            body.str(name);
            op::LOGIN
        }
        Command::SetAsync => op::SET_ASYNC,
        Command::AddChannel { kind, name, header } => {
            body.u8(kind_code(*kind));
            body.str(name);
            body.text(header);
            op::ADD_CHANNEL
        }
        Command::RemoveChannel { chan } => {
            body.chref(chan);
            op::REMOVE_CHANNEL
        }
        Command::SetHeader { chan, header } => {
            body.i16(*chan);
            body.text(header);
            op::SET_HEADER
        }
        Command::Subscribe { chan } => {
            body.chref(chan);
            op::SUBSCRIBE
        }
        Command::Unsubscribe { chan } => {
            body.chref(chan);
            op::UNSUBSCRIBE
        }
        Command::Publish { chan, payload } => {
            body.i16(*chan);
            body.bytes(payload);
            op::PUBLISH
        }
        Command::Call {
            chan,
            timeout_ms,
            payload,
        } => {
            body.chref(chan);
            body.u32(*timeout_ms);
            body.bytes(payload);
            op::CALL
        }
        Command::Respond { call, result } => {
            body.u64(*call);
            match result {
                Ok(payload) => {
                    body.u8(0);
                    body.bytes(payload);
                }
                Err(message) => {
                    body.u8(1);
                    body.bytes(message.as_bytes());
                }
            }
            op::RESPOND
        }
        Command::ListChannels => op::LIST_CHANNELS,
        Command::GetChannel { chan } => {
            body.chref(chan);
            op::GET_CHANNEL
        }
        Command::DbSelect { name } => body.str_op(name, op::DB_SELECT),
        Command::DbCreate { name } => body.str_op(name, op::DB_CREATE),
        Command::DbRemove { name } => body.str_op(name, op::DB_REMOVE),
        Command::DbList => op::DB_LIST,
        Command::VarSet { key, value } => {
            body.str(key);
            body.text(value);
            op::VAR_SET
        }
        Command::VarGet { key } => body.str_op(key, op::VAR_GET),
        Command::VarDel { key } => body.str_op(key, op::VAR_DEL),
        Command::VarList => op::VAR_LIST,
        Command::Ping => op::PING,
        Command::ShmAccept => op::SHM_ACCEPT,
        Command::ShmOpen { chan, slot_size } => {
            body.i16(*chan);
            body.u32(*slot_size);
            op::SHM_OPEN
        }
        Command::PublishRef { chan, slot } => {
            body.i16(*chan);
            body.slot(slot);
            op::PUBLISH_REF
        }
        Command::Release { slots } => {
            // A client holds at most a few slots per segment; a longer list is cut, never wrapped.
            let count = slots.len().min(u16::MAX as usize);
            body.u16(count as u16);
            for slot in &slots[..count] {
                body.slot(slot);
            }
            op::RELEASE
        }
    };
    body.finish(op, env.req);
}

/// Appends one frame holding `event` to `out`.
pub fn encode_event(event: &Event, out: &mut BytesMut) {
    let mut body = BodyWriter::start(out);
    let (op, req) = match event {
        Event::Reply { req, result } => {
            match result {
                Ok(reply) => body.reply(reply),
                Err(err) => {
                    body.u8(0xff);
                    body.u16(err.code as u16);
                    body.str(&err.message);
                }
            }
            (op::REPLY, *req)
        }
        Event::ChannelAdded(info) => {
            body.channel(info);
            (op::CHANNEL_ADDED, 0)
        }
        Event::ChannelRemoved { id, name } => {
            body.i16(*id);
            body.str(name);
            (op::CHANNEL_REMOVED, 0)
        }
        Event::HeaderChanged { id, name, header } => {
            body.i16(*id);
            body.str(name);
            body.text(header);
            (op::HEADER_CHANGED, 0)
        }
        Event::StartPublishing { id } => {
            body.i16(*id);
            (op::START_PUBLISHING, 0)
        }
        Event::StopPublishing { id } => {
            body.i16(*id);
            (op::STOP_PUBLISHING, 0)
        }
        Event::ServiceRequest {
            chan,
            call,
            payload,
        } => {
            body.i16(*chan);
            body.u64(*call);
            body.bytes(payload);
            (op::SERVICE_REQUEST, 0)
        }
        Event::Data {
            chan,
            seq,
            ts_us,
            payload,
        } => {
            body.i16(*chan);
            body.u64(*seq);
            body.u64(*ts_us);
            body.bytes(payload);
            (op::DATA, 0)
        }
        Event::DbChanged { name } => (body.str_op(name, op::DB_CHANGED), 0),
        Event::Goodbye { reason } => (body.str_op(reason, op::GOODBYE), 0),
        Event::Segment(info) => {
            body.segment(info);
            (op::SEGMENT, 0)
        }
        Event::DataRef {
            chan,
            seq,
            ts_us,
            slot,
        } => {
            body.i16(*chan);
            body.u64(*seq);
            body.u64(*ts_us);
            body.slot(slot);
            (op::DATA_REF, 0)
        }
        Event::ReleaseRing { capacity } => {
            body.u32(*capacity);
            (op::RELEASE_RING, 0)
        }
    };
    body.finish(op, req);
}

/// Appends everything of a `DATA` frame except its payload: the frame header
/// and the fixed fields. Followed by the payload's bytes, it equals what
/// [`encode_event`] writes for [`Event::Data`]; writers use it to send large
/// payloads straight from their shared buffer instead of copying them.
pub fn encode_data_head(
    chan: ChanId,
    seq: u64,
    ts_us: u64,
    payload_len: usize,
    out: &mut BytesMut,
) {
    frame::put_header(out, op::DATA, 0, 2 + 8 + 8 + payload_len);
    out.put_i16_le(chan);
    out.put_u64_le(seq);
    out.put_u64_le(ts_us);
}

/// Writes the header of a `Publish` command whose payload of `payload_len`
/// bytes follows separately (sent from its own buffer, uncopied); together
/// they are byte for byte what [`encode_command`] writes for it.
pub fn encode_publish_head(chan: ChanId, payload_len: usize, out: &mut BytesMut) {
    frame::put_header(out, op::PUBLISH, 0, 2 + payload_len);
    out.put_i16_le(chan);
}

/// Writes a body after a placeholder header, then patches the header in.
///
/// Encoding in place avoids a second buffer and a copy of every payload.
struct BodyWriter<'a> {
    out: &'a mut BytesMut,
    start: usize,
}

impl<'a> BodyWriter<'a> {
    fn start(out: &'a mut BytesMut) -> Self {
        let start = out.len();
        out.put_bytes(0, frame::HEADER_LEN);
        BodyWriter { out, start }
    }

    fn finish(self, op: u8, req: u32) {
        let body_len = self.out.len() - self.start - frame::HEADER_LEN;
        let mut header = BytesMut::with_capacity(frame::HEADER_LEN);
        frame::put_header(&mut header, op, req, body_len);
        self.out[self.start..self.start + frame::HEADER_LEN].copy_from_slice(&header);
    }

    fn u8(&mut self, v: u8) {
        self.out.put_u8(v);
    }
    fn u16(&mut self, v: u16) {
        self.out.put_u16_le(v);
    }
    fn i16(&mut self, v: i16) {
        self.out.put_i16_le(v);
    }
    fn u32(&mut self, v: u32) {
        self.out.put_u32_le(v);
    }
    fn u64(&mut self, v: u64) {
        self.out.put_u64_le(v);
    }
    fn f32(&mut self, v: f32) {
        self.out.put_f32_le(v);
    }
    fn bytes(&mut self, v: &[u8]) {
        self.out.extend_from_slice(v);
    }
    /// Short string; longer ones are cut at a character boundary below 64 KiB
    /// (names are validated far shorter; this only guards free-form messages).
    fn str(&mut self, v: &str) {
        let mut end = v.len().min(u16::MAX as usize);
        while !v.is_char_boundary(end) {
            end -= 1;
        }
        self.u16(end as u16);
        self.bytes(&v.as_bytes()[..end]);
    }
    fn str_op(&mut self, v: &str, op: u8) -> u8 {
        self.str(v);
        op
    }
    fn text(&mut self, v: &str) {
        self.u32(v.len() as u32);
        self.bytes(v.as_bytes());
    }
    fn chref(&mut self, chan: &ChanRef) {
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
    fn channel(&mut self, info: &ChannelInfo) {
        self.i16(info.id);
        self.u64(info.hash);
        self.u8(kind_code(info.kind));
        self.str(&info.name);
        self.str(&info.owner);
        self.text(&info.header);
        let s = &info.stats;
        self.u32(s.subscribers);
        self.u64(s.msgs);
        self.u64(s.bytes);
        self.u64(s.dropped);
        self.f32(s.msgs_per_s);
        self.f32(s.bytes_per_s);
    }
    fn slot(&mut self, slot: &SlotRef) {
        self.u32(slot.segment);
        self.u32(slot.slot);
        self.u32(slot.len);
    }
    fn segment(&mut self, info: &SegmentInfo) {
        self.u32(info.id);
        self.i16(info.chan);
        self.u32(info.slots);
        self.u32(info.slot_size);
    }
    fn reply(&mut self, reply: &Reply) {
        match reply {
            Reply::Done => self.u8(0),
            Reply::LoginOk {
                version,
                conn,
                admin,
                server,
            } => {
                self.u8(1);
                self.u16(*version);
                self.u32(*conn);
                self.u8(u8::from(*admin));
                self.str(server);
            }
            Reply::Channel(info) => {
                self.u8(2);
                self.channel(info);
            }
            Reply::Channels(list) => {
                self.u8(3);
                // At most 32768 channels exist, so the count always fits.
                self.u16(list.len() as u16);
                for info in list {
                    self.channel(info);
                }
            }
            Reply::Value(json) => {
                self.u8(4);
                self.text(json);
            }
            Reply::Names(names) => {
                self.u8(5);
                self.u32(names.len() as u32);
                for name in names {
                    self.str(name);
                }
            }
            Reply::Payload(payload) => {
                self.u8(6);
                self.bytes(payload);
            }
            Reply::Pong => self.u8(7),
            Reply::Shm { threshold } => {
                self.u8(8);
                self.u32(*threshold);
            }
            Reply::Segment(info) => {
                self.u8(9);
                self.segment(info);
            }
        }
    }
}

fn kind_code(kind: ChannelKind) -> u8 {
    match kind {
        ChannelKind::Stream => 0,
        ChannelKind::Service => 1,
    }
}

// ---------------------------------------------------------------- decoding

/// Decodes a client frame into a command.
pub fn decode_command(frame: RawFrame) -> Result<Envelope, DecodeError> {
    let mut r = BodyReader::new(frame.body, frame.tail);
    let command = match frame.op {
        op::LOGIN => Command::Login {
            version: r.u16("version")?,
            token: r.str("token")?,
            name: r.str("name")?,
        },
        op::SET_ASYNC => Command::SetAsync,
        op::ADD_CHANNEL => Command::AddChannel {
            kind: r.kind()?,
            name: r.str("name")?,
            header: r.text("header")?,
        },
        op::REMOVE_CHANNEL => Command::RemoveChannel { chan: r.chref()? },
        op::SET_HEADER => Command::SetHeader {
            chan: r.chan_id()?,
            header: r.text("header")?,
        },
        op::SUBSCRIBE => Command::Subscribe { chan: r.chref()? },
        op::UNSUBSCRIBE => Command::Unsubscribe { chan: r.chref()? },
        op::PUBLISH => Command::Publish {
            chan: r.chan_id()?,
            payload: r.rest(),
        },
        op::CALL => Command::Call {
            chan: r.chref()?,
            timeout_ms: r.u32("timeout")?,
            payload: r.rest(),
        },
        op::RESPOND => {
            let call = r.u64("call id")?;
            let result = match r.u8("status")? {
                0 => Ok(r.rest()),
                1 => Err(String::from_utf8_lossy(&r.rest()).into_owned()),
                other => {
                    return Err(DecodeError::BadValue {
                        field: "status",
                        value: other.into(),
                    });
                }
            };
            Command::Respond { call, result }
        }
        op::LIST_CHANNELS => Command::ListChannels,
        op::GET_CHANNEL => Command::GetChannel { chan: r.chref()? },
        op::DB_SELECT => Command::DbSelect {
            name: r.str("database")?,
        },
        op::DB_CREATE => Command::DbCreate {
            name: r.str("database")?,
        },
        op::DB_REMOVE => Command::DbRemove {
            name: r.str("database")?,
        },
        op::DB_LIST => Command::DbList,
        op::VAR_SET => Command::VarSet {
            key: r.str("key")?,
            value: r.text("value")?,
        },
        op::VAR_GET => Command::VarGet { key: r.str("key")? },
        op::VAR_DEL => Command::VarDel { key: r.str("key")? },
        op::VAR_LIST => Command::VarList,
        op::PING => Command::Ping,
        op::SHM_ACCEPT => Command::ShmAccept,
        op::SHM_OPEN => Command::ShmOpen {
            chan: r.chan_id()?,
            slot_size: r.u32("slot size")?,
        },
        op::PUBLISH_REF => Command::PublishRef {
            chan: r.chan_id()?,
            slot: r.slot()?,
        },
        op::RELEASE => {
            let count = r.u16("slot count")? as usize;
            // Each entry is 12 bytes, so the body bounds the count: a lying count fails as truncation.
            let mut slots = Vec::with_capacity(count.min(r.left() / 12));
            for _ in 0..count {
                slots.push(r.slot()?);
            }
            Command::Release { slots }
        }
        other => return Err(DecodeError::UnknownOp(other)),
    };
    r.end()?;
    Ok(Envelope {
        req: frame.req,
        command,
    })
}

/// Decodes a hub frame into an event.
pub fn decode_event(frame: RawFrame) -> Result<Event, DecodeError> {
    let mut r = BodyReader::new(frame.body, frame.tail);
    let event = match frame.op {
        op::REPLY => Event::Reply {
            req: frame.req,
            result: r.reply()?,
        },
        op::CHANNEL_ADDED => Event::ChannelAdded(r.channel()?),
        op::CHANNEL_REMOVED => Event::ChannelRemoved {
            id: r.chan_id()?,
            name: r.str("name")?,
        },
        op::HEADER_CHANGED => Event::HeaderChanged {
            id: r.chan_id()?,
            name: r.str("name")?,
            header: r.text("header")?,
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
        op::DB_CHANGED => Event::DbChanged {
            name: r.str("database")?,
        },
        op::GOODBYE => Event::Goodbye {
            reason: r.str("reason")?,
        },
        op::SEGMENT => Event::Segment(r.segment()?),
        op::DATA_REF => Event::DataRef {
            chan: r.chan_id()?,
            seq: r.u64("seq")?,
            ts_us: r.u64("timestamp")?,
            slot: r.slot()?,
        },
        op::RELEASE_RING => Event::ReleaseRing {
            capacity: r.u32("capacity")?,
        },
        other => return Err(DecodeError::UnknownOp(other)),
    };
    r.end()?;
    Ok(event)
}

/// Reads primitives off a frame body, failing cleanly on truncation.
///
/// The body may come in two parts (`RawFrame::tail`): the fields are read from the first, and the payload at the
/// end of a message is the tail itself when the first part ends where the payload begins, which is how an
/// in-process link delivers a shared payload. Any other split is joined (copied) before a field reads across it.
struct BodyReader {
    head: Bytes,
    tail: Bytes,
}

impl BodyReader {
    fn new(head: Bytes, tail: Bytes) -> Self {
        BodyReader { head, tail }
    }
    fn need(&mut self, n: usize, what: &'static str) -> Result<(), DecodeError> {
        if self.head.remaining() < n && !self.tail.is_empty() {
            let joined = [&self.head[..], &self.tail[..]].concat();
            self.head = Bytes::from(joined);
            self.tail = Bytes::new();
        }
        if self.head.remaining() < n {
            Err(DecodeError::Truncated(what))
        } else {
            Ok(())
        }
    }
    fn u8(&mut self, what: &'static str) -> Result<u8, DecodeError> {
        self.need(1, what)?;
        Ok(self.head.get_u8())
    }
    fn u16(&mut self, what: &'static str) -> Result<u16, DecodeError> {
        self.need(2, what)?;
        Ok(self.head.get_u16_le())
    }
    fn u32(&mut self, what: &'static str) -> Result<u32, DecodeError> {
        self.need(4, what)?;
        Ok(self.head.get_u32_le())
    }
    fn u64(&mut self, what: &'static str) -> Result<u64, DecodeError> {
        self.need(8, what)?;
        Ok(self.head.get_u64_le())
    }
    fn f32(&mut self, what: &'static str) -> Result<f32, DecodeError> {
        self.need(4, what)?;
        Ok(self.head.get_f32_le())
    }
    fn chan_id(&mut self) -> Result<ChanId, DecodeError> {
        self.need(2, "channel id")?;
        let id = self.head.get_i16_le();
        if id < 0 {
            return Err(DecodeError::BadValue {
                field: "channel id",
                value: id.into(),
            });
        }
        Ok(id)
    }
    fn utf8(&mut self, len: usize, what: &'static str) -> Result<String, DecodeError> {
        self.need(len, what)?;
        let raw = self.head.split_to(len);
        String::from_utf8(raw.to_vec()).map_err(|_| DecodeError::Utf8(what))
    }
    fn str(&mut self, what: &'static str) -> Result<String, DecodeError> {
        let len = self.u16(what)? as usize;
        self.utf8(len, what)
    }
    fn text(&mut self, what: &'static str) -> Result<String, DecodeError> {
        let len = self.u32(what)? as usize;
        self.utf8(len, what)
    }
    fn rest(&mut self) -> Bytes {
        let head = std::mem::take(&mut self.head);
        let tail = std::mem::take(&mut self.tail);
        match (head.is_empty(), tail.is_empty()) {
            (_, true) => head,
            (true, false) => tail,
            (false, false) => Bytes::from([&head[..], &tail[..]].concat()),
        }
    }
    fn end(&self) -> Result<(), DecodeError> {
        match self.head.remaining() + self.tail.len() {
            0 => Ok(()),
            n => Err(DecodeError::Trailing(n)),
        }
    }
    fn left(&self) -> usize {
        self.head.remaining() + self.tail.len()
    }
    fn slot(&mut self) -> Result<SlotRef, DecodeError> {
        Ok(SlotRef {
            segment: self.u32("segment")?,
            slot: self.u32("slot")?,
            len: self.u32("length")?,
        })
    }
    fn segment(&mut self) -> Result<SegmentInfo, DecodeError> {
        Ok(SegmentInfo {
            id: self.u32("segment")?,
            chan: self.chan_id()?,
            slots: self.u32("slots")?,
            slot_size: self.u32("slot size")?,
        })
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
    fn chref(&mut self) -> Result<ChanRef, DecodeError> {
        match self.u8("channel reference")? {
            0 => Ok(ChanRef::Id(self.chan_id()?)),
            1 => Ok(ChanRef::Name(self.str("channel name")?)),
            other => Err(DecodeError::BadValue {
                field: "channel reference",
                value: other.into(),
            }),
        }
    }
    fn channel(&mut self) -> Result<ChannelInfo, DecodeError> {
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
    fn reply(&mut self) -> Result<Result<Reply, ErrorReply>, DecodeError> {
        let reply = match self.u8("reply tag")? {
            0 => Reply::Done,
            1 => Reply::LoginOk {
                version: self.u16("version")?,
                conn: self.u32("connection id")?,
                admin: self.u8("admin")? != 0,
                server: self.str("server")?,
            },
            2 => Reply::Channel(self.channel()?),
            3 => {
                let count = self.u16("channel count")?;
                // Each entry takes well over 2 bytes, so the body bounds the count
                // and a lying count fails as truncation, not as a huge allocation.
                let left = self.head.remaining() + self.tail.len();
                let mut list = Vec::with_capacity((count as usize).min(left / 8));
                for _ in 0..count {
                    list.push(self.channel()?);
                }
                Reply::Channels(list)
            }
            4 => Reply::Value(self.text("value")?),
            5 => {
                let count = self.u32("name count")?;
                let mut names = Vec::with_capacity((count as usize).min(self.head.remaining() / 2));
                for _ in 0..count {
                    names.push(self.str("name")?);
                }
                Reply::Names(names)
            }
            6 => Reply::Payload(self.rest()),
            7 => Reply::Pong,
            8 => Reply::Shm {
                threshold: self.u32("threshold")?,
            },
            9 => Reply::Segment(self.segment()?),
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
