//! Benchmark of the speech engines (`make bench`): time to first chunk and real-time factor of the in-process
//! espeak-ng engine, side by side with the `espeak-ng` command-line tool speaking the same sentences in the same
//! run, and how well the viseme cues line up with espeak-ng's events and with the audio itself; then the Piper
//! voice against PyPI's `piper-tts` on the same voice file and against espeak-ng (first audio, real-time factor),
//! its visemes against the audio, what our whisper path (base model) hears of forty sentences from each engine,
//! and the peak memory of a robot-agent speaking with each.

mod baseline;
mod compare;
mod intelligibility;
mod rss;
mod sentences;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use agent_voice::{
    PiperConfig, Recording, SAMPLE_RATE, Synthesizer, SynthesizerConfig, Viseme, VisemeCue,
    VoiceSettings, samples_to_ms,
};
use anyhow::{Context, bail};
use clap::Parser;

/// Command-line options.
#[derive(Debug, Parser)]
#[command(about = "espeak-ng TTS benchmark: first chunk, real-time factor, viseme timing")]
struct Options {
    /// Measured runs per sentence (after two warm-up runs).
    #[arg(long, default_value_t = 15)]
    runs: usize,
    /// The espeak-ng command-line tool used as the baseline.
    #[arg(long, default_value = "espeak-ng")]
    cli: PathBuf,
    /// Measured runs per sentence of the Piper comparison (after one warm-up run).
    #[arg(long, default_value_t = 5)]
    piper_runs: usize,
    /// The Python with PyPI's piper-tts 1.8.0, the Piper baseline (`make bench` makes models/piper-venv).
    #[arg(
        long,
        env = "PIPER_PYTHON",
        default_value = "models/piper-venv/bin/python"
    )]
    piper_python: PathBuf,
    /// ONNX Runtime threads of the Piper engine (default: the engine's own default).
    #[arg(long)]
    piper_threads: Option<usize>,
    /// Words before the first sentence may be cut for an early first part (default: the engine's own, 3; 0 speaks
    /// whole sentences, as before issue 48).
    #[arg(long)]
    first_part_words: Option<usize>,
    /// The Whisper model that judges intelligibility (`make model-release MODEL=base`).
    #[arg(long, default_value = "models/ggml-base.bin")]
    whisper_model: PathBuf,
}

/// The sentences spoken, with their espeak-ng voice: short and long, English and Italian.
const SENTENCES: [(&str, &str); 5] = [
    ("en", "Hello! How can I help you?"),
    (
        "en",
        "It is a quarter past three in the afternoon, and the weather outside looks fine.",
    ),
    (
        "en",
        "I can see two people in front of me. The one on the left is waving at me, and the other one is \
         holding up a code that I can read for you.",
    ),
    (
        "it",
        "Ciao! Sono le tre e un quarto del pomeriggio, e fuori il tempo sembra bello.",
    ),
    (
        "it",
        "Vedo due persone davanti a me. Quella a sinistra mi saluta, e l'altra tiene in mano un codice.",
    ),
];

/// Targets from the issues.
const FIRST_CHUNK_TARGET_MS: f64 = 30.0;
const VISEME_ERROR_TARGET_MS: f64 = 20.0;
const PIPER_VISEME_TARGET_MS: f64 = 40.0;
/// Issue 48: the Piper voice's first audio on a quiet machine, and against piper-tts on the same voice.
const PIPER_FIRST_P50_MS: f64 = 120.0;
const PIPER_FIRST_P95_MS: f64 = 250.0;
const PIPER_FIRST_RATIO: f64 = 0.5;

