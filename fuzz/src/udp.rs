//! What the `udp` fuzz target checks for any input: a UDP session's receiving end (`flow::transport::udp::engine`,
//! the reassembler of best-effort frames and the in-order reliable lane) takes any sequence of datagrams without
//! panicking, never delivers a frame larger than its limit, and everything it sends decodes.
//!
//! The input is read as datagrams, each `[len u8][advance u8][bytes]`: `advance` moves the clock that many ms.
//! Run without libFuzzer by `crates/flow/tests/udp_fuzz_smoke.rs` (which includes this file).

use std::sync::Arc;
use std::time::Duration;

use flow::transport::udp::datagram::Datagram;
use flow::transport::udp::engine::{Engine, Settings, UdpStats};
use tokio::time::Instant;

/// Feeds the datagrams in `data` to a fresh session end with small limits, so that they are reached.
pub fn engine_any(data: &[u8]) {
    let settings = Settings {
        mtu: 64,
        max_message: 4096,
        reassembly_bytes: 8192,
        receive_bytes: 8192,
        ..Settings::default()
    };
    let max_message = settings.max_message;
    let mut now = Instant::now();
    let mut engine = Engine::client(7, settings, Arc::<UdpStats>::default(), now);
    let mut rest = data;
    while let [len, advance, tail @ ..] = rest {
        let take = usize::from(*len).min(tail.len());
        let (bytes, after) = tail.split_at(take);
        rest = after;
        now += Duration::from_millis(u64::from(*advance));
        if let Ok(d) = Datagram::decode(bytes) {
            // A failure (a session that must end) is an answer, not a crash.
            if engine.on_datagram(&d, now).is_err() {
                return;
            }
        }
        if engine.on_timer(now).is_err() {
            return;
        }
        while let Some(frame) = engine.poll_frame() {
            assert!(!frame.is_empty(), "an empty frame delivered");
            assert!(
                frame.len() <= max_message + 64,
                "a frame past the limit delivered"
            );
        }
        while let Some(out) = engine.poll_send(now) {
            assert!(
                Datagram::decode(&out).is_ok(),
                "the engine sent a datagram it cannot read"
            );
        }
    }
}
