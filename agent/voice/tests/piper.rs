//! End-to-end checks of the real Piper voice (`make model-voice`) on the real engine thread beside espeak-ng: its
//! phonemes and visemes lie on the PCM's clock and follow the sound, sentences stream one by one, a cancel stops
//! the stream within a chunk, espeak-ng's Italian still speaks from the same engine, and a missing voice file fails
//! at start naming the path, the checksum and the make target.

use std::path::PathBuf;
use std::sync::OnceLock;

use agent_voice::{
    Engine, PiperConfig, Recording, SAMPLE_RATE, SpeechEvent, Synthesizer, SynthesizerConfig,
    Viseme, VoiceSettings, samples_to_ms,
};

/// espeak-ng allows one engine per process, so every test shares this one.
fn engine() -> &'static Synthesizer {
    static ENGINE: OnceLock<Synthesizer> = OnceLock::new();
    ENGINE.get_or_init(|| {
        Synthesizer::start(SynthesizerConfig {
            piper: Some(PiperConfig::default()),
            ..SynthesizerConfig::default()
        })
        .expect("the engine starts with the Piper voice (run `make model-voice`)")
    })
}

fn speak_all(text: &str, voice: &VoiceSettings) -> Recording {
    engine()
        .speak(text, voice)
        .expect("queued")
        .collect_blocking()
        .expect("synthesised")
}

const ENGLISH: &str =
    "Hello there! It is a quarter past three. I can see two people in front of me.";

/// Energy envelope in 5 ms windows.
fn envelope(pcm: &[i16]) -> Vec<f64> {
    pcm.chunks(SAMPLE_RATE as usize / 200)
        .map(|w| (w.iter().map(|&s| f64::from(s).powi(2)).sum::<f64>() / w.len() as f64).sqrt())
        .collect()
}

/// |audio edge - cue| in ms at every change between rest and an open mouth: the nearest onset (or offset) of the
/// energy envelope (5 ms windows, 5% of the loud level) within 150 ms. Stops at an onset are skipped: the lips
/// close in silence before them, so the shape rightly leads the sound.
fn rest_edges(recording: &Recording) -> Vec<f64> {
    const WINDOW: usize = SAMPLE_RATE as usize / 200;
    let env = envelope(&recording.pcm);
    let mut sorted = env.clone();
    sorted.sort_by(f64::total_cmp);
    let threshold = sorted[sorted.len() * 95 / 100] * 0.05;
    let loud = |i: usize| env.get(i).is_some_and(|&e| e > threshold);
    let mut errors = Vec::new();
    for pair in recording.cues.windows(2) {
        let (before, cue) = (pair[0], pair[1]);
        let at = cue.sample as usize / WINDOW;
        let (from, to) = (at.saturating_sub(30), (at + 30).min(env.len()));
        let cue_ms = samples_to_ms(cue.sample, SAMPLE_RATE);
        let edge = if before.viseme == Viseme::Sil && cue.viseme != Viseme::Sil {
            if matches!(cue.viseme, Viseme::PP | Viseme::DD | Viseme::Kk) {
                continue;
            }
            (from..to)
                .filter(|&i| loud(i) && (i == 0 || !loud(i - 1)))
                .min_by_key(|&i| i.abs_diff(at))
        } else if before.viseme != Viseme::Sil && cue.viseme == Viseme::Sil {
            (from..to)
                .filter(|&i| loud(i) && !loud(i + 1))
                .map(|i| i + 1)
                .min_by_key(|&i| i.abs_diff(at))
        } else {
            continue;
        };
        if let Some(edge) = edge {
            errors.push((samples_to_ms((edge * WINDOW) as u64, SAMPLE_RATE) - cue_ms).abs());
        }
    }
    errors
}

#[test]
fn piper_speaks_english_with_visemes_on_the_pcm_clock() {
    assert!(engine().has_piper());
    let recording = speak_all(ENGLISH, &VoiceSettings::piper());
    assert!(!recording.cancelled);
    let total = recording.pcm.len() as u64;
    let seconds = samples_to_ms(total, SAMPLE_RATE) / 1000.0;
    assert!((2.5..12.0).contains(&seconds), "{seconds} s of audio");
    assert_eq!(recording.sentences.len(), 3);
    assert_eq!(recording.sentences.last().map(|s| s.2), Some(total));
    for pair in recording.sentences.windows(2) {
        assert_eq!(pair[0].2, pair[1].1, "sentences follow each other");
    }
    // Phonemes and cues are ordered, inside the audio, and every mouth shape that this text needs appears.
    assert!(
        recording.phonemes.len() > 60,
        "{} phonemes",
        recording.phonemes.len()
    );
    for pair in recording.phonemes.windows(2) {
        assert!(pair[0].sample <= pair[1].sample, "{pair:?}");
    }
    assert!(recording.cues.len() > 30);
    for pair in recording.cues.windows(2) {
        assert!(pair[0].sample <= pair[1].sample, "{pair:?} out of order");
        assert_ne!(pair[0].viseme, pair[1].viseme, "repeated shapes are merged");
    }
    assert!(recording.cues.iter().all(|c| c.sample <= total));
    assert_eq!(recording.cues.last().map(|c| c.viseme), Some(Viseme::Sil));
    let shapes: std::collections::HashSet<Viseme> =
        recording.cues.iter().map(|c| c.viseme).collect();
    for expected in [
        Viseme::PP,
        Viseme::Aa,
        Viseme::E,
        Viseme::I,
        Viseme::U,
        Viseme::SS,
        Viseme::Nn,
    ] {
        assert!(
            shapes.contains(&expected),
            "{expected} missing from {shapes:?}"
        );
    }
    // The mouth opens where the sound starts and closes where it stops: every move between rest and speech is
    // within 60 ms of the audio's own onset or offset (the network's durations place the cues, not a guess).
    let errors = rest_edges(&recording);
    assert!(
        errors.len() >= 5,
        "{} rest/speech edges matched",
        errors.len()
    );
    let worst = errors.iter().copied().fold(0.0, f64::max);
    println!("rest/speech edges off the audio by (ms): {errors:.0?}");
    assert!(
        worst <= 60.0,
        "a rest/speech edge is {worst:.0} ms off the audio: {errors:?}"
    );
}

