//! hub-bench: fan-out of one publisher to 1, 4 and 16 subscribers over
//! loopback TCP through our hub (`robot-agent`), side by side in the same run
//! with Redis pub/sub and with raw TCP writes (the ceiling). See
//! docs/bench-hub.md for what is measured and why it is a fair comparison.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;
use clap::Parser;

mod modes;
mod payloads;
mod report;
mod rig;
mod servers;
mod stamp;
mod tally;

use modes::Timing;
use payloads::Payload;
use report::{Measured, Outcome};
use rig::{Endpoints, Rig, System};

/// Hub fan-out benchmark against Redis pub/sub and raw TCP.
#[derive(Debug, Parser)]
struct Args {
    /// robot-agent binary [default: next to this binary]
    #[arg(long)]
    agent: Option<PathBuf>,
    /// Keep robot-agent's built-in modules (page link, vision, TTS, brain) on,
    /// as `make run` has them; by default they are off, so that the figures,
    /// peak RSS above all, are the hub's own.
    #[arg(long)]
    with_modules: bool,
    /// Threads of the hub's socket runtime (`hub.io_threads`) [default: the
    /// server's configured default]
    #[arg(long)]
    io_threads: Option<usize>,
    /// redis-server binary (Debian package redis-server).
    #[arg(long, default_value = "redis-server")]
    redis_server: PathBuf,
    /// Fixtures directory [default: $AGENT_FIXTURES or ../shared/fixtures beside the repo]
    #[arg(long)]
    fixtures: Option<PathBuf>,
    /// Subscriber counts to measure.
    #[arg(long, value_delimiter = ',', default_value = "1,4,16")]
    subs: Vec<usize>,
    /// Payloads to measure (audio, jpeg).
    #[arg(long, value_delimiter = ',', default_value = "audio,jpeg")]
    payloads: Vec<String>,
    /// Systems to measure (hub, redis, raw); the SUMMARY lines need all three.
    #[arg(long, value_delimiter = ',', default_value = "hub,redis,raw")]
    systems: Vec<String>,
    /// Modes to run (window: lossless flat out, open: open-loop flat out,
    /// rate: fixed-rate latency); skipped ones print as zero.
    #[arg(long, value_delimiter = ',', default_value = "window,open,rate")]
    modes: Vec<String>,
    /// Sending before each flat-out measurement window (ms).
    #[arg(long, default_value_t = 300)]
    warmup_ms: u64,
    /// Flat-out measurement window (ms).
    #[arg(long, default_value_t = 1500)]
    window_ms: u64,
    /// Duration of each fixed-rate latency run (ms).
    #[arg(long, default_value_t = 3000)]
    rate_ms: u64,
    /// Messages allowed in flight to the slowest subscriber in the lossless flat-out mode.
    #[arg(long, default_value_t = 32)]
    window_msgs: u64,
    /// Lossless flat-out windows per system and configuration, taken in turn;
    /// the median is reported.
    #[arg(long, default_value_t = 3)]
    rounds: usize,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    // Two workers, as many as the target machine has cores: the servers under
    // test get the same CPU budget whichever system is measured.
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    runtime.block_on(run(args))
}

async fn run(args: Args) -> anyhow::Result<()> {
    let fixtures = args
        .fixtures
        .clone()
        .unwrap_or_else(payloads::default_fixtures);
    let payloads: Vec<Payload> = [payloads::audio(&fixtures)?, payloads::jpeg(&fixtures)?]
        .into_iter()
        .filter(|p| args.payloads.iter().any(|n| n == p.name))
        .collect();
    let timing = Timing {
        warmup: Duration::from_millis(args.warmup_ms),
        window: Duration::from_millis(args.window_ms),
        rate_run: Duration::from_millis(args.rate_ms),
        window_msgs: args.window_msgs.max(1),
        stall: Duration::from_secs(3),
    };
    let work = std::env::temp_dir().join(format!("hub-bench-{}", std::process::id()));
    std::fs::create_dir_all(&work)?;
    let result = run_in(&args, &work, &payloads, timing).await;
    if result.is_ok() {
        let _ = std::fs::remove_dir_all(&work);
    } else {
        eprintln!("hub-bench: server logs kept in {}", work.display());
    }
    result
}

