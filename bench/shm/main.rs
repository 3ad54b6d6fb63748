//! shm-bench (issue 39): the hub's shared-memory data path against the hub over TCP, raw TCP and a plain iceoryx2
//! pair, in one run. For payloads of 64 KB, 1 MB and the 640x360 camera JPEG, and 1, 4 and 16 subscribers, each
//! mode is driven flat out under a small window (every message reaches every subscriber) and measured for
//! deliveries/s and CPU per delivery (this process plus the hub process); then 1 MB at 30 Hz to 4 subscribers for
//! latency. Subscribers touch the stamp and the last byte of each payload only. See docs/bench-shm.md.
//!
//! The modes: `shm` is the hub with every client on its Unix socket, where the SDK negotiates shared memory after
//! login (without it the mode runs over bytes, and the SUMMARY says which it was); `shm-frames` the same with the
//! subscribers giving slots back in `Release` frames instead of the hub's release ring; `hub-tcp` the same hub over
//! loopback TCP; `raw-tcp` one writer to N sockets (hub-bench's ceiling); `iceoryx2` the floor.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;
use clap::Parser;

mod drive;
mod flow_rig;
mod hub;
// hub-bench's fixture loader, shared so that both benches send the same JPEG; only its `jpeg` is used here.
#[path = "../hub/payloads.rs"]
#[allow(dead_code)]
mod hub_payloads;
mod iceoryx;
mod payloads;
mod raw_tcp;
mod report;
mod rig;
mod stamp;
mod tally;

use drive::Timing;
use report::{Cell, Results};
use rig::{Mode, Rig, Target};

/// The hub's shared-memory data path against the hub over TCP, raw TCP and iceoryx2.
#[derive(Debug, Parser)]
struct Args {
    /// flow-hub binary [default: $AGENT_BIN_DIR/flow-hub, else beside this binary]
    #[arg(long)]
    hub: Option<PathBuf>,
    /// A TOML file layered over the hub's embedded configuration (passed as its `--config`).
    #[arg(long)]
    hub_config: Option<PathBuf>,
    /// Fixtures directory [default: $AGENT_FIXTURES or ../shared/fixtures beside the repo]
    #[arg(long)]
    fixtures: Option<PathBuf>,
    /// Payloads to measure (64k, 1m, jpeg).
    #[arg(long, value_delimiter = ',', default_value = "64k,1m,jpeg")]
    payloads: Vec<String>,
    /// Subscriber counts to measure.
    #[arg(long, value_delimiter = ',', default_value = "1,4,16")]
    subs: Vec<usize>,
    /// Modes to measure (shm, shm-frames, hub-tcp, raw-tcp, iceoryx2); the ratios need all of them.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "shm,shm-frames,hub-tcp,raw-tcp,iceoryx2"
    )]
    modes: Vec<String>,
    /// Sending before each flat-out measurement window (ms).
    #[arg(long, default_value_t = 300)]
    warmup_ms: u64,
    /// Flat-out measurement window of each cell (ms).
    #[arg(long, default_value_t = 2000)]
    window_ms: u64,
    /// Messages the publisher may be ahead of the slowest subscriber: no more than the slots a subscriber of the
    /// hub's shared memory may hold (`hub.shm_held`), so that the shm mode measures references, not its fallback.
    #[arg(long, default_value_t = 8)]
    window_msgs: u64,
    /// Bytes the publisher may be ahead of the slowest subscriber (fewer messages for large payloads): below the
    /// hub's per-subscriber queue (`hub.subscriber_queue_bytes`, 8 MiB), so that no mode drops.
    #[arg(long, default_value_t = 4 << 20)]
    window_bytes: u64,
    /// Flat-out windows per cell, taken in turn across the modes; the median is reported.
    #[arg(long, default_value_t = 1)]
    rounds: usize,
    /// Rate of the latency runs (Hz).
    #[arg(long, default_value_t = 30.0)]
    rate_hz: f64,
    /// Length of each latency run (ms).
    #[arg(long, default_value_t = 5000)]
    rate_ms: u64,
    /// Payload of the latency runs.
    #[arg(long, default_value = "1m")]
    rate_payload: String,
    /// Subscribers of the latency runs.
    #[arg(long, default_value_t = 4)]
    rate_subs: usize,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    // Two workers, as many as the target machine has cores (hub-bench does the same). The publisher runs on
    // this thread, in `block_on`: the iceoryx2 publisher may not move between threads.
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    runtime.block_on(run(args))
}

