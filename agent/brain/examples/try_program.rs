//! Tries a teleo-reactive program without the hub: each input line is something heard, or a percept command.
//!
//! ```text
//! cargo run -p agent-brain --example try_program -- config/brain.tr
//! > what time is it
//! > !face 2 left          assert face(2, "left")
//! > !speaking             assert speaking (no arguments)
//! > !retract speaking
//! > !wait 3s              let 3 seconds pass (stepping at the brain's wake-ups)
//! ```
//!
//! Prints the effects and rule changes of every step, with how long the step took.

use std::io::BufRead;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use agent_brain::{Brain, Capabilities, NoPairDb, Now, Program, Value, WallClock};

fn main() {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!(
            "usage: try_program PROGRAM.tr [COMMAND...]   (COMMANDs: the names `run` may use)"
        );
        std::process::exit(2);
    };
    let commands: Vec<String> = std::env::args().skip(2).collect();
    let capabilities = if commands.is_empty() {
        Capabilities::with_commands(["uptime", "hostname"])
    } else {
        Capabilities::with_commands(commands)
    };
    let source = match std::fs::read_to_string(&path) {
        Ok(source) => source,
        Err(error) => {
            eprintln!("cannot read {path}: {error}");
            std::process::exit(1);
        }
    };
    let program = match Program::load(&path, &source, &capabilities) {
        Ok(program) => program,
        Err(error) => {
            eprintln!("{error}");
            std::process::exit(1);
        }
    };
    println!("{path}: {} rules loaded", program.rule_count());
    let mut session = Session {
        brain: Brain::new(program),
        start: Instant::now(),
        elapsed: Duration::ZERO,
    };
    session.step();
    for line in std::io::stdin().lock().lines() {
        let Ok(line) = line else { break };
        session.input(line.trim());
    }
}

/// A brain on a simulated clock that starts at the real time and moves with `!wait`.
struct Session {
    brain: Brain,
    start: Instant,
    elapsed: Duration,
}

impl Session {
    fn now(&self) -> Now {
        let unix_ms = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_millis() as i64);
        Now {
            at: self.start + self.elapsed,
            clock: WallClock::from_unix_ms(unix_ms, 0),
        }
    }

    fn input(&mut self, line: &str) {
        let at = self.start + self.elapsed;
        let Some(command) = line.strip_prefix('!') else {
            if !line.is_empty() {
                self.perceive(at, "heard", vec![Value::from(line)]);
            }
            return;
        };
        let mut words = command.split_whitespace();
        match (words.next(), words.next()) {
            (Some("wait"), Some(amount)) => match parse_duration(amount) {
                Some(by) => self.wait(by),
                None => eprintln!("cannot read the duration {amount:?} (write 500ms, 3s, 1m)"),
            },
            (Some("retract"), Some(name)) => {
                self.brain.retract(name);
                self.step();
            }
            (Some(name), first) => {
                let args = first.into_iter().chain(words).map(parse_value).collect();
                self.perceive(at, name, args);
            }
            (None, _) => eprintln!("an empty command"),
        }
    }

    fn perceive(&mut self, at: Instant, name: &str, args: Vec<Value>) {
        match self.brain.perceive(at, name, args) {
            Ok(_) => self.step(),
            Err(error) => eprintln!("rejected: {error}"),
        }
    }

    fn wait(&mut self, by: Duration) {
        let target = self.start + self.elapsed + by;
        while let Some(wake) = self
            .brain
            .next_wakeup(self.start + self.elapsed)
            .filter(|wake| *wake <= target)
        {
            self.elapsed = wake - self.start;
            self.step();
        }
        self.elapsed = target - self.start;
        self.step();
    }

    fn step(&mut self) {
        let now = self.now();
        let started = Instant::now();
        let step = self.brain.step(&now, &NoPairDb);
        let took = started.elapsed();
        for trace in &step.traces {
            println!("[{:>7.3} s] {trace}", self.elapsed.as_secs_f64());
        }
        for warning in &step.warnings {
            println!("warning: {warning}");
        }
        if !step.effects.is_empty() {
            println!("           step took {} µs", took.as_micros());
        }
    }
}

fn parse_duration(text: &str) -> Option<Duration> {
    let (number, unit) = text.split_at(text.find(|c: char| c.is_ascii_alphabetic())?);
    let number: f64 = number.parse().ok()?;
    let seconds = match unit {
        "ms" => number / 1000.0,
        "s" => number,
        "m" => number * 60.0,
        _ => return None,
    };
    Some(Duration::from_secs_f64(seconds))
}

fn parse_value(word: &str) -> Value {
    word.parse::<f64>()
        .map_or_else(|_| Value::from(word), Value::Num)
}
