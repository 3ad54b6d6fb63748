//! Benchmark of the federation (`make bench`), each figure beside its baseline in the same run:
//!
//! - Added latency: the fixture JPEG (640x360) at 15 fps and 20 ms of PCM at 50 Hz published on hub A, received by a
//!   subscriber on hub A and one on hub B (through the federation); the added latency is B's percentile minus A's.
//!   Baseline: a plain Zenoh pub/sub pair (two sessions over TCP loopback) carrying the same payloads at the same
//!   rates, the engine's own floor. Target: added p99 <= 1 ms.
//! - Throughput: the JPEG published as fast as the producer can, delivered per second on hub B; against the plain
//!   Zenoh pair flat out and raw TCP (length-prefixed frames over a loopback socket). Target: >= 0.8x the Zenoh pair.
//!   Measured with the producer and the reader as TCP satellites of two `flow-hub` processes (four processes' work
//!   on the cores), and with both hubs and their producer and reader modules in this process, as the Zenoh pair's
//!   two sessions are, each hub on a runtime of its own (`in_process.rs`): the federation against the engine
//!   alone, with one worker per core as `flow-hub` runs and with one worker per hub.
//!
//! Options: `--seconds N` (per latency phase, default 20), `--burst-seconds N` (per throughput phase, default 5),
//! `--write PATH` (the Markdown report). Needs release builds of `flow-hub` (`AGENT_BIN_DIR`, as `make bench` sets
//! it) and the shared fixtures.

mod in_process;
mod links;

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use clap::Parser;

use agent_bench::percentile;

/// Federation benchmark: the latency two federated hubs add and their throughput, against a plain Zenoh pair and
/// raw TCP. Needs release builds of `flow-hub` (`AGENT_BIN_DIR`) and the shared fixtures.
#[derive(Debug, clap::Parser)]
struct Args {
    /// Seconds per latency phase.
    #[arg(long, default_value_t = 20)]
    seconds: u64,
    /// Seconds per throughput phase.
    #[arg(long, default_value_t = 5)]
    burst_seconds: u64,
    /// Write the Markdown report here.
    #[arg(long, value_name = "PATH")]
    write: Option<PathBuf>,
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> anyhow::Result<()> {
    let Args {
        seconds,
        burst_seconds: burst,
        write,
    } = Args::parse();
    let fixtures = agent_tests::fixtures::fixtures();
    let jpeg = std::fs::read(fixtures.join("faces/derived/fr_two_people_640x360.jpg"))
        .context("reading the fixture JPEG")?;
    // 20 ms of s16 mono at 22050 Hz, as the page sends the microphone.
    let pcm = vec![0u8; 882];
    println!(
        "federation benchmark: {seconds} s of 15 fps JPEG ({} B) + 50 Hz PCM ({} B), {burst} s flat out",
        jpeg.len(),
        pcm.len()
    );

    let hubs = links::Hubs::start().await?;
    let fed = hubs
        .latency(&jpeg, &pcm, Duration::from_secs(seconds))
        .await?;
    let zen = links::zenoh_latency(&jpeg, &pcm, Duration::from_secs(seconds)).await?;
    let hub_rate = hubs.throughput(&jpeg, Duration::from_secs(burst)).await?;
    let link_rate = in_process::throughput(&jpeg, Duration::from_secs(burst), None).await?;
    let one_thread_rate =
        in_process::throughput(&jpeg, Duration::from_secs(burst), Some(1)).await?;
    let zenoh_rate = links::zenoh_throughput(&jpeg, Duration::from_secs(burst)).await?;
    let tcp_rate = links::tcp_throughput(&jpeg, Duration::from_secs(burst)).await?;

    let mut lines = Vec::new();
    for (kind, local, remote, floor) in [
        ("jpeg 15 fps", &fed.jpeg_local, &fed.jpeg_remote, &zen.jpeg),
        ("pcm 50 Hz", &fed.pcm_local, &fed.pcm_remote, &zen.pcm),
    ] {
        let p = |v: &Vec<f64>, q| percentile(v, q);
        let added50 = p(remote, 0.5) - p(local, 0.5);
        let added99 = p(remote, 0.99) - p(local, 0.99);
        lines.push(format!(
            "SUMMARY federation latency {kind}: hub A -> hub B p50 {:.3} ms p99 {:.3} ms; same-hub subscriber p50 \
             {:.3} ms p99 {:.3} ms; added p50 {added50:.3} ms p99 {added99:.3} ms (target p99 <= 1 ms); plain Zenoh \
             pair p50 {:.3} ms p99 {:.3} ms (added p99 vs the Zenoh floor: {:.3} ms); {} / {} messages",
            p(remote, 0.5),
            p(remote, 0.99),
            p(local, 0.5),
            p(local, 0.99),
            p(floor, 0.5),
            p(floor, 0.99),
            p(remote, 0.99) - p(floor, 0.99),
            remote.len(),
            local.len(),
        ));
    }
    lines.push(format!(
        "SUMMARY federation throughput jpeg ({} B): hub A -> hub B {:.0} msg/s ({:.1} MB/s); plain Zenoh pair {:.0} \
         msg/s (ratio {:.2}, target >= 0.8); raw TCP {:.0} msg/s (ratio {:.2})",
        jpeg.len(),
        hub_rate,
        hub_rate * jpeg.len() as f64 / 1e6,
        zenoh_rate,
        hub_rate / zenoh_rate,
        tcp_rate,
        hub_rate / tcp_rate,
    ));
    lines.push(format!(
        "SUMMARY federation throughput jpeg, the federation alone (both hubs in this process, each on a runtime of \
         its own as in its own process, with an in-server producer and reader): {:.0} msg/s ({:.1} MB/s); plain \
         Zenoh pair {:.0} msg/s (ratio {:.2}, target >= 0.8); with one worker thread per hub {:.0} msg/s (ratio \
         {:.2})",
        link_rate,
        link_rate * jpeg.len() as f64 / 1e6,
        zenoh_rate,
        link_rate / zenoh_rate,
        one_thread_rate,
        one_thread_rate / zenoh_rate,
    ));
    for l in &lines {
        println!("{l}");
    }
    if let Some(path) = write {
        let doc = format!(
            "# Federation benchmark\n\nFrom `federation-bench` (`make bench`), release build, on this project's \
             2-core machine: two `flow-hub` processes on loopback federating over Zenoh, against a plain Zenoh pair \
             and raw TCP in the same run. {seconds} s per latency phase, {burst} s per throughput phase. See \
             docs/federation.md.\n\n```\n{}\n```\n\n- Latencies are measured from the publisher's clock stamp in \
             the payload to the subscriber's arrival, on one machine.\n- \"Added\" is hub B's percentile minus \
             that of a subscriber on hub A in the same run: what the federation adds to a local delivery.\n- \
             Throughput counts messages delivered on hub B per second while the producer publishes as fast as its \
             hub takes them; the federation drops (drop-oldest, counted) what the network cannot carry.\n- \
             The second throughput line runs both hubs inside the benchmark's process, each on a tokio runtime of \
             its own (as in its own process; by default one worker per core, as `flow-hub` has), with the producer \
             and the reader as in-server modules (in-process links), as the plain Zenoh pair runs both its sessions \
             in one process: it compares the federation with the engine alone. It is measured again with one \
             worker thread per hub. The first line adds the satellites' TCP hops into hub A and out of hub B, and \
             the work of four processes on the same two cores.\n",
            lines.join("\n")
        );
        std::fs::write(&path, doc).with_context(|| format!("writing {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    hubs.stop().await;
    Ok(())
}
