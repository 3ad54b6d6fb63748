//! Fuzz target: arbitrary datagrams into a UDP session's receiving end (`flow::transport::udp::engine`).
//! Run with `make fuzz` (see docs/testing.md).

#![no_main]

#[path = "../src/udp.rs"]
mod udp;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    udp::engine_any(data);
});
