//! echo-bench: the server's echo canceller (`agent-echo`: AEC3 through sonora, and the residual gate after it)
//! against Speex's canceller (Debian's `libspeexdsp`) on the same audio, in one run (docs/voice.md, "Echo
//! cancellation").
//!
//! The agent's own replies, spoken by the Piper voice and by espeak-ng, are played through a simulated room (sox:
//! the page's 60 ms jitter buffer plus a 50-400 ms path, `reverb 50 50 80`, 12 dB down or as loud) into a
//! microphone that the canceller receives in 20 ms messages stamped as the hub stamps them; both cancellers get
//! the reference at the same lead. Figures:
//! - ERLE after convergence (from 2 s on): the adaptive filter and AEC3's own suppressor, without the residual gate
//!   (Speex has no such gate either), target >= 25 dB and >= 1.0x Speex; CPU per second of audio for both;
//! - double talk: recorded people's sentences (the fixtures) spoken over a Piper reply's 0 dB echo, cleaned by the
//!   canceller as `make run` configures it, transcribed by whisper (base, the satellite's path): WER against the
//!   same sentences with no echo, target ratio <= 1.2; the uncancelled mix and Speex beside it, and AEC3's block
//!   processor driven directly (`aec3_blocks.rs`): its linear filter's output before the suppressor, and a longer
//!   filter with a suppressor tuned for the near end (what `sonora`'s audio processing does not expose).

mod aec3_blocks;
mod speex;

use std::path::{Path, PathBuf};

use agent_echo::{Canceller, CancellerConfig, RATE, samples_us};
use agent_tests::spoken::{mix, read_wav, room_echo};
use agent_voice::{PiperConfig, Synthesizer, SynthesizerConfig, VoiceSettings};
use anyhow::Context;
use clap::Parser;
use whisper_sat::offline::{joined_text, transcribe_clip};
use whisper_sat::segmenter::SegmenterConfig;
use whisper_sat::transcriber::{Transcriber, TranscriberConfig};
use whisper_sat::wer::word_errors;

#[derive(Debug, Parser)]
#[command(
    about = "echo cancellation: agent-echo (AEC3) vs Speex on the agent's replies through a simulated room"
)]
struct Options {
    /// The Whisper model that transcribes the double-talk sentences (`make model-release MODEL=base`).
    #[arg(long, default_value = "models/ggml-base.bin")]
    model: PathBuf,
    /// The shared fixtures (`$AGENT_FIXTURES`, else `../shared/fixtures`).
    #[arg(long, env = "AGENT_FIXTURES", default_value = "../shared/fixtures")]
    fixtures: PathBuf,
    /// Only the double-talk figure.
    #[arg(long)]
    double_talk_only: bool,
}

/// What the agent says: its own replies, some 15 s.
const REPLY: &str = "Let me tell you about the weather today. In the morning it will be cloudy with a chance of \
    light rain, and the afternoon should be sunny and warm. I am the robot agent. I can see, listen and talk. \
    Sorry, I did not understand. You can ask me the time, or what I see.";
/// The page's jitter buffer: the room's delay comes after it.
const PLAYED_MS: u32 = 60;
const DELAYS_MS: [u32; 4] = [50, 150, 300, 400];
const ATTENUATIONS_DB: [f32; 2] = [12.0, 0.0];
/// Speex's filter covers the lead, the longest delay and the reverb's tail.
const SPEEX_FILTER_MS: usize = 900;
const ERLE_TARGET_DB: f64 = 25.0;
const DOUBLE_TALK_RATIO: f64 = 1.2;
/// The people (fixtures with their transcripts) and when they start talking over the reply (s).
const PEOPLE: [&str; 4] = [
    "LJ001-0001",
    "LJ001-0002",
    "LJ001-0004",
    "derived/jfk_22050",
];
const PERSON_AT_S: f64 = 1.0;

