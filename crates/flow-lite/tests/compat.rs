//! Byte compatibility with the SDK's codec (`flow::protocol`): what flow-lite encodes, `flow` decodes to the same
//! commands and encodes to the same bytes; what `flow` encodes, flow-lite decodes to the same events; and on
//! damaged or hostile bytes both give the same verdict, flow-lite never panicking.

use bytes::{Bytes, BytesMut};
use flow::protocol::{self as fp, frame as fframe};
use flow_lite::codec::{self, DecodeError};
use flow_lite::frame::{self, FrameError, Parsed};
use flow_lite::line::{self, Deframed, Deframer};
use flow_lite::message as m;

/// Deterministic pseudo-random numbers (xorshift32).
struct Rng(u32);

impl Rng {
    fn new(seed: u32) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9) | 1)
    }
    fn next(&mut self) -> u32 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        self.0 = x;
        x
    }
    fn below(&mut self, n: u32) -> u32 {
        self.next() % n
    }
    fn u64(&mut self) -> u64 {
        (u64::from(self.next()) << 32) | u64::from(self.next())
    }
    /// Bytes with zeros and 0xFF often, and lengths around COBS's 254-byte blocks now and then.
    fn bytes(&mut self) -> Vec<u8> {
        let n = match self.below(4) {
            0 => 0,
            1 => self.below(8),
            2 => 250 + self.below(10),
            _ => self.below(600),
        } as usize;
        (0..n)
            .map(|_| match self.below(5) {
                0 => 0,
                1 => 0xFF,
                _ => self.next() as u8,
            })
            .collect()
    }
    /// Text with multi-byte characters, so that every length is counted in bytes.
    fn text(&mut self, max: u32) -> String {
        let parts = ["a", "Z", "9", ".", "_", "é", "温", "🦀", "{", "\"", ":"];
        let n = self.below(max + 1);
        (0..n)
            .map(|_| parts[self.below(parts.len() as u32) as usize])
            .collect()
    }
    fn chan(&mut self) -> i16 {
        self.below(32768) as i16
    }
}

// ---------------------------------------------------------------- helpers

fn lite_encode(req: u32, command: &m::Command<'_>) -> Vec<u8> {
    let n = codec::encoded_len(command).expect("measures");
    let mut out = vec![0xAA; n];
    assert_eq!(codec::encode_command(req, command, &mut out), Ok(n));
    out
}

fn flow_decode_command(frame: &[u8]) -> fp::Envelope {
    let mut buf = BytesMut::from(frame);
    let total = match fframe::check(&buf, fp::DEFAULT_MAX_FRAME) {
        Ok(fp::Check::Complete(total)) => total,
        other => panic!("not one whole frame: {other:?}"),
    };
    assert_eq!(total, frame.len());
    fp::decode_command(fframe::parse(&mut buf, total)).expect("the SDK decodes it")
}

fn flow_encode_command(env: &fp::Envelope) -> Vec<u8> {
    let mut out = BytesMut::new();
    fp::encode_command(env, &mut out);
    out.to_vec()
}

fn flow_encode_event(event: &fp::Event) -> Vec<u8> {
    let mut out = BytesMut::new();
    fp::encode_event(event, &mut out);
    out.to_vec()
}

/// The SDK's verdict on one whole event frame.
fn flow_decode_event(frame: &[u8]) -> Result<fp::Event, fp::DecodeError> {
    let mut buf = BytesMut::from(frame);
    let raw = fframe::parse(&mut buf, frame.len());
    fp::decode_event(raw)
}

/// flow-lite's decoding of one whole frame, which must take all of it.
fn lite_decode_event(frame: &[u8]) -> Result<m::Event<'_>, DecodeError> {
    match frame::parse(frame, frame.len()) {
        Ok(Parsed::Frame(raw, used)) => {
            assert_eq!(used, frame.len());
            codec::decode_event(raw)
        }
        other => panic!("not one whole frame: {other:?}"),
    }
}

fn flow_ref(chan: m::ChanRef<'_>) -> fp::ChanRef {
    match chan {
        m::ChanRef::Id(id) => fp::ChanRef::Id(id),
        m::ChanRef::Name(name) => fp::ChanRef::Name(name.into()),
    }
}

