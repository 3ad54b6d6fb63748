//! FlowProtocol codec tests: random round trips of every command and event,
//! frames fed one byte at a time, and a corpus of malformed frames that must each
//! fail with the right error (never a panic, never a huge allocation).
//!
//! Random tests print their seed; `FLOW_TEST_SEED=N cargo test -p flow --test codec`
//! replays a failure.

#[path = "support/random.rs"]
mod random;

use std::collections::VecDeque;
use std::io;

use bytes::{BufMut, Bytes, BytesMut};
use flow::connection::{ConnError, FrameReader};
use flow::protocol::frame::{self, Check, HEADER_LEN, RawFrame};
use flow::protocol::{
    ChanRef, Command, DecodeError, Envelope, Event, FrameError, decode_command, decode_event,
    encode_command, encode_event, op,
};
use flow::transport::TransportRead;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const MAX: usize = frame::DEFAULT_MAX_FRAME;

/// The base seed: from `FLOW_TEST_SEED`, else fresh, and always printed.
fn base_seed(test: &str) -> u64 {
    let seed = std::env::var("FLOW_TEST_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(rand::random);
    eprintln!("{test}: FLOW_TEST_SEED={seed}");
    seed
}

fn encoded_command(env: &Envelope) -> BytesMut {
    let mut buf = BytesMut::new();
    encode_command(env, &mut buf);
    buf
}

fn encoded_event(event: &Event) -> BytesMut {
    let mut buf = BytesMut::new();
    encode_event(event, &mut buf);
    buf
}

/// Cuts exactly one whole frame out of `buf`, asserting that it fills the buffer.
fn single_frame(mut buf: BytesMut, context: &str) -> RawFrame {
    let total = buf.len();
    assert_eq!(
        frame::check(&buf, MAX),
        Ok(Check::Complete(total)),
        "{context}"
    );
    let raw = frame::parse(&mut buf, total);
    assert!(buf.is_empty(), "{context}");
    raw
}

/// A frame with an arbitrary opcode, request id and body, as a hostile peer would send it.
fn raw_frame(op: u8, req: u32, body: &[u8]) -> BytesMut {
    let mut buf = BytesMut::new();
    frame::put_header(&mut buf, op, req, body.len());
    buf.extend_from_slice(body);
    buf
}

fn decode_cmd_bytes(buf: BytesMut) -> Result<Envelope, DecodeError> {
    decode_command(single_frame(buf, "hand-made frame"))
}

fn decode_event_bytes(buf: BytesMut) -> Result<Event, DecodeError> {
    decode_event(single_frame(buf, "hand-made frame"))
}

// ---------------------------------------------------------------- round trips

#[test]
fn every_command_round_trips_with_random_values() {
    let base = base_seed("commands");
    for i in 0..20_000u64 {
        let seed = base.wrapping_add(i);
        let mut rng = StdRng::seed_from_u64(seed);
        let env = random::envelope(&mut rng, i as usize);
        let ctx = format!("seed {seed} ({env:?})");
        let raw = single_frame(encoded_command(&env), &ctx);
        assert_eq!(raw.req, env.req, "{ctx}");
        let back = decode_command(raw).unwrap_or_else(|e| panic!("{ctx}: {e}"));
        assert_eq!(back, env, "{ctx}");
    }
}

#[test]
fn every_event_round_trips_with_random_values() {
    let base = base_seed("events");
    for i in 0..20_000u64 {
        let seed = base.wrapping_add(i);
        let mut rng = StdRng::seed_from_u64(seed);
        let event = random::event(&mut rng, i as usize);
        let ctx = format!(
            "seed {seed} (variant {})",
            i as usize % random::EVENT_VARIANTS
        );
        let raw = single_frame(encoded_event(&event), &ctx);
        let back = decode_event(raw).unwrap_or_else(|e| panic!("{ctx}: {e}"));
        assert_eq!(back, event, "{ctx}");
    }
}

/// The split encodings the writers use for large payloads (a header, then the
/// payload from its own buffer) are byte for byte the plain encodings.
#[test]
fn split_heads_with_their_payloads_match_the_plain_encoding() {
    let base = base_seed("split heads");
    let mut rng = StdRng::seed_from_u64(base);
    for _ in 0..200 {
        let len = rng.random_range(0..70_000usize);
        let payload = Bytes::from((0..len).map(|_| rng.random::<u8>()).collect::<Vec<_>>());
        let chan: i16 = rng.random_range(0..i16::MAX);
        let mut split = BytesMut::new();
        flow::protocol::codec::encode_publish_head(chan, payload.len(), &mut split);
        split.extend_from_slice(&payload);
        let plain = encoded_command(&Envelope {
            req: 0,
            command: Command::Publish {
                chan,
                payload: payload.clone(),
            },
        });
        assert!(split == plain, "publish head for {len} bytes differs");
        let (seq, ts_us) = (rng.random::<u64>(), rng.random::<u64>());
        let mut split = BytesMut::new();
        flow::protocol::codec::encode_data_head(chan, seq, ts_us, payload.len(), &mut split);
        split.extend_from_slice(&payload);
        let plain = encoded_event(&Event::Data {
            chan,
            seq,
            ts_us,
            payload,
        });
        assert!(split == plain, "data head for {len} bytes differs");
    }
}

/// Decodes `raw` with its body cut at every point (up to 300 bytes in) into the body proper and a tail, as an
/// in-process link delivers a payload, and asserts each cut decodes as the whole.
fn assert_every_split_decodes_alike<T: PartialEq + std::fmt::Debug>(
    raw: &RawFrame,
    decode: fn(RawFrame) -> T,
    what: &str,
) {
    let whole = decode(raw.clone());
    for at in 0..=raw.body.len().min(300) {
        let split = RawFrame {
            op: raw.op,
            req: raw.req,
            body: raw.body.slice(..at),
            tail: raw.body.slice(at..),
        };
        assert_eq!(decode(split), whole, "{what} cut at {at}");
    }
}

#[test]
fn a_body_split_anywhere_into_a_tail_decodes_as_the_whole() {
    let base = base_seed("split tail");
    let mut rng = StdRng::seed_from_u64(base);
    for i in 0..(random::COMMAND_VARIANTS * 10) {
        let raw = single_frame(encoded_command(&random::envelope(&mut rng, i)), "command");
        assert_every_split_decodes_alike(
            &raw,
            decode_command,
            &format!("command {i}, seed {base},"),
        );
    }
    for i in 0..(random::EVENT_VARIANTS * 10) {
        let raw = single_frame(encoded_event(&random::event(&mut rng, i)), "event");
        assert_every_split_decodes_alike(&raw, decode_event, &format!("event {i}, seed {base},"));
    }
}

#[test]
fn frames_appended_to_a_buffer_keep_their_boundaries() {
    let base = base_seed("appended");
    let mut rng = StdRng::seed_from_u64(base);
    let events: Vec<Event> = (0..500).map(|i| random::event(&mut rng, i)).collect();
    let mut buf = BytesMut::new();
    for e in &events {
        encode_event(e, &mut buf);
    }
    for (i, expected) in events.iter().enumerate() {
        let Ok(Check::Complete(total)) = frame::check(&buf, MAX) else {
            panic!("seed {base}: frame {i} not complete");
        };
        let got = decode_event(frame::parse(&mut buf, total)).expect("decode");
        assert_eq!(&got, expected, "seed {base}: frame {i}");
    }
    assert!(buf.is_empty());
}

/// A service error message that is not UTF-8 arrives readable instead of
/// failing the whole frame (the owner may be a satellite in another language).
#[test]
fn respond_error_with_invalid_utf8_is_decoded_lossily() {
    let mut body = Vec::new();
    body.extend_from_slice(&7u64.to_le_bytes());
    body.push(1);
    body.extend_from_slice(b"bad \xff byte");
    let env = decode_cmd_bytes(raw_frame(op::RESPOND, 3, &body)).expect("decode");
    assert_eq!(
        env.command,
        Command::Respond {
            call: 7,
            result: Err("bad \u{fffd} byte".into())
        }
    );
}

/// Strings longer than a `str` field can hold are cut at a character boundary,
/// never in the middle of a UTF-8 sequence.
#[test]
fn overlong_short_strings_are_cut_at_a_character_boundary() {
    let long: String = "é".repeat(40_000); // 80 000 bytes, two per character
    let event = Event::Goodbye { reason: long };
    let raw = single_frame(encoded_event(&event), "goodbye");
    let Event::Goodbye { reason } = decode_event(raw).expect("decode") else {
        panic!("not a goodbye");
    };
    assert_eq!(reason.len(), 65_534);
    assert!(reason.chars().all(|c| c == 'é'));
}

// ---------------------------------------------------------------- fragmentation

/// A transport that hands over one byte per read, the worst case of fragmentation.
#[derive(Debug)]
struct OneByteAtATime(VecDeque<u8>);

impl TransportRead for OneByteAtATime {
    async fn read_into(&mut self, buf: &mut BytesMut) -> io::Result<usize> {
        // Yield so the reader really goes back to the runtime between bytes.
        tokio::task::yield_now().await;
        match self.0.pop_front() {
            Some(b) => {
                buf.put_u8(b);
                Ok(1)
            }
            None => Ok(0),
        }
    }
}

#[tokio::test]
async fn frame_reader_reassembles_byte_at_a_time_input() {
    let base = base_seed("byte at a time");
    let mut rng = StdRng::seed_from_u64(base);
    let envs: Vec<Envelope> = (0..300).map(|i| random::envelope(&mut rng, i)).collect();
    let mut wire = BytesMut::new();
    for env in &envs {
        encode_command(env, &mut wire);
    }
    let mut reader = FrameReader::new(OneByteAtATime(wire.iter().copied().collect()), MAX);
    for (i, expected) in envs.iter().enumerate() {
        let raw = reader
            .read_frame()
            .await
            .expect("read")
            .unwrap_or_else(|| panic!("seed {base}: stream ended before frame {i}"));
        assert_eq!(
            &decode_command(raw).expect("decode"),
            expected,
            "seed {base}: frame {i}"
        );
    }
    // A clean end between frames is not an error.
    assert!(reader.read_frame().await.expect("clean end").is_none());
}

#[tokio::test]
async fn frame_reader_over_an_in_memory_pipe_with_random_split_points() {
    use flow::transport::{Transport, TransportWrite, memory};
    let base = base_seed("memory pipe");
    let mut rng = StdRng::seed_from_u64(base);
    let events: Vec<Event> = (0..400).map(|i| random::event(&mut rng, i)).collect();
    let mut wire = BytesMut::new();
    for e in &events {
        encode_event(e, &mut wire);
    }
    let (a, b) = memory::pair("codec-test");
    let (_a_read, mut a_write) = a.split();
    let (b_read, _b_write) = b.split();
    let cuts: Vec<usize> = {
        let mut at = 0;
        let mut cuts = Vec::new();
        while at < wire.len() {
            at = (at + rng.random_range(1..64)).min(wire.len());
            cuts.push(at);
        }
        cuts
    };
    let writer = tokio::spawn(async move {
        let mut from = 0;
        for to in cuts {
            a_write.write_all(&wire[from..to]).await.expect("write");
            tokio::task::yield_now().await;
            from = to;
        }
        a_write.shutdown().await.expect("shutdown");
    });
    let mut reader = FrameReader::new(b_read, MAX);
    for (i, expected) in events.iter().enumerate() {
        let raw = reader.read_frame().await.expect("read").expect("a frame");
        assert_eq!(
            &decode_event(raw).expect("decode"),
            expected,
            "seed {base}: frame {i}"
        );
    }
    assert!(reader.read_frame().await.expect("clean end").is_none());
    writer.await.expect("writer");
}

#[test]
fn check_on_a_growing_buffer_says_incomplete_until_the_last_byte() {
    let base = base_seed("growing buffer");
    let mut rng = StdRng::seed_from_u64(base);
    for i in 0..200 {
        let frame = encoded_command(&random::envelope(&mut rng, i));
        let total = frame.len();
        for n in 0..total {
            match frame::check(&frame[..n], MAX) {
                Ok(Check::Incomplete(need)) => {
                    assert!(need > n, "seed {base}: asks for {need} with {n} bytes");
                    // Once the header is in, the answer is the exact frame size.
                    if n >= HEADER_LEN {
                        assert_eq!(need, total, "seed {base}");
                    }
                }
                other => panic!("seed {base}: prefix of {n}/{total} bytes gave {other:?}"),
            }
        }
        assert_eq!(frame::check(&frame, MAX), Ok(Check::Complete(total)));
    }
}

#[tokio::test]
async fn peer_closing_in_the_middle_of_a_frame_is_reported() {
    let frame = encoded_command(&Envelope {
        req: 1,
        command: Command::Ping,
    });
    for cut in 1..frame.len() {
        let mut reader =
            FrameReader::new(OneByteAtATime(frame[..cut].iter().copied().collect()), MAX);
        let result = reader.read_frame().await;
        assert!(
            matches!(result, Err(ConnError::TruncatedFrame)),
            "cut at {cut}: {result:?}"
        );
    }
}

#[tokio::test]
async fn frame_reader_refuses_an_oversized_length_before_reading_the_body() {
    // Only the 4-byte prefix is sent: the reader must fail on it alone.
    let prefix = (1u32 << 30).to_le_bytes();
    let mut reader = FrameReader::new(OneByteAtATime(prefix.into_iter().collect()), 1 << 20);
    match reader.read_frame().await {
        Err(ConnError::Frame(FrameError::TooLarge { len, max })) => {
            assert_eq!(len, (1 << 30) + 4);
            assert_eq!(max, 1 << 20);
        }
        other => panic!("expected TooLarge, got {other:?}"),
    }
}

// ---------------------------------------------------------------- malformed frames

#[test]
fn lengths_below_the_header_are_refused() {
    for len in 0u32..5 {
        let mut buf = len.to_le_bytes().to_vec();
        buf.extend_from_slice(&[0u8; 16]);
        assert_eq!(
            frame::check(&buf, MAX),
            Err(FrameError::TooShort(len as usize)),
            "len {len}"
        );
    }
}

#[test]
fn lengths_above_the_maximum_are_refused() {
    let max = 4096;
    // The largest legal frame is exactly `max` bytes including the prefix.
    let legal = raw_frame(op::PUBLISH, 0, &vec![0u8; max - HEADER_LEN]);
    assert_eq!(frame::check(&legal, max), Ok(Check::Complete(max)));
    let over = raw_frame(op::PUBLISH, 0, &vec![0u8; max - HEADER_LEN + 1]);
    assert_eq!(
        frame::check(&over, max),
        Err(FrameError::TooLarge { len: max + 1, max })
    );
    // Refused from the prefix alone, before the body arrives.
    assert_eq!(
        frame::check(&u32::MAX.to_le_bytes(), max),
        Err(FrameError::TooLarge {
            len: u32::MAX as usize + 4,
            max
        })
    );
}

const COMMAND_OPS: [u8; 25] = [
    op::LOGIN,
    op::SET_ASYNC,
    op::ADD_CHANNEL,
    op::REMOVE_CHANNEL,
    op::SET_HEADER,
    op::SUBSCRIBE,
    op::UNSUBSCRIBE,
    op::PUBLISH,
    op::CALL,
    op::RESPOND,
    op::LIST_CHANNELS,
    op::GET_CHANNEL,
    op::DB_SELECT,
    op::DB_CREATE,
    op::DB_REMOVE,
    op::DB_LIST,
    op::VAR_SET,
    op::VAR_GET,
    op::VAR_DEL,
    op::VAR_LIST,
    op::PING,
    op::SHM_ACCEPT,
    op::SHM_OPEN,
    op::PUBLISH_REF,
    op::RELEASE,
];

const EVENT_OPS: [u8; 13] = [
    op::REPLY,
    op::CHANNEL_ADDED,
    op::CHANNEL_REMOVED,
    op::HEADER_CHANGED,
    op::START_PUBLISHING,
    op::STOP_PUBLISHING,
    op::SERVICE_REQUEST,
    op::DATA,
    op::DB_CHANGED,
    op::GOODBYE,
    op::SEGMENT,
    op::DATA_REF,
    op::RELEASE_RING,
];

#[test]
fn unknown_opcodes_are_refused_in_both_directions() {
    for code in 0..=u8::MAX {
        let as_command = decode_cmd_bytes(raw_frame(code, 1, &[]));
        if !COMMAND_OPS.contains(&code) {
            assert_eq!(
                as_command,
                Err(DecodeError::UnknownOp(code)),
                "op {code:#04x}"
            );
        }
        let as_event = decode_event_bytes(raw_frame(code, 1, &[]));
        if !EVENT_OPS.contains(&code) {
            assert_eq!(
                as_event,
                Err(DecodeError::UnknownOp(code)),
                "op {code:#04x}"
            );
        }
    }
    // An event sent to the hub is an unknown command, and the other way round.
    assert_eq!(
        decode_cmd_bytes(raw_frame(op::DATA, 0, &[0; 18])),
        Err(DecodeError::UnknownOp(op::DATA))
    );
    assert_eq!(
        decode_event_bytes(raw_frame(op::PUBLISH, 0, &[0; 2])),
        Err(DecodeError::UnknownOp(op::PUBLISH))
    );
}

fn cmd_err(op: u8, body: &[u8]) -> DecodeError {
    match decode_cmd_bytes(raw_frame(op, 5, body)) {
        Err(e) => e,
        Ok(env) => panic!("op {op:#04x} body {body:02x?} decoded as {env:?}"),
    }
}

fn event_err(op: u8, body: &[u8]) -> DecodeError {
    match decode_event_bytes(raw_frame(op, 5, body)) {
        Err(e) => e,
        Ok(ev) => panic!("op {op:#04x} body {body:02x?} decoded as {ev:?}"),
    }
}

/// `len:u16 | bytes`, as a `str` field is laid out.
fn str_field(bytes: &[u8]) -> Vec<u8> {
    let mut v = (bytes.len() as u16).to_le_bytes().to_vec();
    v.extend_from_slice(bytes);
    v
}

fn cat(parts: &[&[u8]]) -> Vec<u8> {
    parts.concat()
}

#[test]
fn truncated_bodies_name_the_missing_field() {
    use DecodeError::Truncated;
    assert_eq!(cmd_err(op::LOGIN, &[]), Truncated("version"));
    assert_eq!(cmd_err(op::LOGIN, &[1]), Truncated("version"));
    assert_eq!(cmd_err(op::LOGIN, &[1, 0]), Truncated("token"));
    // The token says 10 bytes, only 3 follow.
    assert_eq!(
        cmd_err(op::LOGIN, &cat(&[&[1, 0], &[10, 0], b"abc"])),
        Truncated("token")
    );
    assert_eq!(
        cmd_err(op::LOGIN, &cat(&[&[1, 0], &str_field(b"tok")])),
        Truncated("name")
    );
    assert_eq!(cmd_err(op::ADD_CHANNEL, &[]), Truncated("channel kind"));
    assert_eq!(
        cmd_err(op::ADD_CHANNEL, &cat(&[&[0], &str_field(b"A")])),
        Truncated("header")
    );
    // A header announcing 4 GiB in a tiny frame fails as truncation, without allocating.
    assert_eq!(
        cmd_err(
            op::ADD_CHANNEL,
            &cat(&[&[0], &str_field(b"A"), &u32::MAX.to_le_bytes(), b"{}"])
        ),
        Truncated("header")
    );
    assert_eq!(
        cmd_err(op::REMOVE_CHANNEL, &[]),
        Truncated("channel reference")
    );
    assert_eq!(cmd_err(op::SUBSCRIBE, &[0, 1]), Truncated("channel id"));
    assert_eq!(
        cmd_err(op::UNSUBSCRIBE, &[1, 5, 0]),
        Truncated("channel name")
    );
    assert_eq!(cmd_err(op::SET_HEADER, &[3]), Truncated("channel id"));
    assert_eq!(cmd_err(op::PUBLISH, &[]), Truncated("channel id"));
    assert_eq!(cmd_err(op::CALL, &[0, 1, 0, 9, 9]), Truncated("timeout"));
    assert_eq!(cmd_err(op::RESPOND, &[0; 7]), Truncated("call id"));
    assert_eq!(cmd_err(op::RESPOND, &[0; 8]), Truncated("status"));
    assert_eq!(cmd_err(op::VAR_SET, &str_field(b"k")), Truncated("value"));
    assert_eq!(cmd_err(op::DB_SELECT, &[]), Truncated("database"));

    assert_eq!(event_err(op::REPLY, &[]), Truncated("reply tag"));
    assert_eq!(
        event_err(op::REPLY, &[1, 1, 0, 7]),
        Truncated("connection id")
    );
    assert_eq!(event_err(op::REPLY, &[0xff, 5]), Truncated("error code"));
    assert_eq!(
        event_err(op::REPLY, &[0xff, 5, 0]),
        Truncated("error message")
    );
    assert_eq!(event_err(op::DATA, &[1, 0, 0, 0]), Truncated("seq"));
    assert_eq!(
        event_err(op::DATA, &[1, 0, 1, 0, 0, 0, 0, 0, 0, 0]),
        Truncated("timestamp")
    );
    assert_eq!(
        event_err(op::SERVICE_REQUEST, &[1, 0]),
        Truncated("call id")
    );
    assert_eq!(event_err(op::CHANNEL_ADDED, &[1, 0, 0]), Truncated("hash"));
    // A list claiming 65535 channels in a few bytes: truncation, not a huge allocation.
    assert_eq!(
        event_err(op::REPLY, &[3, 0xff, 0xff, 1]),
        Truncated("channel id")
    );
    // A name list claiming 4 billion names.
    assert_eq!(
        event_err(
            op::REPLY,
            &cat(&[&[5], &u32::MAX.to_le_bytes(), &str_field(b"a")])
        ),
        Truncated("name")
    );
}

/// Cutting any valid frame's body short and re-framing it must give an error or
/// (for messages ending in a payload) a different, shorter message; never a panic.
#[test]
fn every_truncation_of_valid_messages_fails_cleanly() {
    let base = base_seed("truncations");
    let mut rng = StdRng::seed_from_u64(base);
    for i in 0..(random::COMMAND_VARIANTS * 20) {
        let env = random::envelope(&mut rng, i);
        let raw = single_frame(encoded_command(&env), "valid");
        for cut in 0..raw.body.len().min(400) {
            let shorter = raw_frame(raw.op, raw.req, &raw.body[..cut]);
            if let Ok(got) = decode_cmd_bytes(shorter) {
                assert_ne!(got, env, "seed {base}: cut {cut} decoded to the original");
            }
        }
    }
    for i in 0..(random::EVENT_VARIANTS * 20) {
        let event = random::event(&mut rng, i);
        let raw = single_frame(encoded_event(&event), "valid");
        for cut in 0..raw.body.len().min(400) {
            let shorter = raw_frame(raw.op, raw.req, &raw.body[..cut]);
            if let Ok(got) = decode_event_bytes(shorter) {
                assert_ne!(got, event, "seed {base}: cut {cut} decoded to the original");
            }
        }
    }
}

#[test]
fn trailing_bytes_after_a_complete_message_are_refused() {
    assert_eq!(cmd_err(op::SET_ASYNC, &[1, 2, 3]), DecodeError::Trailing(3));
    assert_eq!(cmd_err(op::PING, &[0]), DecodeError::Trailing(1));
    assert_eq!(
        cmd_err(op::SUBSCRIBE, &[0, 4, 0, 9]),
        DecodeError::Trailing(1)
    );
    assert_eq!(
        cmd_err(
            op::LOGIN,
            &cat(&[&[1, 0], &str_field(b"t"), &str_field(b"n"), b"xy"])
        ),
        DecodeError::Trailing(2)
    );
    assert_eq!(
        cmd_err(op::VAR_GET, &cat(&[&str_field(b"k"), b"!"])),
        DecodeError::Trailing(1)
    );
    assert_eq!(
        event_err(op::START_PUBLISHING, &[1, 0, 0]),
        DecodeError::Trailing(1)
    );
    assert_eq!(event_err(op::REPLY, &[0, 0]), DecodeError::Trailing(1));
    assert_eq!(event_err(op::REPLY, &[7, 1, 2]), DecodeError::Trailing(2));
}

#[test]
fn invalid_utf8_is_refused_with_the_field_name() {
    let bad = [0xffu8, 0xfe];
    assert_eq!(
        cmd_err(
            op::LOGIN,
            &cat(&[&[1, 0], &str_field(&bad), &str_field(b"n")])
        ),
        DecodeError::Utf8("token")
    );
    assert_eq!(
        cmd_err(
            op::LOGIN,
            &cat(&[&[1, 0], &str_field(b"t"), &str_field(&bad)])
        ),
        DecodeError::Utf8("name")
    );
    assert_eq!(
        cmd_err(
            op::ADD_CHANNEL,
            &cat(&[&[0], &str_field(b"\xc3("), &[0, 0, 0, 0]])
        ),
        DecodeError::Utf8("name")
    );
    assert_eq!(
        cmd_err(op::SUBSCRIBE, &cat(&[&[1], &str_field(b"ok\xe2\x82")])),
        DecodeError::Utf8("channel name")
    );
    // A header of three bytes that are not UTF-8.
    assert_eq!(
        cmd_err(
            op::SET_HEADER,
            &cat(&[&[0, 0], &3u32.to_le_bytes(), b"\x80\x80\x80"])
        ),
        DecodeError::Utf8("header")
    );
    assert_eq!(
        cmd_err(
            op::VAR_SET,
            &cat(&[&str_field(b"k"), &1u32.to_le_bytes(), b"\xff"])
        ),
        DecodeError::Utf8("value")
    );
    assert_eq!(
        event_err(op::GOODBYE, &str_field(&bad)),
        DecodeError::Utf8("reason")
    );
    assert_eq!(
        event_err(op::REPLY, &cat(&[&[0xff, 1, 0], &str_field(&bad)])),
        DecodeError::Utf8("error message")
    );
}

#[test]
fn negative_channel_ids_are_refused() {
    let neg = (-1i16).to_le_bytes();
    let min = i16::MIN.to_le_bytes();
    let bad = |value: i64| DecodeError::BadValue {
        field: "channel id",
        value,
    };
    assert_eq!(cmd_err(op::PUBLISH, &cat(&[&neg, b"payload"])), bad(-1));
    assert_eq!(
        cmd_err(op::SET_HEADER, &cat(&[&min, &[2, 0, 0, 0], b"{}"])),
        bad(-32768)
    );
    assert_eq!(cmd_err(op::SUBSCRIBE, &cat(&[&[0], &neg])), bad(-1));
    assert_eq!(
        cmd_err(op::REMOVE_CHANNEL, &cat(&[&[0], &min])),
        bad(-32768)
    );
    assert_eq!(cmd_err(op::CALL, &cat(&[&[0], &neg, &[0; 4]])), bad(-1));
    assert_eq!(event_err(op::DATA, &cat(&[&neg, &[0; 16]])), bad(-1));
    assert_eq!(event_err(op::STOP_PUBLISHING, &min), bad(-32768));
    assert_eq!(
        event_err(op::CHANNEL_REMOVED, &cat(&[&neg, &str_field(b"x")])),
        bad(-1)
    );
}

#[test]
fn every_error_code_crosses_the_wire_as_its_number() {
    for (i, code) in flow::protocol::ErrorCode::ALL.into_iter().enumerate() {
        let number = u16::try_from(i + 1).expect("few codes");
        assert_eq!(code as u16, number, "{code:?}");
        assert_eq!(flow::protocol::ErrorCode::from_u16(number), Some(code));
        let event = Event::Reply {
            req: 7,
            result: Err(flow::protocol::ErrorReply::new(code, "why")),
        };
        let back = decode_event(single_frame(encoded_event(&event), "error reply"))
            .unwrap_or_else(|e| panic!("{code:?}: {e}"));
        assert_eq!(back, event);
    }
    // "No such database" and "no such key" are told apart on the wire.
    let body = cat(&[&[0xff], &17u16.to_le_bytes(), &str_field(b"no database x")]);
    assert_eq!(
        decode_event_bytes(raw_frame(op::REPLY, 1, &body)),
        Ok(Event::Reply {
            req: 1,
            result: Err(flow::protocol::ErrorReply::new(
                flow::protocol::ErrorCode::NoDatabase,
                "no database x"
            )),
        })
    );
}

#[test]
fn bad_tags_and_enum_values_are_refused() {
    let bad = |field: &'static str, value: i64| DecodeError::BadValue { field, value };
    for tag in (10u8..0xff).step_by(17) {
        assert_eq!(event_err(op::REPLY, &[tag]), bad("reply tag", tag.into()));
    }
    assert_eq!(event_err(op::REPLY, &[0xfe]), bad("reply tag", 0xfe));
    // Error replies with codes outside the known range.
    for code in [0u16, 18, 999, u16::MAX] {
        let body = cat(&[&[0xff], &code.to_le_bytes(), &str_field(b"m")]);
        assert_eq!(event_err(op::REPLY, &body), bad("error code", code.into()));
    }
    assert_eq!(
        cmd_err(
            op::ADD_CHANNEL,
            &cat(&[&[2], &str_field(b"A"), &[2, 0, 0, 0], b"{}"])
        ),
        bad("channel kind", 2)
    );
    assert_eq!(
        cmd_err(op::SUBSCRIBE, &[2, 0, 0]),
        bad("channel reference", 2)
    );
    assert_eq!(
        cmd_err(op::GET_CHANNEL, &[0xff]),
        bad("channel reference", 255)
    );
    assert_eq!(
        cmd_err(op::RESPOND, &cat(&[&[0; 8], &[2]])),
        bad("status", 2)
    );
}

/// The request id travels in the header, untouched by the body decoder.
#[test]
fn request_ids_survive_the_full_range() {
    for req in [0u32, 1, 0x7fff_ffff, u32::MAX] {
        let env = Envelope {
            req,
            command: Command::GetChannel {
                chan: ChanRef::Name("Robot.audio".into()),
            },
        };
        let back = decode_command(single_frame(encoded_command(&env), "req")).expect("decode");
        assert_eq!(back, env);
        let ev = Event::Reply {
            req,
            result: Ok(flow::protocol::Reply::Pong),
        };
        assert_eq!(
            decode_event(single_frame(encoded_event(&ev), "req")).expect("decode"),
            ev
        );
    }
}

/// Payload bytes are shared with the receive buffer rather than copied.
#[test]
fn payloads_are_not_copied_out_of_the_receive_buffer() {
    let payload = Bytes::from(vec![7u8; 100_000]);
    let mut buf = encoded_command(&Envelope {
        req: 0,
        command: Command::Publish {
            chan: 3,
            payload: payload.clone(),
        },
    });
    let total = buf.len();
    let start = buf.as_ptr() as usize;
    let raw = frame::parse(&mut buf, total);
    let Command::Publish { payload: got, .. } = decode_command(raw).expect("decode").command else {
        panic!("not a publish");
    };
    assert_eq!(got, payload);
    let at = got.as_ptr() as usize;
    assert!(
        at > start && at < start + total,
        "payload was copied out of the frame buffer"
    );
}
