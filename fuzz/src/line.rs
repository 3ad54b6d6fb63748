//! What the `line` fuzz target checks for any input: the serial deframer (`flow_lite::line`) never panics, consumes
//! every byte it is given, and whatever it accepts as a packet is a body that encodes back to a packet it reads as
//! the same body; fed a byte at a time it finds exactly what it finds fed at once.
//!
//! Run without libFuzzer by `crates/flow/tests/line_fuzz_smoke.rs` (which includes this file).

use flow_lite::line::{Deframed, Deframer, encode, max_encoded_len};

/// The bodies (or damage) `data` yields, fed `step` bytes at a time into a reader of `cap` bytes.
fn read(data: &[u8], step: usize, cap: usize) -> Vec<Result<Vec<u8>, flow_lite::line::Damage>> {
    let mut d = Deframer::new(vec![0u8; cap]);
    let mut out = Vec::new();
    for chunk in data.chunks(step.max(1)) {
        let mut rest = chunk;
        while !rest.is_empty() {
            let (used, got) = d.push(rest);
            assert!(
                used > 0 && used <= rest.len(),
                "consumed {used} of {}",
                rest.len()
            );
            rest = &rest[used..];
            match got {
                Some(Deframed::Packet(body)) => out.push(Ok(body.to_vec())),
                Some(Deframed::Damaged(why)) => out.push(Err(why)),
                None => assert!(rest.is_empty(), "stopped early without a packet"),
            }
        }
    }
    out
}

/// Feeds `data` to the deframer whole and a byte at a time, under a small buffer and a large one.
pub fn deframe_any(data: &[u8]) {
    for cap in [64, 1 << 16] {
        let whole = read(data, data.len(), cap);
        assert_eq!(whole, read(data, 1, cap), "byte-at-a-time differs");
        for body in whole.into_iter().flatten() {
            assert!(!body.is_empty());
            let mut wire = vec![0; max_encoded_len(body.len())];
            let n = encode(&body, &mut wire).expect("a body encodes");
            wire.truncate(n);
            assert_eq!(read(&wire, 3, max_encoded_len(body.len())), vec![Ok(body)]);
        }
    }
}
