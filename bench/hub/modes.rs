//! The three ways a rig is driven: flat out under a flow-control window
//! (lossless throughput), flat out open loop (what a careless producer gets,
//! with drops), and at a fixed rate (latency as the avatar sees it).

use std::time::{Duration, Instant};

use anyhow::bail;

use crate::rig::Rig;

/// How long each mode runs.
#[derive(Debug, Clone, Copy)]
pub struct Timing {
    /// Sending before the measurement window opens.
    pub warmup: Duration,
    /// The measurement window of the flat-out modes.
    pub window: Duration,
    /// Duration of a fixed-rate run.
    pub rate_run: Duration,
    /// Messages allowed on their way to the slowest subscriber in the windowed mode.
    pub window_msgs: u64,
    /// No delivery for this long means the system under test is stuck.
    pub stall: Duration,
}

/// Latency percentiles in milliseconds.
#[derive(Debug, Clone, Copy, Default)]
pub struct Latency {
    pub p50_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
    pub samples: usize,
}

impl Latency {
    fn from_sorted(ns: &[u64]) -> Latency {
        let pick = |q: f64| -> f64 {
            if ns.is_empty() {
                return f64::NAN;
            }
            // Nearest-rank percentile.
            let rank = ((q * ns.len() as f64).ceil() as usize).clamp(1, ns.len());
            ns[rank - 1] as f64 / 1e6
        };
        Latency {
            p50_ms: pick(0.50),
            p99_ms: pick(0.99),
            max_ms: pick(1.0),
            samples: ns.len(),
        }
    }
}

/// Result of a flat-out run.
#[derive(Debug, Clone, Copy, Default)]
pub struct FlatOut {
    /// Messages received in the window, summed over subscribers, per second.
    pub delivered_per_s: f64,
    /// Messages published in the window per second.
    pub sent_per_s: f64,
    pub latency: Latency,
    /// Share of (message, subscriber) deliveries that never happened, over the whole run.
    pub drop_ratio: f64,
    /// The part of `drop_ratio` the server reports having dropped itself (hub only).
    pub server_drop_ratio: Option<f64>,
    /// Subscribers the server disconnected.
    pub disconnected: u64,
    /// Server CPU time per delivered message in the window, in microseconds.
    pub server_cpu_us: Option<f64>,
    /// This benchmark process's CPU time per delivered message in the window
    /// (publisher and subscribers: the clients' side), in microseconds.
    pub client_cpu_us: Option<f64>,
    /// Deliveries that arrived reordered, duplicated or unreadable (should be 0).
    pub damaged: u64,
}

/// The run with the median delivery rate (the lower middle one of an even
/// count); the default when there are none.
pub fn median_by_rate(mut runs: Vec<FlatOut>) -> FlatOut {
    runs.sort_by(|a, b| a.delivered_per_s.total_cmp(&b.delivered_per_s));
    match runs.len() {
        0 => FlatOut::default(),
        n => runs[(n - 1) / 2],
    }
}

/// Result of a fixed-rate run.
#[derive(Debug, Clone, Copy, Default)]
pub struct FixedRate {
    pub latency: Latency,
    pub drop_ratio: f64,
}

/// Flat out, but never more than `window_msgs` ahead of the slowest
/// subscriber: the highest rate at which every subscriber gets every message.
pub async fn windowed(rig: &mut Rig, template: &[u8], t: Timing) -> anyhow::Result<FlatOut> {
    flat_out(rig, template, t, Some(t.window_msgs)).await
}

/// Flat out with no end-to-end flow control: the publisher goes as fast as
/// the system lets it, and whatever the subscribers cannot take is dropped
/// (hub), buffered (Redis, up to its output-buffer limit) or pushed back (TCP).
pub async fn open_loop(rig: &mut Rig, template: &[u8], t: Timing) -> anyhow::Result<FlatOut> {
    flat_out(rig, template, t, None).await
}

/// Where the measurement window of a flat-out run opened.
#[derive(Debug, Clone, Copy)]
struct WindowStart {
    at: Instant,
    /// Deliveries counted so far.
    received: u64,
    /// Messages published so far.
    sent: u64,
    server_cpu_ns: Option<u64>,
    own_cpu_ns: Option<u64>,
}

/// CPU time used so far by this benchmark process (publisher and subscribers).
fn own_cpu_ns() -> Option<u64> {
    crate::servers::cpu_ns(std::process::id())
}

