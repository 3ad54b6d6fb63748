//! Damaged programs never panic the loader: every mutation of the default program either loads (and runs) or
//! fails with an error placed inside the text.

mod common;

use agent_brain::{Program, Value};
use common::{Sim, capabilities, default_program_source};

/// A small deterministic generator (xorshift64*), so that a failure is reproducible from the printed seed.
struct Xorshift(u64);

impl Xorshift {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Characters that matter to the grammar, plus a few that do not belong in it.
const PIECES: [&str; 24] = [
    "(", ")", "{", "}", "[", "]", "\"", ",", ":", "&", "~", "~>", "++", "not ", "_", "X", "1s",
    "\n", "#", "é", "$", "{{", "\\", "within ",
];

fn mutate(source: &str, rng: &mut Xorshift) -> String {
    let mut chars: Vec<char> = source.chars().collect();
    for _ in 0..1 + rng.below(3) {
        let at = rng.below(chars.len());
        match rng.below(3) {
            0 => {
                let len = 1 + rng.below(8);
                chars.drain(at..(at + len).min(chars.len()));
            }
            1 => {
                let piece = PIECES[rng.below(PIECES.len())];
                for (i, c) in piece.chars().enumerate() {
                    chars.insert(at + i, c);
                }
            }
            _ => {
                let from = rng.below(chars.len());
                let len = 1 + rng.below(12);
                let copied: Vec<char> = chars[from..(from + len).min(chars.len())].to_vec();
                for (i, c) in copied.into_iter().enumerate() {
                    chars.insert((at + i).min(chars.len()), c);
                }
            }
        }
    }
    chars.into_iter().collect()
}

#[test]
fn mutated_programs_load_or_fail_cleanly() {
    let source = default_program_source();
    let mut rng = Xorshift(0x9E37_79B9_7F4A_7C15);
    let (mut loaded, mut rejected) = (0, 0);
    for round in 0..1000 {
        let mutated = mutate(&source, &mut rng);
        match Program::load("mutated.tr", &mutated, &capabilities()) {
            Ok(program) => {
                loaded += 1;
                let mut sim = Sim::new(program);
                sim.perceive("face", vec![Value::Num(1.0), Value::from("left")]);
                sim.advance(std::time::Duration::from_secs(1));
                let _ = sim.brain.perceive(
                    sim.start + sim.elapsed,
                    "heard",
                    vec![Value::from("what time is it")],
                );
                sim.step();
            }
            Err(error) => {
                rejected += 1;
                let lines = mutated.lines().count().max(1) as u32;
                assert!(
                    error.line >= 1 && error.line <= lines,
                    "round {round}: line out of range: {error}"
                );
                let line_len = mutated
                    .lines()
                    .nth(error.line as usize - 1)
                    .map_or(0, |l| l.chars().count());
                assert!(
                    error.col as usize <= line_len + 1,
                    "round {round}: column out of range: {error}"
                );
                assert!(!error.message.is_empty());
            }
        }
    }
    // Both outcomes occur, so the test exercises the loader's errors and the evaluator alike.
    eprintln!("loaded {loaded}, rejected {rejected}");
    assert!(
        loaded > 30 && rejected > 300,
        "loaded {loaded}, rejected {rejected}"
    );
}
