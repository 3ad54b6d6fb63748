//! Gaze and the moods of conversation: look at what the vision modules point at (a face, else the centre of
//! motion); with nothing in view, small idle saccades around the centre; look away while thinking about an
//! answer; while the user speaks, hold the gaze, show a listening mood and nod at the pauses.

use std::time::Duration;

use agent_contract::avatar::AvatarCommand;
use rand::Rng;
use rand::rngs::StdRng;
use tokio::time::Instant;

use super::params::{BehaviourParams, Event};
use crate::modules::tts::wire::Sighting;

/// Where the eyes rest when nothing is in view (normalised camera coordinates: a little above the middle,
/// where a seated person's face usually is).
const CENTRE: (f64, f64) = (0.5, 0.45);
/// Looking away while thinking: this far sideways from the centre, up at this height.
const THINK_SIDEWAYS: f64 = 0.22;
const THINK_HEIGHT: f64 = 0.22;
/// A nod: the gaze (and with it, more slowly, the head) dips this much and comes back after `NOD_TIME`.
const NOD_DEPTH: f64 = 0.07;
const NOD_TIME: Duration = Duration::from_millis(250);
/// Only speech at least this long earns a nod at its pause.
const NOD_AFTER: Duration = Duration::from_millis(600);
/// An expression a rule asked for (`mood(M)`) is shown this long.
const ASKED_MOOD_FADES: Duration = Duration::from_secs(3);
/// The listening mood fades this long after the user's last pause if no transcript follows.
const LISTENING_FADES: Duration = Duration::from_secs(2);
const MOOD_INTENSITY: f64 = 0.7;

#[derive(Debug)]
pub struct Gazer {
    deadband: f64,
    shift_blink: f64,
    idle_after: Duration,
    saccade: (Duration, Duration),
    radius: f64,
    think: Duration,
    nod: bool,
    /// The last target the vision modules reported, and when.
    target: Option<(Sighting, Instant)>,
    /// Where the last gaze command pointed.
    looking_at: (f64, f64),
    next_saccade: Instant,
    thinking_until: Option<Instant>,
    listening_since: Option<Instant>,
    nod_back_at: Option<Instant>,
    mood: &'static str,
    mood_fades_at: Option<Instant>,
}

impl Gazer {
    pub fn new(params: &BehaviourParams, now: Instant, rng: &mut StdRng) -> Gazer {
        let saccade = (
            Duration::from_millis(params.saccade_min_ms),
            Duration::from_millis(params.saccade_max_ms),
        );
        Gazer {
            deadband: params.gaze_deadband,
            shift_blink: params.gaze_shift_blink,
            idle_after: Duration::from_millis(params.idle_after_ms),
            saccade,
            radius: params.saccade_radius,
            think: Duration::from_millis(params.think_ms),
            nod: params.nod,
            target: None,
            looking_at: CENTRE,
            next_saccade: now + between(saccade, rng),
            thinking_until: None,
            listening_since: None,
            nod_back_at: None,
            mood: "neutral",
            mood_fades_at: None,
        }
    }

    /// Reacts to an event; returns whether the gaze jumped far enough to blink.
    pub fn handle(
        &mut self,
        now: Instant,
        event: Event,
        rng: &mut StdRng,
        out: &mut Vec<AvatarCommand>,
    ) -> bool {
        match event {
            Event::Seen(Some(sighting)) => {
                self.target = Some((sighting, now));
                self.thinking_until.is_none()
                    && self.nod_back_at.is_none()
                    && self.look(sighting.x, sighting.y, sighting.source, out)
            }
            Event::UserSpeaking => {
                self.listening_since.get_or_insert(now);
                self.mood_fades_at = None;
                self.thinking_until = None;
                self.set_mood("listening", out);
                // Attend: back to the person if they are in view.
                match self.fresh_target(now) {
                    Some(target) => self.look(target.x, target.y, target.source, out),
                    None => false,
                }
            }
            Event::UserPaused => {
                let spoke_long = self
                    .listening_since
                    .is_some_and(|since| now.duration_since(since) >= NOD_AFTER);
                if self.nod && spoke_long && self.nod_back_at.is_none() {
                    let (x, y) = self.looking_at;
                    out.push(gaze(x, (y + NOD_DEPTH).min(1.0), "listening"));
                    self.nod_back_at = Some(now + NOD_TIME);
                }
                self.listening_since = None;
                self.mood_fades_at = Some(now + LISTENING_FADES);
                false
            }
            Event::Heard => {
                self.listening_since = None;
                self.mood_fades_at = None;
                self.thinking_until = Some(now + self.think);
                let side = if rng.random_bool(0.5) { -1.0 } else { 1.0 };
                let away = (CENTRE.0 + side * THINK_SIDEWAYS, THINK_HEIGHT);
                out.push(gaze(away.0, away.1, "thinking"));
                self.looking_at = away;
                self.set_mood("thinking", out);
                false
            }
            Event::SpeechStarted => {
                let was_thinking = self.thinking_until.take().is_some();
                self.set_mood("neutral", out);
                was_thinking && self.look_back(now, out)
            }
            Event::Mood(mood) => {
                self.set_mood(mood, out);
                self.mood_fades_at = Some(now + ASKED_MOOD_FADES);
                false
            }
            Event::Seen(None) | Event::PhraseBoundary { .. } | Event::SpeechEnded { .. } => false,
        }
    }

