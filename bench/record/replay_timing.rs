//! The replay-timing phase: a recording of 15 fps JPEG + 50 Hz PCM on an exact grid, replayed by `flowctl replay`,
//! with its lateness and the subscriber-side error of arrival times.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use agent_bench::percentile;
use agent_tests::{Agent, DataDir, fixture, run};
use anyhow::Context;
use bytes::Bytes;
use flow::{ChannelInfo, ChannelKind, ChannelStats, Data};
use flow_record::SinkOptions;
use flow_record::sink::Sink;
use tokio::time::Instant;

const VIDEO: &str = "Bench.replay.video";
const AUDIO: &str = "Bench.replay.audio";

/// What the replay measured.
#[derive(Debug, Clone, Default)]
pub struct Timing {
    pub messages: u64,
    pub p50_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
    pub arrival_p99_ms: f64,
}

pub async fn measure(length: Duration) -> anyhow::Result<Timing> {
    let work = tempfile::tempdir()?;
    let file = work.path().join("grid.mcap");
    let messages = write_grid(&file, length)?;
    let dir = DataDir::new()?;
    let hub = Agent::hub(&dir).await?;
    let client = hub.client("bench-replay-watch").await?;
    let arrivals: Arc<Mutex<Vec<(u64, Instant)>>> = Arc::default();
    for name in [VIDEO, AUDIO] {
        let sub = client.subscribe(name).await?;
        let seen = arrivals.clone();
        sub.spawn_callback(move |d| {
            let at = Instant::now();
            // The payload's first 8 bytes are its recorded offset in microseconds.
            if let Some(offset) = d.payload.get(..8).and_then(|b| b.try_into().ok())
                && let Ok(mut seen) = seen.lock()
            {
                seen.push((u64::from_le_bytes(offset), at));
            }
        });
    }
    let mut cmd = hub.flowctl()?;
    cmd.arg("replay").arg(&file).arg("--wait-subscriber");
    let out = run(cmd, b"", length + Duration::from_secs(120))
        .await?
        .ok()?;
    println!("{}", out.trim_end());
    let lateness = out
        .lines()
        .find(|l| l.starts_with("lateness over"))
        .context("flowctl replay printed no lateness")?;
    let ms = |key: &str| -> anyhow::Result<f64> {
        let after = lateness
            .split(key)
            .nth(1)
            .with_context(|| format!("no {key} in {lateness}"))?;
        Ok(after
            .split_whitespace()
            .next()
            .context("no value")?
            .parse()?)
    };
    // The last deliveries may still be on their way; the arrivals are read once the count is complete.
    let settle = Instant::now() + Duration::from_secs(10);
    while arrivals.lock().map(|a| a.len() as u64).unwrap_or(0) < messages && Instant::now() < settle
    {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let mut seen = arrivals.lock().map(|a| a.clone()).unwrap_or_default();
    seen.sort_by_key(|(_, at)| *at);
    let errors: Vec<f64> = match seen.first() {
        Some(&(offset0, at0)) => seen
            .iter()
            .map(|&(offset, at)| {
                let want = offset.saturating_sub(offset0) as f64 / 1000.0;
                let got = at.duration_since(at0).as_secs_f64() * 1000.0;
                (got - want).abs()
            })
            .collect(),
        None => Vec::new(),
    };
    Ok(Timing {
        messages,
        p50_ms: ms("p50")?,
        p99_ms: ms("p99")?,
        max_ms: ms("max")?,
        arrival_p99_ms: percentile(&errors, 0.99),
    })
}

fn channel(id: i16, name: &str, header: &str) -> ChannelInfo {
    ChannelInfo {
        id,
        hash: 0,
        kind: ChannelKind::Stream,
        name: name.into(),
        owner: "bench#0".into(),
        header: header.into(),
        stats: ChannelStats::default(),
    }
}

/// Writes `length` of 15 fps JPEG and 50 Hz PCM with log times exactly on their grids; each payload starts with
/// its offset in microseconds, so that a subscriber knows when it was due. Returns the message count.
fn write_grid(path: &std::path::Path, length: Duration) -> anyhow::Result<u64> {
    let jpeg = std::fs::read(fixture("faces/derived/fr_two_people_640x360.jpg")?)?;
    let mut sink = Sink::create(path, &SinkOptions::default())?;
    sink.channel(channel(
        1,
        VIDEO,
        r#"{"format":"jpeg","width":640,"height":360,"fps":15}"#,
    ));
    sink.channel(channel(
        2,
        AUDIO,
        r#"{"format":"s16le","rate":22050,"channels":1,"chunk_ms":20}"#,
    ));
    let t0_ns: u64 = 1_800_000_000_000_000_000;
    let mut events: Vec<(u64, &str)> = Vec::new();
    let total_us = u64::try_from(length.as_micros())?;
    let mut t = 0;
    while t < total_us {
        events.push((t, VIDEO));
        t += 1_000_000 / 15;
    }
    let mut t = 0;
    while t < total_us {
        events.push((t, AUDIO));
        t += 20_000;
    }
    events.sort_unstable();
    let (mut vseq, mut aseq) = (0u64, 0u64);
    for (offset_us, name) in &events {
        let mut payload = offset_us.to_le_bytes().to_vec();
        let seq = if *name == VIDEO {
            payload.extend_from_slice(&jpeg);
            vseq += 1;
            vseq
        } else {
            // 20 ms of s16le mono at 22050 Hz: 441 samples.
            payload.resize(8 + 882, 0);
            aseq += 1;
            aseq
        };
        let data = Data {
            channel: 1,
            seq,
            ts_us: t0_ns / 1000 + offset_us,
            payload: Bytes::from(payload),
        };
        sink.message(name, &data, t0_ns + offset_us * 1000)?;
    }
    sink.finish()?;
    Ok(events.len() as u64)
}
