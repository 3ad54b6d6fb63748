//! Fuzz target: arbitrary bytes through the serial line deframer (`flow_lite::line`).
//! Run with `make fuzz` (see docs/testing.md).

#![no_main]

#[path = "../src/line.rs"]
mod line;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    line::deframe_any(data);
});