fn main() -> anyhow::Result<()> {
    let options = Options::parse();
    let defaults = PiperConfig::default();
    let piper = PiperConfig {
        threads: options.piper_threads.unwrap_or(defaults.threads),
        first_part_words: options
            .first_part_words
            .unwrap_or(defaults.first_part_words),
        // Every sentence is spoken several times: the cache would answer all but the first.
        cache_seconds: 0,
        ..defaults
    };
    let engine = Synthesizer::start(SynthesizerConfig {
        piper: Some(piper.clone()),
        ..SynthesizerConfig::default()
    })
    .context("starting the speech engine with the Piper voice (`make model-voice`)")?;
    if engine.sample_rate() != SAMPLE_RATE {
        bail!(
            "espeak-ng produces {} Hz, expected {SAMPLE_RATE}",
            engine.sample_rate()
        );
    }
    let scratch = std::env::temp_dir().join(format!("voice-bench-{}.wav", std::process::id()));

    println!(
        "voice-bench: {} runs per sentence after 2 warm-up runs; CLI baseline: {}",
        options.runs,
        options.cli.display()
    );
    println!(
        "{:<5} {:>7} | {:>9} {:>9} {:>8} | {:>11} {:>9} {:>8} | sentence",
        "voice", "audio s", "ours 1st", "ours all", "ours RTF", "CLI 1st out", "CLI -w", "CLI RTF"
    );
    let mut ours_first = Vec::new();
    let mut cli_first = Vec::new();
    let (mut ours_synth_s, mut cli_synth_s, mut audio_total_s) = (0.0, 0.0, 0.0);
    for (voice, text) in SENTENCES {
        let settings = VoiceSettings::for_voice(voice);
        let mut first = Vec::new();
        let mut whole = Vec::new();
        let mut cli_out = Vec::new();
        let mut cli_wav = Vec::new();
        let mut audio_s = 0.0;
        for run in 0..options.runs + 2 {
            let (ours_first_ms, ours_whole_ms, samples) =
                compare::time_engine(&engine, text, &settings)?;
            let cli_first_ms = time_cli_first_output(&options.cli, voice, text)?;
            let (cli_whole_ms, cli_samples) = time_cli_wav(&options.cli, voice, text, &scratch)?;
            if run < 2 {
                continue;
            }
            audio_s = samples as f64 / f64::from(SAMPLE_RATE);
            // Both run the same espeak-ng data, so the audio should be as long; a large gap means the
            // comparison is not like for like.
            let cli_audio_s = cli_samples as f64 / f64::from(SAMPLE_RATE);
            if (cli_audio_s - audio_s).abs() > 0.15 * audio_s {
                bail!("CLI audio {cli_audio_s:.2} s differs from ours {audio_s:.2} s for {text:?}");
            }
            first.push(ours_first_ms);
            whole.push(ours_whole_ms);
            cli_out.push(cli_first_ms);
            cli_wav.push(cli_whole_ms);
        }
        let (first_p50, whole_p50) = (median(&first), median(&whole));
        let (cli_out_p50, cli_wav_p50) = (median(&cli_out), median(&cli_wav));
        println!(
            "{voice:<5} {audio_s:>7.2} | {first_p50:>6.2} ms {whole_p50:>6.1} ms {:>8.4} | {cli_out_p50:>8.1} ms {cli_wav_p50:>6.1} ms {:>8.4} | {}",
            whole_p50 / 1000.0 / audio_s,
            cli_wav_p50 / 1000.0 / audio_s,
            compare::shorten(text, 40)
        );
        ours_first.extend(first);
        cli_first.extend(cli_out);
        ours_synth_s += whole_p50 / 1000.0;
        cli_synth_s += cli_wav_p50 / 1000.0;
        audio_total_s += audio_s;
    }
    let _ = std::fs::remove_file(&scratch);

    let timing = viseme_timing(&engine)?;
    println!(
        "viseme cues: {} checked against espeak-ng events ({} glide/rest cues without an event); {} speech onsets and \
         {} offsets checked against the audio energy",
        timing.clock_errors.len(),
        timing.cues_without_event,
        timing.onset_errors.len(),
        timing.offset_errors.len()
    );

    let first_p50 = median(&ours_first);
    let first_p95 = percentile(&ours_first, 95.0);
    let cli_first_p50 = median(&cli_first);
    let ours_rtf = ours_synth_s / audio_total_s;
    let cli_rtf = cli_synth_s / audio_total_s;
    let clock_max = timing.clock_errors.iter().copied().fold(0.0, f64::max);
    let acoustic: Vec<f64> = timing
        .onset_errors
        .iter()
        .chain(&timing.offset_errors)
        .map(|e| e.abs())
        .collect();
    let acoustic_p50 = median(&acoustic);
    let acoustic_p95 = percentile(&acoustic, 95.0);
    println!();
    println!(
        "SUMMARY tts first chunk: {first_p50:.2} ms median, p95 {first_p95:.2} ms (baseline espeak-ng CLI first audio \
         on stdout {cli_first_p50:.1} ms, ratio {:.3}; target <= {FIRST_CHUNK_TARGET_MS} ms: {})",
        first_p50 / cli_first_p50,
        verdict(first_p95 <= FIRST_CHUNK_TARGET_MS)
    );
    println!(
        "SUMMARY tts real-time factor: {ours_rtf:.4} (baseline espeak-ng CLI -w {cli_rtf:.4}, ratio {:.3})",
        ours_rtf / cli_rtf
    );
    println!(
        "SUMMARY viseme timing error vs espeak events: max {clock_max:.2} ms (baseline target {VISEME_ERROR_TARGET_MS} \
         ms, ratio {:.3}: {})",
        clock_max / VISEME_ERROR_TARGET_MS,
        verdict(clock_max <= VISEME_ERROR_TARGET_MS)
    );
    println!(
        "SUMMARY viseme timing error vs audio onsets/offsets: median {acoustic_p50:.1} ms, p95 {acoustic_p95:.1} ms \
         (baseline target {VISEME_ERROR_TARGET_MS} ms, ratio {:.3}: {})",
        acoustic_p95 / VISEME_ERROR_TARGET_MS,
        verdict(acoustic_p95 <= VISEME_ERROR_TARGET_MS)
    );
    piper_section(&options, &engine, &piper)
}

