//! The Piper voice's quick first audio, on the real engine thread with the real voice (`make model-voice`): a long
//! first sentence is spoken in two runs of the network and its first part arrives before the rest is synthesised
//! (the order of events and the engine's run counter, never wall time), the parts join without a gap or a click,
//! and a sentence spoken before is played from the cache without the network until the rate or volume changes.

use std::sync::{Mutex, MutexGuard, OnceLock};

use agent_voice::{
    PiperConfig, Recording, SAMPLE_RATE, SpeechEvent, SpeechStats, Synthesizer, SynthesizerConfig,
    Viseme, VoiceSettings, samples_to_ms,
};

/// espeak-ng allows one engine per process, so the tests share this one. Its chunk queue holds two events, so
/// that while the test has not read them the engine waits with at most three chunks sent: a first part that
/// is longer keeps the engine inside it until the test reads on.
fn engine() -> &'static Synthesizer {
    static ENGINE: OnceLock<Synthesizer> = OnceLock::new();
    ENGINE.get_or_init(|| {
        Synthesizer::start(SynthesizerConfig {
            chunk_queue: 2,
            piper: Some(PiperConfig::default()),
            ..SynthesizerConfig::default()
        })
        .expect("the engine starts with the Piper voice (run `make model-voice`)")
    })
}

/// The tests count the engine's runs, so they take turns (`cargo test` runs them on threads of one process).
fn turn() -> MutexGuard<'static, ()> {
    static TURN: Mutex<()> = Mutex::new(());
    TURN.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

const CUT: &str = "I can tell you the time, or what I see in front of me right now.";

fn speak_all(text: &str, voice: &VoiceSettings) -> Recording {
    engine()
        .speak(text, voice)
        .expect("queued")
        .collect_blocking()
        .expect("synthesised")
}

fn runs_since(before: SpeechStats) -> (u64, u64) {
    let now = engine().stats();
    (
        now.piper_runs - before.piper_runs,
        now.piper_cache_hits - before.piper_cache_hits,
    )
}

#[test]
fn the_first_part_of_a_long_first_sentence_arrives_before_the_rest_is_synthesised() {
    let _turn = turn();
    // Words no other test speaks, so that the cache cannot answer.
    let text = "I can tell you the date, or who I see in front of me right now. Then I listen.";
    let before = engine().stats();
    let mut utterance = engine()
        .speak(text, &VoiceSettings::piper())
        .expect("queued");
    let first = utterance.blocking_next().expect("an event");
    let SpeechEvent::Chunk(chunk) = first else {
        panic!("expected audio first, got {first:?}")
    };
    assert_eq!((chunk.sentence, chunk.part, chunk.start_sample), (0, 0, 0));
    // The engine now waits to send the first part's fourth chunk: one run of the network so far.
    assert_eq!(
        runs_since(before),
        (1, 0),
        "only the first part was synthesised"
    );
    let mut parts = vec![chunk.part];
    let mut first_part_samples = chunk.pcm.len();
    while let Some(event) = utterance.blocking_next() {
        match event {
            SpeechEvent::Chunk(chunk) if chunk.sentence == 0 => {
                if chunk.part == 0 {
                    first_part_samples += chunk.pcm.len();
                }
                parts.push(chunk.part);
            }
            SpeechEvent::Finished { cancelled, .. } => {
                assert!(!cancelled);
                break;
            }
            SpeechEvent::Failed { message } => panic!("{message}"),
            _ => {}
        }
    }
    // Parts 0 then 1, each in order; the second sentence is spoken whole: three runs in all.
    assert!(parts.windows(2).all(|w| w[0] <= w[1]), "{parts:?}");
    assert_eq!(parts.last(), Some(&1));
    assert_eq!(runs_since(before), (3, 0));
    // "I can tell you the date," is well under the sentence's length.
    let first_ms = samples_to_ms(first_part_samples as u64, SAMPLE_RATE);
    assert!(
        (500.0..2500.0).contains(&first_ms),
        "first part {first_ms} ms"
    );
}

