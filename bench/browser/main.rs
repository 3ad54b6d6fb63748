//! Benchmark of the browser link (`make bench`): server CPU and memory while one real browser streams audio and
//! video with the Y and FFT modules on, and the latency the link adds between a page's WebSocket and a hub
//! subscriber. Each figure is measured side by side with a baseline in the same run:
//!
//! - CPU/RSS baseline: the same media (the same JPEG frames at 15 fps and 20 ms PCM chunks) published straight
//!   into the hub by a flow satellite over TCP, with the same Y and FFT subscribers.
//! - Latency baseline: a flow satellite publishing over TCP to the same subscriber.
//!
//! Options: `--seconds N` (streaming window per CPU phase, default 60), `--chunks N` (latency samples per path,
//! default 1500). Needs a built `robot-agent` (found like the integration tests find it), chromium and ffmpeg.

use agent_contract::channels as ch;
use std::path::Path;
use std::time::{Duration, Instant};

use agent_bench::{cpu_ticks, percentile};
use agent_tests::browser_chromium::Chromium;
use agent_tests::browser_link::{session_token, start_link_only};
use agent_tests::browser_media::{prepare, read_wav, speech_fixture};
use agent_tests::fixtures::fixtures;
use agent_tests::{Agent, DataDir};
use anyhow::{Context, bail};
use bytes::Bytes;
use clap::Parser;
use futures_util::{SinkExt, StreamExt};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

const CHUNK_BYTES: usize = 882; // 20 ms at 22050 Hz, s16le mono

/// Browser link benchmark: server CPU and memory with a real browser streaming, and the latency the link adds,
/// each against a flow satellite over TCP. Needs a built `robot-agent`, chromium and ffmpeg.
#[derive(Debug, clap::Parser)]
struct Args {
    /// Streaming window per CPU phase (s).
    #[arg(long, default_value_t = 60)]
    seconds: u64,
    /// Latency samples per path.
    #[arg(long, default_value_t = 1500)]
    chunks: usize,
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let Args { seconds, chunks } = Args::parse();
    let window = Duration::from_secs(seconds);
    let dir = tempfile::Builder::new()
        .prefix("bench-browser-")
        .tempdir()?;
    let (speech, _) = prepare(dir.path())?;

    println!(
        "browser link benchmark: {seconds} s per CPU phase, {chunks} latency samples per path"
    );
    let browser = browser_phase(&speech, window).await?;
    let direct = satellite_phase(window).await?;
    let (link_lat, direct_lat) = latency_phase(chunks).await?;

    println!();
    println!("phase               cpu%    rss MiB   audio/s  video/s  y/s   fft/s");
    for (name, m) in [("browser (link)", &browser), ("satellite (tcp)", &direct)] {
        println!(
            "{name:<18} {:>6.2}  {:>8.1}  {:>7.1}  {:>7.1}  {:>5.1} {:>5.1}",
            m.cpu_pct, m.rss_mib, m.rates[0], m.rates[1], m.rates[2], m.rates[3]
        );
    }
    let p = |v: &[f64], q: f64| percentile(v, q);
    println!("latency (ms)        p50     p99     max");
    for (name, v) in [
        ("link: ws -> sub", &link_lat),
        ("direct: tcp -> sub", &direct_lat),
    ] {
        println!(
            "{name:<18} {:>6.3}  {:>6.3}  {:>6.3}",
            p(v, 0.5),
            p(v, 0.99),
            p(v, 1.0)
        );
    }
    let added50 = p(&link_lat, 0.5) - p(&direct_lat, 0.5);
    let added99 = p(&link_lat, 0.99) - p(&direct_lat, 0.99);
    println!();
    println!(
        "SUMMARY browser_ingest_cpu: {:.2}% of one core (baseline satellite {:.2}%, ratio {:.2}; target <= 10%)",
        browser.cpu_pct,
        direct.cpu_pct,
        browser.cpu_pct / direct.cpu_pct.max(1e-9)
    );
    println!(
        "SUMMARY browser_ingest_rss: {:.1} MiB (baseline satellite {:.1} MiB, ratio {:.2})",
        browser.rss_mib,
        direct.rss_mib,
        browser.rss_mib / direct.rss_mib.max(1e-9)
    );
    println!(
        "SUMMARY browser_link_added_latency_p50: {added50:.3} ms (baseline direct {:.3} ms, ratio {:.2})",
        p(&direct_lat, 0.5),
        p(&link_lat, 0.5) / p(&direct_lat, 0.5).max(1e-9)
    );
    println!(
        "SUMMARY browser_link_added_latency_p99: {added99:.3} ms (baseline direct {:.3} ms, ratio {:.2}; target <= 2 ms)",
        p(&direct_lat, 0.99),
        p(&link_lat, 0.99) / p(&direct_lat, 0.99).max(1e-9)
    );
    Ok(())
}

