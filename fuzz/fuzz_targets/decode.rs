//! Fuzz target: arbitrary bytes through frame cutting and both decoders.
//! Run with `make fuzz` (see docs/testing.md).

#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    flow_fuzz::decode_any(data);
});