/// The Piper voice: against piper-tts and espeak-ng, its visemes, intelligibility and memory.
fn piper_section(
    options: &Options,
    engine: &Synthesizer,
    piper: &PiperConfig,
) -> anyhow::Result<()> {
    println!();
    println!(
        "Piper voice {} ({} ONNX Runtime thread(s)) vs piper-tts 1.8.0 ({}, its defaults) on the same file and vs \
         espeak-ng (en), {} runs after 1 warm-up",
        piper.voice.display(),
        piper.threads,
        options.piper_python.display(),
        options.piper_runs
    );
    let mut baseline =
        baseline::PiperTts::start(&options.piper_python, &piper.voice, &piper.voice_json)?;
    let english: Vec<&str> = SENTENCES
        .iter()
        .filter(|(voice, _)| *voice == "en")
        .map(|(_, text)| *text)
        .chain([
            sentences::INTELLIGIBILITY[4],
            sentences::INTELLIGIBILITY[36],
        ])
        .collect();
    let times = compare::compare(engine, &mut baseline, &english, options.piper_runs)?;
    let piper_tts_rss = baseline.finish()?;

    // Visemes against the audio: the English reply spoken five times (the voice draws noise, so every run differs).
    let mut timing = VisemeTiming::default();
    for _ in 0..5 {
        let recording = engine
            .speak(&english.join(" "), &VoiceSettings::piper())?
            .collect_blocking()?;
        check_against_energy(&recording, &mut timing, |cue| {
            matches!(cue.viseme, Viseme::PP | Viseme::DD | Viseme::Kk)
        });
    }
    let onsets: Vec<f64> = timing.onset_errors.iter().map(|e| e.abs()).collect();
    let offsets: Vec<f64> = timing.offset_errors.iter().map(|e| e.abs()).collect();
    let both: Vec<f64> = onsets.iter().chain(&offsets).copied().collect();
    println!(
        "piper visemes: {} onsets (signed median {:+.1} ms) and {} offsets (signed median {:+.1} ms) checked against \
         the audio energy",
        onsets.len(),
        median(&timing.onset_errors),
        offsets.len(),
        median(&timing.offset_errors)
    );

    // Intelligibility: forty sentences from each engine through our whisper path, base model.
    let mut transcriber = intelligibility::transcriber(&options.whisper_model)?;
    let piper_heard = intelligibility::score(engine, &VoiceSettings::piper(), &mut transcriber)?;
    let espeak_heard =
        intelligibility::score(engine, &VoiceSettings::for_voice("en"), &mut transcriber)?;
    for (name, heard) in [("piper", &piper_heard), ("espeak-ng", &espeak_heard)] {
        println!(
            "{name}: {} of {} words wrong; misheard sentences:",
            heard.errors, heard.words
        );
        for (said, written) in &heard.misheard {
            println!("  {said:?} -> {written:?}");
        }
    }

    // Memory of a real robot-agent with each engine.
    let runtime = tokio::runtime::Runtime::new()?;
    let replies = &english[..3];
    let piper_rss = runtime.block_on(rss::agent_peak_rss_mb("piper", replies))?;
    let espeak_rss = runtime.block_on(rss::agent_peak_rss_mb("espeak", replies))?;

    let piper_first = median(&times.piper.first_ms);
    let piper_first_p95 = percentile(&times.piper.first_ms, 95.0);
    let py_first = median(&times.piper_tts.first_ms);
    let espeak_first = median(&times.espeak.first_ms);
    let (piper_rtf, py_rtf, espeak_rtf) =
        (times.piper.rtf(), times.piper_tts.rtf(), times.espeak.rtf());
    println!();
    println!(
        "SUMMARY piper first audio: {piper_first:.1} ms median, p95 {piper_first_p95:.1} ms (first part after {} \
         words; targets p50 <= {PIPER_FIRST_P50_MS} ms, p95 <= {PIPER_FIRST_P95_MS} ms: {}; baseline piper-tts \
         {py_first:.1} ms, ratio {:.3}; target <= {PIPER_FIRST_RATIO}: {}; espeak-ng {espeak_first:.2} ms)",
        piper.first_part_words,
        verdict(piper_first <= PIPER_FIRST_P50_MS && piper_first_p95 <= PIPER_FIRST_P95_MS),
        piper_first / py_first,
        verdict(piper_first / py_first <= PIPER_FIRST_RATIO)
    );
    println!(
        "SUMMARY piper real-time factor: {piper_rtf:.4} (baseline piper-tts {py_rtf:.4}, ratio {:.3}; target <= 1.0: \
         {}; espeak-ng {espeak_rtf:.4})",
        piper_rtf / py_rtf,
        verdict(piper_rtf <= py_rtf)
    );
    println!(
        "SUMMARY tts intelligibility (whisper base, {} sentences): WER piper {:.1}% ({}/{} words), espeak-ng {:.1}% \
         ({}/{} words), ratio {:.3}; target piper <= espeak-ng: {}",
        sentences::INTELLIGIBILITY.len(),
        piper_heard.wer() * 100.0,
        piper_heard.errors,
        piper_heard.words,
        espeak_heard.wer() * 100.0,
        espeak_heard.errors,
        espeak_heard.words,
        piper_heard.wer() / espeak_heard.wer().max(f64::MIN_POSITIVE),
        verdict(piper_heard.wer() <= espeak_heard.wer())
    );
    println!(
        "SUMMARY piper viseme timing vs audio onsets/offsets: median {:.1} ms, p95 {:.1} ms (onsets p95 {:.1} ms, \
         offsets p95 {:.1} ms; target {PIPER_VISEME_TARGET_MS} ms, ratio {:.3}: {})",
        median(&both),
        percentile(&both, 95.0),
        percentile(&onsets, 95.0),
        percentile(&offsets, 95.0),
        percentile(&both, 95.0) / PIPER_VISEME_TARGET_MS,
        verdict(percentile(&both, 95.0) <= PIPER_VISEME_TARGET_MS)
    );
    println!(
        "SUMMARY tts peak rss of robot-agent: piper {piper_rss:.0} MB, espeak-ng {espeak_rss:.0} MB (ratio {:.2}; \
         piper-tts's Python process {piper_tts_rss:.0} MB)",
        piper_rss / espeak_rss
    );
    Ok(())
}