/// The SDK's value for a flow-lite command.
fn flow_command(command: &m::Command<'_>) -> fp::Command {
    match *command {
        m::Command::Login {
            version,
            token,
            name,
        } => fp::Command::Login {
            version,
            token: token.into(),
            name: name.into(),
        },
        m::Command::SetAsync => fp::Command::SetAsync,
        m::Command::AddChannel { kind, name, header } => fp::Command::AddChannel {
            kind: match kind {
                m::ChannelKind::Stream => fp::ChannelKind::Stream,
                m::ChannelKind::Service => fp::ChannelKind::Service,
            },
            name: name.into(),
            header: header.into(),
        },
        m::Command::RemoveChannel { chan } => fp::Command::RemoveChannel {
            chan: flow_ref(chan),
        },
        m::Command::Subscribe { chan } => fp::Command::Subscribe {
            chan: flow_ref(chan),
        },
        m::Command::Unsubscribe { chan } => fp::Command::Unsubscribe {
            chan: flow_ref(chan),
        },
        m::Command::Publish { chan, payload } => fp::Command::Publish {
            chan,
            payload: Bytes::copy_from_slice(payload),
        },
        m::Command::Call {
            chan,
            timeout_ms,
            payload,
        } => fp::Command::Call {
            chan: flow_ref(chan),
            timeout_ms,
            payload: Bytes::copy_from_slice(payload),
        },
        m::Command::Respond { call, result } => fp::Command::Respond {
            call,
            result: result.map(Bytes::copy_from_slice).map_err(String::from),
        },
        m::Command::Ping => fp::Command::Ping,
    }
}

fn flow_info(info: &m::ChannelInfo<'_>) -> fp::ChannelInfo {
    fp::ChannelInfo {
        id: info.id,
        hash: info.hash,
        kind: match info.kind {
            m::ChannelKind::Stream => fp::ChannelKind::Stream,
            m::ChannelKind::Service => fp::ChannelKind::Service,
        },
        name: info.name.into(),
        owner: info.owner.into(),
        header: info.header.into(),
        stats: fp::ChannelStats {
            subscribers: info.stats.subscribers,
            msgs: info.stats.msgs,
            bytes: info.stats.bytes,
            dropped: info.stats.dropped,
            msgs_per_s: info.stats.msgs_per_s,
            bytes_per_s: info.stats.bytes_per_s,
        },
    }
}

/// The SDK's value for a flow-lite event; `None` for what flow-lite leaves whole (`Other`).
fn flow_event(event: &m::Event<'_>) -> Option<fp::Event> {
    Some(match *event {
        m::Event::Reply { req, result } => fp::Event::Reply {
            req,
            result: match result {
                Ok(reply) => Ok(match reply {
                    m::Reply::Done => fp::Reply::Done,
                    m::Reply::LoginOk {
                        version,
                        conn,
                        admin,
                        server,
                    } => fp::Reply::LoginOk {
                        version,
                        conn,
                        admin,
                        server: server.into(),
                    },
                    m::Reply::Channel(info) => fp::Reply::Channel(flow_info(&info)),
                    m::Reply::Value(json) => fp::Reply::Value(json.into()),
                    m::Reply::Payload(p) => fp::Reply::Payload(Bytes::copy_from_slice(p)),
                    m::Reply::Pong => fp::Reply::Pong,
                    m::Reply::Other { .. } => return None,
                }),
                Err(e) => Err(fp::ErrorReply {
                    code: fp::ErrorCode::from_u16(e.code as u16).expect("same codes"),
                    message: e.message.into(),
                }),
            },
        },
        m::Event::ChannelRemoved { id, name } => fp::Event::ChannelRemoved {
            id,
            name: name.into(),
        },
        m::Event::StartPublishing { id } => fp::Event::StartPublishing { id },
        m::Event::StopPublishing { id } => fp::Event::StopPublishing { id },
        m::Event::ServiceRequest {
            chan,
            call,
            payload,
        } => fp::Event::ServiceRequest {
            chan,
            call,
            payload: Bytes::copy_from_slice(payload),
        },
        m::Event::Data {
            chan,
            seq,
            ts_us,
            payload,
        } => fp::Event::Data {
            chan,
            seq,
            ts_us,
            payload: Bytes::copy_from_slice(payload),
        },
        m::Event::Goodbye { reason } => fp::Event::Goodbye {
            reason: reason.into(),
        },
        m::Event::Other { .. } => return None,
    })
}

fn random_info(r: &mut Rng) -> fp::ChannelInfo {
    let name = format!("Sensor.{}", r.text(12));
    fp::ChannelInfo {
        id: r.chan(),
        hash: fp::channel_hash(&name),
        kind: if r.below(2) == 0 {
            fp::ChannelKind::Stream
        } else {
            fp::ChannelKind::Service
        },
        name,
        owner: format!("board#{}", r.below(100)),
        header: format!("{{\"mime\":\"{}\"}}", r.text(20)),
        stats: fp::ChannelStats {
            subscribers: r.next(),
            msgs: r.u64(),
            bytes: r.u64(),
            dropped: r.u64(),
            msgs_per_s: r.below(100_000) as f32 / 8.0,
            bytes_per_s: r.below(1_000_000) as f32 / 4.0,
        },
    }
}