async fn run_in(
    args: &Args,
    work: &Path,
    payloads: &[Payload],
    timing: Timing,
) -> anyhow::Result<()> {
    let agent_bin = args
        .agent
        .clone()
        .unwrap_or_else(servers::default_agent_bin);
    let mut agent = servers::start_agent(&agent_bin, work, !args.with_modules, args.io_threads)
        .await
        .with_context(|| {
            format!(
                "build it first: cargo build --release -p robot-agent (looked for {})",
                agent_bin.display()
            )
        })?;
    let mut redis = servers::start_redis(&args.redis_server, work).await?;
    let ends = Endpoints {
        hub: format!("tcp://{}", agent.flow_tcp)
            .parse()
            .map_err(|e| anyhow::anyhow!("robot-agent's flow address: {e}"))?,
        hub_token: agent.token.clone(),
        redis_url: redis.url.clone(),
    };
    println!("hub-bench: load average before: {}", load_average());
    let idle = |s: &servers::Server| {
        s.rss()
            .map_or("?".into(), |b| format!("{:.1} MB", b as f64 / 1e6))
    };
    println!(
        "hub-bench: idle RSS robot-agent {}, redis-server {}",
        idle(&agent.server),
        idle(&redis.server)
    );
    println!(
        "hub-bench: robot-agent pid {} at {}, redis-server pid {}; window {} msgs, \
         warm-up {:?}, flat-out window {:?}, fixed-rate runs {:?}",
        agent.server.pid,
        agent.flow_tcp,
        redis.server.pid,
        timing.window_msgs,
        timing.warmup,
        timing.window,
        timing.rate_run
    );
    let mut outcomes = Vec::new();
    let wants = |mode: &str| args.modes.iter().any(|m| m == mode);
    for payload in payloads {
        for &subs in &args.subs {
            let systems: Vec<System> = [System::Hub, System::Redis, System::RawTcp]
                .into_iter()
                .filter(|s| {
                    args.systems
                        .iter()
                        .any(|n| s.label().starts_with(n.as_str()))
                })
                .collect();
            let server_of = |system: System| match system {
                System::Hub => Some(&agent.server),
                System::Redis => Some(&redis.server),
                System::RawTcp => None,
            };
            for s in [&agent.server, &redis.server] {
                s.reset_peak();
            }
            // The throughput figure is the median of several windows taken in
            // turn (hub, redis, raw, hub, ...): on a shared two-core machine the
            // rates drift by a third over minutes, and alternating keeps the
            // ratios between systems fair whatever the drift does.
            let mut windows: Vec<Vec<modes::FlatOut>> = vec![Vec::new(); systems.len()];
            if wants("window") {
                for round in 0..args.rounds.max(1) {
                    for (i, &system) in systems.iter().enumerate() {
                        let flat = measure_window(
                            round,
                            system,
                            &ends,
                            server_of(system).map(|s| s.pid),
                            payload,
                            subs,
                            timing,
                        )
                        .await
                        .with_context(|| {
                            format!("{} {} x {subs} subscribers", system.label(), payload.name)
                        })?;
                        windows[i].push(flat);
                    }
                }
            }
            if wants("window") {
                let spread: Vec<String> = systems
                    .iter()
                    .zip(&windows)
                    .map(|(s, w)| {
                        let rates: Vec<String> = w
                            .iter()
                            .map(|f| format!("{:.0}", f.delivered_per_s))
                            .collect();
                        format!("{} [{}]", s.label(), rates.join(", "))
                    })
                    .collect();
                println!(
                    "hub-bench: {} x {subs} lossless windows, msg/s in turn: {}",
                    payload.name,
                    spread.join("; ")
                );
            }
            let mut rows = Vec::new();
            for (i, &system) in systems.iter().enumerate() {
                let server = server_of(system);
                let mut measured = measure(
                    system,
                    &ends,
                    server.map(|s| s.pid),
                    payload,
                    subs,
                    timing,
                    &args.modes,
                )
                .await
                .with_context(|| {
                    format!("{} {} x {subs} subscribers", system.label(), payload.name)
                })?;
                measured.flat = modes::median_by_rate(std::mem::take(&mut windows[i]));
                let peak_rss = server.and_then(servers::Server::peak_rss);
                rows.push(Measured {
                    peak_rss,
                    ..measured
                });
            }
            if !agent.server.alive() || !redis.server.alive() {
                anyhow::bail!("a server under test died (logs in {})", work.display());
            }
            let outcome = Outcome {
                payload: payload.clone(),
                subs,
                rows,
            };
            report::print_table(&outcome);
            outcomes.push(outcome);
        }
    }
    println!();
    println!("hub-bench: load average after: {}", load_average());
    report::print_summary(&outcomes);
    agent.server.stop().await;
    redis.server.stop().await;
    Ok(())
}

/// One lossless flat-out window against one system, on freshly connected clients.
async fn measure_window(
    round: usize,
    system: System,
    ends: &Endpoints,
    server_pid: Option<u32>,
    payload: &Payload,
    subs: usize,
    timing: Timing,
) -> anyhow::Result<modes::FlatOut> {
    // A fresh channel name per rig: the previous owner's channel may still be
    // in the middle of being removed.
    let channel = format!("Bench.{}.{subs}.window.{round}", payload.name);
    let mut rig = Rig::connect(system, ends, &channel, subs).await?;
    rig.watch_server(server_pid);
    let flat = modes::windowed(&mut rig, &payload.bytes, timing).await;
    rig.close().await;
    // Let the server finish tearing the connections down before the next system.
    tokio::time::sleep(Duration::from_millis(100)).await;
    flat
}

/// Runs the open-loop and fixed-rate modes against one system, each on
/// freshly connected clients (the windowed mode runs in rounds, apart).
async fn measure(
    system: System,
    ends: &Endpoints,
    server_pid: Option<u32>,
    payload: &Payload,
    subs: usize,
    timing: Timing,
    wanted: &[String],
) -> anyhow::Result<Measured> {
    let wants = |mode: &str| wanted.iter().any(|m| m == mode);
    // A fresh channel name per rig: the previous owner's channel may still be
    // in the middle of being removed.
    let channel = |mode: &str| format!("Bench.{}.{subs}.{mode}", payload.name);
    let mut measured = Measured {
        system,
        flat: Default::default(),
        open: Default::default(),
        rate: Default::default(),
        peak_rss: None,
    };
    if wants("open") {
        let mut rig = Rig::connect(system, ends, &channel("open"), subs).await?;
        rig.watch_server(server_pid);
        let open = modes::open_loop(&mut rig, &payload.bytes, timing).await;
        rig.close().await;
        measured.open = open?;
        // The server may still be flushing the flood to the closed subscribers.
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    if wants("rate") {
        let mut rig = Rig::connect(system, ends, &channel("rate"), subs).await?;
        let rate = modes::fixed_rate(&mut rig, &payload.bytes, payload.hz, timing).await;
        rig.close().await;
        measured.rate = rate?;
    }
    // Let the server finish tearing the connections down before the next system.
    tokio::time::sleep(Duration::from_millis(100)).await;
    Ok(measured)
}

/// The 1, 5 and 15 minute load averages: figures taken on a busy machine say so.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "unknown".into())
}