/// Runs `espeak-ng --stdout` and returns the milliseconds until its first audio bytes (past the 44-byte WAV
/// header) arrive: the command-line tool's own time to first chunk, process start and data loading included.
fn time_cli_first_output(cli: &Path, voice: &str, text: &str) -> anyhow::Result<f64> {
    let start = Instant::now();
    let mut child = Command::new(cli)
        .args(["-v", voice, "--stdout", text])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .with_context(|| format!("running {}", cli.display()))?;
    let mut stdout = child.stdout.take().context("no stdout")?;
    let mut buffer = [0u8; 4096];
    let mut received = 0;
    let mut first = None;
    loop {
        let read = stdout.read(&mut buffer)?;
        if read == 0 {
            break;
        }
        received += read;
        if received > 44 && first.is_none() {
            first = Some(ms(start.elapsed()));
        }
    }
    let status = child.wait()?;
    if !status.success() {
        bail!("{} failed with {status}", cli.display());
    }
    first.context("the CLI produced no audio")
}

/// Runs `espeak-ng -w out.wav` and returns its wall time in milliseconds and the samples it wrote.
fn time_cli_wav(cli: &Path, voice: &str, text: &str, out: &Path) -> anyhow::Result<(f64, usize)> {
    let start = Instant::now();
    let status = Command::new(cli)
        .args(["-v", voice, "-w"])
        .arg(out)
        .arg(text)
        .stderr(Stdio::null())
        .status()
        .with_context(|| format!("running {}", cli.display()))?;
    let elapsed = ms(start.elapsed());
    if !status.success() {
        bail!("{} failed with {status}", cli.display());
    }
    let reader =
        hound::WavReader::open(out).with_context(|| format!("reading {}", out.display()))?;
    if reader.spec().sample_rate != SAMPLE_RATE {
        bail!("the CLI wrote {} Hz", reader.spec().sample_rate);
    }
    Ok((elapsed, reader.len() as usize))
}