async fn run(args: Args) -> anyhow::Result<()> {
    let modes: Vec<Mode> = Mode::ALL
        .into_iter()
        .filter(|m| args.modes.iter().any(|n| n == m.label()))
        .collect();
    anyhow::ensure!(!modes.is_empty(), "no known mode in {:?}", args.modes);
    let fixtures = args
        .fixtures
        .clone()
        .unwrap_or_else(hub_payloads::default_fixtures);
    let all = payloads::all(&fixtures)?;
    let rate_payload = all
        .iter()
        .find(|p| p.name == args.rate_payload)
        .cloned()
        .with_context(|| format!("no payload {:?} (64k, 1m, jpeg)", args.rate_payload))?;
    let payloads: Vec<payloads::Payload> = all
        .into_iter()
        .filter(|p| args.payloads.iter().any(|n| n == p.name))
        .collect();
    let timing = Timing {
        warmup: Duration::from_millis(args.warmup_ms),
        window: Duration::from_millis(args.window_ms),
        window_msgs: args.window_msgs.max(1),
        rate_run: Duration::from_millis(args.rate_ms),
        stall: Duration::from_secs(5),
    };
    let work = std::env::temp_dir().join(format!("shm-bench-{}", std::process::id()));
    std::fs::create_dir_all(&work)?;
    let mut results = Results {
        payloads,
        subs: args.subs.clone(),
        modes,
        latency_label: format!(
            "{} Hz, {}, {} subs",
            args.rate_hz,
            rate_payload.human(),
            args.rate_subs
        ),
        ..Results::default()
    };
    let outcome = run_in(&args, &work, timing, &rate_payload, &mut results).await;
    if outcome.is_ok() {
        let _ = std::fs::remove_dir_all(&work);
    } else {
        eprintln!("shm-bench: the hub's log is kept in {}", work.display());
    }
    outcome
}

async fn run_in(
    args: &Args,
    work: &Path,
    timing: Timing,
    rate_payload: &payloads::Payload,
    results: &mut Results,
) -> anyhow::Result<()> {
    let bin = args.hub.clone().unwrap_or_else(hub::default_bin);
    let mut hub = hub::start(&bin, work, args.hub_config.as_deref()).await?;
    println!(
        "shm-bench: commit {}, flow-hub pid {} at {} and {}; load average {}",
        agent_bench::summary::current_commit(),
        hub.pid,
        hub.tcp,
        hub.unix,
        load_average()
    );
    println!(
        "shm-bench: window {} msgs and at most {} bytes, warm-up {:?}, flat-out window {:?} x {} round(s), \
         latency runs {:?}",
        timing.window_msgs,
        args.window_bytes,
        timing.warmup,
        timing.window,
        args.rounds,
        timing.rate_run
    );
    let memfd_before = flow_rig::memfd_mappings();
    let payloads = results.payloads.clone();
    for payload in &payloads {
        let cell_timing = Timing {
            window_msgs: (args.window_bytes / payload.bytes.len().max(1) as u64)
                .clamp(1, timing.window_msgs),
            ..timing
        };
        println!(
            "shm-bench: {}: window {} msgs",
            payload.label(),
            cell_timing.window_msgs
        );
        for &subs in &args.subs {
            let mut runs: Vec<Vec<drive::Flat>> = vec![Vec::new(); results.modes.len()];
            // Rounds alternate the modes (shm, hub-tcp, raw-tcp, iceoryx2, shm, ...), so that a drift of the
            // machine's speed over the run touches every mode alike.
            for round in 0..args.rounds.max(1) {
                for (i, &mode) in results.modes.clone().iter().enumerate() {
                    let name = format!(
                        "Bench.shm.{}.{}.{subs}.{}.{round}",
                        std::process::id(),
                        payload.name,
                        mode.label()
                    );
                    let target = Target {
                        hub: &hub,
                        name: &name,
                        subscribers: subs,
                        payload_len: payload.bytes.len(),
                        buffer: cell_timing.window_msgs as usize + 4,
                    };
                    let mut rig = Rig::connect(mode, target)
                        .await
                        .with_context(|| format!("{} {} x {subs}", mode.label(), payload.name))?;
                    let flat = drive::flat_out(&mut rig, &payload.bytes, cell_timing).await;
                    if mode == Mode::Shm {
                        let held = flow_rig::memfd_mappings().saturating_sub(memfd_before);
                        results.memfd_mappings = results.memfd_mappings.max(held);
                    }
                    rig.close();
                    runs[i].push(
                        flat.with_context(|| {
                            format!("{} {} x {subs}", mode.label(), payload.name)
                        })?,
                    );
                    // Let the hub finish tearing the connections down before the next mode.
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
            }
            for (i, &mode) in results.modes.clone().iter().enumerate() {
                runs[i].sort_by(|a, b| a.deliveries_per_s.total_cmp(&b.deliveries_per_s));
                let median = runs[i]
                    .get(runs[i].len().saturating_sub(1) / 2)
                    .copied()
                    .unwrap_or_default();
                results.cells.push(Cell {
                    payload: payload.name,
                    subs,
                    mode,
                    flat: median,
                });
            }
            anyhow::ensure!(
                hub.alive(),
                "flow-hub died (its log is in {})",
                work.display()
            );
        }
        report::print_table(results, payload);
    }
    for &mode in &results.modes.clone() {
        let name = format!("Bench.shm.{}.rate.{}", std::process::id(), mode.label());
        let target = Target {
            hub: &hub,
            name: &name,
            subscribers: args.rate_subs,
            payload_len: rate_payload.bytes.len(),
            buffer: timing.window_msgs as usize + 4,
        };
        let mut rig = Rig::connect(mode, target)
            .await
            .with_context(|| format!("{} latency", mode.label()))?;
        let latency = drive::fixed_rate(&mut rig, &rate_payload.bytes, args.rate_hz, timing).await;
        rig.close();
        results.latency.push((
            mode,
            latency.with_context(|| format!("{} latency", mode.label()))?,
        ));
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    report::print_latency(results);
    println!();
    println!("shm-bench: load average after: {}", load_average());
    report::print_summary(results);
    hub.stop().await;
    Ok(())
}

/// The 1, 5 and 15 minute load averages: figures taken on a busy machine say so.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "unknown".into())
}