    /// The reply ended.
    pub fn speech_ended(&mut self) {
        self.thinking_until = None;
    }

    /// Emits what is due at `now`; returns whether the gaze jumped far enough to blink.
    pub fn tick(&mut self, now: Instant, rng: &mut StdRng, out: &mut Vec<AvatarCommand>) -> bool {
        let mut jumped = false;
        if self.nod_back_at.is_some_and(|at| at <= now) {
            self.nod_back_at = None;
            let (x, y) = self.looking_at;
            out.push(gaze(x, y, "listening"));
        }
        if self.thinking_until.is_some_and(|until| until <= now) {
            self.thinking_until = None;
            self.set_mood("neutral", out);
            jumped = self.look_back(now, out);
        }
        if self.mood_fades_at.is_some_and(|at| at <= now) {
            self.mood_fades_at = None;
            if self.mood != "thinking" {
                self.set_mood("neutral", out);
            }
        }
        if now >= self.next_saccade {
            self.next_saccade = now + between(self.saccade, rng);
            let idle = self.thinking_until.is_none()
                && self.listening_since.is_none()
                && self.nod_back_at.is_none()
                && self.fresh_target(now).is_none();
            if idle {
                let x = CENTRE.0 + rng.random_range(-self.radius..=self.radius);
                let y = CENTRE.1 + rng.random_range(-self.radius..=self.radius) / 2.0;
                out.push(gaze(x, y, "idle"));
                self.looking_at = (x, y);
            }
        }
        jumped
    }

    pub fn next_deadline(&self) -> Instant {
        [self.nod_back_at, self.thinking_until, self.mood_fades_at]
            .into_iter()
            .flatten()
            .fold(self.next_saccade, Instant::min)
    }

    fn fresh_target(&self, now: Instant) -> Option<Sighting> {
        self.target
            .filter(|(_, seen)| now.duration_since(*seen) <= self.idle_after)
            .map(|(target, _)| target)
    }

    /// After thinking: back to the person, or to the centre.
    fn look_back(&mut self, now: Instant, out: &mut Vec<AvatarCommand>) -> bool {
        match self.fresh_target(now) {
            Some(target) => self.look(target.x, target.y, target.source, out),
            None => self.look(CENTRE.0, CENTRE.1, "idle", out),
        }
    }

    /// Sends a gaze command unless the move is within the dead band; returns whether it is a large jump.
    fn look(&mut self, x: f64, y: f64, source: &'static str, out: &mut Vec<AvatarCommand>) -> bool {
        let distance = (x - self.looking_at.0).hypot(y - self.looking_at.1);
        if distance < self.deadband {
            return false;
        }
        out.push(gaze(x, y, source));
        self.looking_at = (x, y);
        distance > self.shift_blink
    }

    fn set_mood(&mut self, mood: &'static str, out: &mut Vec<AvatarCommand>) {
        if self.mood != mood {
            self.mood = mood;
            out.push(AvatarCommand::Mood {
                mood: mood.to_owned(),
                intensity: if mood == "neutral" {
                    1.0
                } else {
                    MOOD_INTENSITY
                },
            });
        }
    }
}

/// A gaze command from the controllers (the vision module's carry a frame number; these do not).
fn gaze(x: f64, y: f64, source: &str) -> AvatarCommand {
    AvatarCommand::Gaze {
        x,
        y,
        source: Some(source.to_owned()),
        seq: None,
    }
}

