//! The faster-whisper baseline of the ASR benchmarks: `bench/asr/faster_whisper_bench.py` run on the same
//! CTranslate2 weights and clips, its per-clip times and texts read back.

use std::path::Path;
use std::process::Command;

use anyhow::Context;

use crate::clips::{ClipAudio, median};

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
    // The script lives beside this benchmark's sources, wherever the build runs from.
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("asr/faster_whisper_bench.py");
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