/// CPU, memory and message rates of one phase.
#[derive(Debug)]
struct Phase {
    cpu_pct: f64,
    rss_mib: f64,
    /// Messages per second on Agent.audio, Agent.video, Agent.video.y, Agent.audio.fft.
    rates: [f64; 4],
}

/// Subscribes to the four media channels (the Y and FFT modules work only while subscribed) and counts messages.
async fn count_channels(
    hub: &flow::Client,
) -> anyhow::Result<(
    tokio::task::JoinSet<(usize, u64)>,
    tokio::sync::watch::Sender<bool>,
)> {
    let (stop, stopped) = tokio::sync::watch::channel(false);
    let mut set = tokio::task::JoinSet::new();
    for (i, name) in [
        ch::AUDIO.name,
        ch::VIDEO.name,
        ch::VIDEO_Y.name,
        ch::AUDIO_FFT.name,
    ]
    .into_iter()
    .enumerate()
    {
        let sub = hub.subscribe(name).await?;
        let mut stopped = stopped.clone();
        set.spawn(async move {
            let mut n = 0u64;
            loop {
                tokio::select! {
                    _ = stopped.changed() => return (i, n),
                    d = sub.recv() => if d.is_some() { n += 1 } else { return (i, n) },
                }
            }
        });
    }
    Ok((set, stop))
}

/// Measures the server over `window` while media streams; returns the phase figures.
async fn measure(agent: &Agent, hub: &flow::Client, window: Duration) -> anyhow::Result<Phase> {
    let pid = agent.pid().context("robot-agent has exited")?;
    // Warm up: the page's first seconds (JIT, channel creation) are not the steady state.
    tokio::time::sleep(Duration::from_secs(3)).await;
    let (mut counters, stop) = count_channels(hub).await?;
    tokio::time::sleep(Duration::from_secs(1)).await;
    let cpu0 = cpu_ticks(pid)?;
    let t0 = Instant::now();
    let mut rss_max = 0u64;
    while t0.elapsed() < window {
        tokio::time::sleep(Duration::from_secs(1)).await;
        rss_max = rss_max.max(rss_kib(pid)?);
    }
    let cpu1 = cpu_ticks(pid)?;
    let elapsed = t0.elapsed().as_secs_f64();
    let _ = stop.send(true);
    let mut rates = [0f64; 4];
    while let Some(r) = counters.join_next().await {
        let (i, n) = r?;
        // The counters started one second before the CPU window.
        rates[i] = n as f64 / (elapsed + 1.0);
    }
    let hz = clock_ticks_per_second();
    Ok(Phase {
        cpu_pct: (cpu1 - cpu0) as f64 / hz / elapsed * 100.0,
        rss_mib: rss_max as f64 / 1024.0,
        rates,
    })
}

fn kiosk_url(agent: &Agent) -> String {
    agent.page_url("autostart=1&aec=0")
}

async fn browser_phase(
    media: &agent_tests::browser_chromium::FakeMedia,
    window: Duration,
) -> anyhow::Result<Phase> {
    let data = DataDir::new()?;
    let agent = start_link_only(&data).await?;
    let hub = agent.client("bench").await?;
    let browser = Chromium::launch(media).await?;
    let tab = browser.open(&kiosk_url(&agent)).await?;
    browser
        .wait_for(
            &tab,
            "window.agentDebug && agentDebug.role === 'holder' && agentDebug.sent.video > 0",
            Duration::from_secs(30),
        )
        .await?;
    println!("browser phase: streaming from headless Chromium");
    let phase = measure(&agent, &hub, window).await?;
    let sent = browser.eval(&tab, "agentDebug.sent").await?;
    println!("browser phase: page sent {sent}");
    let status = agent_tests::http::get_json(agent.http, "/api/status", agent.token()).await?;
    println!("browser phase: Y module {}", status["modules"]["video_y"]);
    browser.quit().await;
    Ok(phase)
}

/// The same media published by a flow satellite over TCP: the recorded camera frames at 15 fps and the speech
/// fixture in 20 ms chunks.
async fn satellite_phase(window: Duration) -> anyhow::Result<Phase> {
    let data = DataDir::new()?;
    let agent = start_link_only(&data).await?;
    let hub = agent.client("bench").await?;
    let sat = agent.client("satellite").await?;
    let frames =
        load_frames(&fixtures().join("motion/derived/intel_one-by-one_t2-10s_640x360_15fps"))?;
    let (_, pcm) = read_wav(&speech_fixture())?;
    let pcm: Vec<u8> = pcm.iter().flat_map(|s| s.to_le_bytes()).collect();
    let audio = sat
        .publisher(
            ch::AUDIO.name,
            r#"{"format":"s16le","rate":22050,"channels":1,"chunk_ms":20}"#,
        )
        .await?;
    let video = sat
        .publisher(
            ch::VIDEO.name,
            r#"{"format":"jpeg","width":640,"height":360,"fps":15}"#,
        )
        .await?;
    let (stop, mut stopped) = tokio::sync::watch::channel(false);
    let feeder = tokio::spawn(async move {
        let mut a = tokio::time::interval(Duration::from_millis(20));
        let mut v = tokio::time::interval(Duration::from_micros(66_667));
        let (mut ai, mut vi) = (0usize, 0usize);
        loop {
            tokio::select! {
                _ = stopped.changed() => return,
                _ = a.tick() => {
                    let start = (ai * CHUNK_BYTES) % (pcm.len() - CHUNK_BYTES);
                    let _ = audio.publish(Bytes::copy_from_slice(&pcm[start..start + CHUNK_BYTES])).await;
                    ai += 1;
                }
                _ = v.tick() => {
                    let _ = video.publish(frames[vi % frames.len()].clone()).await;
                    vi += 1;
                }
            }
        }
    });
    println!("satellite phase: publishing the same media over TCP");
    let phase = measure(&agent, &hub, window).await?;
    let _ = stop.send(true);
    let _ = feeder.await;
    Ok(phase)
}

