//! End-to-end checks of the real espeak-ng engine: PCM against events, viseme ordering, languages, streaming
//! and cancellation.

use std::sync::OnceLock;
use std::time::Duration;

use agent_voice::{
    Recording, SAMPLE_RATE, SpeechEvent, Synthesizer, SynthesizerConfig, Viseme, VoiceError,
    VoiceSettings, samples_to_ms,
};

/// espeak-ng allows one engine per process, so every test shares this one.
fn engine() -> &'static Synthesizer {
    static ENGINE: OnceLock<Synthesizer> = OnceLock::new();
    ENGINE.get_or_init(|| {
        Synthesizer::start(SynthesizerConfig::default()).expect("espeak-ng engine starts")
    })
}

/// Speaks `text` and waits for the whole recording.
fn speak_all(text: &str, voice: &VoiceSettings) -> Recording {
    engine()
        .speak(text, voice)
        .expect("queued")
        .collect_blocking()
        .expect("synthesised")
}

const ENGLISH: &str =
    "Hello there! It is a quarter past three. I can see two people in front of me.";
const ITALIAN: &str = "Ciao! Sono le tre e un quarto. Vedo due persone davanti a me.";

fn rms(pcm: &[i16]) -> f64 {
    if pcm.is_empty() {
        return 0.0;
    }
    (pcm.iter().map(|&s| f64::from(s).powi(2)).sum::<f64>() / pcm.len() as f64).sqrt()
}

#[test]
fn english_pcm_matches_the_phoneme_events() {
    let recording = speak_all(ENGLISH, &VoiceSettings::for_voice("en"));
    assert!(!recording.cancelled);
    assert_eq!(engine().sample_rate(), SAMPLE_RATE);
    let total = recording.pcm.len() as u64;
    // Three sentences of ordinary speech last seconds, not milliseconds.
    assert!(
        samples_to_ms(total, SAMPLE_RATE) > 3000.0,
        "only {total} samples"
    );
    assert_eq!(recording.sentences.len(), 3);
    assert_eq!(
        recording.sentences.last().map(|s| s.2),
        Some(total),
        "sentences cover the whole PCM"
    );

    // Every phoneme lies inside the audio, in order, and espeak-ng's own millisecond clock agrees with the
    // sample positions once each sentence's offset is added.
    assert!(
        recording.phonemes.len() > 40,
        "{} phonemes",
        recording.phonemes.len()
    );
    let mut previous = 0;
    for mark in &recording.phonemes {
        assert!(
            mark.sample >= previous && mark.sample <= total,
            "{mark:?} outside 0..{total}"
        );
        previous = mark.sample;
        // A mark exactly on a boundary may close one sentence or open the next; it must fit one of them.
        let actual_ms = samples_to_ms(mark.sample, SAMPLE_RATE);
        let error_ms = recording
            .sentences
            .iter()
            .filter(|s| (s.1..=s.2).contains(&mark.sample))
            .map(|s| (samples_to_ms(s.1, SAMPLE_RATE) + mark.espeak_ms as f64 - actual_ms).abs())
            .fold(f64::INFINITY, f64::min);
        // espeak-ng truncates its own clock to whole milliseconds.
        assert!(
            error_ms < 1.5,
            "{mark:?} at {actual_ms} ms is {error_ms} ms off espeak-ng's clock"
        );
    }
    // The last phoneme starts before the audio ends, and what follows it is the closing pause, not speech
    // that no event accounts for.
    let last_voiced = recording
        .phonemes
        .iter()
        .rev()
        .find(|m| !m.ipa.starts_with('_'))
        .expect("voiced");
    let tail = &recording.pcm[usize::try_from(last_voiced.sample).expect("fits")..];
    assert!(
        samples_to_ms(tail.len() as u64, SAMPLE_RATE) < 1500.0,
        "{} ms after the last phoneme",
        tail.len()
    );
    // Speech is where the phonemes say: the span of voiced phonemes holds almost all the energy.
    assert!(rms(&recording.pcm) > 300.0, "the audio is not silent");
}

