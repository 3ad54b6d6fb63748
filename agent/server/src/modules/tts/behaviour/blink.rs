//! Blinking: spontaneous blinks at random intervals (450 ms to 4 s by default), extra blinks at phrase boundaries
//! of the agent's speech and on large gaze shifts, each blink with its own closing, closed and opening times.

use std::time::Duration;

use agent_contract::avatar::AvatarCommand;
use rand::Rng;
use rand::rngs::StdRng;
use tokio::time::Instant;

use super::params::BehaviourParams;

/// Two blinks closer than this look like a twitch; an extra blink that soon after another is skipped.
const MIN_GAP: Duration = Duration::from_millis(300);

#[derive(Debug)]
pub struct Blinker {
    min: Duration,
    max: Duration,
    /// The next spontaneous blink.
    next: Instant,
    last: Option<Instant>,
    /// Extra blinks still to come (phrase boundaries lie ahead on the audio clock), in time order.
    extra: Vec<Instant>,
}

impl Blinker {
    pub fn new(params: &BehaviourParams, now: Instant, rng: &mut StdRng) -> Blinker {
        let min = Duration::from_millis(params.blink_min_ms);
        let max = Duration::from_millis(params.blink_max_ms);
        Blinker {
            min,
            max,
            next: now + interval(min, max, rng),
            last: None,
            extra: Vec::new(),
        }
    }

    /// Asks for an extra blink at `at` (now, or when the audio reaches a phrase boundary).
    pub fn blink_at(&mut self, at: Instant) {
        let position = self.extra.partition_point(|t| *t <= at);
        self.extra.insert(position, at);
    }

    pub fn tick(&mut self, now: Instant, rng: &mut StdRng, out: &mut Vec<AvatarCommand>) {
        let extra_due = self.extra.first().is_some_and(|t| *t <= now);
        if now < self.next && !extra_due {
            return;
        }
        self.extra.retain(|t| *t > now);
        if self
            .last
            .is_none_or(|last| now.duration_since(last) >= MIN_GAP)
        {
            out.push(blink(rng));
            self.last = Some(now);
        }
        // Every blink, spontaneous or not, restarts the spontaneous interval.
        self.next = now + interval(self.min, self.max, rng);
    }

    pub fn next_deadline(&self) -> Instant {
        self.extra
            .first()
            .map_or(self.next, |t| (*t).min(self.next))
    }
}

fn interval(min: Duration, max: Duration, rng: &mut StdRng) -> Duration {
    Duration::from_millis(rng.random_range(min.as_millis() as u64..=max.as_millis() as u64))
}

/// One blink: the lid closes fast, stays shut briefly, and opens more slowly, as human blinks do.
fn blink(rng: &mut StdRng) -> AvatarCommand {
    AvatarCommand::Blink {
        close_ms: rng.random_range(60..=90),
        hold_ms: rng.random_range(30..=60),
        open_ms: rng.random_range(130..=190),
    }
}