#[test]
fn the_first_sentence_streams_before_the_rest_is_synthesised() {
    let reply =
        "This is the first sentence. ".to_string() + &"And here is a longer tail. ".repeat(6);
    let mut utterance = engine()
        .speak(&reply, &VoiceSettings::piper())
        .expect("queued");
    let first = utterance.blocking_next().expect("an event");
    let SpeechEvent::Chunk(chunk) = first else {
        panic!("expected audio first, got {first:?}")
    };
    assert_eq!((chunk.sentence, chunk.start_sample), (0, 0));
    // Chunks are `chunk_ms` long (20 ms: 441 samples), not whole sentences.
    assert_eq!(chunk.pcm.len(), 441);
    let rest = utterance.collect_blocking().expect("rest");
    assert_eq!(rest.sentences.len(), 7, "the other sentences followed");
}

#[test]
fn cancelling_mid_sentence_stops_within_one_chunk() {
    let long = "This sentence keeps going and going, with many words, so that it lasts for quite a long time \
                indeed, and then it goes on a little more, just to be sure it is long enough.";
    let mut utterance = engine()
        .speak(long, &VoiceSettings::piper())
        .expect("queued");
    let mut samples = 0u64;
    let mut chunks_after_cancel = 0;
    let mut cancelled = false;
    let finished = loop {
        match utterance
            .blocking_next()
            .expect("the engine always sends an end")
        {
            SpeechEvent::Chunk(chunk) => {
                samples += chunk.pcm.len() as u64;
                if cancelled {
                    chunks_after_cancel += 1;
                } else if samples > u64::from(SAMPLE_RATE) / 2 {
                    utterance.cancel();
                    cancelled = true;
                }
            }
            SpeechEvent::SentenceEnd { .. } => panic!("the sentence must not complete"),
            SpeechEvent::Finished {
                cancelled,
                total_samples,
            } => break (cancelled, total_samples),
            SpeechEvent::Failed { message } => panic!("{message}"),
        }
    };
    assert!(finished.0, "reported as cancelled");
    assert!(
        chunks_after_cancel <= 1,
        "{chunks_after_cancel} chunks after the cancel"
    );
    // The engine itself stopped: it did not go on to the end of the sentence (several seconds).
    assert!(
        samples_to_ms(finished.1, SAMPLE_RATE) < 8000.0,
        "{} samples made",
        finished.1
    );
    // The next request speaks normally.
    let next = speak_all("But this one, yes.", &VoiceSettings::piper());
    assert!(!next.cancelled && next.pcm.len() > 10_000);
}

#[test]
fn espeak_still_speaks_italian_beside_the_piper_voice() {
    let english = speak_all("Good morning.", &VoiceSettings::piper());
    let italian = speak_all("Ciao! Come stai?", &VoiceSettings::for_voice("it"));
    let ipa: String = italian.phonemes.iter().map(|m| m.ipa.as_str()).collect();
    assert!(
        ipa.contains("tʃ"),
        "espeak-ng's Italian reads Ciao with tʃ: {ipa}"
    );
    assert!(
        italian.phonemes.iter().any(|m| m.ipa.len() > 1),
        "espeak-ng marks phonemes, not characters"
    );
    assert!(!english.pcm.is_empty() && !italian.pcm.is_empty());
    // And back: the voice change for phonemising does not stick to espeak-ng's own utterances.
    let again = speak_all("Ciao!", &VoiceSettings::for_voice("it"));
    let ipa: String = again.phonemes.iter().map(|m| m.ipa.as_str()).collect();
    assert!(ipa.contains("tʃ"), "{ipa}");
    assert_eq!(VoiceSettings::piper().engine, Engine::Piper);
}

#[test]
fn a_missing_voice_file_fails_at_start_naming_path_checksum_and_target() {
    let missing = PathBuf::from("/nonexistent/models/piper/en_US-joe-medium.durations.onnx");
    let error = Synthesizer::start(SynthesizerConfig {
        piper: Some(PiperConfig {
            voice: missing.clone(),
            ..PiperConfig::default()
        }),
        ..SynthesizerConfig::default()
    })
    .expect_err("no voice file");
    let message = error.to_string();
    let listed = agent_voice::listed_sha256(&missing).expect("the default voice is listed");
    assert!(
        message.contains(&missing.display().to_string())
            && message.contains(listed)
            && message.contains("make model-voice"),
        "{message}"
    );
    // A voice without a durations output is refused when it loads: the original file from the wheel.
    let original = PiperConfig::default()
        .voice
        .with_file_name("en_US-joe-medium.onnx");
    let sum = agent_voice::file_sha256(&original).expect("the original voice is provisioned");
    let error = Synthesizer::start(SynthesizerConfig {
        piper: Some(PiperConfig {
            voice: original,
            voice_sha256: Some(sum),
            ..PiperConfig::default()
        }),
        ..SynthesizerConfig::default()
    })
    .expect_err("no durations output");
    assert!(error.to_string().contains("durations"), "{error}");
}