/// Every event kind the hub sends, with random contents.
fn random_events(r: &mut Rng) -> Vec<fp::Event> {
    let reply = |req, result| fp::Event::Reply { req, result };
    let code = fp::ErrorCode::ALL[r.below(17) as usize];
    vec![
        reply(r.next(), Ok(fp::Reply::Done)),
        reply(
            r.next(),
            Ok(fp::Reply::LoginOk {
                version: 1,
                conn: r.next(),
                admin: r.below(2) == 1,
                server: format!("robot-agent {}", r.text(10)),
            }),
        ),
        reply(r.next(), Ok(fp::Reply::Channel(random_info(r)))),
        reply(
            r.next(),
            Ok(fp::Reply::Channels(vec![random_info(r), random_info(r)])),
        ),
        reply(r.next(), Ok(fp::Reply::Value(r.text(40)))),
        reply(r.next(), Ok(fp::Reply::Names(vec![r.text(5), r.text(5)]))),
        reply(r.next(), Ok(fp::Reply::Payload(Bytes::from(r.bytes())))),
        reply(r.next(), Ok(fp::Reply::Pong)),
        reply(r.next(), Err(fp::ErrorReply::new(code, r.text(30)))),
        fp::Event::ChannelAdded(random_info(r)),
        fp::Event::ChannelRemoved {
            id: r.chan(),
            name: r.text(10),
        },
        fp::Event::HeaderChanged {
            id: r.chan(),
            name: r.text(10),
            header: r.text(20),
        },
        fp::Event::StartPublishing { id: r.chan() },
        fp::Event::StopPublishing { id: r.chan() },
        fp::Event::ServiceRequest {
            chan: r.chan(),
            call: r.u64(),
            payload: Bytes::from(r.bytes()),
        },
        fp::Event::Data {
            chan: r.chan(),
            seq: r.u64(),
            ts_us: r.u64(),
            payload: Bytes::from(r.bytes()),
        },
        fp::Event::DbChanged { name: r.text(10) },
        fp::Event::Goodbye { reason: r.text(30) },
    ]
}

// ---------------------------------------------------------------- tests

#[test]
fn commands_flow_lite_encodes_are_the_sdks_commands_byte_for_byte() {
    for seed in 0..300 {
        let mut r = Rng::new(seed);
        let (token, name, header) = (r.text(40), r.text(20), r.text(60));
        let (payload, message) = (r.bytes(), r.text(30));
        let chan = if r.below(2) == 0 {
            m::ChanRef::Id(r.chan())
        } else {
            m::ChanRef::Name(&name)
        };
        let commands = [
            m::Command::Login {
                version: m::PROTOCOL_VERSION,
                token: &token,
                name: &name,
            },
            m::Command::SetAsync,
            m::Command::AddChannel {
                kind: m::ChannelKind::Stream,
                name: &name,
                header: &header,
            },
            m::Command::AddChannel {
                kind: m::ChannelKind::Service,
                name: &name,
                header: &header,
            },
            m::Command::RemoveChannel { chan },
            m::Command::Subscribe { chan },
            m::Command::Unsubscribe { chan },
            m::Command::Publish {
                chan: r.chan(),
                payload: &payload,
            },
            m::Command::Call {
                chan,
                timeout_ms: r.next(),
                payload: &payload,
            },
            m::Command::Respond {
                call: r.u64(),
                result: Ok(&payload),
            },
            m::Command::Respond {
                call: r.u64(),
                result: Err(&message),
            },
            m::Command::Ping,
        ];
        for command in &commands {
            let req = if r.below(3) == 0 { 0 } else { r.next() };
            let wire = lite_encode(req, command);
            let envelope = flow_decode_command(&wire);
            let expected = fp::Envelope {
                req,
                command: flow_command(command),
            };
            assert_eq!(envelope, expected, "seed {seed}");
            assert_eq!(
                wire,
                flow_encode_command(&expected),
                "seed {seed}: {command:?}"
            );
        }
    }
}

