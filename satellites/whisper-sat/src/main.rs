//! Command-line entry point of the Whisper ASR satellite: `convert`, `transcribe`, `run` and `bench`.

mod cli;

use clap::Parser;

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info,whisper_rs=warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    cli::Command::parse().run()
}