fn between((min, max): (Duration, Duration), rng: &mut StdRng) -> Duration {
    Duration::from_millis(rng.random_range(min.as_millis() as u64..=max.as_millis() as u64))
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;

    use super::*;

    fn gazer(now: Instant) -> (Gazer, StdRng) {
        let mut rng = StdRng::seed_from_u64(3);
        (Gazer::new(&BehaviourParams::default(), now, &mut rng), rng)
    }

    fn gazes(out: &[AvatarCommand]) -> Vec<(f64, f64, &str)> {
        out.iter()
            .filter_map(|c| match c {
                AvatarCommand::Gaze { x, y, source, .. } => {
                    Some((*x, *y, source.as_deref().unwrap_or_default()))
                }
                _ => None,
            })
            .collect()
    }

    #[test]
    fn follows_faces_and_saccades_when_nothing_is_seen() {
        let t0 = Instant::now();
        let (mut gazer, mut rng) = gazer(t0);
        let mut out = Vec::new();
        let face = Sighting {
            x: 0.3,
            y: 0.4,
            source: "face",
        };
        gazer.handle(t0, Event::Seen(Some(face)), &mut rng, &mut out);
        assert_eq!(gazes(&out), vec![(0.3, 0.4, "face")]);
        // Wobble within the dead band is not sent.
        out.clear();
        gazer.handle(
            t0,
            Event::Seen(Some(Sighting { x: 0.305, ..face })),
            &mut rng,
            &mut out,
        );
        assert!(out.is_empty());
        // While the face is fresh, no idle saccades.
        gazer.tick(t0 + Duration::from_millis(1000), &mut rng, &mut out);
        assert!(gazes(&out).is_empty());
        // Long after it vanished, small saccades around the centre.
        let mut now = t0 + Duration::from_secs(3);
        for _ in 0..5 {
            now = gazer.next_deadline().max(now);
            gazer.tick(now, &mut rng, &mut out);
        }
        let idle = gazes(&out);
        assert!(idle.len() >= 3, "{idle:?}");
        for (x, y, source) in idle {
            assert_eq!(source, "idle");
            assert!(
                (x - 0.5).abs() <= 0.06 + 1e-9 && (y - 0.45).abs() <= 0.03 + 1e-9,
                "{x} {y}"
            );
        }
    }

    #[test]
    fn listens_nods_thinks_and_looks_back() {
        let t0 = Instant::now();
        let (mut gazer, mut rng) = gazer(t0);
        let mut out = Vec::new();
        gazer.handle(
            t0,
            Event::Seen(Some(Sighting {
                x: 0.6,
                y: 0.4,
                source: "face",
            })),
            &mut rng,
            &mut out,
        );
        gazer.handle(t0, Event::UserSpeaking, &mut rng, &mut out);
        assert!(out.contains(&AvatarCommand::Mood {
            mood: "listening".into(),
            intensity: MOOD_INTENSITY
        }));
        out.clear();
        let pause = t0 + Duration::from_millis(1200);
        gazer.handle(pause, Event::UserPaused, &mut rng, &mut out);
        assert_eq!(
            gazes(&out),
            vec![(0.6, 0.4 + NOD_DEPTH, "listening")],
            "a nod dips the gaze"
        );
        gazer.tick(pause + NOD_TIME, &mut rng, &mut out);
        assert_eq!(
            gazes(&out).last(),
            Some(&(0.6, 0.4, "listening")),
            "and brings it back"
        );
        out.clear();
        let heard = pause + Duration::from_millis(400);
        gazer.handle(
            heard,
            Event::Seen(Some(Sighting {
                x: 0.6,
                y: 0.4,
                source: "face",
            })),
            &mut rng,
            &mut out,
        );
        gazer.handle(heard, Event::Heard, &mut rng, &mut out);
        let away = gazes(&out);
        assert_eq!(away.len(), 1);
        assert_eq!(away[0].2, "thinking");
        assert!((away[0].0 - 0.5).abs() > 0.2, "looks to the side: {away:?}");
        assert!(out.contains(&AvatarCommand::Mood {
            mood: "thinking".into(),
            intensity: MOOD_INTENSITY
        }));
        out.clear();
        // Faces seen while thinking do not pull the gaze back before the answer starts.
        gazer.handle(
            heard + Duration::from_millis(100),
            Event::Seen(Some(Sighting {
                x: 0.6,
                y: 0.4,
                source: "face",
            })),
            &mut rng,
            &mut out,
        );
        assert!(gazes(&out).is_empty());
        gazer.handle(
            heard + Duration::from_millis(300),
            Event::SpeechStarted,
            &mut rng,
            &mut out,
        );
        assert_eq!(gazes(&out), vec![(0.6, 0.4, "face")]);
        assert!(out.contains(&AvatarCommand::Mood {
            mood: "neutral".into(),
            intensity: 1.0
        }));
    }

    #[test]
    fn thinking_ends_by_itself() {
        let t0 = Instant::now();
        let (mut gazer, mut rng) = gazer(t0);
        let mut out = Vec::new();
        gazer.handle(t0, Event::Heard, &mut rng, &mut out);
        assert!(gazer.next_deadline() <= t0 + Duration::from_millis(1500));
        out.clear();
        gazer.tick(t0 + Duration::from_millis(1500), &mut rng, &mut out);
        assert!(gazes(&out).contains(&(0.5, 0.45, "idle")), "{out:?}");
        assert!(out.contains(&AvatarCommand::Mood {
            mood: "neutral".into(),
            intensity: 1.0
        }));
    }
}