fn main() -> anyhow::Result<()> {
    let options = Options::parse();
    let scratch = tempfile::tempdir()?;
    let engine = Synthesizer::start(SynthesizerConfig {
        piper: Some(PiperConfig {
            cache_seconds: 0,
            ..PiperConfig::default()
        }),
        ..SynthesizerConfig::default()
    })
    .context("starting the speech engine with the Piper voice (`make model-voice`)")?;
    let voices = [
        ("piper", VoiceSettings::piper()),
        ("espeak", VoiceSettings::for_voice("en")),
    ];
    println!(
        "{:<7} {:>6} {:>6} | {:>9} {:>9} {:>6} | {:>10} {:>10}",
        "voice", "delay", "echo", "ours dB", "speex dB", "ratio", "ours ms/s", "speex ms/s"
    );
    let mut ours_erle = Vec::new();
    let mut speex_erle = Vec::new();
    let (mut ours_cpu, mut speex_cpu, mut audio_s) = (0.0, 0.0, 0.0);
    let mut piper_reply = Vec::new();
    for (name, voice) in &voices {
        let reply = engine.speak(REPLY, voice)?.collect_blocking()?.pcm;
        let delays: &[u32] = if options.double_talk_only {
            &[]
        } else {
            &DELAYS_MS
        };
        for &delay in delays {
            for attenuation in ATTENUATIONS_DB {
                let echo = room_echo(&reply, PLAYED_MS + delay, attenuation, scratch.path())?;
                let filter_only = CancellerConfig {
                    residual_gate: false,
                    ..CancellerConfig::default()
                };
                let (ours, ours_s) = cancel(filter_only, &reply, &echo);
                let (theirs, theirs_s) = speex_cancel(&reply, &echo)?;
                let (a, b) = (erle(&echo, &ours), erle(&echo, &theirs));
                let seconds = echo.len() as f64 / f64::from(RATE);
                println!(
                    "{name:<7} {delay:>4}ms {:>4}dB | {a:>9.1} {b:>9.1} {:>6.2} | {:>10.2} {:>10.2}",
                    -attenuation,
                    a / b,
                    ours_s * 1000.0 / seconds,
                    theirs_s * 1000.0 / seconds
                );
                ours_erle.push(a);
                speex_erle.push(b);
                ours_cpu += ours_s;
                speex_cpu += theirs_s;
                audio_s += seconds;
            }
        }
        if *name == "piper" {
            piper_reply = reply;
        }
    }
    if !options.double_talk_only {
        erle_summary(
            &ours_erle,
            &speex_erle,
            ours_cpu / audio_s,
            speex_cpu / audio_s,
        );
    }

    let mut transcriber = Transcriber::load(
        &options.model,
        TranscriberConfig {
            threads: 2,
            language: "en".into(),
            ..TranscriberConfig::default()
        },
    )
    .with_context(|| {
        format!(
            "loading {} (`make model-release MODEL=base`)",
            options.model.display()
        )
    })?;
    let echo = room_echo(&piper_reply, PLAYED_MS + 150, 0.0, scratch.path())?;
    let mut errors = [0usize; 8];
    let mut words = 0;
    println!(
        "double talk over the Piper reply's 0 dB echo (150 ms, reverb): alone | raw mix | ours | speex | ours \
         without the residual gate"
    );
    let filter_only = CancellerConfig {
        residual_gate: false,
        ..CancellerConfig::default()
    };
    for (name, config) in [
        ("default", aec3_blocks::default_config()),
        ("long filter, near-end tuned", aec3_blocks::nearend_config()),
    ] {
        let alone = aec3_blocks::run(&config, &piper_reply, &echo)?;
        let echo16: Vec<f32> = aec3_blocks::run(&config, &[], &echo)?.suppressed;
        let energy = |x: &[f32]| {
            x.iter()
                .skip(32_000)
                .map(|&s| f64::from(s).powi(2))
                .sum::<f64>()
        };
        println!(
            "AEC3's block processor, {name}: ERLE suppressed {:.1} dB, linear {:.1} dB",
            10.0 * (energy(&echo16) / energy(&alone.suppressed).max(1e-12)).log10(),
            10.0 * (energy(&echo16) / energy(&alone.linear).max(1e-12)).log10()
        );
    }
    for person in PEOPLE {
        let (samples, text) = person_clip(&options.fixtures, person)?;
        let at = (PERSON_AT_S * f64::from(RATE)) as usize;
        let mic = mix(&echo, &samples, at);
        let (ours, _) = cancel(CancellerConfig::default(), &piper_reply, &mic);
        let (theirs, _) = speex_cancel(&piper_reply, &mic)?;
        let (ungated, _) = cancel(filter_only, &piper_reply, &mic);
        let blocks = aec3_blocks::run(&aec3_blocks::default_config(), &piper_reply, &mic)?;
        let nearend = aec3_blocks::run(&aec3_blocks::nearend_config(), &piper_reply, &mic)?;
        let heard = [
            hear(&mut transcriber, &samples)?,
            hear(&mut transcriber, &mic)?,
            hear(&mut transcriber, &ours)?,
            hear(&mut transcriber, &theirs)?,
            hear(&mut transcriber, &ungated)?,
            hear16(&mut transcriber, &blocks.suppressed)?,
            hear16(&mut transcriber, &blocks.linear)?,
            hear16(&mut transcriber, &nearend.suppressed)?,
        ];
        for (e, h) in errors.iter_mut().zip(&heard) {
            *e += word_errors(&text, h).0;
        }
        words += word_errors(&text, "").1;
        println!("{person}: {text}\n  {heard:?}");
    }
    let wer = |e: usize| e as f64 / words.max(1) as f64;
    let (alone, raw, ours, theirs, ungated) = (
        wer(errors[0]),
        wer(errors[1]),
        wer(errors[2]),
        wer(errors[3]),
        wer(errors[4]),
    );
    println!(
        "AEC3's block processor at 16 kHz: suppressed {:.1}%, linear output {:.1}%, long filter and near-end \
         tuned suppressor {:.1}%",
        wer(errors[5]) * 100.0,
        wer(errors[6]) * 100.0,
        wer(errors[7]) * 100.0
    );
    // With no error at all alone, the ratio is taken against one error.
    let ratio = errors[2] as f64 / errors[0].max(1) as f64;
    println!(
        "SUMMARY echo_double_talk_wer: {:.1}% ({} people over a 0 dB echo of the Piper reply, {words} words; alone \
         {:.1}%, ratio {ratio:.2}; uncancelled {:.1}%, Speex {:.1}%, ours without the residual gate {:.1}%; target \
         ratio <= {DOUBLE_TALK_RATIO}: {})",
        ours * 100.0,
        PEOPLE.len(),
        alone * 100.0,
        raw * 100.0,
        theirs * 100.0,
        ungated * 100.0,
        verdict(ratio <= DOUBLE_TALK_RATIO)
    );
    Ok(())
}