#[test]
fn visemes_are_ordered_inside_the_audio_and_cover_the_mouth_shapes() {
    let recording = speak_all(ENGLISH, &VoiceSettings::for_voice("en"));
    let total = recording.pcm.len() as u64;
    assert!(recording.cues.len() > 30);
    for pair in recording.cues.windows(2) {
        assert!(pair[0].sample <= pair[1].sample, "{pair:?} out of order");
        assert_ne!(pair[0].viseme, pair[1].viseme, "repeated shapes are merged");
    }
    assert!(recording.cues.iter().all(|c| c.sample <= total));
    assert_eq!(
        recording.cues.last().map(|c| c.viseme),
        Some(Viseme::Sil),
        "the mouth closes at the end"
    );
    let shapes: std::collections::HashSet<Viseme> =
        recording.cues.iter().map(|c| c.viseme).collect();
    for expected in [
        Viseme::PP,
        Viseme::Aa,
        Viseme::E,
        Viseme::I,
        Viseme::U,
        Viseme::Nn,
        Viseme::SS,
    ] {
        assert!(
            shapes.contains(&expected),
            "{expected} missing from {shapes:?}"
        );
    }
    // The mouth is at rest during the silence before "It": a `sil` cue lies between the sentences.
    let boundary = recording.sentences[0].2;
    assert!(
        recording
            .cues
            .iter()
            .any(|c| c.viseme == Viseme::Sil && c.sample.abs_diff(boundary) < 22050),
        "no rest between sentences"
    );
}

#[test]
fn italian_and_english_voices_both_speak_and_differ() {
    let italian = speak_all(ITALIAN, &VoiceSettings::for_voice("it"));
    let english = speak_all(ITALIAN, &VoiceSettings::for_voice("en"));
    assert!(samples_to_ms(italian.pcm.len() as u64, SAMPLE_RATE) > 2000.0);
    assert!(rms(&italian.pcm) > 300.0);
    let italian_ipa: String = italian.phonemes.iter().map(|m| m.ipa.as_str()).collect();
    let english_ipa: String = english.phonemes.iter().map(|m| m.ipa.as_str()).collect();
    // The Italian voice reads "Ciao" with the affricate tʃ; English letter-to-sound rules do not.
    assert!(italian_ipa.contains("tʃ"), "{italian_ipa}");
    assert_ne!(
        italian_ipa, english_ipa,
        "the language changes the phonemes"
    );
    // Every phoneme of both languages has a mouth shape.
    for mark in italian.phonemes.iter().chain(&english.phonemes) {
        assert!(
            agent_voice::mouth_shape(&mark.ipa).is_some(),
            "no viseme for {:?}",
            mark.ipa
        );
    }
}

#[test]
fn rate_and_pitch_change_the_audio() {
    let text = "The quick brown fox jumps over the lazy dog.";
    let normal = VoiceSettings::for_voice("en");
    let slow = VoiceSettings {
        rate_wpm: 100,
        ..normal.clone()
    };
    let high = VoiceSettings {
        pitch: 90,
        ..normal.clone()
    };
    let speak = |voice: &VoiceSettings| {
        engine()
            .speak(text, voice)
            .expect("queued")
            .collect_blocking()
            .expect("synthesised")
            .pcm
    };
    let (normal_pcm, slow_pcm, high_pcm) = (speak(&normal), speak(&slow), speak(&high));
    assert!(
        slow_pcm.len() as f64 > normal_pcm.len() as f64 * 1.4,
        "{} vs {}",
        slow_pcm.len(),
        normal_pcm.len()
    );
    assert!(high_pcm != normal_pcm, "pitch changes the waveform");
    // The same request twice gives the same speech; espeak-ng's generator keeps a little state (flutter,
    // noise) across calls, so the samples differ slightly but the length does not.
    let again = speak(&normal);
    assert!(
        again.len().abs_diff(normal_pcm.len()) < normal_pcm.len() / 100,
        "{} vs {}",
        again.len(),
        normal_pcm.len()
    );
}

