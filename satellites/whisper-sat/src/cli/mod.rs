//! The `whisper-sat` subcommands.
//!
//! Argument parsing only: each subcommand calls into the library (the satellite's runtime is
//! `whisper_sat::satellite`). The ASR benchmark is a binary of its own, `asr-bench` in `bench/asr`.

mod convert;
mod progress;
mod run;
mod transcribe;

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
