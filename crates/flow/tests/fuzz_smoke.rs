//! The `decode` fuzz target's property, run without libFuzzer on 100 000
//! generated inputs: valid frames of every kind, then mutated (bit flips,
//! byte changes, truncation, insertion, length-field edits, concatenation) and
//! plain random bytes. Nothing may panic; see `fuzz/src/lib.rs` for the checks.
//!
//! `FLOW_TEST_SEED=N` replays a failing run.

#[path = "support/random.rs"]
mod random;

#[path = "../../../fuzz/src/lib.rs"]
mod decode_any;

use bytes::BytesMut;
use flow::protocol::{encode_command, encode_event};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn valid_frame(rng: &mut StdRng, i: usize) -> Vec<u8> {
    let mut buf = BytesMut::new();
    if rng.random() {
        encode_command(&random::envelope(rng, i), &mut buf);
    } else {
        encode_event(&random::event(rng, i), &mut buf);
    }
    // Keep inputs small so mutations land in headers and fields, not payloads.
    buf.truncate(buf.len().min(2048));
    buf.to_vec()
}

fn mutate(rng: &mut StdRng, data: &mut Vec<u8>) {
    for _ in 0..rng.random_range(1..4) {
        if data.is_empty() {
            data.push(rng.random());
            continue;
        }
        let at = rng.random_range(0..data.len());
        match rng.random_range(0..7) {
            0 => data[at] ^= 1 << rng.random_range(0..8),
            1 => data[at] = rng.random(),
            2 => data.truncate(at),
            3 => data.insert(at, rng.random()),
            4 => {
                data.remove(at);
            }
            // Rewrite the length prefix so that it stays plausible but wrong.
            5 if data.len() >= 4 => {
                let len = u32::from_le_bytes([data[0], data[1], data[2], data[3]]);
                let len = len.wrapping_add(rng.random_range(0..16)).wrapping_sub(8);
                data[..4].copy_from_slice(&len.to_le_bytes());
            }
            // Interesting values in a random field position.
            _ => {
                let v: [u8; 4] = *[
                    [0xff, 0xff, 0xff, 0xff],
                    [0, 0, 0, 0x80],
                    [0xff, 0x7f, 0, 0],
                    [0, 0x80, 0, 0],
                ]
                .get(rng.random_range(0..4))
                .unwrap_or(&[0; 4]);
                for (k, b) in v.iter().enumerate() {
                    if let Some(slot) = data.get_mut(at + k) {
                        *slot = *b;
                    }
                }
            }
        }
    }
}

#[test]
fn decoder_survives_100k_generated_inputs() {
    let seed = std::env::var("FLOW_TEST_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(rand::random);
    eprintln!("fuzz smoke: FLOW_TEST_SEED={seed}");
    let mut rng = StdRng::seed_from_u64(seed);
    for i in 0..100_000usize {
        let input = match i % 4 {
            // Unchanged valid frames, several back to back.
            0 => {
                let mut v = valid_frame(&mut rng, i);
                for _ in 0..rng.random_range(0..3) {
                    v.extend(valid_frame(&mut rng, i + 1));
                }
                v
            }
            1 | 2 => {
                let mut v = valid_frame(&mut rng, i);
                mutate(&mut rng, &mut v);
                v
            }
            _ => {
                let len = rng.random_range(0..64);
                (0..len).map(|_| rng.random()).collect()
            }
        };
        let outcome = std::panic::catch_unwind(|| decode_any::decode_any(&input));
        assert!(
            outcome.is_ok(),
            "seed {seed}, input {i}: decoder panicked on {input:02x?}"
        );
    }
}
