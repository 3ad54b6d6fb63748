//! `flowctl top`: a live table of the hub's channels (rates, subscribers, drops), redrawn every second with plain
//! ANSI escapes; `--once` prints one table and exits.

use std::io::Write;
use std::time::Duration;

use flow::{ChannelInfo, Client};

/// `flowctl top` options.
#[derive(Debug, clap::Args)]
pub struct TopArgs {
    /// Print one table and exit (no screen redraw).
    #[arg(long)]
    once: bool,
    /// Seconds between refreshes.
    #[arg(long, default_value_t = 1.0)]
    interval: f64,
}

/// Clears the screen and moves the cursor home.
const REDRAW: &str = "\x1b[2J\x1b[H";

pub async fn top(client: &Client, args: TopArgs) -> anyhow::Result<()> {
    if !(args.interval >= 0.1 && args.interval <= 3600.0) {
        anyhow::bail!("--interval must be between 0.1 and 3600 seconds");
    }
    let mut tick = tokio::time::interval(Duration::from_secs_f64(args.interval));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    // An interval's first tick is immediate: take it now, so that the second table comes a period after the first.
    tick.tick().await;
    loop {
        let mut list = client.channels().await?;
        list.sort_by(|a, b| a.name.cmp(&b.name));
        let table = table(&list);
        let mut out = std::io::stdout().lock();
        let shown = if args.once {
            write!(out, "{table}")
        } else {
            write!(out, "{REDRAW}{table}")
        };
        // A closed pipe ends the command quietly.
        if shown.and_then(|()| out.flush()).is_err() || args.once {
            return Ok(());
        }
        drop(out);
        tokio::select! {
            _ = tick.tick() => {}
            r = tokio::signal::ctrl_c() => return Ok(r?),
        }
    }
}

/// The table: one row per channel, the hub's own per-second rates.
fn table(list: &[ChannelInfo]) -> String {
    let mut s = format!(
        "{:<32} {:<7} {:<24} {:>9} {:>11} {:>5} {:>8}\n",
        "NAME", "KIND", "OWNER", "MSG/S", "BYTES/S", "SUBS", "DROPS"
    );
    for c in list {
        s.push_str(&format!(
            "{:<32} {:<7} {:<24} {:>9.1} {:>11} {:>5} {:>8}\n",
            c.name,
            c.kind.as_str(),
            c.owner,
            c.stats.msgs_per_s,
            human_bytes(f64::from(c.stats.bytes_per_s)),
            c.stats.subscribers,
            c.stats.dropped
        ));
    }
    s
}

/// A byte rate with a binary prefix (`1.5M`).
fn human_bytes(b: f64) -> String {
    const UNITS: [&str; 4] = ["", "K", "M", "G"];
    let mut value = b;
    let mut unit = 0;
    while value >= 1024.0 && unit < UNITS.len() - 1 {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{value:.0}")
    } else {
        format!("{value:.1}{}", UNITS[unit])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_rates_read_with_binary_prefixes() {
        assert_eq!(human_bytes(512.0), "512");
        assert_eq!(human_bytes(1536.0), "1.5K");
        assert_eq!(human_bytes(3.0 * 1024.0 * 1024.0), "3.0M");
    }
}
