//! The recording-overhead phases: the hub's CPU per delivery to four JPEG subscribers, without and with a
//! recorder.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use agent_bench::{SECONDS_PER_TICK, cpu_ticks};
use agent_tests::recording::{self, RecordProcess};
use agent_tests::{Agent, DataDir, fixture};
use anyhow::Context;
use bytes::Bytes;
use tokio::time::Instant;

const SUBSCRIBERS: usize = 4;
const CHANNEL: &str = "Bench.video";

/// One phase's counts.
#[derive(Debug, Clone, Copy)]
pub struct Phase {
    pub recorder: bool,
    pub frames: u64,
    pub deliveries: u64,
    pub ticks: u64,
}

impl Phase {
    pub fn us_per_delivery(&self) -> f64 {
        self.ticks as f64 * SECONDS_PER_TICK * 1e6 / self.deliveries.max(1) as f64
    }

    fn us_per_frame(&self) -> f64 {
        self.ticks as f64 * SECONDS_PER_TICK * 1e6 / self.frames.max(1) as f64
    }
}

/// Every phase, in the order run.
#[derive(Debug, Clone, Default)]
pub struct Cost {
    pub phases: Vec<Phase>,
    pub with_us: f64,
    pub without_us: f64,
}

impl Cost {
    pub fn ratio(&self) -> f64 {
        self.with_us / self.without_us
    }

    /// With / without per published frame (the recorder's delivery included in the cost).
    pub fn frame_ratio(&self) -> f64 {
        let per = |rec: bool| {
            let ps: Vec<_> = self.phases.iter().filter(|p| p.recorder == rec).collect();
            ps.iter().map(|p| p.us_per_frame()).sum::<f64>() / ps.len().max(1) as f64
        };
        per(true) / per(false)
    }
}

pub async fn measure(window: Duration, rounds: u32, fps: u32) -> anyhow::Result<Cost> {
    let dir = DataDir::new()?;
    let hub = Agent::hub_with_config(&dir, "[hub]\nsubscriber_queue = 1024\n").await?;
    let pid = hub.pid().context("the hub has exited")?;
    let jpeg = Bytes::from(std::fs::read(fixture(
        "faces/derived/fr_two_people_640x360.jpg",
    )?)?);
    let feeder = hub.client("bench-camera").await?;
    let publisher = feeder
        .publisher(CHANNEL, r#"{"format":"jpeg","width":640,"height":360}"#)
        .await?;
    let delivered = Arc::new(AtomicU64::new(0));
    let mut clients = Vec::new();
    for i in 0..SUBSCRIBERS {
        let client = hub.client(&format!("bench-sub-{i}")).await?;
        let sub = client.subscribe(CHANNEL).await?;
        let count = delivered.clone();
        sub.spawn_callback(move |_| {
            count.fetch_add(1, Ordering::Relaxed);
        });
        clients.push(client);
    }
    agent_tests::until_subscribed(&publisher).await?;
    let work = tempfile::tempdir()?;
    let mut cost = Cost::default();
    // Warm-up: buffers, the first connections' allocations.
    publish(&publisher, &jpeg, fps, Duration::from_secs(1)).await?;
    for round in 0..rounds {
        for recorder in [false, true] {
            let rec = if recorder {
                let path = work.path().join(format!("round{round}.mcap"));
                Some(RecordProcess::start(&hub, &path, &["--channels", CHANNEL]).await?)
            } else {
                None
            };
            let before = delivered.load(Ordering::Relaxed);
            let t0 = cpu_ticks(pid)?;
            let frames = publish(&publisher, &jpeg, fps, window).await?;
            // Let the last frames reach every subscriber before the CPU is read.
            let expected = before + frames * SUBSCRIBERS as u64;
            let settle = Instant::now() + Duration::from_secs(5);
            while delivered.load(Ordering::Relaxed) < expected && Instant::now() < settle {
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
            let ticks = cpu_ticks(pid)? - t0;
            let mut deliveries = delivered.load(Ordering::Relaxed) - before;
            if let Some(rec) = rec {
                let path = rec.path.clone();
                rec.interrupt().await?;
                let recorded = recording::read(&path)?.on(CHANNEL).len() as u64;
                deliveries += recorded;
            }
            let phase = Phase {
                recorder,
                frames,
                deliveries,
                ticks,
            };
            println!(
                "round {} {:<14} frames {:>5} deliveries {:>6} hub cpu {:>4} ticks = {:>6.1} us/delivery",
                round + 1,
                if recorder { "with recorder" } else { "without" },
                frames,
                deliveries,
                ticks,
                phase.us_per_delivery()
            );
            cost.phases.push(phase);
        }
    }
    let mean = |rec: bool| {
        let ps: Vec<_> = cost.phases.iter().filter(|p| p.recorder == rec).collect();
        ps.iter().map(|p| p.us_per_delivery()).sum::<f64>() / ps.len().max(1) as f64
    };
    cost.with_us = mean(true);
    cost.without_us = mean(false);
    drop(clients);
    Ok(cost)
}

/// Publishes the frame at `fps` on an absolute schedule for `window`; returns the frames sent.
async fn publish(
    publisher: &flow::Publisher,
    jpeg: &Bytes,
    fps: u32,
    window: Duration,
) -> anyhow::Result<u64> {
    let period = Duration::from_secs_f64(1.0 / f64::from(fps.max(1)));
    let start = Instant::now();
    let mut n = 0u32;
    while start.elapsed() < window {
        tokio::time::sleep_until(start + period * n).await;
        publisher.publish(jpeg.clone()).await?;
        n += 1;
    }
    Ok(u64::from(n))
}