#[test]
fn first_chunk_arrives_before_the_reply_is_synthesised() {
    let reply =
        "This is the first sentence. ".to_string() + &"And here is a much longer tail. ".repeat(20);
    let mut utterance = engine()
        .speak(&reply, &VoiceSettings::for_voice("en"))
        .expect("queued");
    let first = utterance.blocking_next().expect("an event");
    let SpeechEvent::Chunk(chunk) = first else {
        panic!("expected audio first, got {first:?}")
    };
    assert_eq!((chunk.sentence, chunk.start_sample), (0, 0));
    // At that moment only a small part of the 21 sentences can have been produced: the channel holds at most
    // 64 events, far fewer than the whole reply's chunks.
    let recording_rest = utterance.collect_blocking().expect("rest");
    assert_eq!(
        recording_rest.sentences.len(),
        21,
        "the other sentences followed"
    );
    assert!(recording_rest.pcm.len() > chunk.pcm.len() * 100);
}

#[test]
fn cancellation_stops_output_mid_sentence() {
    let long = "This sentence keeps going and going, with many words, so that it lasts for quite a long time \
                indeed, and then it goes on a little more, just to be sure it is long enough.";
    let full = speak_all(long, &VoiceSettings::for_voice("en"));
    let mut utterance = engine()
        .speak(long, &VoiceSettings::for_voice("en"))
        .expect("queued");
    let mut samples = 0u64;
    let mut chunks_after_cancel = 0;
    let mut cancelled_at = None;
    let finished = loop {
        match utterance
            .blocking_next()
            .expect("the engine always sends an end")
        {
            SpeechEvent::Chunk(chunk) => {
                samples += chunk.pcm.len() as u64;
                if cancelled_at.is_some() {
                    chunks_after_cancel += 1;
                } else if samples > u64::from(SAMPLE_RATE) / 2 {
                    utterance.cancel();
                    cancelled_at = Some(samples);
                }
            }
            SpeechEvent::SentenceEnd { .. } => panic!("the sentence must not complete"),
            SpeechEvent::Finished {
                total_samples,
                cancelled,
            } => break (total_samples, cancelled),
            SpeechEvent::Failed { message } => panic!("{message}"),
        }
    };
    assert!(finished.1, "reported as cancelled");
    assert!(
        finished.0 < full.pcm.len() as u64 / 2,
        "{} of {} samples",
        finished.0,
        full.pcm.len()
    );
    // Only the chunks already queued when the flag was raised can still arrive (bounded by the queue).
    assert!(
        chunks_after_cancel <= 64,
        "{chunks_after_cancel} chunks after cancel"
    );
}

#[test]
fn a_cancelled_request_does_not_speak_and_the_next_one_does() {
    let first = engine()
        .speak("You will never hear this.", &VoiceSettings::for_voice("en"))
        .expect("queued");
    first.cancel();
    let recording = first.collect_blocking().expect("ends");
    assert!(recording.cancelled);
    let next = speak_all("But this one, yes.", &VoiceSettings::for_voice("en"));
    assert!(!next.cancelled && !next.pcm.is_empty());
}

#[test]
fn bad_requests_get_clear_errors() {
    let error = engine()
        .speak("hello", &VoiceSettings::for_voice("xx-nonexistent"))
        .expect("queued");
    let result = error.collect_blocking();
    assert!(
        matches!(&result, Err(VoiceError::Synthesis(m)) if m.contains("xx-nonexistent")),
        "{result:?}"
    );
    let nul = engine().speak("a\0b", &VoiceSettings::default());
    assert!(matches!(nul, Err(VoiceError::InvalidText(_))));
    // The engine recovers: the next request with a known voice works.
    let ok = engine()
        .speak("fine", &VoiceSettings::default())
        .expect("queued")
        .collect_blocking();
    assert!(ok.is_ok_and(|r| !r.pcm.is_empty()));
    // A second engine in the same process is refused instead of corrupting the first.
    let second = Synthesizer::start(SynthesizerConfig::default());
    assert!(matches!(second, Err(VoiceError::EngineBusy)), "{second:?}");
}

#[test]
fn async_consumers_receive_the_stream() {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    runtime.block_on(async {
        let utterance = engine()
            .speak("Async works too.", &VoiceSettings::default())
            .expect("queued");
        let recording = tokio::time::timeout(Duration::from_secs(30), utterance.collect())
            .await
            .expect("in time")
            .expect("synthesised");
        assert!(!recording.pcm.is_empty() && !recording.cues.is_empty());
    });
}
