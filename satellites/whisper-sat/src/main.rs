//! Command-line entry point of the Whisper ASR satellite: `convert`, `transcribe`, `run` and `wer`.

mod cli;

use clap::Parser;

/// Logging when `RUST_LOG` is not set. whisper.cpp's own messages are left out: every speculative decode that the
/// voice's return aborts makes it log "failed to encode" or "failed to decode" as an error, which is the expected
/// end of that decode, and real failures reach the log as the satellite's own `transcription failed` errors.
/// `RUST_LOG=info,whisper_rs=debug` shows them.
const DEFAULT_LOG: &str = "info,whisper_rs=warn,whisper_rs::whisper_logging_hook=off";

fn main() -> anyhow::Result<()> {
    let mut filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(DEFAULT_LOG));
    // A filter that does not name whisper_rs (`RUST_LOG=warn`, as the benches set it) still leaves whisper.cpp's
    // own messages out: an aborted speculative decode is normal operation, not an error to show.
    if !std::env::var("RUST_LOG").is_ok_and(|v| v.contains("whisper_rs"))
        && let Ok(quiet) = "whisper_rs::whisper_logging_hook=off".parse()
    {
        filter = filter.add_directive(quiet);
    }
    // Plain lines unless stderr is a terminal, as every process of the workspace logs.
    flow::log::init(filter);
    cli::Command::parse().run()
}
