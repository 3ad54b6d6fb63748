//! `flowctl record`: records hub channels into an MCAP file until Ctrl-C, SIGTERM or `--duration`, then writes
//! the file's summary and prints what it holds.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use flow::Client;
use flow_record::{RecordOptions, Recorder, Selection};

/// Messages each of the recorder's subscriptions may hold before it drops the oldest: 5 s of 20 ms audio, 17 s of
/// 15 fps video, while bounding a recording of every channel to some tens of MB even if the disk stalls.
pub const SUBSCRIPTION_QUEUE: usize = 256;

/// `flowctl record` options.
#[derive(Debug, clap::Args)]
pub struct RecordArgs {
    /// The MCAP file to write (replaced if it exists).
    #[arg(short = 'o', long)]
    output: PathBuf,
    /// Record only channels matching this glob (repeatable); by default every stream channel, including those
    /// created while recording.
    #[arg(long = "channels")]
    channels: Vec<String>,
    /// Stop after this long (e.g. 30s, 5m); by default at Ctrl-C or SIGTERM.
    #[arg(long, value_parser = crate::duration::parse)]
    duration: Option<Duration>,
}

pub async fn record(client: &Client, args: RecordArgs) -> anyhow::Result<()> {
    let opts = RecordOptions {
        channels: Selection::new(&args.channels)?,
        ..RecordOptions::default()
    };
    let recorder = Recorder::start(client.clone(), &args.output, opts)
        .await
        .with_context(|| format!("recording to {}", args.output.display()))?;
    eprintln!("recording to {} (Ctrl-C stops)", args.output.display());
    let mut connected = client.connection_state();
    let lost = tokio::select! {
        r = crate::signals::until_stopped(args.duration) => { r?; false }
        // A hub that goes away ends the recording too, with its file finished.
        _ = connected.wait_for(|up| !*up) => true,
    };
    let report = recorder.stop().await?;
    if lost {
        eprintln!("flowctl: the hub closed the connection; the recording ends here");
    }
    println!(
        "recorded {} messages on {} channels into {}",
        report.messages(),
        report.channels.len(),
        args.output.display()
    );
    for (name, c) in &report.channels {
        println!(
            "  {name:<32} {:>8} msgs {:>12} bytes {:>6} missing {:>6} dropped",
            c.written.messages, c.written.bytes, c.written.missing, c.dropped
        );
    }
    if report.annotations > 0 {
        println!("  {} image annotations", report.annotations);
    }
    Ok(())
}