fn load_frames(dir: &Path) -> anyhow::Result<Vec<Bytes>> {
    let mut names: Vec<_> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    names.sort();
    names
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "jpg"))
        .map(|p| Ok(Bytes::from(std::fs::read(p)?)))
        .collect()
}

/// Latency samples (ms) of the link path (page WebSocket -> hub subscriber) and of the direct path (flow TCP
/// publisher -> the same subscriber), interleaved so both see the same machine load.
async fn latency_phase(chunks: usize) -> anyhow::Result<(Vec<f64>, Vec<f64>)> {
    let data = DataDir::new()?;
    let agent = start_link_only(&data).await?;
    let hub = agent.client("bench").await?;
    let link_sub = hub.subscribe(ch::AUDIO.name).await?;
    let direct_sub = hub.subscribe("Bench.direct").await?;
    let sat = agent.client("satellite").await?;
    let direct = sat
        .publisher("Bench.direct", r#"{"format":"s16le"}"#)
        .await?;

    // A minimal page: session, socket, claim, media on.
    let origin = format!("http://{}", agent.http);
    let http = agent.http.to_string();
    let token = session_token(&http, agent.page_token()).await?;
    let mut req = format!("ws://{http}/link?session={token}").into_client_request()?;
    req.headers_mut().insert("Origin", origin.parse()?);
    req.headers_mut().insert(
        "Authorization",
        format!("Bearer {}", agent.page_token()).parse()?,
    );
    // Browsers send WebSocket frames with Nagle's algorithm off; so does this page stand-in.
    let (ws, _) = tokio_tungstenite::connect_async_with_config(req, None, true).await?;
    let (mut tx, mut rx) = ws.split();
    tokio::spawn(async move { while let Some(Ok(_)) = rx.next().await {} });
    tx.send(Message::Text(r#"{"type":"claim"}"#.into())).await?;
    tx.send(Message::Text(
        r#"{"type":"media","audio":true,"video":false}"#.into(),
    ))
    .await?;
    let deadline = Instant::now() + Duration::from_secs(10);
    while hub.channel(ch::AUDIO.name).await.is_err() {
        if Instant::now() > deadline {
            bail!("the link did not create Agent.audio");
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }

    let mut link = Vec::with_capacity(chunks);
    let mut base = Vec::with_capacity(chunks);
    let mut tick = tokio::time::interval(Duration::from_millis(20));
    for i in 0..chunks + 50 {
        tick.tick().await;
        let mut chunk = vec![0u8; CHUNK_BYTES];
        chunk[..8].copy_from_slice(&(i as u64).to_le_bytes());
        let mut frame = vec![0x01, 1, 0, 0];
        frame.extend_from_slice(&(i as u32).to_le_bytes());
        frame.extend_from_slice(&chunk);
        let t = Instant::now();
        tx.send(Message::Binary(frame.into())).await?;
        let got = tokio::time::timeout(Duration::from_secs(2), link_sub.recv())
            .await?
            .context("link closed")?;
        let dt_link = t.elapsed();
        if got.payload.get(..8) != Some(&chunk[..8]) {
            bail!("link delivered chunk out of order");
        }
        let t = Instant::now();
        direct.publish(Bytes::from(chunk)).await?;
        tokio::time::timeout(Duration::from_secs(2), direct_sub.recv())
            .await?
            .context("direct closed")?;
        let dt_direct = t.elapsed();
        // The first 50 are warm-up (allocations, connection buffers).
        if i >= 50 {
            link.push(dt_link.as_secs_f64() * 1e3);
            base.push(dt_direct.as_secs_f64() * 1e3);
        }
    }
    Ok((link, base))
}

fn rss_kib(pid: u32) -> anyhow::Result<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    let line = status
        .lines()
        .find(|l| l.starts_with("VmRSS:"))
        .context("no VmRSS")?;
    Ok(line
        .split_whitespace()
        .nth(1)
        .context("VmRSS value")?
        .parse()?)
}

fn clock_ticks_per_second() -> f64 {
    // Linux reports /proc times in USER_HZ, which is 100 on every architecture Debian ships.
    100.0
}