#[test]
fn a_login_is_laid_out_as_the_protocol_says() {
    let wire = lite_encode(
        1,
        &m::Command::Login {
            version: 1,
            token: "tk",
            name: "b",
        },
    );
    #[rustfmt::skip]
    let expected = [
        14, 0, 0, 0,   0x01,   1, 0, 0, 0,   // len, op, req
        1, 0,                                // version
        2, 0, b't', b'k',                    // token:str
        1, 0, b'b',                          // name:str
    ];
    assert_eq!(wire, expected);
}

#[test]
fn events_the_sdk_encodes_decode_with_flow_lite_to_the_same_values() {
    let mut others = 0;
    for seed in 0..300 {
        let mut r = Rng::new(seed);
        for event in random_events(&mut r) {
            let wire = flow_encode_event(&event);
            let decoded = lite_decode_event(&wire).expect("flow-lite decodes what the SDK wrote");
            match flow_event(&decoded) {
                Some(same) => assert_eq!(same, event, "seed {seed}"),
                None => {
                    others += 1;
                    // Left whole: the raw body (after a reply's tag) is all there, nothing lost.
                    match decoded {
                        m::Event::Other { op, req, body } => {
                            assert_eq!((op, req), (wire[4], 0));
                            assert_eq!(body, &wire[9..]);
                        }
                        m::Event::Reply {
                            result: Ok(m::Reply::Other { tag, body }),
                            ..
                        } => {
                            assert!(tag == 3 || tag == 5);
                            assert_eq!(body, &wire[10..]);
                        }
                        other => panic!("{other:?} is not left whole"),
                    }
                }
            }
        }
    }
    // Channels, Names, ChannelAdded, HeaderChanged, DbChanged of every seed.
    assert_eq!(others, 300 * 5);
}

#[test]
fn frames_fed_a_byte_at_a_time_are_cut_where_the_sdk_cut_them() {
    let mut r = Rng::new(7);
    let events: Vec<fp::Event> = (0..10).flat_map(|_| random_events(&mut r)).collect();
    let stream: Vec<u8> = events.iter().flat_map(flow_encode_event).collect();
    let mut held: Vec<u8> = Vec::new();
    let mut got: Vec<Option<fp::Event>> = Vec::new();
    for &b in &stream {
        held.push(b);
        match frame::parse(&held, 1 << 20).expect("valid lengths") {
            Parsed::Incomplete(need) => assert!(need > held.len()),
            Parsed::Frame(raw, used) => {
                assert_eq!(
                    used,
                    held.len(),
                    "a frame is whole at its last byte, not before"
                );
                let event = codec::decode_event(raw).expect("decodes");
                got.push(flow_event(&event));
                held.clear();
            }
        }
    }
    assert!(held.is_empty());
    assert_eq!(got.len(), events.len());
    for (got, want) in got.iter().zip(&events) {
        if let Some(got) = got {
            assert_eq!(got, want);
        }
    }
}

#[test]
fn packets_of_several_frames_fed_a_byte_at_a_time_give_every_event() {
    let mut r = Rng::new(11);
    let events = random_events(&mut r);
    // The hub batches: several whole frames in one packet body.
    let mut wire = Vec::new();
    for group in events.chunks(4) {
        let body: Vec<u8> = group.iter().flat_map(flow_encode_event).collect();
        let mut packet = vec![0; line::max_encoded_len(body.len())];
        let n = line::encode(&body, &mut packet).expect("encodes");
        wire.extend_from_slice(&packet[..n]);
    }
    let mut deframer = Deframer::new(vec![0u8; 1 << 16]);
    let mut decoded = Vec::new();
    for b in wire.chunks(1) {
        let (_, out) = deframer.push(b);
        if let Some(Deframed::Packet(mut body)) = out {
            while !body.is_empty() {
                let Ok(Parsed::Frame(raw, used)) = frame::parse(body, body.len()) else {
                    panic!("a packet holds whole frames");
                };
                let event = codec::decode_event(raw).expect("decodes");
                decoded.push(flow_event(&event));
                body = &body[used..];
            }
        }
    }
    assert_eq!(decoded.len(), events.len());
    for (got, want) in decoded.iter().zip(&events) {
        if let Some(got) = got {
            assert_eq!(got, want);
        }
    }
}

/// flow-lite's verdict must be the SDK's for everything it takes apart; never a panic.
fn same_verdict(frame_bytes: &[u8], context: &str) {
    let lite = lite_decode_event(frame_bytes);
    let sdk = flow_decode_event(frame_bytes);
    match (&lite, &sdk) {
        (Ok(m::Event::Other { .. }), _) => {}
        (
            Ok(m::Event::Reply {
                result: Ok(m::Reply::Other { .. }),
                ..
            }),
            _,
        ) => {}
        (Ok(event), Ok(sdk)) => assert_eq!(flow_event(event).as_ref(), Some(sdk), "{context}"),
        (Err(_), Err(_)) => {}
        _ => panic!("{context}: flow-lite {lite:?}, the SDK {sdk:?}"),
    }
}