async fn flat_out(
    rig: &mut Rig,
    template: &[u8],
    t: Timing,
    window: Option<u64>,
) -> anyhow::Result<FlatOut> {
    let tally = rig.tally.clone();
    let subscribers = tally.subscribers() as u64;
    let start = Instant::now();
    let mut seq = 0u64;
    let mut opened: Option<WindowStart> = None;
    let closed = loop {
        if let Some(w) = window
            && !tally.window_open(seq, w)
        {
            rig.flush().await?;
            if !tally.wait_window(seq, w, t.stall).await {
                bail!(
                    "no delivery for {:?}: the system under test stalled",
                    t.stall
                );
            }
        }
        seq += 1;
        rig.send(template, seq).await?;
        let elapsed = start.elapsed();
        match opened {
            None if elapsed >= t.warmup => {
                tally.set_recording(true);
                opened = Some(WindowStart {
                    at: Instant::now(),
                    received: tally.totals().received,
                    sent: seq,
                    server_cpu_ns: rig.server_cpu_ns(),
                    own_cpu_ns: own_cpu_ns(),
                });
            }
            Some(w) if w.at.elapsed() >= t.window => {
                tally.set_recording(false);
                let secs = w.at.elapsed().as_secs_f64();
                let got = tally.totals().received - w.received;
                let per_delivery = |a: Option<u64>, b: Option<u64>| {
                    a.zip(b)
                        .map(|(a, b)| b.saturating_sub(a) as f64 / 1e3 / got.max(1) as f64)
                };
                break (
                    got as f64 / secs,
                    (seq - w.sent) as f64 / secs,
                    per_delivery(w.server_cpu_ns, rig.server_cpu_ns()),
                    per_delivery(w.own_cpu_ns, own_cpu_ns()),
                );
            }
            _ => {}
        }
    };
    rig.flush().await?;
    settle(rig, seq, t.stall).await;
    let server_dropped = rig.server_dropped().await;
    let totals = tally.totals();
    Ok(FlatOut {
        delivered_per_s: closed.0,
        sent_per_s: closed.1,
        server_cpu_us: closed.2,
        client_cpu_us: closed.3,
        latency: Latency::from_sorted(&tally.latencies()),
        drop_ratio: tally.missing(seq) as f64 / (seq * subscribers).max(1) as f64,
        server_drop_ratio: server_dropped.map(|d| d as f64 / (seq * subscribers).max(1) as f64),
        disconnected: totals.ended,
        damaged: totals.out_of_order + totals.corrupt,
    })
}

/// Publishes at `hz` for the configured duration; every delivery after a
/// short warm-up is a latency sample.
pub async fn fixed_rate(
    rig: &mut Rig,
    template: &[u8],
    hz: f64,
    t: Timing,
) -> anyhow::Result<FixedRate> {
    const WARMUP_MSGS: u64 = 3;
    let tally = rig.tally.clone();
    let subscribers = tally.subscribers() as u64;
    let mut ticks = tokio::time::interval(Duration::from_secs_f64(1.0 / hz));
    ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let total = WARMUP_MSGS + (t.rate_run.as_secs_f64() * hz).round() as u64;
    for seq in 1..=total {
        ticks.tick().await;
        if seq == WARMUP_MSGS + 1 {
            // The first messages pay for cold caches and lazily grown buffers.
            if !tally.wait_window(WARMUP_MSGS, 1, t.stall).await {
                bail!("warm-up messages never arrived");
            }
            tally.set_recording(true);
        }
        rig.send(template, seq).await?;
        rig.flush().await?;
    }
    settle(rig, total, t.stall).await;
    tally.set_recording(false);
    Ok(FixedRate {
        latency: Latency::from_sorted(&tally.latencies()),
        drop_ratio: tally.missing(total) as f64 / (total * subscribers).max(1) as f64,
    })
}

/// Waits until every subscriber has seen message `last`, or until deliveries
/// stop for a while (the rest was dropped), so losses are counted fully.
async fn settle(rig: &Rig, last: u64, stall: Duration) {
    let tally = &rig.tally;
    let quiet = Duration::from_millis(300).min(stall);
    let mut before = tally.totals().received;
    loop {
        if tally.wait_window(last, 1, quiet).await {
            return;
        }
        let now = tally.totals().received;
        if now == before {
            return;
        }
        before = now;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_percentiles() {
        let ns: Vec<u64> = (1..=100).map(|i| i * 1_000_000).collect();
        let l = Latency::from_sorted(&ns);
        assert_eq!(l.p50_ms, 50.0);
        assert_eq!(l.p99_ms, 99.0);
        assert_eq!(l.max_ms, 100.0);
        assert!(Latency::from_sorted(&[]).p99_ms.is_nan());
    }
}
