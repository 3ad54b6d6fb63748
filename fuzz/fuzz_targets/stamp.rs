//! Fuzz target: arbitrary bytes as the attachment of a sample crossing hubs (`flow_hub::federation::stamp`). A
//! decode never panics, and whatever decodes re-encodes to the same bytes.
//! Run with `make fuzz`.

#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Ok(stamp) = flow_hub::federation::stamp::Stamp::decode(data) {
        assert_eq!(&stamp.encode()[..], data);
    }
});
