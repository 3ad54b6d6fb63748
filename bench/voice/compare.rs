//! The Piper engine against PyPI's `piper-tts` on the same voice file and against our espeak-ng path, sentence by
//! sentence in the same run: time to the first audio and the real-time factor.

use std::time::Instant;

use agent_voice::{SAMPLE_RATE, SpeechEvent, Synthesizer, VoiceSettings};
use anyhow::{Context, bail};

use crate::baseline::PiperTts;

/// Medians of one engine over the sentences.
#[derive(Debug, Clone, Default)]
pub struct EngineTimes {
    /// Milliseconds to the first audio, every run.
    pub first_ms: Vec<f64>,
    /// Sum over sentences of the median synthesis time, and of the audio.
    pub synth_s: f64,
    pub audio_s: f64,
}

impl EngineTimes {
    pub fn rtf(&self) -> f64 {
        self.synth_s / self.audio_s
    }
}

/// The three engines' times.
#[derive(Debug, Clone, Default)]
pub struct Comparison {
    pub piper: EngineTimes,
    pub piper_tts: EngineTimes,
    pub espeak: EngineTimes,
}

/// In-process: milliseconds to the first PCM chunk and to the end, and the samples.
pub fn time_engine(
    engine: &Synthesizer,
    text: &str,
    voice: &VoiceSettings,
) -> anyhow::Result<(f64, f64, usize)> {
    let start = Instant::now();
    let mut utterance = engine.speak(text, voice)?;
    let mut first = None;
    let mut samples = 0;
    while let Some(event) = utterance.blocking_next() {
        match event {
            SpeechEvent::Chunk(chunk) if !chunk.pcm.is_empty() => {
                first.get_or_insert_with(|| start.elapsed().as_secs_f64() * 1000.0);
                samples += chunk.pcm.len();
            }
            SpeechEvent::Finished { .. } => break,
            SpeechEvent::Failed { message } => bail!("synthesis failed: {message}"),
            _ => {}
        }
    }
    let first = first.context("no audio produced")?;
    Ok((first, start.elapsed().as_secs_f64() * 1000.0, samples))
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    values.get(values.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Speaks every sentence `runs` times (after one warm-up) with each engine in turn, and prints a row per sentence.
pub fn compare(
    engine: &Synthesizer,
    baseline: &mut PiperTts,
    sentences: &[&str],
    runs: usize,
) -> anyhow::Result<Comparison> {
    let rate = f64::from(SAMPLE_RATE);
    let mut result = Comparison::default();
    println!(
        "{:>7} | {:>9} {:>8} | {:>9} {:>8} | {:>9} {:>8} | sentence",
        "audio s", "piper 1st", "RTF", "py 1st", "py RTF", "espk 1st", "espk RTF"
    );
    for text in sentences {
        let (mut ours, mut theirs, mut espeak) = (Vec::new(), Vec::new(), Vec::new());
        let (mut ours_total, mut theirs_total, mut espeak_total) =
            (Vec::new(), Vec::new(), Vec::new());
        let (mut audio_s, mut theirs_audio_s, mut espeak_audio_s) = (0.0, 0.0, 0.0);
        for run in 0..=runs {
            let (first, total, samples) = time_engine(engine, text, &VoiceSettings::piper())?;
            let py = baseline.speak(text)?;
            let (e_first, e_total, e_samples) =
                time_engine(engine, text, &VoiceSettings::for_voice("en"))?;
            if run == 0 {
                continue;
            }
            ours.push(first);
            ours_total.push(total);
            theirs.push(py.first_ms);
            theirs_total.push(py.total_ms);
            espeak.push(e_first);
            espeak_total.push(e_total);
            audio_s = samples as f64 / rate;
            theirs_audio_s = py.samples as f64 / rate;
            espeak_audio_s = e_samples as f64 / rate;
        }
        // The voice draws noise, so lengths vary a little run to run; a large gap would mean different phonemes.
        if (theirs_audio_s - audio_s).abs() > 0.25 * audio_s {
            bail!(
                "piper-tts made {theirs_audio_s:.2} s of audio, ours {audio_s:.2} s, for {text:?}"
            );
        }
        let (first, total) = (median(&mut ours.clone()), median(&mut ours_total));
        let (py_first, py_total) = (median(&mut theirs.clone()), median(&mut theirs_total));
        let (e_first, e_total) = (median(&mut espeak.clone()), median(&mut espeak_total));
        println!(
            "{audio_s:>7.2} | {first:>6.1} ms {:>8.4} | {py_first:>6.1} ms {:>8.4} | {e_first:>6.2} ms {:>8.4} | {}",
            total / 1000.0 / audio_s,
            py_total / 1000.0 / theirs_audio_s,
            e_total / 1000.0 / espeak_audio_s,
            shorten(text, 40)
        );
        result.piper.first_ms.extend(ours);
        result.piper.synth_s += total / 1000.0;
        result.piper.audio_s += audio_s;
        result.piper_tts.first_ms.extend(theirs);
        result.piper_tts.synth_s += py_total / 1000.0;
        result.piper_tts.audio_s += theirs_audio_s;
        result.espeak.first_ms.extend(espeak);
        result.espeak.synth_s += e_total / 1000.0;
        result.espeak.audio_s += espeak_audio_s;
    }
    Ok(result)
}

/// The first `chars` characters of `text`, with an ellipsis when it is longer.
pub fn shorten(text: &str, chars: usize) -> String {
    let mut short: String = text.chars().take(chars).collect();
    if text.chars().count() > chars {
        short.push('…');
    }
    short
}
