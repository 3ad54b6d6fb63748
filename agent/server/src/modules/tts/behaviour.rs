//! The avatar's behaviour, driven from the server: blinking, gaze and listening (the first paper's section 4:
//! blinks every 450 ms to 4 s with distinct phase speeds; gaze from the detected faces, else the centre of
//! motion). The controllers are plain state machines fed with events and the time; `run` drives them on the
//! hub and publishes their commands through the TTS module's `Agent.avatar` publisher (a channel has a single
//! owner, so both share it).

mod blink;
mod gaze;
mod params;

use agent_contract::avatar::AvatarCommand;
use rand::SeedableRng;
use rand::rngs::StdRng;
use tokio::sync::mpsc;
use tokio::time::Instant;
use tracing::debug;

use super::avatar_out::AvatarOut;
use blink::Blinker;
use gaze::Gazer;
pub use params::{BehaviourParams, Event};

/// Events waiting for the controllers; behaviour is cosmetic, so when they fall this far behind new events are
/// dropped (and counted) rather than delaying anything else.
const EVENT_QUEUE: usize = 64;

/// The sending side, cheap to clone.
#[derive(Debug, Clone)]
pub struct Sender {
    events: mpsc::Sender<Event>,
    dropped: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl Sender {
    /// Queues an event; when the controllers are switched off (receiver gone) it is simply not needed.
    pub fn send(&self, event: Event) {
        if let Err(mpsc::error::TrySendError::Full(_)) = self.events.try_send(event) {
            self.dropped
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
    }

    pub fn dropped(&self) -> u64 {
        self.dropped.load(std::sync::atomic::Ordering::Relaxed)
    }
}

/// A channel to the controllers.
pub fn channel() -> (Sender, mpsc::Receiver<Event>) {
    let (events, queue) = mpsc::channel(EVENT_QUEUE);
    (
        Sender {
            events,
            dropped: Default::default(),
        },
        queue,
    )
}

/// Blink and gaze controllers together, with the mood that follows listening and thinking.
#[derive(Debug)]
pub struct Controllers {
    blinker: Blinker,
    gazer: Gazer,
    rng: StdRng,
}

impl Controllers {
    pub fn new(params: &BehaviourParams, now: Instant, seed: Option<u64>) -> Controllers {
        let mut rng = match seed {
            Some(seed) => StdRng::seed_from_u64(seed),
            None => StdRng::from_os_rng(),
        };
        Controllers {
            blinker: Blinker::new(params, now, &mut rng),
            gazer: Gazer::new(params, now, &mut rng),
            rng,
        }
    }

    /// Reacts to an event; returns the commands to send now.
    pub fn handle(&mut self, now: Instant, event: Event, out: &mut Vec<AvatarCommand>) {
        match event {
            Event::PhraseBoundary { at } => self.blinker.blink_at(at),
            Event::SpeechEnded { at } => {
                // The end of a reply is a phrase boundary too, and the speaking mood ends with it.
                self.blinker.blink_at(at);
                self.gazer.speech_ended();
            }
            other => {
                if self.gazer.handle(now, other, &mut self.rng, out) {
                    self.blinker.blink_at(now);
                }
            }
        }
        self.tick(now, out);
    }

    /// Emits what is due at `now`.
    pub fn tick(&mut self, now: Instant, out: &mut Vec<AvatarCommand>) {
        if self.gazer.tick(now, &mut self.rng, out) {
            self.blinker.blink_at(now);
        }
        self.blinker.tick(now, &mut self.rng, out);
    }

    /// When something is next due.
    pub fn next_deadline(&self) -> Instant {
        self.blinker.next_deadline().min(self.gazer.next_deadline())
    }
}

/// Drives the controllers until the event channel closes. While nobody subscribes to `Agent.avatar` the timers
/// rest (events still update the state), so an unattended agent costs nothing.
pub async fn run(params: BehaviourParams, avatar: AvatarOut, mut events: mpsc::Receiver<Event>) {
    let mut controllers = Controllers::new(&params, Instant::now(), None);
    let mut watched = avatar.watched();
    let mut commands = Vec::new();
    loop {
        let active = *watched.borrow();
        let deadline = controllers.next_deadline();
        tokio::select! {
            event = events.recv() => match event {
                Some(event) => controllers.handle(Instant::now(), event, &mut commands),
                None => break,
            },
            () = tokio::time::sleep_until(deadline), if active => controllers.tick(Instant::now(), &mut commands),
            changed = watched.changed() => {
                if changed.is_err() {
                    break;
                }
            }
        }
        if active {
            for command in commands.drain(..) {
                avatar.send(&command).await;
            }
        } else {
            commands.clear();
        }
    }
    debug!("behaviour controllers stopped");
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;
    use crate::modules::tts::wire::Sighting;

    fn blinks(commands: &[AvatarCommand]) -> usize {
        commands
            .iter()
            .filter(|c| matches!(c, AvatarCommand::Blink { .. }))
            .count()
    }

    #[test]
    fn blinks_come_every_450_ms_to_4_s_with_distinct_phase_speeds() {
        let params = BehaviourParams::default();
        let t0 = Instant::now();
        let mut controllers = Controllers::new(&params, t0, Some(7));
        let mut times = Vec::new();
        let mut now = t0;
        while times.len() < 200 {
            now = controllers.next_deadline();
            let mut out = Vec::new();
            controllers.tick(now, &mut out);
            for command in &out {
                if let AvatarCommand::Blink {
                    close_ms,
                    hold_ms,
                    open_ms,
                } = command
                {
                    assert!(
                        close_ms < hold_ms.max(open_ms) && close_ms < open_ms,
                        "{command:?}"
                    );
                    times.push(now);
                }
            }
        }
        let gaps: Vec<Duration> = times.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(
            gaps.iter()
                .all(|g| *g >= Duration::from_millis(450) && *g <= Duration::from_millis(4000)),
            "{gaps:?}"
        );
        let short = gaps
            .iter()
            .filter(|g| **g < Duration::from_millis(1500))
            .count();
        let long = gaps
            .iter()
            .filter(|g| **g > Duration::from_millis(3000))
            .count();
        assert!(
            short > 10 && long > 10,
            "intervals vary: {short} short, {long} long"
        );
        assert!(now > t0);
    }

    #[test]
    fn phrase_boundaries_and_gaze_shifts_add_blinks() {
        let params = BehaviourParams {
            blink_min_ms: 3900,
            blink_max_ms: 4000,
            ..BehaviourParams::default()
        };
        let t0 = Instant::now();
        let mut controllers = Controllers::new(&params, t0, Some(1));
        let mut out = Vec::new();
        controllers.handle(
            t0,
            Event::PhraseBoundary {
                at: t0 + Duration::from_millis(500),
            },
            &mut out,
        );
        assert_eq!(blinks(&out), 0, "not before the boundary is heard");
        assert!(controllers.next_deadline() <= t0 + Duration::from_millis(500));
        controllers.tick(t0 + Duration::from_millis(500), &mut out);
        assert_eq!(blinks(&out), 1);
        out.clear();
        let face = |x| {
            Event::Seen(Some(Sighting {
                x,
                y: 0.5,
                source: "face",
            }))
        };
        let t1 = t0 + Duration::from_millis(1500);
        controllers.handle(t1, face(0.1), &mut out);
        controllers.handle(t1 + Duration::from_millis(600), face(0.9), &mut out);
        assert!(blinks(&out) >= 1, "a large gaze jump blinks: {out:?}");
        assert!(
            out.iter()
                .any(|c| matches!(c, AvatarCommand::Gaze { source: Some(s), .. } if s == "face"))
        );
    }
}
