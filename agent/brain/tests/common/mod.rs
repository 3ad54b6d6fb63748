//! Shared test driver: a brain on a simulated clock, stepped at percepts and at its own wake-up times.

#![allow(dead_code)]

use std::path::PathBuf;
use std::time::{Duration, Instant};

use agent_brain::{
    Action, Brain, Capabilities, Effect, Language, NoPairDb, Now, Program, Step, Trace, Value,
    WallClock,
};

/// 2024-02-29 15:15:00 UTC, a Thursday afternoon: "quarter past 3 in the afternoon".
pub const BASE_UNIX_MS: i64 = 1_709_219_700_000;

/// The commands the tests' host whitelists, as robot-agent's default configuration does.
pub fn capabilities() -> Capabilities {
    Capabilities::with_commands(["uptime", "hostname"])
}

pub fn load(source: &str) -> Program {
    match Program::load("test.tr", source, &capabilities()) {
        Ok(program) => program,
        Err(error) => panic!("test program does not load:\n{error}"),
    }
}

pub fn default_program_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/brain.tr")
}

pub fn default_program_source() -> String {
    let path = default_program_path();
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
}

/// A program shipped in `config/`, loaded as the server loads it.
pub fn shipped_program(name: &str) -> Program {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name);
    let source = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    match Program::load(&format!("config/{name}"), &source, &capabilities()) {
        Ok(program) => program,
        Err(error) => panic!("config/{name} does not load:\n{error}"),
    }
}

pub fn default_program() -> Program {
    match Program::load(
        "config/brain.tr",
        &default_program_source(),
        &capabilities(),
    ) {
        Ok(program) => program,
        Err(error) => panic!("the default program does not load:\n{error}"),
    }
}

/// A brain on a simulated clock; `elapsed` is the simulated time since the start.
pub struct Sim {
    pub brain: Brain,
    pub start: Instant,
    pub elapsed: Duration,
    /// Every effect and trace produced so far, with the simulated time it happened at.
    pub effects: Vec<(Duration, Effect)>,
    pub traces: Vec<Trace>,
    pub warnings: Vec<String>,
    /// The language of the clock's words.
    pub language: Language,
}

impl Sim {
    pub fn new(program: Program) -> Self {
        let mut sim = Sim {
            brain: Brain::new(program),
            start: Instant::now(),
            elapsed: Duration::ZERO,
            effects: Vec::new(),
            traces: Vec::new(),
            warnings: Vec::new(),
            language: Language::En,
        };
        sim.step();
        sim
    }

    /// A brain whose clock speaks `language`.
    pub fn in_language(program: Program, language: Language) -> Self {
        let mut sim = Sim::new(program);
        sim.language = language;
        sim
    }

    pub fn now(&self) -> Now {
        let unix_ms = BASE_UNIX_MS + self.elapsed.as_millis() as i64;
        Now {
            at: self.start + self.elapsed,
            clock: WallClock::from_unix_ms(unix_ms, 0).in_language(self.language),
        }
    }

    pub fn step(&mut self) -> Step {
        let step = self.brain.step(&self.now(), &NoPairDb);
        self.record(&step);
        step
    }

    fn record(&mut self, step: &Step) {
        for effect in &step.effects {
            self.effects.push((self.elapsed, effect.clone()));
        }
        self.traces.extend(step.traces.iter().cloned());
        self.warnings.extend(step.warnings.iter().cloned());
    }

    /// Moves the clock forward, stepping at every wake-up the brain asks for on the way (as the host's timer does).
    pub fn advance(&mut self, by: Duration) {
        let target = self.start + self.elapsed + by;
        while let Some(wake) = self.brain.next_wakeup(self.start + self.elapsed) {
            if wake > target {
                break;
            }
            self.elapsed = wake - self.start;
            self.step();
        }
        self.elapsed = target - self.start;
        self.step();
    }

    /// Asserts a percept now and steps; returns the effects of that step.
    pub fn perceive(&mut self, name: &str, args: Vec<Value>) -> Vec<Effect> {
        let at = self.start + self.elapsed;
        if let Err(error) = self.brain.perceive(at, name, args) {
            panic!("percept rejected: {error}");
        }
        self.step().effects
    }

    pub fn retract(&mut self, name: &str) -> Vec<Effect> {
        self.brain.retract(name);
        self.step().effects
    }

    /// Simulates the host hearing a transcript, and returns what the agent says in response (if anything).
    pub fn hear(&mut self, text: &str) -> Vec<Effect> {
        self.perceive("heard", vec![Value::from(text)])
    }

    /// When each effect matching `wanted` happened, in simulated time.
    pub fn times_of(&self, wanted: impl Fn(&Effect) -> bool) -> Vec<Duration> {
        self.effects
            .iter()
            .filter(|(_, effect)| wanted(effect))
            .map(|(at, _)| *at)
            .collect()
    }

    /// All the texts said (fired or started) so far.
    pub fn said(&self) -> Vec<String> {
        self.effects
            .iter()
            .filter_map(|(_, effect)| said_text(effect))
            .collect()
    }
}

pub fn said_text(effect: &Effect) -> Option<String> {
    match effect {
        Effect::Fire(Action::Say { text }) | Effect::Start(Action::Say { text }) => {
            Some(text.clone())
        }
        _ => None,
    }
}

/// The texts said in a list of effects.
pub fn says(effects: &[Effect]) -> Vec<String> {
    effects.iter().filter_map(said_text).collect()
}

pub fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}
