//! The `udp` fuzz target's property, run without libFuzzer on 3 000 generated inputs: runs of datagrams of a
//! session (best-effort and reliable fragments, acks, nacks), mutated (bit flips, changed fields, cuts) and mixed
//! with noise. Nothing may panic; see `fuzz/src/udp.rs` for the checks.
//!
//! `FLOW_TEST_SEED=N` replays a failing run.

#[path = "../../../fuzz/src/udp.rs"]
mod udp;

use flow::transport::udp::datagram::{Datagram, Kind};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// A datagram of session 7 that the engine may take, often mutated.
fn datagram(rng: &mut StdRng) -> Vec<u8> {
    let kind = match rng.random_range(0..10) {
        0..=3 => Kind::BestEffort,
        4..=6 => Kind::Reliable,
        7 => Kind::Ack,
        8 => Kind::Nack,
        _ => Kind::Keepalive,
    };
    let frags = rng.random_range(1..6u16);
    let payload: Vec<u8> = match kind {
        Kind::BestEffort | Kind::Reliable => (0..rng.random_range(1..=64))
            .map(|_| rng.random())
            .collect(),
        Kind::Ack => rng.random::<u32>().to_le_bytes().to_vec(),
        Kind::Nack => vec![rng.random()],
        _ => Vec::new(),
    };
    let fragment = matches!(kind, Kind::BestEffort | Kind::Reliable);
    let mut bytes = Datagram {
        kind,
        session: 7,
        seq: if kind == Kind::Keepalive {
            0
        } else {
            rng.random_range(0..12)
        },
        frag: if fragment {
            rng.random_range(0..frags)
        } else {
            0
        },
        frags: if fragment { frags } else { 0 },
        payload: &payload,
    }
    .to_vec();
    if rng.random_range(0..5) == 0 {
        let at = rng.random_range(0..bytes.len());
        match rng.random_range(0..3) {
            0 => bytes[at] ^= 1 << rng.random_range(0..8),
            1 => bytes[at] = rng.random(),
            _ => bytes.truncate(at),
        }
    }
    bytes
}

#[test]
fn a_session_end_survives_3k_generated_runs_of_datagrams() {
    let seed = std::env::var("FLOW_TEST_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(rand::random);
    eprintln!("udp fuzz smoke: FLOW_TEST_SEED={seed}");
    let mut rng = StdRng::seed_from_u64(seed);
    for _ in 0..3_000 {
        let mut input = Vec::new();
        for _ in 0..rng.random_range(1..60) {
            let d = if rng.random_range(0..20) == 0 {
                (0..rng.random_range(0..40)).map(|_| rng.random()).collect()
            } else {
                datagram(&mut rng)
            };
            let d = &d[..d.len().min(255)];
            input.push(d.len() as u8);
            input.push(rng.random_range(0..30));
            input.extend_from_slice(d);
        }
        udp::engine_any(&input);
    }
}
