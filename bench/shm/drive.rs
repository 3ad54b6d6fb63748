//! The two ways a rig is driven: flat out under a window (the publisher never more than a few messages ahead of
//! the slowest subscriber, so every message reaches every subscriber and the CPU per delivery is not diluted by
//! drops), and at a fixed rate for latency.

use std::time::{Duration, Instant};

use anyhow::bail;

use crate::hub;
use crate::rig::Rig;

/// How long each part runs.
#[derive(Debug, Clone, Copy)]
pub struct Timing {
    /// Sending before the measurement window opens.
    pub warmup: Duration,
    /// The flat-out measurement window.
    pub window: Duration,
    /// Messages allowed on their way to the slowest subscriber.
    pub window_msgs: u64,
    /// A fixed-rate run's length.
    pub rate_run: Duration,
    /// No delivery for this long means the mode under test is stuck.
    pub stall: Duration,
}

/// Latency percentiles in milliseconds (nearest rank).
#[derive(Debug, Clone, Copy, Default)]
pub struct Latency {
    pub p50_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
    pub samples: usize,
}

impl Latency {
    pub fn from_sorted(ns: &[u64]) -> Latency {
        let pick = |q: f64| -> f64 {
            if ns.is_empty() {
                return f64::NAN;
            }
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

/// A flat-out cell's figures.
#[derive(Debug, Clone, Copy, Default)]
pub struct Flat {
    /// Messages received in the window, summed over subscribers, per second.
    pub deliveries_per_s: f64,
    /// CPU time per delivery in the window, µs: this process (publisher and subscribers) plus the hub's.
    pub cpu_us: f64,
    /// The hub's part of `cpu_us` (zero where there is no hub).
    pub hub_cpu_us: f64,
    /// Deliveries that never happened, or came damaged or out of order, over the whole run (should be 0).
    pub missing: u64,
    pub damaged: u64,
}

/// CPU time of this process so far (every thread, ended ones included), in ns.
fn own_cpu_ns() -> anyhow::Result<u64> {
    Ok(cpu_time::ProcessTime::try_now()?.as_duration().as_nanos() as u64)
}

/// Where the measurement window opened.
#[derive(Debug, Clone, Copy)]
struct Opened {
    at: Instant,
    received: u64,
    own_ns: u64,
    hub_ns: u64,
}

/// Publishes `template` as fast as the window lets it, for the warm-up and then the measurement window.
pub async fn flat_out(rig: &mut Rig, template: &[u8], t: Timing) -> anyhow::Result<Flat> {
    let tally = rig.tally.clone();
    let hub_ns = |pid: Option<u32>| pid.and_then(hub::cpu_ns).unwrap_or(0);
    let start = Instant::now();
    let mut seq = 0u64;
    let mut opened: Option<Opened> = None;
    let mut flat = loop {
        if !tally.window_open(seq, t.window_msgs) {
            rig.flush().await?;
            if !tally.wait_window(seq, t.window_msgs, t.stall).await {
                bail!("no delivery for {:?}: the mode under test stalled", t.stall);
            }
        }
        seq += 1;
        rig.send(template, seq).await?;
        match opened {
            None if start.elapsed() >= t.warmup => {
                opened = Some(Opened {
                    at: Instant::now(),
                    received: tally.totals().received,
                    own_ns: own_cpu_ns()?,
                    hub_ns: hub_ns(rig.hub_pid),
                });
            }
            Some(o) if o.at.elapsed() >= t.window => {
                let secs = o.at.elapsed().as_secs_f64();
                let got = tally.totals().received - o.received;
                let own = own_cpu_ns()?.saturating_sub(o.own_ns);
                let hub = hub_ns(rig.hub_pid).saturating_sub(o.hub_ns);
                let per = |ns: u64| ns as f64 / 1e3 / got.max(1) as f64;
                break Flat {
                    deliveries_per_s: got as f64 / secs,
                    cpu_us: per(own + hub),
                    hub_cpu_us: per(hub),
                    ..Flat::default()
                };
            }
            _ => {}
        }
    };
    rig.flush().await?;
    settle(rig, seq, t.stall).await;
    let totals = tally.totals();
    flat.missing = (seq * tally.subscribers() as u64).saturating_sub(totals.received);
    flat.damaged = totals.damaged;
    Ok(flat)
}

/// Publishes at `hz` for the run's length; every delivery after three warm-up messages is a latency sample.
pub async fn fixed_rate(
    rig: &mut Rig,
    template: &[u8],
    hz: f64,
    t: Timing,
) -> anyhow::Result<Latency> {
    const WARMUP_MSGS: u64 = 3;
    let tally = rig.tally.clone();
    let mut ticks = tokio::time::interval(Duration::from_secs_f64(1.0 / hz));
    ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let total = WARMUP_MSGS + (t.rate_run.as_secs_f64() * hz).round() as u64;
    for seq in 1..=total {
        ticks.tick().await;
        if seq == WARMUP_MSGS + 1 {
            // The first messages pay for cold caches, lazily mapped segments and grown buffers.
            if !tally.wait_window(WARMUP_MSGS, 1, t.stall).await {
                bail!("the warm-up messages never arrived");
            }
            tally.set_recording(true);
        }
        rig.send(template, seq).await?;
        rig.flush().await?;
    }
    settle(rig, total, t.stall).await;
    tally.set_recording(false);
    Ok(Latency::from_sorted(&tally.latencies()))
}

/// Waits until every subscriber has seen message `last`, or until deliveries stop for a while.
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
