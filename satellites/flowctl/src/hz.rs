//! `flowctl hz`: the rate of a channel and the spread of its messages' inter-arrival times over a window,
//! printed every second (as `ros2 topic hz` does); `--count N` stops after N messages.

use std::collections::VecDeque;
use std::io::Write;
use std::time::Duration;

use anyhow::bail;
use flow::Client;
use tokio::time::Instant;

/// `flowctl hz` options.
#[derive(Debug, clap::Args)]
pub struct HzArgs {
    name: String,
    /// Inter-arrival times the statistics cover (the newest ones).
    #[arg(long, default_value_t = 10_000)]
    window: usize,
    /// Stop after this many messages, printing the statistics once more.
    #[arg(long)]
    count: Option<u64>,
}

/// Inter-arrival times of the last `window` messages, on the local monotonic clock (arrival, as `ros2 topic hz`
/// measures it).
#[derive(Debug)]
struct Window {
    gaps: VecDeque<f64>,
    capacity: usize,
    last: Option<Instant>,
}

/// What a window says.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Stats {
    rate: f64,
    min: f64,
    max: f64,
    mean: f64,
    std: f64,
    n: usize,
}

impl Window {
    fn new(capacity: usize) -> Window {
        Window {
            gaps: VecDeque::with_capacity(capacity.min(65_536)),
            capacity,
            last: None,
        }
    }

    fn arrived(&mut self, at: Instant) {
        if let Some(last) = self.last {
            if self.gaps.len() == self.capacity {
                self.gaps.pop_front();
            }
            self.gaps
                .push_back(at.saturating_duration_since(last).as_secs_f64());
        }
        self.last = Some(at);
    }

    fn stats(&self) -> Option<Stats> {
        stats(self.gaps.iter().copied())
    }
}

fn stats(gaps: impl Iterator<Item = f64> + Clone) -> Option<Stats> {
    let n = gaps.clone().count();
    if n == 0 {
        return None;
    }
    let mean = gaps.clone().sum::<f64>() / n as f64;
    let var = gaps.clone().map(|g| (g - mean).powi(2)).sum::<f64>() / n as f64;
    let min = gaps.clone().fold(f64::INFINITY, f64::min);
    let max = gaps.fold(0.0, f64::max);
    Some(Stats {
        rate: if mean > 0.0 {
            1.0 / mean
        } else {
            f64::INFINITY
        },
        min,
        max,
        mean,
        std: var.sqrt(),
        n,
    })
}

impl std::fmt::Display for Stats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "average rate: {:.3}\n\tmin: {:.6}s max: {:.6}s mean: {:.6}s std dev: {:.6}s window: {}",
            self.rate, self.min, self.max, self.mean, self.std, self.n
        )
    }
}

pub async fn hz(client: &Client, args: HzArgs) -> anyhow::Result<()> {
    if args.window < 1 {
        bail!("--window must be at least 1");
    }
    let sub = client.subscribe(&args.name).await?;
    eprintln!("subscribed to [{}]", args.name);
    let mut window = Window::new(args.window);
    let mut seen = 0u64;
    let mut report = tokio::time::interval(Duration::from_secs(1));
    report.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut out = std::io::stdout();
    let mut changed = false;
    while args.count.is_none_or(|c| seen < c) {
        tokio::select! {
            msg = sub.recv() => {
                if msg.is_none() {
                    bail!("connection closed");
                }
                window.arrived(Instant::now());
                seen += 1;
                changed = true;
            }
            _ = report.tick() => {
                let line = match window.stats() {
                    Some(s) if changed => s.to_string(),
                    _ => "no new messages".to_string(),
                };
                changed = false;
                if writeln!(out, "{line}").and_then(|()| out.flush()).is_err() {
                    return Ok(());
                }
            }
            r = tokio::signal::ctrl_c() => return Ok(r?),
        }
    }
    match window.stats() {
        Some(s) => println!("{s}"),
        None => println!("no inter-arrival times: fewer than two messages"),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statistics_cover_the_gaps_between_messages() {
        let s = stats([0.1, 0.1, 0.1, 0.1].into_iter()).expect("gaps");
        assert!((s.rate - 10.0).abs() < 1e-9);
        assert!(s.std.abs() < 1e-12);
        let s = stats([0.1, 0.3].into_iter()).expect("gaps");
        assert!((s.mean - 0.2).abs() < 1e-12 && (s.std - 0.1).abs() < 1e-12);
        assert_eq!((s.min, s.max, s.n), (0.1, 0.3, 2));
        assert!(stats(std::iter::empty()).is_none());
    }

    #[test]
    fn a_window_keeps_only_its_newest_gaps() {
        let t0 = Instant::now();
        let mut w = Window::new(2);
        for ms in [0, 100, 300, 600] {
            w.arrived(t0 + Duration::from_millis(ms));
        }
        let s = w.stats().expect("gaps");
        assert_eq!(s.n, 2);
        assert!((s.min - 0.2).abs() < 1e-9 && (s.max - 0.3).abs() < 1e-9);
    }
}