#[test]
fn the_parts_of_a_sentence_join_without_a_gap_or_a_click() {
    let _turn = turn();
    // Words no other test speaks, so that the cache cannot answer.
    let text = "You can ask me the time, or what I see in front of me right now.";
    let mut utterance = engine()
        .speak(text, &VoiceSettings::piper())
        .expect("queued");
    let mut pcm = Vec::new();
    let mut join = None;
    let mut cues = Vec::new();
    while let Some(event) = utterance.blocking_next() {
        match event {
            SpeechEvent::Chunk(chunk) => {
                if chunk.part == 1 && join.is_none() {
                    join = Some(pcm.len());
                }
                pcm.extend_from_slice(&chunk.pcm);
                cues.extend(chunk.cues);
            }
            SpeechEvent::Finished { .. } => break,
            SpeechEvent::Failed { message } => panic!("{message}"),
            SpeechEvent::SentenceEnd { .. } => {}
        }
    }
    let join = join.expect("the sentence was spoken in two parts");
    // Sample continuity: both sides of the join are at zero, and no step around it is larger than the quiet
    // level (a click is a step of thousands).
    assert_eq!((pcm[join - 1], pcm[join]), (0, 0));
    let steps = pcm[join - 64..join + 64]
        .windows(2)
        .map(|w| (i32::from(w[1]) - i32::from(w[0])).abs())
        .max()
        .unwrap_or(0);
    assert!(steps < 700, "a step of {steps} at the join");
    // No gap: the quiet around the join is a comma's pause, not a sentence's.
    let loud = |s: &i16| s.unsigned_abs() > 330;
    let before = pcm[..join].iter().rposition(loud).expect("sound before");
    let after = pcm[join..].iter().position(loud).expect("sound after") + join;
    let pause_ms = samples_to_ms((after - before) as u64, SAMPLE_RATE);
    println!("join at sample {join}: pause {pause_ms:.0} ms, largest step near it {steps}");
    assert!(
        (60.0..=300.0).contains(&pause_ms),
        "pause at the join {pause_ms} ms"
    );
    // The mouth rests in the pause and its shapes stay in order on the joined clock.
    assert!(cues.windows(2).all(|w| w[0].sample <= w[1].sample));
    // (The rest cue sits where the sound's envelope fades, which may be a little before its last loud sample.)
    let slack = SAMPLE_RATE as usize / 20;
    let rest_from = before.saturating_sub(slack) as u64;
    assert!(
        cues.iter()
            .any(|c| c.viseme == Viseme::Sil && (rest_from..=after as u64).contains(&c.sample)),
        "no rest between {before} and {after}: {cues:?}"
    );
    assert!(
        cues.iter()
            .any(|c| c.viseme != Viseme::Sil && c.sample > after as u64)
    );
}

#[test]
fn a_sentence_spoken_before_is_played_from_the_cache_until_the_voice_settings_change() {
    let _turn = turn();
    let greeting = "Nice to see you. Ask me anything.";
    let voice = VoiceSettings::piper();
    let first = speak_all(greeting, &voice);
    let before = engine().stats();
    let again = speak_all(greeting, &voice);
    assert_eq!(
        runs_since(before),
        (0, 2),
        "both sentences came from the cache"
    );
    assert_eq!(again.pcm, first.pcm, "the same audio");
    assert_eq!(again.cues, first.cues);
    assert_eq!(again.sentences, first.sentences);
    // A first sentence spoken in two parts is kept whole.
    speak_all(CUT, &voice);
    let before = engine().stats();
    let cut = speak_all(CUT, &voice);
    assert_eq!(runs_since(before), (0, 1));
    assert!(cut.cues.iter().any(|c| c.viseme != Viseme::Sil));
    // Another rate or volume is another sound: the network runs again.
    let faster = VoiceSettings {
        rate_wpm: 220,
        ..voice.clone()
    };
    let before = engine().stats();
    let quick = speak_all(greeting, &faster);
    assert_eq!(runs_since(before), (2, 0));
    assert!(quick.pcm.len() < first.pcm.len());
    let louder = VoiceSettings {
        volume: 150,
        ..voice
    };
    let before = engine().stats();
    speak_all(greeting, &louder);
    assert_eq!(runs_since(before), (2, 0));
}