/// The ERLE and CPU SUMMARY lines (CPU in seconds per second of audio).
fn erle_summary(ours_erle: &[f64], speex_erle: &[f64], ours_cpu: f64, speex_cpu: f64) {
    let (ours_p50, speex_p50) = (median(ours_erle), median(speex_erle));
    let ours_min = ours_erle.iter().copied().fold(f64::INFINITY, f64::min);
    let ratio = ours_p50 / speex_p50;
    println!(
        "SUMMARY echo_erle_p50: {ours_p50:.1} dB (min {ours_min:.1} dB over {} rooms: Piper and espeak-ng replies, \
         {}-{} ms, -12 and 0 dB, reverb; Speex {speex_p50:.1} dB, ratio {ratio:.2}; target >= {ERLE_TARGET_DB} dB \
         and >= 1.0x Speex: {})",
        ours_erle.len(),
        DELAYS_MS[0],
        DELAYS_MS[DELAYS_MS.len() - 1],
        verdict(ours_p50 >= ERLE_TARGET_DB && ratio >= 1.0)
    );
    println!(
        "SUMMARY echo_cpu: {:.2} ms per second of audio (Speex with a {SPEEX_FILTER_MS} ms filter {:.2} ms, ratio {:.2})",
        ours_cpu * 1000.0,
        speex_cpu * 1000.0,
        ours_cpu / speex_cpu
    );
}

