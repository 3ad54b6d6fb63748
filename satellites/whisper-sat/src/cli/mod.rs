//! The `whisper-sat` subcommands.

mod bench;
mod bench_clips;
mod convert;
mod faster_whisper;
mod fleet;
mod fleet_bench;
mod progress;
mod recognition;
mod run;
mod satellite;
mod transcribe;
mod wer_bench;

use clap::{Parser, Subcommand};

/// Whisper ASR satellite for the flow hub.
#[derive(Debug, Parser)]
#[command(name = "whisper-sat", version, about)]
pub struct Command {
    #[command(subcommand)]
    action: Action,
}

#[derive(Debug, Subcommand)]
enum Action {
    /// Convert a CTranslate2 Whisper model directory to a ggml file for whisper.cpp.
    Convert(convert::Args),
    /// Transcribe a WAV file offline (VAD segmentation + Whisper), printing one line per utterance.
    Transcribe(transcribe::Args),
    /// Run as a satellite: segment Agent.audio, claim and transcribe utterances, publish Agent.transcript.
    Run(run::Args),
    /// Benchmark against faster-whisper: RTF, end-of-speech latency, 1, 2 and 3 satellites, peak RSS.
    Bench(bench::Args),
    /// One satellite process of `bench`'s fleets (decodes the jobs it is handed on stdin).
    #[command(hide = true)]
    BenchWorker(fleet::WorkerArgs),
    /// Print the word error rate of a hypothesis against a reference (case and punctuation ignored).
    Wer {
        /// Reference transcript.
        reference: String,
        /// Recognised text.
        hypothesis: String,
    },
}

impl Command {
    /// Runs the chosen subcommand.
    pub fn run(self) -> anyhow::Result<()> {
        match self.action {
            Action::Convert(a) => convert::run(a),
            Action::Transcribe(a) => transcribe::run(a),
            Action::Run(a) => run::run(a),
            Action::Bench(a) => bench::run(a),
            Action::BenchWorker(a) => fleet::worker(a),
            Action::Wer {
                reference,
                hypothesis,
            } => {
                let (errors, words) = whisper_sat::wer::word_errors(&reference, &hypothesis);
                println!(
                    "{:.4} {errors} {words}",
                    errors as f64 / words.max(1) as f64
                );
                Ok(())
            }
        }
    }
}
