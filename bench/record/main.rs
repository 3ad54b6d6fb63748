//! Benchmark of recording and replay (`make bench`), each figure beside its baseline in the same run:
//!
//! - Recording overhead: the hub's CPU time per delivery while a satellite publishes camera JPEGs to four
//!   subscribers, without and with a `flowctl record` of the channel as a fifth subscriber, in alternating phases
//!   (the hub process's utime + stime from /proc/PID/stat). Target: with / without <= 1.2.
//! - Replay timing: `flowctl replay` of a recording of 15 fps JPEG + 50 Hz PCM (written on an exact grid), its own
//!   lateness report and the error of arrival times at a subscriber against the recorded schedule. Target: p99
//!   lateness <= 2 ms.
//!
//! Options: `--seconds N` (per CPU phase, default 10), `--rounds N` (default 3), `--fps N` (publish rate of the CPU
//! phases, default 200), `--replay-seconds N` (default 20), `--write PATH` (the Markdown report). Needs release
//! builds of `flow-hub` and `flowctl` (`AGENT_BIN_DIR`, as `make bench` sets it).

mod overhead;
mod replay_timing;

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use clap::Parser;

/// Recording benchmark: the hub's CPU cost of a `flowctl record` subscriber, and `flowctl replay`'s timing. Needs
/// release builds of `flow-hub` and `flowctl` (`AGENT_BIN_DIR`).
#[derive(Debug, clap::Parser)]
struct Args {
    /// Seconds per CPU phase.
    #[arg(long, default_value_t = 10)]
    seconds: u64,
    /// Rounds of the alternating CPU phases.
    #[arg(long, default_value_t = 3)]
    rounds: u32,
    /// Publish rate of the CPU phases (frames per second).
    #[arg(long, default_value_t = 200)]
    fps: u32,
    /// Seconds of the replayed recording.
    #[arg(long, default_value_t = 20)]
    replay_seconds: u64,
    /// Write the Markdown report here.
    #[arg(long, value_name = "PATH")]
    write: Option<PathBuf>,
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> anyhow::Result<()> {
    let Args {
        seconds,
        rounds,
        fps,
        replay_seconds,
        write,
    } = Args::parse();
    println!(
        "recording benchmark: {rounds} rounds of {seconds} s per phase at {fps} fps, {replay_seconds} s replay"
    );
    let cost = overhead::measure(Duration::from_secs(seconds), rounds, fps).await?;
    let timing = replay_timing::measure(Duration::from_secs(replay_seconds)).await?;

    let overhead_line = format!(
        "SUMMARY record_overhead: hub CPU per delivery {:.1} us with the recorder vs {:.1} us without (ratio {:.2}; \
         per published frame {:.2}x; 4 JPEG subscribers + 1 recorder; target <= 1.2)",
        cost.with_us,
        cost.without_us,
        cost.ratio(),
        cost.frame_ratio()
    );
    let timing_line = format!(
        "SUMMARY replay_timing: lateness p50 {:.3} ms p99 {:.3} ms max {:.3} ms over {} messages; subscriber-side \
         error p99 {:.3} ms (15 fps JPEG + 50 Hz PCM; target p99 <= 2 ms)",
        timing.p50_ms, timing.p99_ms, timing.max_ms, timing.messages, timing.arrival_p99_ms
    );
    println!("{overhead_line}");
    println!("{timing_line}");
    if let Some(path) = write {
        let doc = report(
            &cost,
            &timing,
            &overhead_line,
            &timing_line,
            seconds,
            rounds,
            fps,
        );
        std::fs::write(&path, doc).with_context(|| format!("writing {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn report(
    cost: &overhead::Cost,
    timing: &replay_timing::Timing,
    overhead_line: &str,
    timing_line: &str,
    seconds: u64,
    rounds: u32,
    fps: u32,
) -> String {
    let mut rows = String::new();
    for (i, p) in cost.phases.iter().enumerate() {
        rows.push_str(&format!(
            "| {} | {} | {} | {} | {:.1} |\n",
            i / 2 + 1,
            if p.recorder {
                "with recorder"
            } else {
                "without"
            },
            p.frames,
            p.deliveries,
            p.us_per_delivery()
        ));
    }
    format!(
        "# Recording and replay benchmark\n\n\
         Written by `make bench` (`bench/record/main.rs`); the hub is `flow-hub` (release), the recorder `flowctl \
         record`, the replayer `flowctl replay`.\n\n\
         ## Recording overhead on the hub\n\n\
         A satellite publishes a 640x360 camera JPEG at {fps} fps to four subscribers over TCP for {seconds} s per \
         phase; phases without and with a `flowctl record` of the channel alternate, {rounds} rounds. CPU is the hub \
         process's utime + stime from /proc/PID/stat; a delivery is one message received by one subscriber (the \
         recorder counts as one).\n\n\
         | round | phase | frames | deliveries | hub CPU per delivery (us) |\n|---|---|---|---|---|\n{rows}\n\
         ```text\n{overhead_line}\n```\n\n\
         ## Replay timing\n\n\
         A recording of 15 fps JPEG and 50 Hz PCM (20 ms chunks) with log times on an exact grid, replayed at speed \
         1 into the hub. Lateness is the replayer's own figure (how long after its absolute deadline each message \
         was handed to the hub); the subscriber-side error compares each arrival's offset from the first arrival \
         with its recorded offset (it includes the hub's delivery).\n\n\
         | messages | p50 (ms) | p99 (ms) | max (ms) | subscriber p99 (ms) |\n|---|---|---|---|---|\n\
         | {} | {:.3} | {:.3} | {:.3} | {:.3} |\n\n```text\n{timing_line}\n```\n",
        timing.messages, timing.p50_ms, timing.p99_ms, timing.max_ms, timing.arrival_p99_ms
    )
}