/// Errors in milliseconds of the viseme cues.
#[derive(Debug, Default)]
struct VisemeTiming {
    /// |cue time - espeak-ng's own event time|, for every cue that starts at a phoneme event.
    clock_errors: Vec<f64>,
    /// Diphthong second halves and closing rests, which no event marks.
    cues_without_event: usize,
    /// Signed (audio onset - cue) at every start of speech after a rest.
    onset_errors: Vec<f64>,
    /// Signed (audio offset - cue) at every return to rest.
    offset_errors: Vec<f64>,
}

/// Speaks every sentence of the set as one multi-sentence reply and checks each cue twice: against the
/// millisecond position espeak-ng itself gives the phoneme event, and against where the sound starts or stops.
fn viseme_timing(engine: &Synthesizer) -> anyhow::Result<VisemeTiming> {
    let mut timing = VisemeTiming::default();
    for voice in ["en", "it"] {
        let reply: Vec<&str> = SENTENCES
            .iter()
            .filter(|(v, _)| *v == voice)
            .map(|(_, text)| *text)
            .collect();
        let recording = engine
            .speak(&reply.join(" "), &VoiceSettings::for_voice(voice))?
            .collect_blocking()?;
        check_against_events(&recording, &mut timing);
        // Stops and affricates: their lips close during a silent closure before any sound.
        check_against_energy(&recording, &mut timing, |cue| {
            recording
                .phonemes
                .iter()
                .find(|m| m.sample == cue.sample)
                .is_some_and(|m| {
                    m.ipa
                        .trim_start_matches(['ˈ', 'ˌ'])
                        .starts_with(['p', 'b', 't', 'd', 'k', 'g', 'ɡ'])
                })
        });
    }
    Ok(timing)
}

