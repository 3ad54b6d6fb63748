//! `flowctl replay`: publishes an MCAP recording again with its recorded timing, then prints how late the
//! messages were.

use std::path::PathBuf;

use anyhow::{Context, bail};
use flow::Client;
use flow_record::{Remap, ReplayOptions, Replayer, Selection};

/// `flowctl replay` options.
#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// The MCAP file (one `flowctl record` wrote; a file cut short replays up to its cut).
    file: PathBuf,
    /// Replay speed: 2 is twice as fast.
    #[arg(long, default_value_t = 1.0)]
    speed: f64,
    /// Start again at the end, until Ctrl-C.
    #[arg(long = "loop")]
    looping: bool,
    /// Replay only recorded channels matching this glob (repeatable).
    #[arg(long = "channels")]
    channels: Vec<String>,
    /// Publish the recorded channel OLD as NEW (repeatable).
    #[arg(long = "remap")]
    remap: Vec<String>,
    /// Wait until every replayed channel has a subscriber before starting.
    #[arg(long)]
    wait_subscriber: bool,
}

pub async fn replay(client: &Client, args: ReplayArgs) -> anyhow::Result<()> {
    if !(args.speed > 0.0 && args.speed <= 1000.0) {
        bail!("--speed must be above 0 and at most 1000");
    }
    let opts = ReplayOptions {
        speed: args.speed,
        looping: args.looping,
        channels: Selection::new(&args.channels)?,
        remap: Remap::new(&args.remap)?,
        wait_subscribers: args.wait_subscriber,
        ..ReplayOptions::default()
    };
    let replayer = Replayer::new(client.clone(), opts);
    let stop = async {
        // A failure to watch for signals only means the replay cannot be interrupted early.
        let _ = crate::signals::until_stopped(None).await;
    };
    let report = replayer
        .run(&args.file, stop)
        .await
        .with_context(|| format!("replaying {}", args.file.display()))?;
    for (name, why) in &report.skipped {
        eprintln!("flowctl: not replaying {name}: {why}");
    }
    if let Some(cut) = &report.truncated {
        eprintln!("flowctl: the recording is cut short ({cut}); replayed up to the cut");
    }
    let total: u64 = report.published.values().sum();
    println!(
        "replayed {total} messages on {} channels ({} passes, {} undecodable)",
        report.published.len(),
        report.passes,
        report.undecodable
    );
    for (name, n) in &report.published {
        println!("  {name:<32} {n:>8} msgs");
    }
    println!("{}", report.lateness);
    Ok(())
}
