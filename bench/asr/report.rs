//! The full report of the ASR benchmark: real-time factor, end-of-speech latency and peak RSS, side by side with
//! faster-whisper (int8 and float32) on the same CTranslate2 model, in the same run; then the fleets
//! (`crate::fleets`) and the word error rates (`crate::wer`).
//!
//! The latency follows the satellite's pipeline: an utterance that paused with the audio it ended with is decoded
//! from the pause on (speculation), so its transcript is ready at the later of the end (the hangover) and the pause
//! plus the inference; one without such a pause (cut at the maximum length) is decoded from the end. The figure
//! without speculation (`--no-speculate`: end plus inference) is printed beside it. It assumes the transcriber is
//! free at the pause; in the satellite an aborted speculative decode of an earlier pause in the same utterance may
//! still be finishing its encoder then (whisper.cpp cannot stop the encoder), which this figure does not count.

use std::path::Path;

use anyhow::Context;
use whisper_sat::segmenter::RATE;
use whisper_sat::transcriber::{AudioContext, Transcriber, TranscriberConfig};

use crate::args::Args;
use crate::clips::{ClipAudio, median, peak_rss_mb, percentile, segment};
use crate::faster_whisper::{FasterWhisper, faster_whisper};
use crate::fleets::fleets;
use crate::wer::{ModelUnderTest, Suite, wer_bench};

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

/// Measures everything and prints the report, writing it to `--write` when given.
pub fn full(
    args: Args,
    model: &Path,
    ct2: &Path,
    python: &Path,
    clips: &[ClipAudio],
    models: &[ModelUnderTest],
) -> anyhow::Result<()> {
    let cfg = TranscriberConfig {
        threads: args.threads,
        ..TranscriberConfig::default()
    };
    let mut report = Vec::new();
    let mut line = |s: String| {
        println!("{s}");
        report.push(s);
    };

    let mut fit = Transcriber::load(model, cfg.clone())?;
    let ours = time_clips(&mut fit, clips, args.runs)?;

    // End of speech -> final transcript: the hangover the segmenter must wait, and the inference of the utterance,
    // which speculation starts at the pause instead of the end.
    let mut latencies_short = Vec::new();
    let mut plain_short = Vec::new();
    let mut per_clip_latency = Vec::new();
    let mut utterances = Vec::new();
    for c in clips {
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
        model,
        TranscriberConfig {
            audio_context: AudioContext::Full,
            ..cfg.clone()
        },
    )?;
    let ours_full = time_clips(&mut full, clips, args.runs)?;
    drop(full);

    let fw = FasterWhisper {
        python,
        ct2,
        language: "en",
        compute_types: &["int8", "float32"],
        beams: &[1],
    };
    let (baselines, fw_rss) = faster_whisper(&fw, args.threads, args.runs, clips)?;
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
    let fleets = fleets(model, clips, &utterances, args.runs)?;
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
    let (table, summary) = wer_bench(models, python, args.threads, &Suite::all(clips)?)?;
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