/// The frame of `body` with the header's length fixed to it.
fn reframe(op: u8, req: u32, body: &[u8]) -> Vec<u8> {
    let mut out = vec![0; frame::HEADER_LEN];
    frame::put_header(&mut out, op, req, body.len()).expect("fits");
    out.extend_from_slice(body);
    out
}

#[test]
fn cut_and_flipped_bodies_get_the_sdks_verdict_and_never_a_panic() {
    let mut r = Rng::new(3);
    let mut errors = 0;
    for event in random_events(&mut r) {
        let wire = flow_encode_event(&event);
        let (op, req, body) = (
            wire[4],
            u32::from_le_bytes([wire[5], wire[6], wire[7], wire[8]]),
            &wire[9..],
        );
        for cut in 0..body.len() {
            let framed = reframe(op, req, &body[..cut]);
            errors += usize::from(lite_decode_event(&framed).is_err());
            same_verdict(&framed, &format!("{event:?} cut at {cut}"));
        }
        for at in 0..body.len().min(80) {
            for bit in [0x01, 0x80, 0xFF] {
                let mut flipped = body.to_vec();
                flipped[at] ^= bit;
                same_verdict(
                    &reframe(op, req, &flipped),
                    &format!("{event:?} flipped at {at}"),
                );
            }
        }
        let mut longer = body.to_vec();
        longer.push(0);
        same_verdict(
            &reframe(op, req, &longer),
            &format!("{event:?} with a trailing byte"),
        );
    }
    assert!(errors > 100, "cut bodies must mostly fail: {errors}");
}

#[test]
fn random_bodies_under_every_known_opcode_get_the_sdks_verdict() {
    let ops = [0x80, 0x82, 0x84, 0x85, 0x86, 0x87, 0x89];
    for seed in 0..3000 {
        let mut r = Rng::new(seed);
        let op = ops[r.below(ops.len() as u32) as usize];
        let n = r.below(40) as usize;
        let mut body: Vec<u8> = (0..n).map(|_| r.next() as u8).collect();
        if op == 0x80 && !body.is_empty() && r.below(2) == 0 {
            body[0] = [0, 1, 2, 4, 6, 7, 0xff][r.below(7) as usize];
        }
        same_verdict(&reframe(op, r.next(), &body), &format!("seed {seed}"));
    }
}

#[test]
fn a_malformed_corpus_is_refused_with_an_error() {
    let corpus: [(u8, &[u8], DecodeError); 10] = [
        (0x80, &[], DecodeError::Truncated("reply tag")),
        (
            0x80,
            &[8],
            DecodeError::BadValue {
                field: "reply tag",
                value: 8,
            },
        ),
        (
            0x80,
            &[0xff, 0, 0, 0, 0],
            DecodeError::BadValue {
                field: "error code",
                value: 0,
            },
        ),
        (
            0x80,
            &[0xff, 99, 0, 0, 0],
            DecodeError::BadValue {
                field: "error code",
                value: 99,
            },
        ),
        (
            0x80,
            &[4, 0xff, 0xff, 0xff, 0xff, b'{'],
            DecodeError::Truncated("value"),
        ),
        (0x80, &[0, 1], DecodeError::Trailing(1)),
        (
            0x84,
            &[0xff, 0xff],
            DecodeError::BadValue {
                field: "channel id",
                value: -1,
            },
        ),
        (0x85, &[1, 0, 0], DecodeError::Trailing(1)),
        (0x89, &[2, 0, 0xc3, 0x28], DecodeError::Utf8("reason")),
        (0x87, &[1, 0, 1, 2, 3], DecodeError::Truncated("seq")),
    ];
    for (op, body, want) in corpus {
        let framed = reframe(op, 1, body);
        assert_eq!(lite_decode_event(&framed), Err(want), "{op:#x} {body:?}");
        assert!(
            flow_decode_event(&framed).is_err(),
            "the SDK refuses it too"
        );
    }
    assert_eq!(
        frame::check(&[4, 0, 0, 0, 0], 64),
        Err(FrameError::TooShort(4))
    );
    assert_eq!(
        frame::check(&[60, 0, 0, 0], 64),
        Ok(frame::Check::Incomplete(64))
    );
    assert_eq!(
        frame::check(&[61, 0, 0, 0], 64),
        Err(FrameError::TooLarge { len: 65, max: 64 })
    );
}
