//! The `line` fuzz target's property, run without libFuzzer on 20 000 generated inputs: packets of random bodies,
//! then mutated (bit flips, lost bytes, inserted bytes, zeros, cuts) and run together, and plain random bytes.
//! Nothing may panic and nothing damaged may pass; see `fuzz/src/line.rs` for the checks.
//!
//! `FLOW_TEST_SEED=N` replays a failing run.

#[path = "../../../fuzz/src/line.rs"]
mod line;

use flow_lite::line::{encode, max_encoded_len};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn packet(rng: &mut StdRng) -> Vec<u8> {
    let len = rng.random_range(1..700);
    let body: Vec<u8> = (0..len)
        .map(|_| match rng.random_range(0..4) {
            0 => 0,
            1 => 0xff,
            _ => rng.random(),
        })
        .collect();
    let mut wire = vec![0; max_encoded_len(body.len())];
    let n = encode(&body, &mut wire).expect("encodes");
    wire.truncate(n);
    wire
}

fn mutate(rng: &mut StdRng, data: &mut Vec<u8>) {
    for _ in 0..rng.random_range(0..4) {
        if data.is_empty() {
            return;
        }
        let at = rng.random_range(0..data.len());
        match rng.random_range(0..5) {
            0 => data[at] ^= 1 << rng.random_range(0..8),
            1 => {
                data.remove(at);
            }
            2 => data.insert(at, rng.random()),
            3 => data[at] = 0,
            _ => data.truncate(at),
        }
    }
}

#[test]
fn the_deframer_survives_20k_generated_inputs() {
    let seed = std::env::var("FLOW_TEST_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(rand::random);
    eprintln!("line fuzz smoke: FLOW_TEST_SEED={seed}");
    let mut rng = StdRng::seed_from_u64(seed);
    for _ in 0..20_000 {
        let mut data = Vec::new();
        if rng.random_range(0..10) == 0 {
            data = (0..rng.random_range(0..300))
                .map(|_| rng.random())
                .collect();
        } else {
            for _ in 0..rng.random_range(1..4) {
                data.extend(packet(&mut rng));
            }
            mutate(&mut rng, &mut data);
        }
        line::deframe_any(&data);
    }
}
