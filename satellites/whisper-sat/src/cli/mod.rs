//! The `whisper-sat` subcommands.

mod convert;
mod progress;
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
}

impl Command {
    /// Runs the chosen subcommand.
    pub fn run(self) -> anyhow::Result<()> {
        match self.action {
            Action::Convert(a) => convert::run(a),
            Action::Transcribe(a) => transcribe::run(a),
        }
    }
}
