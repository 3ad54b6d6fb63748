//! What the `decode` fuzz target checks for any input: cutting frames and
//! decoding them as commands and as events never panics and never allocates
//! beyond the frame limit, a body whose end arrived apart (a tail) decodes as
//! the whole, and whatever decodes re-encodes to a frame that decodes to the
//! same bytes again.
//!
//! The same function runs without libFuzzer in `crates/flow/tests/fuzz_smoke.rs`
//! (which includes this file), so the property is exercised by every
//! `cargo test` even where cargo-fuzz is not installed.

use bytes::BytesMut;
use flow::protocol::frame::{self, Check};
use flow::protocol::{Envelope, Event, decode_command, decode_event, encode_command, encode_event};

/// A small limit, so that length checks are exercised by short inputs too.
const SMALL_MAX: usize = 4096;

/// Feeds `data` to the frame cutter and both decoders under two frame limits.
pub fn decode_any(data: &[u8]) {
    for max in [SMALL_MAX, frame::DEFAULT_MAX_FRAME] {
        let mut buf = BytesMut::from(data);
        loop {
            match frame::check(&buf, max) {
                // Garbage lengths end the stream, as they end a connection.
                Err(_) => break,
                Ok(Check::Incomplete(need)) => {
                    assert!(need > buf.len(), "incomplete frame asks for no more bytes");
                    assert!(
                        need <= max.max(frame::HEADER_LEN),
                        "asks for more than the limit"
                    );
                    break;
                }
                Ok(Check::Complete(total)) => {
                    assert!(total <= max && total >= frame::HEADER_LEN && total <= buf.len());
                    let raw = frame::parse(&mut buf, total);
                    let as_command = decode_command(raw.clone());
                    let as_event = decode_event(raw.clone());
                    // The same body with its end apart, as an in-process link delivers a payload, at a cut the
                    // input chooses: it decodes exactly as the whole.
                    let at = raw
                        .body
                        .first()
                        .map_or(0, |b| usize::from(*b) % (raw.body.len() + 1));
                    let split = frame::RawFrame {
                        tail: raw.body.slice(at..),
                        body: raw.body.slice(..at),
                        ..raw
                    };
                    // Compared by their encodings: a decoded float may be NaN, which equals nothing.
                    assert_eq!(
                        decode_command(split.clone()).map(|e| command_bytes(&e)),
                        as_command.as_ref().map(command_bytes).map_err(Clone::clone),
                        "a split body decodes otherwise as a command"
                    );
                    assert_eq!(
                        decode_event(split).map(|e| event_bytes(&e)),
                        as_event.as_ref().map(event_bytes).map_err(Clone::clone),
                        "a split body decodes otherwise as an event"
                    );
                    if let Ok(env) = as_command {
                        command_is_stable(&env);
                    }
                    if let Ok(event) = as_event {
                        event_is_stable(&event);
                    }
                }
            }
        }
    }
}

fn command_bytes(env: &Envelope) -> BytesMut {
    let mut out = BytesMut::new();
    encode_command(env, &mut out);
    out
}

fn event_bytes(event: &Event) -> BytesMut {
    let mut out = BytesMut::new();
    encode_event(event, &mut out);
    out
}

/// Decoding normalises (e.g. lossy error text, admin flags to 0/1); after one
/// encode the bytes must be a fixed point of decode-then-encode.
fn command_is_stable(env: &Envelope) {
    let once = command_bytes(env);
    let again = reframe(&once, |raw| {
        decode_command(raw).unwrap_or_else(|e| panic!("re-encoded command fails: {e} ({env:?})"))
    });
    assert_eq!(
        once,
        command_bytes(&again),
        "command encoding is not stable"
    );
}

fn event_is_stable(event: &Event) {
    let once = event_bytes(event);
    let again = reframe(&once, |raw| {
        decode_event(raw).unwrap_or_else(|e| panic!("re-encoded event fails: {e} ({event:?})"))
    });
    assert_eq!(once, event_bytes(&again), "event encoding is not stable");
}

fn reframe<T>(bytes: &[u8], decode: impl FnOnce(frame::RawFrame) -> T) -> T {
    let mut buf = BytesMut::from(bytes);
    let total = match frame::check(&buf, usize::MAX) {
        Ok(Check::Complete(total)) => total,
        other => panic!("encoder produced an unframed buffer: {other:?}"),
    };
    assert_eq!(total, buf.len(), "encoder produced trailing bytes");
    decode(frame::parse(&mut buf, total))
}