fn check_against_events(recording: &Recording, timing: &mut VisemeTiming) {
    for cue in &recording.cues {
        let Some(mark) = recording.phonemes.iter().find(|m| m.sample == cue.sample) else {
            timing.cues_without_event += 1;
            continue;
        };
        // espeak-ng numbers each sentence from zero; a mark on a boundary may belong to either side.
        let cue_ms = cue.at_ms(SAMPLE_RATE);
        let error = recording
            .sentences
            .iter()
            .filter(|(_, start, end)| (*start..=*end).contains(&mark.sample))
            .map(|(_, start, _)| {
                (samples_to_ms(*start, SAMPLE_RATE) + mark.espeak_ms as f64 - cue_ms).abs()
            })
            .fold(f64::INFINITY, f64::min);
        timing.clock_errors.push(error);
    }
}

/// Compares rest/speech transitions of the cues with the energy envelope (5 ms windows). Onsets that `is_stop`
/// says are stops are skipped: their lips close during a silent closure before any sound, so the viseme rightly
/// leads the audio there.
fn check_against_energy(
    recording: &Recording,
    timing: &mut VisemeTiming,
    is_stop: impl Fn(&VisemeCue) -> bool,
) {
    const WINDOW: usize = (SAMPLE_RATE as usize) / 200;
    let envelope: Vec<f64> = recording
        .pcm
        .chunks(WINDOW)
        .map(|w| (w.iter().map(|&s| f64::from(s).powi(2)).sum::<f64>() / w.len() as f64).sqrt())
        .collect();
    let mut sorted = envelope.clone();
    sorted.sort_by(f64::total_cmp);
    let loud = sorted.get(sorted.len() * 95 / 100).copied().unwrap_or(0.0);
    let threshold = loud * 0.05;
    let window_ms = samples_to_ms(WINDOW as u64, SAMPLE_RATE);
    let is_loud = |index: usize| envelope.get(index).is_some_and(|&e| e > threshold);
    let search = (150.0 / window_ms) as usize;

    for pair in recording.cues.windows(2) {
        let (before, cue) = (pair[0], pair[1]);
        let at = (cue.sample as usize) / WINDOW;
        let from = at.saturating_sub(search);
        let to = (at + search).min(envelope.len());
        if before.viseme == Viseme::Sil && cue.viseme != Viseme::Sil {
            if is_stop(&cue) {
                continue;
            }
            if let Some(onset) = (from..to).find(|&i| is_loud(i) && (i == 0 || !is_loud(i - 1))) {
                timing
                    .onset_errors
                    .push(onset as f64 * window_ms - cue.at_ms(SAMPLE_RATE));
            }
        } else if before.viseme != Viseme::Sil
            && cue.viseme == Viseme::Sil
            && let Some(offset) = (from..to).rev().find(|&i| is_loud(i) && !is_loud(i + 1))
        {
            timing
                .offset_errors
                .push((offset + 1) as f64 * window_ms - cue.at_ms(SAMPLE_RATE));
        }
    }
}

fn ms(duration: Duration) -> f64 {
    duration.as_secs_f64() * 1000.0
}

fn median(values: &[f64]) -> f64 {
    percentile(values, 50.0)
}

/// Nearest-rank percentile; 0 for no values.
fn percentile(values: &[f64], pct: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let rank = ((pct / 100.0) * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

fn verdict(met: bool) -> &'static str {
    if met { "met" } else { "NOT met" }
}