/// Runs `mic` through a canceller sent `reply` at once (as the TTS module sends ahead), the microphone in 20 ms
/// messages stamped 5 ms after their last sample; returns the cleaned microphone and the thread's CPU seconds.
fn cancel(cfg: CancellerConfig, reply: &[i16], mic: &[i16]) -> (Vec<i16>, f64) {
    let started = cpu_time::ThreadTime::now();
    let Ok(mut canceller) = Canceller::new(cfg) else {
        return (mic.to_vec(), 0.0);
    };
    let t0 = 1_000_000_000u64;
    for (k, chunk) in reply.chunks(441).enumerate() {
        canceller.speech(t0, Some((1, (k * 441) as u32)), &le_bytes(chunk));
    }
    let mut out = Vec::with_capacity(mic.len() * 2);
    for (k, chunk) in mic.chunks(441).enumerate() {
        let stamp = t0 + samples_us((k * 441 + chunk.len()) as u64) + 5_000;
        canceller.microphone(k as u64 + 1, stamp, &le_bytes(chunk), &mut out);
    }
    let cleaned = out
        .chunks_exact(2)
        .map(|b| i16::from_le_bytes([b[0], b[1]]))
        .collect();
    (cleaned, started.elapsed().as_secs_f64())
}

/// The same with Speex: the reference at the same lead (the page plays it `PLAYED_MS` after it arrived, and the
/// lead is as long), in the same 10 ms frames.
fn speex_cancel(reply: &[i16], mic: &[i16]) -> anyhow::Result<(Vec<i16>, f64)> {
    let started = cpu_time::ThreadTime::now();
    let frame = RATE as usize / 100;
    let mut speex = speex::SpeexEcho::new(frame, SPEEX_FILTER_MS * RATE as usize / 1000, RATE)?;
    let lead = CancellerConfig::default().lead_ms as usize * RATE as usize / 1000;
    let shift = lead as i64 - (PLAYED_MS as usize * RATE as usize / 1000) as i64;
    let mut out = vec![0i16; mic.len() / frame * frame];
    let mut play = vec![0i16; frame];
    for (k, rec) in mic.chunks_exact(frame).enumerate() {
        for (i, p) in play.iter_mut().enumerate() {
            let j = (k * frame + i) as i64 + shift;
            *p = usize::try_from(j)
                .ok()
                .and_then(|j| reply.get(j))
                .copied()
                .unwrap_or(0);
        }
        speex.cancel(rec, &play, &mut out[k * frame..(k + 1) * frame]);
    }
    Ok((out, started.elapsed().as_secs_f64()))
}

/// Echo return loss enhancement from 2 s on (the filters have converged) over what was processed (dB).
fn erle(echo: &[i16], cleaned: &[i16]) -> f64 {
    let span = 2 * RATE as usize..cleaned.len().min(echo.len());
    let energy = |x: &[i16]| x.iter().map(|&s| f64::from(s).powi(2)).sum::<f64>();
    10.0 * (energy(&echo[span.clone()]) / energy(&cleaned[span]).max(1.0)).log10()
}

/// A person's recording and its transcript.
fn person_clip(fixtures: &Path, name: &str) -> anyhow::Result<(Vec<i16>, String)> {
    let wav = fixtures.join(format!("audio/{name}.wav"));
    let base = name
        .rsplit('/')
        .next()
        .unwrap_or(name)
        .trim_end_matches("_22050");
    let txt = fixtures.join(format!("audio/{base}.txt"));
    let text =
        std::fs::read_to_string(&txt).with_context(|| format!("reading {}", txt.display()))?;
    Ok((read_wav(&wav)?, text.trim().to_owned()))
}

/// What whisper writes for `pcm` through the satellite's path (resampling, segmentation, transcriber).
fn hear(transcriber: &mut Transcriber, pcm: &[i16]) -> anyhow::Result<String> {
    let samples: Vec<f32> = pcm.iter().map(|&s| f32::from(s) / 32768.0).collect();
    let results = transcribe_clip(&samples, RATE, SegmenterConfig::default(), transcriber)?;
    Ok(joined_text(&results))
}

/// The same for 16 kHz samples in [-1, 1].
fn hear16(transcriber: &mut Transcriber, samples: &[f32]) -> anyhow::Result<String> {
    let results = transcribe_clip(
        samples,
        aec3_blocks::RATE_16K,
        SegmenterConfig::default(),
        transcriber,
    )?;
    Ok(joined_text(&results))
}

fn le_bytes(samples: &[i16]) -> Vec<u8> {
    samples.iter().flat_map(|s| s.to_le_bytes()).collect()
}

fn median(values: &[f64]) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN)
}

fn verdict(met: bool) -> &'static str {
    if met { "met" } else { "missed" }
}
